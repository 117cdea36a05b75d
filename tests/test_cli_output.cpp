// The command-line tool's output files (tools/cli.h, Output) and the scenes' pictures
// (scenes::Image::writePng): written beside the destination and renamed over it, so that a run
// that fails, throws or is interrupted leaves an existing file as it was and no temporary file
// behind.
#include "core/mesh.h"
#include "scenes/output_file.h"
#include "scenes/render.h"
#include "tools/cli.h"

#include <catch2/catch.hpp>

#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using meshsweeper::cli::IoError;
using meshsweeper::cli::Output;

namespace {

// A fresh directory under the build's temporary directory, removed with the object.
struct Scratch {
  fs::path dir;
  explicit Scratch(const std::string& name) {
    dir = fs::temp_directory_path() / ("meshsweeper_test_cli_output_" + name + "_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  ~Scratch() {
    std::error_code error;
    fs::remove_all(dir, error);
  }
  std::string path(const std::string& name) const { return (dir / name).string(); }
  // The names in the directory, sorted.
  std::vector<std::string> names() const {
    std::vector<std::string> out;
    for (const auto& entry : fs::directory_iterator(dir)) out.push_back(entry.path().filename().string());
    std::sort(out.begin(), out.end());
    return out;
  }
};

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

void writeFile(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

unsigned permissions(const std::string& path) {
  struct stat st {};
  REQUIRE(::stat(path.c_str(), &st) == 0);
  return st.st_mode & 07777;
}

}  // namespace

TEST_CASE("output: an existing file is replaced only when close() succeeds", "[cli][output]") {
  Scratch s("replace");
  const std::string file = s.path("result.json");
  writeFile(file, "keep\n");
  ::chmod(file.c_str(), 0640);
  {
    Output out(file);
    out.write("new contents\n");
    // Until close(), the destination holds what it held, and the rows go to a temporary file
    // beside it.
    CHECK(readFile(file) == "keep\n");
    const std::vector<std::string> names = s.names();
    REQUIRE(names.size() == 2);
    CHECK(names[0] == "result.json");
    CHECK(names[1].rfind("result.json.partial-", 0) == 0);
    out.close();
  }
  CHECK(readFile(file) == "new contents\n");
  CHECK(permissions(file) == 0640);
  CHECK(s.names() == std::vector<std::string>{"result.json"});
}

TEST_CASE("output: a run that throws before close() leaves the file as it was", "[cli][output]") {
  Scratch s("throw");
  const std::string file = s.path("result.csv");
  writeFile(file, "keep\n");
  try {
    Output out(file);
    out.write("half a result");
    throw std::runtime_error("the computation failed");
  } catch (const std::runtime_error&) {
  }
  CHECK(readFile(file) == "keep\n");
  CHECK(s.names() == std::vector<std::string>{"result.csv"});
  // A new file is not created at all.
  try {
    Output out(s.path("new.csv"));
    throw std::runtime_error("the computation failed");
  } catch (const std::runtime_error&) {
  }
  CHECK(s.names() == std::vector<std::string>{"result.csv"});
}

TEST_CASE("output: an interrupted run leaves the file as it was and no temporary file", "[cli][output]") {
  Scratch s("signal");
  const std::string file = s.path("result.json");
  // Every signal that ends a process by default, save a fault's (found by an audit: SIGQUIT,
  // SIGALRM, SIGUSR1 and a full file's SIGXFSZ left the temporary behind).
  for (const int sig : {SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGPIPE, SIGALRM, SIGUSR1, SIGUSR2, SIGXCPU,
                        SIGXFSZ, SIGVTALRM, SIGPROF, SIGIO, SIGPWR, SIGRTMIN, SIGRTMAX}) {
    writeFile(file, "keep\n");
    const pid_t child = ::fork();
    REQUIRE(child >= 0);
    if (child == 0) {
      // Default actions, as a shell gives a command it runs in the foreground; no core file
      // for the signals that would dump one.
      std::signal(sig, SIG_DFL);
      const struct rlimit no_core {0, 0};
      ::setrlimit(RLIMIT_CORE, &no_core);
      Output out(file);
      out.write("half a result");
      ::raise(sig);
      ::_exit(0);  // not reached: the signal ends the process
    }
    int status = 0;
    REQUIRE(::waitpid(child, &status, 0) == child);
    CAPTURE(sig);
    CHECK(WIFSIGNALED(status));
    CHECK(WTERMSIG(status) == sig);
    CHECK(readFile(file) == "keep\n");
    CHECK(s.names() == std::vector<std::string>{"result.json"});
  }
}

TEST_CASE("output: a new file takes the umask's permissions; a link is written through", "[cli][output]") {
  Scratch s("link");
  const mode_t mask = ::umask(022);
  {
    Output out(s.path("plain.txt"));
    out.write("x");
    out.close();
  }
  CHECK(permissions(s.path("plain.txt")) == 0644);
  fs::create_directories(s.dir / "sub");
  fs::create_symlink("sub/target.txt", s.dir / "link.txt");  // dangling until written
  {
    Output out(s.path("link.txt"));
    out.write("through");
    out.close();
  }
  ::umask(mask);
  CHECK(fs::is_symlink(s.dir / "link.txt"));
  CHECK(readFile(s.path("sub/target.txt")) == "through");
  CHECK(fs::directory_iterator(s.dir / "sub")->path().filename() == "target.txt");
}

TEST_CASE("output: devices and files with several names are written in place", "[cli][output]") {
  Scratch s("in_place");
  const std::string file = s.path("a.txt");
  writeFile(file, "keep\n");
  fs::create_hard_link(file, s.dir / "b.txt");
  {
    Output out(file);
    out.write("both names");
    CHECK(s.names() == std::vector<std::string>{"a.txt", "b.txt"});  // no temporary file
    out.close();
  }
  CHECK(readFile(s.path("b.txt")) == "both names");
  // In place, the file is not truncated when opened, only cut to what was written when closed
  // (found by an audit: a run that failed before writing emptied it).
  try {
    Output out(file);
    throw std::runtime_error("the computation failed");
  } catch (const std::runtime_error&) {
  }
  CHECK(readFile(file) == "both names");
  {
    Output out(file);
    out.write("one");
    out.close();
  }
  CHECK(readFile(s.path("b.txt")) == "one");
  // Cut at the first write (found by review: cut only at the end, a run that failed after
  // writing left the new bytes followed by the old ones).
  writeFile(file, std::string(100000, 'o'));
  try {
    Output out(file);
    out.write(std::string(70000, 'n'));  // past the buffer: written
    throw std::runtime_error("the computation failed");
  } catch (const std::runtime_error&) {
  }
  CHECK(readFile(file) == std::string(70000, 'n'));  // partly written, no old tail
  {
    Output out(file);  // nothing written: empty
    out.close();
  }
  CHECK(readFile(file).empty());
  {
    Output out("/dev/null");
    out.write("nothing");
    out.close();
  }
  CHECK(fs::is_character_file("/dev/null"));
}

TEST_CASE("output: a missing directory or a directory as the file is refused at once", "[cli][output]") {
  Scratch s("refused");
  CHECK_THROWS_WITH(Output(s.path("no/such/dir/out.csv")),
                    Catch::Contains("no/such/dir/out.csv: cannot open for writing: No such file or directory"));
  fs::create_directories(s.dir / "taken");
  CHECK_THROWS_WITH(Output(s.path("taken")), Catch::Contains("taken: cannot open for writing: Is a directory"));
  // A loop of links is refused as such, not replaced by a file.
  fs::create_symlink("loop_b", s.dir / "loop_a");
  fs::create_symlink("loop_a", s.dir / "loop_b");
  CHECK_THROWS_WITH(Output(s.path("loop_a")), Catch::Contains("loop_a: cannot open for writing: Too many levels"));
  CHECK(fs::is_symlink(s.dir / "loop_a"));
  CHECK(s.names() == std::vector<std::string>{"loop_a", "loop_b", "taken"});
}

// Found by an audit: a name with no room left for ".partial-XXXXXX" (255 bytes at most) was
// written in place, so a failed run emptied it.
TEST_CASE("output: a name at the length limit still gets a temporary file", "[cli][output]") {
  Scratch s("long");
  const std::string name = std::string(250, 'n') + ".csv";
  const std::string file = s.path(name);
  writeFile(file, "keep\n");
  try {
    Output out(file);
    out.write("half a result");
    const std::vector<std::string> names = s.names();
    REQUIRE(names.size() == 2);  // the file and its temporary, a short name in the same directory
    CHECK(names[0].rfind(".meshsweep-partial-", 0) == 0);
    throw std::runtime_error("the computation failed");
  } catch (const std::runtime_error&) {
  }
  CHECK(readFile(file) == "keep\n");
  CHECK(s.names() == std::vector<std::string>{name});
  {
    Output out(file);
    out.write("whole");
    out.close();
  }
  CHECK(readFile(file) == "whole");
  CHECK(s.names() == std::vector<std::string>{name});
}

#if defined(__linux__)
TEST_CASE("output: a write that fails is reported by flush() and close()", "[cli][output]") {
  // /dev/full refuses every write: written in place (a device), the error is reported by close().
  if (!fs::exists("/dev/full")) return;
  Output out("/dev/full");
  out.write("anything");
  CHECK_THROWS_AS(out.close(), IoError);
  Output flushed("/dev/full");
  flushed.write("anything");
  CHECK_THROWS_WITH(flushed.flush(), "/dev/full: write failed");
}
#endif

// ---- Pictures (scenes::Image::writePng) -----------------------------------------------------

namespace {
ino_t inode(const std::string& path) {
  struct stat st {};
  REQUIRE(::stat(path.c_str(), &st) == 0);
  return st.st_ino;
}
bool isPng(const std::string& bytes) { return bytes.size() > 8 && bytes.compare(0, 8, "\x89PNG\r\n\x1a\n") == 0; }
}  // namespace

TEST_CASE("png: written whole beside the destination, renamed over it, permissions kept", "[cli][output][png]") {
  using meshsweeper::scenes::Image;
  Scratch s("png");
  Image image(16, 8, meshsweeper::scenes::Colour(0.2, 0.4, 0.6));
  const std::string file = s.path("picture.png");
  const mode_t mask = ::umask(022);
  image.writePng(file);
  CHECK(permissions(file) == 0644);
  CHECK(isPng(readFile(file)));
  CHECK(s.names() == std::vector<std::string>{"picture.png"});  // no temporary file left
  // An existing picture is replaced by a new file (a rename: never half written) that keeps its
  // permissions.
  ::chmod(file.c_str(), 0640);
  writeFile(file, "old");
  const ino_t before = inode(file);
  image.writePng(file);
  ::umask(mask);
  CHECK(inode(file) != before);
  CHECK(permissions(file) == 0640);
  CHECK(isPng(readFile(file)));
  // A file with two names is written in place (a rename would part them).
  fs::create_hard_link(file, s.dir / "second.png");
  writeFile(file, "old");
  const ino_t shared = inode(file);
  image.writePng(file);
  CHECK(inode(file) == shared);
  CHECK(isPng(readFile(s.path("second.png"))));
  fs::remove(s.dir / "second.png");
  // A link is written through: the link stays, its target is the picture.
  fs::create_directories(s.dir / "sub");
  fs::create_symlink("sub/target.png", s.dir / "link.png");
  image.writePng(s.path("link.png"));
  CHECK(fs::is_symlink(s.dir / "link.png"));
  CHECK(isPng(readFile(s.path("sub/target.png"))));
  CHECK(s.names() == std::vector<std::string>{"link.png", "picture.png", "sub"});
}

// The pictures' temporary files are removed on a signal too (openOutput registers them; they
// were the tool's own outputs' only).
TEST_CASE("png: a signal between opening and finishing leaves no temporary file", "[cli][output][png]") {
  Scratch s("png_signal");
  const std::string file = s.path("picture.png");
  writeFile(file, "keep\n");
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    std::signal(SIGTERM, SIG_DFL);
    meshsweeper::OpenOutput out;
    if (meshsweeper::openOutput(file, out) != 0 || out.temporary.empty()) ::_exit(3);
    std::fputs("half a picture", out.file);
    std::fflush(out.file);
    ::raise(SIGTERM);
    ::_exit(0);  // not reached
  }
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);
  CHECK(WIFSIGNALED(status));
  CHECK(readFile(file) == "keep\n");
  CHECK(s.names() == std::vector<std::string>{"picture.png"});
}

