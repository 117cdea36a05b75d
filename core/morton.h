#pragma once
// Morton (Z-order) codes, 21 bits per axis: sorting points by them keeps consecutive points
// close (contraction pairs across gaps in the build, the vertex order of Hausdorff queries).
#include "core/types.h"

#include <algorithm>

namespace meshsweeper {

// Spreads the low 21 bits of x so that two zero bits separate each bit.
inline uint64_t spreadBits(uint64_t x) {
  x &= 0x1fffff;
  x = (x | x << 32) & 0x1f00000000ffffull;
  x = (x | x << 16) & 0x1f0000ff0000ffull;
  x = (x | x << 8) & 0x100f00f00f00f00full;
  x = (x | x << 4) & 0x10c30c30c30c30c3ull;
  x = (x | x << 2) & 0x1249249249249249ull;
  return x;
}

// The Morton code of x in the box [lower, lower + extent], clamped to it.
// Precondition: every component of extent is > 0.
inline uint64_t mortonCode(const Vec3& x, const Vec3& lower, const Vec3& extent) {
  uint64_t code = 0;
  for (int axis = 0; axis < 3; ++axis) {
    const double t = (x[axis] - lower[axis]) / extent[axis];
    code |= spreadBits(static_cast<uint64_t>(std::clamp(t, 0.0, 1.0) * 2097151.0)) << axis;
  }
  return code;
}

}  // namespace meshsweeper
