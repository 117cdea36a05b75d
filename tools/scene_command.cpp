// meshsweep scene: runs a demo scene (scenes/scene_demos.h) and writes its picture as PNG.
#include "scenes/scene_demos.h"
#include "tools/cli.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <exception>
#include <new>
#include <string>
#include <vector>

namespace meshsweeper::cli {

extern const char kSceneHelp[];
int runScene(int argc, char** argv, int first);

const char kSceneHelp[] =
    "Usage: meshsweep scene NAME [--out DIR]\n"
    "\n"
    "Runs a demo scene and writes its picture to DIR/NAME.png (default DIR: out/scenes,\n"
    "created if missing). Bounds and timings are printed. NAME is one of:\n"
    "  hausdorff  armadillo coloured by its distance to an 8k-triangle simplification of it\n"
    "             (front and back), certified Hausdorff bounds\n"
    "  particle   a particle falling onto a torus (paper Fig. 6): four frames with the closest\n"
    "             point and the dynamic front that found it\n"
    "  cloth      cloth points draped over a key-framed body through the distance service,\n"
    "             per-step query timings\n"
    "  all        the three in turn (a scene that fails is named, the others still run)\n"
    "\n"
    "Exit status: 0 success, 1 missing mesh data or unwritable output, 2 bad command line.\n";

namespace {

// mkdir -p.
void makeDirectories(const std::string& path) {
  for (size_t i = 1; i <= path.size(); ++i) {
    if (i < path.size() && path[i] != '/') continue;
    const std::string prefix = path.substr(0, i);
    if (::mkdir(prefix.c_str(), 0777) != 0 && errno != EEXIST)
      throw IoError(prefix + ": cannot create directory (" + std::strerror(errno) + ")");
  }
}

// Checks, before a scene runs, that DIR/NAME.png can be written: DIR is a directory and the
// file can be created there (or, if it exists, opened for writing). Leaves an existing picture
// as it is and removes the probe it created. Throws IoError.
void checkWritable(const std::string& out_dir, const std::string& path) {
  struct stat status;
  if (::stat(out_dir.c_str(), &status) != 0)
    throw IoError(out_dir + ": cannot use as output directory (" + std::strerror(errno) + ")");
  if (!S_ISDIR(status.st_mode)) throw IoError(out_dir + ": not a directory");
  int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0666);
  const bool created = fd >= 0;
  if (!created && errno == EEXIST) fd = ::open(path.c_str(), O_WRONLY);
  if (fd < 0) throw IoError(path + ": cannot open for writing: " + std::strerror(errno));
  ::close(fd);
  if (created) ::unlink(path.c_str());
}

}  // namespace

int runScene(int argc, char** argv, int first) {
  const Args args("scene", argc, argv, first, {{"--out", true}});
  args.expectPositional({"NAME"});
  const std::string name = args.positional()[0];
  const std::string out_dir = args.has("--out") ? args.value("--out") : "out/scenes";
  std::vector<std::string> names;
  if (name == "all") {
    names = scenes::sceneNames();
  } else {
    bool known = false;
    for (const std::string& n : scenes::sceneNames()) known = known || n == name;
    if (!known) throw UsageError("scene: unknown scene '" + name + "' (hausdorff, particle, cloth, all)");
    names = {name};
  }
  // Before any scene runs (the hausdorff scene takes a while), so a bad DIR fails at once.
  makeDirectories(out_dir);
  for (const std::string& n : names) checkWritable(out_dir, out_dir + "/" + n + ".png");
  // `all` goes on past a scene that fails (the hausdorff scene without its meshes, say: the
  // other two need none), names it on standard error, and exits 1 at the end.
  int status = kExitOk;
  for (const std::string& n : names) {
    const auto start = std::chrono::steady_clock::now();
    std::string path;
    try {
      path = scenes::runScene(n, out_dir, stdout);
    } catch (const std::bad_alloc&) {
      throw;
    } catch (const std::exception& e) {
      if (names.size() == 1) throw;
      std::fflush(stdout);
      std::fprintf(stderr, "meshsweep: scene %s: %s\n", n.c_str(), oneLine(e.what()).c_str());
      status = kExitInput;
      continue;
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::printf("scene %s: %s (%.2f s)\n", n.c_str(), oneLine(path).c_str(), seconds);
    std::fflush(stdout);
  }
  return status;
}

}  // namespace meshsweeper::cli
