#include "tools/cli.h"

#include "core/mesh_io.h"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdarg>
#include <cstdlib>
#include <cstring>

#include <sys/stat.h>

namespace meshsweeper::cli {

namespace {

constexpr size_t kOutputBufferBytes = 1 << 16;

const OptionSpec* findSpec(const std::vector<OptionSpec>& specs, const std::string& name) {
  for (const OptionSpec& spec : specs) {
    if (name == spec.name) return &spec;
  }
  return nullptr;
}

}  // namespace

Args::Args(const char* command, int argc, char** argv, int first,
           const std::vector<OptionSpec>& specs)
    : command_(command) {
  // Help first, wherever it stands: it wins over any mistake on the same line.
  for (int i = first; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--") break;
    if (arg == "--help" || arg == "-h") throw HelpRequested();
    const OptionSpec* spec = findSpec(specs, arg);
    if (spec && spec->takes_value) ++i;  // its value, whatever it reads
  }
  bool options_done = false;
  for (int i = first; i < argc; ++i) {
    const std::string arg = argv[i];
    // A negative number ("-5") is an argument, not an option, so that a bad count or
    // coordinate is reported for what it is rather than as an unknown option.
    const bool negative_number =
        arg.size() >= 2 && arg[0] == '-' && (std::isdigit(static_cast<unsigned char>(arg[1])) ||
                                             (arg[1] == '.' && arg.size() >= 3 &&
                                              std::isdigit(static_cast<unsigned char>(arg[2]))));
    if (options_done || arg.size() < 2 || arg[0] != '-' || negative_number) {
      positional_.push_back(arg);
      continue;
    }
    if (arg == "--") {
      options_done = true;
      continue;
    }
    std::string name = arg;
    std::string value;
    bool inline_value = false;
    const size_t equals = arg.find('=');
    if (arg.compare(0, 2, "--") == 0 && equals != std::string::npos) {
      name = arg.substr(0, equals);
      value = arg.substr(equals + 1);
      inline_value = true;
    }
    const OptionSpec* spec = findSpec(specs, name);
    if (!spec) throw UsageError(command_ + ": unknown option " + name);
    if (has(spec->name)) throw UsageError(command_ + ": option " + name + " given twice");
    if (spec->takes_value) {
      if (!inline_value) {
        if (i + 1 >= argc) throw UsageError(command_ + ": option " + name + " needs a value");
        value = argv[++i];
      }
      if (value.empty()) throw UsageError(command_ + ": option " + name + " needs a value, got an empty one");
    } else if (inline_value) {
      throw UsageError(command_ + ": option " + name + " takes no value");
    }
    options_.emplace_back(spec->name, value);
  }
}

void Args::expectPositional(const std::vector<const char*>& names) const {
  if (positional_.size() < names.size())
    throw UsageError(command_ + ": missing argument " + names[positional_.size()]);
  if (positional_.size() > names.size())
    throw UsageError(command_ + ": unexpected argument '" + positional_[names.size()] + "'");
  for (size_t i = 0; i < names.size(); ++i)
    if (positional_[i].empty()) throw UsageError(command_ + ": argument " + names[i] + " is empty");
}

bool Args::has(const char* name) const {
  for (const auto& option : options_) {
    if (option.first == name) return true;
  }
  return false;
}

const std::string& Args::value(const char* name) const {
  for (const auto& option : options_) {
    if (option.first == name) return option.second;
  }
  throw UsageError(command_ + ": option " + name + " is required");
}

double Args::nonNegativeDouble(const char* name) const {
  const std::string what = command_ + ": " + name;
  const double x = parseFiniteDouble(value(name), what);
  if (x < 0) throw UsageError(what + " must not be negative (got " + value(name) + ")");
  return x;
}

double Args::positiveDouble(const char* name) const {
  const double x = nonNegativeDouble(name);
  if (x > 0) return x;
  // Digits not all zero in the mantissa: it rounded to 0 (1e-400).
  const std::string& text = value(name);
  const bool rounded = text.substr(0, text.find_first_of("eE")).find_first_of("123456789") != std::string::npos;
  throw UsageError(command_ + ": " + name + " must be > 0 (got " + text + (rounded ? ", which rounds to 0)" : ")"));
}

uint64_t Args::integer(const char* name, uint64_t min, uint64_t max) const {
  return parseInteger(value(name), command_ + ": " + name, min, max);
}

uint64_t parseInteger(const std::string& text, const std::string& what, uint64_t min,
                      uint64_t max) {
  const std::string range = "an integer in [" + std::to_string(min) + ", " +
                            std::to_string(max) + "]";
  if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos)
    throw UsageError(what + " must be " + range + " (got '" + text + "')");
  // Digits only, so strtoull sees no sign; ERANGE past 2^64 - 1 (which itself is accepted).
  errno = 0;
  const uint64_t x = std::strtoull(text.c_str(), nullptr, 10);
  if (errno == ERANGE || x < min || x > max)
    throw UsageError(what + " must be " + range + " (got " + text + ")");
  return x;
}

