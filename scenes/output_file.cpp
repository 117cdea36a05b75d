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
// the signal handler reads (async-signal-safe: lock-free atomics, no allocation, no locks). A
// slot is claimed (1) before its name is written and published (2) after, so a handler on any
// thread reads only whole names.
constexpr int kMaxTemporaries = 8;
constexpr size_t kMaxTemporaryPath = 4096;
char g_temporaries[kMaxTemporaries][kMaxTemporaryPath];
std::atomic<int> g_temporary_state[kMaxTemporaries];  // 0 free, 1 being written, 2 registered
static_assert(std::atomic<int>::is_always_lock_free);
// Every signal whose default action ends the process and that a program may catch, save the
// ones a fault raises (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP, SIGSYS): an
// interrupt, a timer, a full file (SIGXFSZ), a closed pipe, a user's signal; and the
// real-time signals (installCleanup).
constexpr int kCleanupSignals[] = {SIGINT,  SIGTERM, SIGHUP,  SIGQUIT,   SIGPIPE, SIGALRM, SIGUSR1,
                                   SIGUSR2, SIGXCPU, SIGXFSZ, SIGVTALRM, SIGPROF, SIGIO,
#ifdef SIGPWR
                                   SIGPWR,
#endif
#ifdef SIGSTKFLT
                                   SIGSTKFLT,
#endif
};

extern "C" void removeTemporariesAndResignal(int signal) {
  for (int i = 0; i < kMaxTemporaries; ++i)
    if (g_temporary_state[i].load(std::memory_order_acquire) == 2) ::unlink(g_temporaries[i]);
  // The handler was reset on entry (SA_RESETHAND): the signal, blocked until the handler
  // returns, then ends the process as it would have.
  ::raise(signal);
}

// Installs the handler for a signal that has its default action now (an ignored SIGHUP, under
// nohup, stays ignored; a program's own handler is kept).
void installCleanup(int sig) {
  struct sigaction old {};
  if (::sigaction(sig, nullptr, &old) != 0 || old.sa_handler != SIG_DFL) return;
  struct sigaction act {};
  act.sa_handler = removeTemporariesAndResignal;
  sigemptyset(&act.sa_mask);
  act.sa_flags = SA_RESETHAND;
  ::sigaction(sig, &act, nullptr);
}

void installCleanup() {
  for (const int sig : kCleanupSignals) installCleanup(sig);
#if defined(SIGRTMIN) && defined(SIGRTMAX)
  for (int sig = SIGRTMIN; sig <= SIGRTMAX; ++sig) installCleanup(sig);
#endif
}

// Registers a temporary file for removal on a signal (quietly not, past the table's size).
void registerTemporary(const std::string& path) {
  if (path.size() >= kMaxTemporaryPath) return;
  installCleanup();
  for (int i = 0; i < kMaxTemporaries; ++i) {
    int free = 0;
    if (!g_temporary_state[i].compare_exchange_strong(free, 1, std::memory_order_acquire)) continue;
    std::memcpy(g_temporaries[i], path.c_str(), path.size() + 1);
    g_temporary_state[i].store(2, std::memory_order_release);
    return;
  }
}

void unregisterTemporary(const std::string& path) {
  for (int i = 0; i < kMaxTemporaries; ++i)
    if (g_temporary_state[i].load(std::memory_order_acquire) == 2 && path == g_temporaries[i])
      g_temporary_state[i].store(0, std::memory_order_release);
}

// Whether a rename could not replace the existing file `target`: in a sticky directory (/tmp)
// only the owner of the file or of the directory may (found by an audit: a writable file of
// another user there failed at the end, after the long work).
bool sticky(const std::string& target, const struct stat& file) {
  const uid_t me = ::geteuid();
  if (me == 0 || file.st_uid == me) return false;
  struct stat dir {};
  const std::string parent = std::filesystem::path(target).parent_path().string();
  return ::stat(parent.c_str(), &dir) == 0 && (dir.st_mode & S_ISVTX) && dir.st_uid != me;
}

// Cuts a regular file written in place to nothing, once, before its first byte.
bool cutIfPending(OpenOutput& out) {
  if (!out.cut_pending) return true;
  out.cut_pending = false;
  return std::fflush(out.file) == 0 && ::ftruncate(::fileno(out.file), 0) == 0;
}

}  // namespace

std::filesystem::path outputDestination(const std::string& name) {
  namespace fs = std::filesystem;
  std::error_code error;
  fs::path path = fs::absolute(name, error);
  for (int hop = 0; hop < 40 && fs::is_symlink(path, error); ++hop) {
    const fs::path target = fs::read_symlink(path, error);
    if (error) break;
    const fs::path next = target.is_absolute() ? target : path.parent_path() / target;
    // A link that opens although its text leads nowhere is one of /proc's (/dev/fd/N to a pipe
    // reads "pipe:[1234]"): the destination is the link itself (found by an audit: a file was
    // looked for beside it).
    if (!fs::exists(next, error) && fs::exists(path, error)) return path;
    path = next;
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
  const bool in_place = (exists && (!S_ISREG(st.st_mode) || st.st_nlink > 1 || sticky(target, st))) ||
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
      registerTemporary(name);
      out.file = ::fdopen(fd, "wb");
      if (!out.file) {
        const int error = errno;
        ::close(fd);
        ::unlink(name.c_str());
        unregisterTemporary(name);
        return error;
      }
      out.temporary = name;
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
    // No temporary beside it (a writable file in a directory that is not): the file itself. A
    // path too long for any temporary (past PATH_MAX) is refused, not written in place.
    const int error = errno;
    if (!(exists && (error == EACCES || error == EPERM || error == EROFS))) return error;
  }
  // In place, not cut yet: a run that fails before it writes leaves the file as it was;
  // writeOutput() cuts a regular file before its first byte.
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0666);
  if (fd < 0) return errno;
  out.file = ::fdopen(fd, "wb");
  if (!out.file) {
    const int error = errno;
    ::close(fd);
    return error;
  }
  struct stat opened {};
  out.cut_pending = ::fstat(fd, &opened) == 0 && S_ISREG(opened.st_mode);
  return 0;
}

bool writeOutput(OpenOutput& out, const void* data, size_t size) {
  if (size == 0) return true;
  if (!cutIfPending(out)) return false;
  return std::fwrite(data, 1, size, out.file) == size;
}

int finishOutput(OpenOutput& out, bool write_failed, bool* at_rename) {
  if (at_rename) *at_rename = false;
  int error = write_failed ? EIO : 0;
  if (std::fflush(out.file) != 0 && !error) error = errno ? errno : EIO;
  if (!out.temporary.empty()) (void)::fchmod(::fileno(out.file), static_cast<mode_t>(out.mode));
  if (!error && !cutIfPending(out)) error = errno ? errno : EIO;  // nothing was written: empty
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
