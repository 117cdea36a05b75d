#pragma once
// Certified bounds as short text, rounded outward: a lower bound printed with few digits must
// not exceed the proven value, nor an upper bound fall below it, or the printed interval would
// no longer contain the quantity. Header-only, so that the demo scenes (scenes/, a library
// without the tool) print their bounds the way `meshsweep hausdorff` does.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace meshsweeper::cli {

// x with `digits` significant digits (1 to 17), rounded down (up = false) or up.
inline std::string outwardBound(double x, int digits, bool up) {
  if (!std::isfinite(x)) return x > 0 ? "inf" : (x < 0 ? "-inf" : "nan");
  char text[40];
  double y = x;
  for (int attempt = 0; attempt < 4; ++attempt) {
    std::snprintf(text, sizeof text, "%.*g", digits, y);
    const double shown = std::strtod(text, nullptr);
    if (up ? shown >= x : shown <= x) break;
    // One unit of the last digit shown beyond the rounded value, in the needed direction.
    const double unit = shown == 0 ? std::abs(x)
                                   : std::pow(10.0, std::floor(std::log10(std::abs(shown))) -
                                                        (digits - 1));
    y = up ? shown + unit : shown - unit;
  }
  return text;
}

// x with `decimals` digits after the point (0 to 17), rounded down (up = false) or up: a bound
// shown as a percentage.
inline std::string outwardFixed(double x, int decimals, bool up) {
  if (!std::isfinite(x)) return x > 0 ? "inf" : (x < 0 ? "-inf" : "nan");
  const double scale = std::pow(10.0, decimals);
  double y = (up ? std::ceil(x * scale) : std::floor(x * scale)) / scale;
  char text[400];  // %f of the largest double: 309 digits before the point
  for (int attempt = 0; attempt < 4; ++attempt) {
    std::snprintf(text, sizeof text, "%.*f", decimals, y);
    // x * scale is rounded: the text is checked, and moved one unit out if it fell inside.
    const double shown = std::strtod(text, nullptr);
    if (up ? shown >= x : shown <= x) break;
    y = up ? shown + 1 / scale : shown - 1 / scale;
  }
  return text;
}

}  // namespace meshsweeper::cli