double parseFiniteDouble(const std::string& text, const std::string& what) {
  // Decimal notation only: strtod also reads hexadecimal ("0x10" is 16), "inf" and "nan".
  if (text.empty() || text.find_first_not_of("0123456789+-.eE") != std::string::npos)
    throw UsageError(what + " must be a finite decimal number (got '" + text + "')");
  const char* begin = text.c_str();
  char* end = nullptr;
  errno = 0;
  const double x = std::strtod(begin, &end);
  if (end != begin + text.size())
    throw UsageError(what + " must be a finite decimal number (got '" + text + "')");
  // Past the largest double; a value below the smallest rounds (to a subnormal or 0), which
  // the option's own range check judges.
  if (!std::isfinite(x) || (errno == ERANGE && std::fabs(x) > 1))
    throw UsageError(what + " is beyond the largest double, 1.8e308 (got '" + text + "')");
  return x;
}

Mesh readMeshArgument(const char* command, const std::string& path) {
  if (path == "-")
    throw UsageError(std::string(command) +
                     ": a mesh is read from a file, not from standard input ('-'; a file called '-' is ./-)");
  return readMesh(path);
}

int standardStreamOf(const std::string& path) {
  if (path == "-") return 1;
  struct stat named {};
  if (::stat(path.c_str(), &named) != 0) return 0;
  for (const int fd : {1, 2}) {
    struct stat stream {};
    if (::fstat(fd, &stream) == 0 && stream.st_dev == named.st_dev && stream.st_ino == named.st_ino) return fd;
  }
  return 0;
}

Output::Output(const std::string& path) : path_(path) {
  buffer_.reserve(kOutputBufferBytes);
  // A name of standard output or error (/dev/stdout, /dev/fd/2, the file they write to) is
  // written through the stream: reopening it would start at the file's beginning, or fail on
  // a pipe (found by an audit).
  if (const int stream = standardStreamOf(path_)) {
    out_.file = stream == 1 ? stdout : stderr;
    path_ = stream == 1 ? "standard output" : "standard error";
    return;
  }
  if (const int error = openOutput(path_, out_))
    throw IoError(path_ + ": cannot open for writing: " + std::strerror(error));
  owned_ = true;
}

Output::~Output() {
  if (owned_) discardOutput(out_);
}

void Output::flushBuffer() {
  if (!buffer_.empty() && !writeOutput(out_, buffer_.data(), buffer_.size())) failed_ = true;
  buffer_.clear();
}

void Output::write(const char* data, size_t size) {
  buffer_.append(data, size);
  if (buffer_.size() >= kOutputBufferBytes) flushBuffer();
}

void Output::printf(const char* format, ...) {
  char line[1024];
  va_list args;
  va_start(args, format);
  const int n = std::vsnprintf(line, sizeof line, format, args);
  va_end(args);
  if (n < 0 || static_cast<size_t>(n) >= sizeof line) {
    failed_ = true;
    return;
  }
  write(line, static_cast<size_t>(n));
}

void Output::flush() {
  flushBuffer();
  if (std::fflush(out_.file) != 0) failed_ = true;
  if (failed_) throw IoError(path_ + ": write failed");
}

void Output::close() {
  flushBuffer();
  if (!owned_) {  // standard output or error
    if (std::fflush(out_.file) != 0) failed_ = true;
    if (failed_) throw IoError(path_ + ": write failed");
    return;
  }
  owned_ = false;
  bool at_rename = false;
  const int error = finishOutput(out_, failed_, &at_rename);  // removes the temporary if it fails
  if (at_rename) throw IoError(path_ + ": cannot replace: " + std::strerror(error));
  if (error) throw IoError(path_ + ": write failed");
}

std::string jsonString(const std::string& text) {
  std::string out = "\"";
  for (unsigned char c : text) {
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      default:
        if (c < 0x20) {
          char escaped[8];
          std::snprintf(escaped, sizeof escaped, "\\u%04x", c);
          out += escaped;
        } else {
          out += static_cast<char>(c);
        }
    }
  }
  return out + "\"";
}

std::string oneLine(const std::string& text) { return escapedText(text, false); }

}  // namespace meshsweeper::cli
