#pragma once
// Certified bounds as short text, rounded outward: a lower bound printed with few digits must
// not exceed the proven value, nor an upper bound fall below it, or the printed interval would
// no longer contain the quantity. Header-only, so that the demo scenes (scenes/, a library
// without the tool) print their bounds the way `meshsweep hausdorff` does.
//
// The text is read back in long double (64-bit mantissa) and compared with the value there: a
// decimal within half an ulp of a double reads back as that double, which would hide that "0.1"
// is below 0.1000000000000000055 (the double 0.1). Subnormals and the largest doubles work in
// long double too.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace meshsweeper::cli {

// x with `digits` significant digits (1 to 17), rounded down (up = false) or up.
inline std::string outwardBound(double x, int digits, bool up) {
  if (!std::isfinite(x)) return x > 0 ? "inf" : (x < 0 ? "-inf" : "nan");
  const long double target = x;
  char text[64];
  long double y = target;
  for (int attempt = 0; attempt < 8; ++attempt) {
    std::snprintf(text, sizeof text, "%.*Lg", digits, y);
    const long double shown = std::strtold(text, nullptr);
    if (up ? shown >= target : shown <= target) return text;
    // One unit of the last digit shown beyond the rounded value, in the needed direction.
    const long double unit = shown == 0 ? std::fabs(target)
                                        : std::pow(10.0L, std::floor(std::log10(std::fabs(shown))) - (digits - 1));
    y = up ? shown + unit : shown - unit;
  }
  std::snprintf(text, sizeof text, "%.21Lg", target);  // not reached in practice: x itself
  return text;
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
  long double y = (up ? std::ceil(target * scale) : std::floor(target * scale)) / scale;
  for (int attempt = 0; attempt < 8; ++attempt) {
    std::snprintf(text, sizeof text, "%.*Lf", decimals, y);
    // The scaling rounds: the text is checked, and moved one unit out if it fell inside.
    const long double shown = std::strtold(text, nullptr);
    if (up ? shown >= target : shown <= target) return text;
    y = up ? shown + 1 / scale : shown - 1 / scale;
  }
  std::snprintf(text, sizeof text, "%.*Lf", decimals, target);
  return text;
}

}  // namespace meshsweeper::cli
