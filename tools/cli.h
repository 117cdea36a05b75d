#pragma once
// Small, strict command-line helpers shared by the meshsweep subcommands: option parsing,
// number parsing, output files, timing and JSON text. No external argument-parsing library.
//
// Exit codes of the tool: 0 success, 1 an input or output file could not be read, parsed or
// written (MeshError, IoError), 2 a bad command line (UsageError).
#include "core/mesh.h"
#include "core/types.h"
#include "scenes/output_file.h"

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace meshsweeper::cli {

inline constexpr int kExitOk = 0;
inline constexpr int kExitInput = 1;  // a file could not be read, parsed or written
inline constexpr int kExitUsage = 2;  // bad command line

// A bad command line: unknown option, missing argument, invalid number. Exit code 2.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// An output file that cannot be opened or written. Exit code 1.
class IoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "--help" or "-h" where an option may stand (not an option's value, nor after "--"): the
// command's help is wanted instead of a run. Thrown by Args; main() prints the help, exit 0.
class HelpRequested : public std::exception {
 public:
  const char* what() const noexcept override { return "help requested"; }
};

// One option a subcommand accepts: "--name VALUE" (or "--name=VALUE") when takes_value,
// else a flag "--name".
struct OptionSpec {
  const char* name;  // with the leading "--"
  bool takes_value;
};

// The parsed arguments of one subcommand.
class Args {
 public:
  // Parses argv[first..argc). Options may appear anywhere; "--" ends options; "-" alone is a
  // positional argument (standard input), and so is a negative number ("-5", "-.5"). Throws
  // HelpRequested for "--help" or "-h" in an option's place; UsageError on an unknown option,
  // a repeated option, or an option missing its value or given an empty one.
  // `command` names the subcommand in messages.
  Args(const char* command, int argc, char** argv, int first, const std::vector<OptionSpec>& specs);

  const std::vector<std::string>& positional() const { return positional_; }
  // Throws UsageError unless there are exactly `names.size()` positional arguments, none empty;
  // the message names the missing one (e.g. "closest: missing argument POINTS").
  void expectPositional(const std::vector<const char*>& names) const;

  bool has(const char* name) const;
  // The value of an option that takes one. Precondition: has(name).
  const std::string& value(const char* name) const;

  // Typed values, validated strictly. Each throws UsageError naming the option.
  // A finite double >= 0 (rejects NaN, infinity, negative, trailing garbage).
  double nonNegativeDouble(const char* name) const;
  // The same, > 0: a number that parses as 0 is refused with its text ("must be > 0 (got 0)",
  // or "(got 1e-400, which rounds to 0)").
  double positiveDouble(const char* name) const;
  // A decimal integer in [min, max] (digits only: no sign, no exponent, no fraction).
  uint64_t integer(const char* name, uint64_t min, uint64_t max) const;

 private:
  std::string command_;
  std::vector<std::string> positional_;
  std::vector<std::pair<std::string, std::string>> options_;  // name, value ("" for flags)
};

// Parses a whole string as a decimal integer in [min, max]; `what` names it in the message.
// Throws UsageError.
uint64_t parseInteger(const std::string& text, const std::string& what, uint64_t min, uint64_t max);
// Parses a whole string as a finite double; throws UsageError.
double parseFiniteDouble(const std::string& text, const std::string& what);

// The mesh a command line names (readMesh). "-" is refused (UsageError): meshes are read from
// files, not from standard input ("./-" names a file called "-").
Mesh readMeshArgument(const char* command, const std::string& path);

// 1 or 2 when `path` names standard output ("-" included) or standard error (/dev/stdout,
// /dev/fd/2, /proc/self/fd/1, the file a stream is redirected to), else 0.
int standardStreamOf(const std::string& path);

// An output destination: a file, or standard output for "-" (or standard error), written
// through the stream when named by another name too (standardStreamOf). Writes are buffered;
// close() flushes and throws IoError if anything failed.
//
// A regular file (new, or existing with one name) is written to a temporary file beside it
// ("NAME.partial-XXXXXX", or ".meshsweep-partial-XXXXXX" in its directory for a name too long
// for the suffix; created at once: the commands construct it once their inputs are read, an
// output written in place could be one of them, and before the long work) that close()
// renames over it: a run that fails, throws or is interrupted (by a signal that ends it:
// SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGPIPE, SIGXFSZ, ...) leaves the file as it was and
// removes the temporary one. An existing file keeps its permissions; a symbolic link is
// written through (its target is replaced, the link stays). Anything else (a device, a pipe,
// /dev/stdout, a file with several hard links) is written in place: a regular one is cut at
// the first write, not when opened (scenes/output_file.h).
class Output {
 public:
  explicit Output(const std::string& path);
  ~Output();
  Output(const Output&) = delete;
  Output& operator=(const Output&) = delete;

  void write(const char* data, size_t size);
  void write(const std::string& text) { write(text.data(), text.size()); }
  // printf-style formatted line or fragment (at most 1024 characters per call).
  void printf(const char* format, ...) __attribute__((format(printf, 2, 3)));
  // Writes out what is buffered; throws IoError ("PATH: write failed") if any write failed.
  // Lets a command check all its outputs before it puts any in place: a file with a temporary
  // is then unchanged (one written in place may be partly written; inPlace()).
  void flush();
  // Written in place (standard output, a device, a pipe, a file with several names), not
  // through a temporary file.
  bool inPlace() const { return !owned_ || out_.temporary.empty(); }
  // Flushes and puts the file in place; throws IoError ("PATH: write failed") if any write
  // failed, the destination then unchanged.
  void close();

 private:
  std::string path_;      // for messages: the name, "standard output" or "standard error"
  OpenOutput out_;       // the file (standard output, or opened by openOutput())
  bool owned_ = false;   // opened here (not standard output), not yet closed
  std::string buffer_;
  bool failed_ = false;
  void flushBuffer();
};

using meshsweeper::outputDestination;  // scenes/output_file.h

// Wall-clock seconds since construction.
class Timer {
 public:
  Timer() : start_(std::chrono::steady_clock::now()) {}
  double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

// `text` as a JSON string literal, quotes included.
std::string jsonString(const std::string& text);

// An error message on one line: its control characters (a line break in a file's name, say)
// written as C escapes ("\n", "\r", "\t", "\x1b"), a backslash as it is (escapedText,
// core/mesh_io.h, keeping UTF-8).
std::string oneLine(const std::string& text);

}  // namespace meshsweeper::cli
