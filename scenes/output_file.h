#pragma once
// Output files written beside their destination and renamed over it (README "Output files"),
// shared by the tool's outputs (tools/cli.h, Output) and the scenes' pictures
// (Image::writePng): a write that fails or is interrupted leaves the destination as it was.
#include <cstddef>
#include <cstdio>
#include <filesystem>
#include <string>

namespace meshsweeper {

// The path a name leads to, symbolic links followed even when their target does not exist yet
// (a dangling link is created through when written).
std::filesystem::path outputDestination(const std::string& name);

// An output file open for writing. A regular file (new, or existing with one name) is written
// to a temporary file beside its destination ("NAME.partial-XXXXXX"), which finishOutput()
// renames over it with the permissions of the file it replaces (a new one's: 0666 less the
// umask); a symbolic link is written through. Anything else (a device, a pipe, a file with
// several names, a link that leads nowhere, /proc's link to a pipe) is written in place, and
// so is a writable file in a directory where no temporary can be created or another user's
// file in a sticky directory (a rename could not replace it); a name too long for the suffix
// gets a short temporary in the same directory (".meshsweep-partial-XXXXXX"), and a path too
// long for any (past PATH_MAX) is refused. A regular file written in
// place is not truncated when opened, only cut by the first writeOutput() (or finishOutput(),
// when nothing was written), so a run that fails before writing leaves it as it was; one that
// fails after its first write leaves it partly written.
struct OpenOutput {
  std::FILE* file = nullptr;
  std::string temporary;  // the file written ("": in place)
  std::string target;     // the destination, links followed (with a temporary)
  unsigned mode = 0;      // the permissions target gets (with a temporary)
  bool cut_pending = false;  // a regular file in place, not cut yet (writeOutput())
};

// Opens `path` for writing: 0, or the errno value that says why it cannot be written (an
// existing file that is not writable included; nothing is left behind). A temporary file is
// removed by a signal that ends the process (SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGPIPE, the
// timers', SIGXFSZ, ...: a handler is installed for those that have their default action)
// until finishOutput() or discardOutput().
int openOutput(const std::string& path, OpenOutput& out);

// Writes `size` bytes to out.file (every write goes through here: a file written in place is
// cut before the first). False when the write failed (errno says why).
bool writeOutput(OpenOutput& out, const void* data, size_t size);

// Flushes and closes out.file, then puts a temporary in place. `write_failed`: one of the
// caller's writes failed. Returns 0, or the errno value of what failed (EIO for a write that
// set none), the destination then as it was and the temporary removed; *at_rename tells
// whether it was the rename. A file system that refuses the permissions is no failure.
int finishOutput(OpenOutput& out, bool write_failed, bool* at_rename = nullptr);

// Closes out.file and removes its temporary, the destination left as it was: for a run that
// gives up before finishOutput().
void discardOutput(OpenOutput& out);

}  // namespace meshsweeper