TEST_CASE("png: a destination that cannot be written is named in the error and left as it was", "[cli][output][png]") {
  using meshsweeper::scenes::Image;
  Scratch s("png_refused");
  Image image(4, 4);
  CHECK_THROWS_WITH(image.writePng(s.path("no/such/dir/p.png")),
                    Catch::Contains("no/such/dir/p.png: cannot write PNG (No such file or directory)"));
  fs::create_directories(s.dir / "taken.png");
  CHECK_THROWS_AS(image.writePng(s.path("taken.png")), meshsweeper::MeshError);
  CHECK(fs::is_directory(s.dir / "taken.png"));
  if (::geteuid() != 0) {  // root writes anyway
    const std::string locked = s.path("locked.png");
    writeFile(locked, "keep");
    ::chmod(locked.c_str(), 0444);
    CHECK_THROWS_WITH(image.writePng(locked), Catch::Contains("locked.png: cannot write PNG (Permission denied)"));
    CHECK(readFile(locked) == "keep");
  }
  // No temporary file is left by any of them.
  for (const std::string& name : s.names()) CHECK(name.find(".partial-") == std::string::npos);
}

// Found by an audit: a file name with a line break made a two-line error message; every error
// is one line (README "Command-line tool").
TEST_CASE("error messages are one line: control characters escaped", "[cli]") {
  using meshsweeper::cli::oneLine;
  CHECK(oneLine("x\ny.off: no such file") == "x\\ny.off: no such file");
  CHECK(oneLine("a\rb\tc\x1b[31md\x7f") == "a\\rb\\tc\\x1b[31md\\x7f");
  CHECK(oneLine("caf\xc3\xa9 \\ ok") == "caf\xc3\xa9 \\ ok");  // UTF-8 and backslashes kept
  CHECK(oneLine("") == "");
}

