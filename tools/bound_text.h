#pragma once
// Certified bounds as short text, rounded outward: a lower bound printed with few digits must
// not exceed the proven value, nor an upper bound fall below it, or the printed interval would
// no longer contain the quantity. Header-only, so that the demo scenes (scenes/, a library
// without the tool) print their bounds the way `meshsweep hausdorff` does.
//
// The text is compared with the value exactly, digit by digit against the double's exact
// decimal expansion: a read-back in double takes "0.1" for the double 0.1 (0.1000000000000000055),
// and one in long double still takes about one short decimal in 2,048 for a double it is not
// ("0.110499" reads back as the double 0.110499, which is 0.11049899999999999999999911; found by
// review). Subnormals and the largest doubles included.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace meshsweeper::cli {

namespace detail {

// A decimal number: sign, significant digits (no leading or trailing zeros; empty for zero)
// and exponent, value = d1.d2d3... x 10^exponent.
struct Decimal {
  bool negative = false;
  std::string digits;
  long exponent = 0;
};

// Reads "[-]ddd[.ddd][e[+-]dd]" (what printf's %e, %f and %g write).
inline Decimal parseDecimal(const char* text) {
  Decimal d;
  const char* c = text;
  if (*c == '-' || *c == '+') d.negative = *c++ == '-';
  long point = -1;  // digits before the point
  std::string all;
  for (; (*c >= '0' && *c <= '9') || *c == '.'; ++c) {
    if (*c == '.') point = static_cast<long>(all.size());
    else all.push_back(*c);
  }
  if (point < 0) point = static_cast<long>(all.size());
  long exponent = (*c == 'e' || *c == 'E') ? std::strtol(c + 1, nullptr, 10) : 0;
  const std::size_t first = all.find_first_not_of('0');
  if (first == std::string::npos) return Decimal{d.negative, "", 0};
  const std::size_t last = all.find_last_not_of('0');
  d.digits = all.substr(first, last - first + 1);
  d.exponent = exponent + point - 1 - static_cast<long>(first);
  return d;
}

// -1, 0 or 1 as |a| is below, equal to or above |b|.
inline int compareMagnitude(const Decimal& a, const Decimal& b) {
  if (a.digits.empty() || b.digits.empty()) return a.digits.empty() ? (b.digits.empty() ? 0 : -1) : 1;
  if (a.exponent != b.exponent) return a.exponent < b.exponent ? -1 : 1;
  const int c = a.digits.compare(b.digits);  // no trailing zeros: a longer prefix match is larger
  return c < 0 ? -1 : (c > 0 ? 1 : 0);
}

// The exact decimal expansion of a finite double (at most 767 significant digits), in %e form
// without trailing zeros.
inline std::string exactText(double x) {
  char text[900];
  std::snprintf(text, sizeof text, "%.800e", x);
  std::string s = text;
  const std::size_t e = s.find('e');
  std::size_t end = s.find_last_not_of('0', e - 1);
  if (s[end] == '.') --end;
  return s.substr(0, end + 1) + s.substr(e);
}

// -1, 0 or 1 as a is below, equal to or above b.
inline int compare(const Decimal& a, const Decimal& b) {
  const bool a_negative = a.negative && !a.digits.empty(), b_negative = b.negative && !b.digits.empty();
  if (a_negative != b_negative) return a_negative ? -1 : 1;
  const int m = compareMagnitude(a, b);
  return a_negative ? -m : m;
}

// The first text, of `print(y)` from y = start, on the outer side of x (up: at or above it),
// each miss moved one `unit(text)` further out; x's exact expansion once in 8 misses (none
// happen in practice: one or two attempts).
template <class Print, class Unit>
std::string outward(double x, bool up, long double start, Print print, Unit unit) {
  const Decimal exact = parseDecimal(exactText(x).c_str());
  long double y = start;
  for (int attempt = 0; attempt < 8; ++attempt) {
    const std::string text = print(y);
    const int side = compare(parseDecimal(text.c_str()), exact);
    if (up ? side >= 0 : side <= 0) return text;
    const long double shown = std::strtold(text.c_str(), nullptr);
    y = up ? shown + unit(text, shown) : shown - unit(text, shown);
  }
  return exactText(x);
}

}  // namespace detail

// -1, 0 or 1 as the decimal `text` is below, equal to or above the finite double x, exactly.
inline int compareDecimal(const std::string& text, double x) {
  return detail::compare(detail::parseDecimal(text.c_str()), detail::parseDecimal(detail::exactText(x).c_str()));
}

// x with `digits` significant digits (1 to 17), rounded down (up = false) or up.
inline std::string outwardBound(double x, int digits, bool up) {
  if (!std::isfinite(x)) return x > 0 ? "inf" : (x < 0 ? "-inf" : "nan");
  auto print = [digits](long double y) {
    char text[64];
    std::snprintf(text, sizeof text, "%.*Lg", digits, y);
    return std::string(text);
  };
  // One unit of the last digit shown, its place read off the text (log10 of a power of ten can
  // fall an ulp short of the integer, and a unit ten times too small never changed the text;
  // found by review).
  auto unit = [digits, x](const std::string& text, long double shown) {
    return shown == 0 ? std::fabs(static_cast<long double>(x))
                      : std::pow(10.0L, detail::parseDecimal(text.c_str()).exponent - (digits - 1));
  };
  return detail::outward(x, up, x, print, unit);
}

// x with `decimals` digits after the point (0 to 17), rounded down (up = false) or up: a bound
// shown as a percentage.
inline std::string outwardFixed(double x, int decimals, bool up) {
  if (!std::isfinite(x)) return x > 0 ? "inf" : (x < 0 ? "-inf" : "nan");
  const long double target = x;
  const long double scale = std::pow(10.0L, decimals);
  char text[400];  // %f of the largest double: 309 digits before the point
  if (std::fabs(target) * scale >= 4e18L) {
    // Beyond long double's integers: cut the exact decimal expansion of x (a double this large
    // has at most 60 binary places after the point) and move the last digit kept one unit
    // away from zero when something was cut and the direction asks for it.
    std::snprintf(text, sizeof text, "%.*Lf", decimals + 70, target);
    std::string digits = text;
    const std::size_t point = digits.find('.');
    const bool cut = digits.find_first_not_of('0', point + 1 + decimals) != std::string::npos;
    digits.resize(decimals > 0 ? point + 1 + decimals : point);
    const bool negative = digits[0] == '-';
    if (cut && up != negative) {  // truncation went toward zero: one unit away from it
      std::size_t i = digits.size();
      while (i-- > 0) {
        if (digits[i] == '.' ) continue;
        if (digits[i] == '-') { digits.insert(i + 1, "1"); break; }
        if (digits[i] != '9') { ++digits[i]; break; }
        digits[i] = '0';
        if (i == 0) digits.insert(0, "1");
      }
    }
    return digits;
  }
  // The scaling rounds: the text is checked, and moved one unit out if it fell inside.
  auto print = [decimals](long double y) {
    char line[400];
    std::snprintf(line, sizeof line, "%.*Lf", decimals, y);
    return std::string(line);
  };
  auto unit = [scale](const std::string&, long double) { return 1 / scale; };
  return detail::outward(x, up, (up ? std::ceil(target * scale) : std::floor(target * scale)) / scale, print, unit);
}

}  // namespace meshsweeper::cli
