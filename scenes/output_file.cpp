#include "scenes/output_file.h"

#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstring>

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

namespace meshsweeper {

namespace {

// Temporary output files that an interrupted run removes: a fixed table of C strings, which
// the signal handler reads (async-signal-safe: no allocation, no locks).
constexpr int kMaxTemporaries = 8;
constexpr size_t kMaxTemporaryPath = 4096;
char g_temporaries[kMaxTemporaries][kMaxTemporaryPath];
volatile sig_atomic_t g_temporary_used[kMaxTemporaries];
// Every signal whose default action ends the process and that a program may catch, save the
// ones a fault raises (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP, SIGSYS): an
// interrupt, a timer, a full file (SIGXFSZ), a closed pipe, a user's signal.
constexpr int kCleanupSignals[] = {SIGINT,  SIGTERM, SIGHUP,    SIGQUIT, SIGPIPE, SIGALRM, SIGUSR1,
                                   SIGUSR2, SIGXCPU, SIGXFSZ, SIGVTALRM, SIGPROF, SIGIO};

extern "C" void removeTemporariesAndResignal(int signal) {
  for (int i = 0; i < kMaxTemporaries; ++i)
    if (g_temporary_used[i]) ::unlink(g_temporaries[i]);
  // The handler was reset on entry (SA_RESETHAND): the signal, blocked until the handler
  // returns, then ends the process as it would have.
  ::raise(signal);
}

// Installs the handler for signals that have their default action now (an ignored SIGHUP,
// under nohup, stays ignored; a program's own handler is kept).
void installCleanup() {
  for (const int sig : kCleanupSignals) {
    struct sigaction old {};
    if (::sigaction(sig, nullptr, &old) != 0 || old.sa_handler != SIG_DFL) continue;
    struct sigaction act {};
    act.sa_handler = removeTemporariesAndResignal;
    sigemptyset(&act.sa_mask);
    act.sa_flags = SA_RESETHAND;
    ::sigaction(sig, &act, nullptr);
  }
}

// Registers a temporary file for removal on a signal (quietly not, past the table's size).
void registerTemporary(const std::string& path) {
  if (path.size() >= kMaxTemporaryPath) return;
  installCleanup();
  for (int i = 0; i < kMaxTemporaries; ++i) {
    if (g_temporary_used[i]) continue;
    std::memcpy(g_temporaries[i], path.c_str(), path.size() + 1);
    std::atomic_signal_fence(std::memory_order_seq_cst);  // the name is whole before it is used
    g_temporary_used[i] = 1;
    return;
  }
}

void unregisterTemporary(const std::string& path) {
  for (int i = 0; i < kMaxTemporaries; ++i)
    if (g_temporary_used[i] && path == g_temporaries[i]) g_temporary_used[i] = 0;
}

}  // namespace

std::filesystem::path outputDestination(const std::string& name) {
  namespace fs = std::filesystem;
  std::error_code error;
  fs::path path = fs::absolute(name, error);
  for (int hop = 0; hop < 40 && fs::is_symlink(path, error); ++hop) {
    const fs::path target = fs::read_symlink(path, error);
    if (error) break;
    path = target.is_absolute() ? target : path.parent_path() / target;
  }
  const fs::path canonical = fs::weakly_canonical(path, error);
  return error ? path.lexically_normal() : canonical;
}

int openOutput(const std::string& path, OpenOutput& out) {
  out = OpenOutput();
  const std::string target = outputDestination(path).string();
  struct stat st {};
  const bool exists = ::stat(target.c_str(), &st) == 0;
  // In place: not a regular file (a device, a pipe, a directory, which fopen refuses), one
  // with other names that a rename would separate from it, or a link that leads nowhere (a
  // loop, which fopen reports).
  struct stat link {};
  const bool in_place = (exists && (!S_ISREG(st.st_mode) || st.st_nlink > 1)) ||
                        (::lstat(target.c_str(), &link) == 0 && S_ISLNK(link.st_mode));
  if (!in_place) {
    // A rename would replace a file its owner made read-only.
    if (exists && ::access(target.c_str(), W_OK) != 0) return errno;
    std::string name = target + ".partial-XXXXXX";
    int fd = ::mkstemp(name.data());
    if (fd < 0 && errno == ENAMETOOLONG) {
      // A name at the length limit: a short temporary in the same directory, so that the
      // rename stays within it.
      name = (std::filesystem::path(target).parent_path() / ".meshsweep-partial-XXXXXX").string();
      fd = ::mkstemp(name.data());
    }
    if (fd >= 0) {
      out.file = ::fdopen(fd, "wb");
      if (!out.file) {
        const int error = errno;
        ::close(fd);
        ::unlink(name.c_str());
        return error;
      }
      out.temporary = name;
      registerTemporary(name);
      out.target = target;
      if (exists) {
        out.mode = st.st_mode & 07777;
      } else {
        const mode_t mask = ::umask(0);
        ::umask(mask);
        out.mode = 0666 & ~mask;
      }
      return 0;
    }
    // No temporary beside it (a writable file in a directory that is not): the file itself.
    const int error = errno;
    if (!(error == ENAMETOOLONG || (exists && (error == EACCES || error == EPERM || error == EROFS)))) return error;
  }
  // In place, not truncated yet: a run that fails before it writes leaves the file as it was;
  // finishOutput() cuts a regular file to what was written.
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0666);
  if (fd < 0) return errno;
  out.file = ::fdopen(fd, "wb");
  if (!out.file) {
    const int error = errno;
    ::close(fd);
    return error;
  }
  return 0;
}

int finishOutput(OpenOutput& out, bool write_failed, bool* at_rename) {
  if (at_rename) *at_rename = false;
  int error = write_failed ? EIO : 0;
  if (std::fflush(out.file) != 0 && !error) error = errno ? errno : EIO;
  if (!out.temporary.empty()) (void)::fchmod(::fileno(out.file), static_cast<mode_t>(out.mode));
  struct stat st {};
  if (!error && out.temporary.empty() && ::fstat(::fileno(out.file), &st) == 0 && S_ISREG(st.st_mode)) {
    const off_t written = ::ftello(out.file);
    if (written < 0 || ::ftruncate(::fileno(out.file), written) != 0) error = errno ? errno : EIO;
  }
  if (std::fclose(out.file) != 0 && !error) error = errno ? errno : EIO;
  out.file = nullptr;
  if (!error && !out.temporary.empty() && std::rename(out.temporary.c_str(), out.target.c_str()) != 0) {
    error = errno;
    if (at_rename) *at_rename = true;
  }
  if (error && !out.temporary.empty()) ::unlink(out.temporary.c_str());
  unregisterTemporary(out.temporary);  // after the rename or the removal: nothing is left between
  out.temporary.clear();
  return error;
}

void discardOutput(OpenOutput& out) {
  if (out.file) std::fclose(out.file);
  out.file = nullptr;
  if (out.temporary.empty()) return;
  ::unlink(out.temporary.c_str());
  unregisterTemporary(out.temporary);
  out.temporary.clear();
}

}  // namespace meshsweeper