// Found by an audit: "--out -h" printed the help instead of writing a file named "-h", and an
// empty output name or argument meant standard output or "': no such file".
TEST_CASE("arguments: help where an option stands, empty values and arguments refused", "[cli]") {
  using meshsweeper::cli::Args;
  using meshsweeper::cli::HelpRequested;
  using meshsweeper::cli::UsageError;
  const std::vector<meshsweeper::cli::OptionSpec> specs = {{"--out", true}, {"--path", false}};
  auto parse = [&](std::vector<std::string> words) {
    std::vector<char*> argv;
    for (std::string& word : words) argv.push_back(word.data());
    const Args args("closest", static_cast<int>(argv.size()), argv.data(), 0, specs);
    args.expectPositional({"MESH", "POINTS"});
    return args.has("--out") ? args.value("--out") : std::string("(none)");
  };
  CHECK(parse({"m.off", "p.txt", "--out", "-h"}) == "-h");
  CHECK(parse({"m.off", "p.txt", "--out", "--help"}) == "--help");
  CHECK_THROWS_AS(parse({"m.off", "p.txt", "--path", "-h"}), HelpRequested);
  CHECK_THROWS_AS(parse({"--help", "--bogus"}), HelpRequested);  // help wins over mistakes
  CHECK_THROWS_AS(parse({"m.off", "--out", "x", "--help"}), HelpRequested);
  CHECK(parse({"m.off", "--", "--help"}) == "(none)");  // POINTS is a file named --help
  CHECK_THROWS_WITH(parse({"m.off", "p.txt", "--out", ""}), "closest: option --out needs a value, got an empty one");
  CHECK_THROWS_WITH(parse({"m.off", "p.txt", "--out="}), "closest: option --out needs a value, got an empty one");
  CHECK_THROWS_WITH(parse({"", "p.txt"}), "closest: argument MESH is empty");
  CHECK_THROWS_WITH(parse({"m.off", ""}), "closest: argument POINTS is empty");
  CHECK_THROWS_AS(parse({"m.off", ""}), UsageError);
}
