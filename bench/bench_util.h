#pragma once
// Small pieces every benchmark binary uses: its own command-line flags and its summary tables.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace meshsweeper::bench {

// "a,b,,c" -> {"a", "b", "c"}.
inline std::vector<std::string> splitList(const std::string& s) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= s.size()) {
    const size_t comma = s.find(',', start);
    const size_t end = comma == std::string::npos ? s.size() : comma;
    if (end > start) out.push_back(s.substr(start, end - start));
    start = end + 1;
  }
  return out;
}

// "program: message" on stderr, exit code 2.
[[noreturn]] inline void usageError(const char* program, const std::string& message) {
  std::fprintf(stderr, "%s: %s\n", program, message.c_str());
  std::exit(2);
}

// A positive integer flag value, else a usage error.
inline size_t parseCount(const char* program, const std::string& flag, const std::string& value) {
  char* end = nullptr;
  const unsigned long long n = std::strtoull(value.c_str(), &end, 10);
  if (value.empty() || *end != '\0' || n == 0) usageError(program, flag + " needs a positive integer");
  return static_cast<size_t>(n);
}

// v printed with a printf format, "-" when not finite (a table cell).
inline std::string formatCell(const char* format, double v) {
  if (!std::isfinite(v)) return "-";
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, format, v);
  return buffer;
}

}  // namespace meshsweeper::bench
