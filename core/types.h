#pragma once
// Basic types shared by every module of Meshsweeper.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cmath>
#include <limits>
#include <cstdint>

namespace meshsweeper {

using Vec3 = Eigen::Vector3d;
using VertexIndex = uint32_t;    // index into Mesh::positions
using TriangleIndex = uint32_t;  // index into Mesh::triangles (file order, after triangulation)
using Triangle = std::array<VertexIndex, 3>;

inline constexpr uint32_t kInvalidIndex = 0xffffffffu;

// The largest coordinate magnitude accepted for meshes, moved vertices, rigid translations and
// the service's query points. A query (core/sweep_query.h) takes points up to
// kMaxQueryCoordinate, which leaves room for a rigid body's frame: a squared distance between
// such a point and a mesh vertex (at most 3 x 1.001e153 squared) stays below the largest
// double, so no distance overflows.
inline constexpr double kMaxCoordinate = 1e150;
inline constexpr double kMaxQueryCoordinate = 1e153;
// |d| with no underflow of the squares to 0 (below about 1e-154) and no overflow: scaled by the
// largest coordinate, as Eigen's stableNorm() does. (stableNorm's blocked loop draws GCC 12's
// maybe-uninitialized false positive in its AVX-512 code in the ASan/UBSan build.) Infinite
// for an infinite coordinate, NaN for a NaN one.
inline double stableLength(const Vec3& d) {
  if (!d.allFinite())
    return d.hasNaN() ? std::numeric_limits<double>::quiet_NaN() : std::numeric_limits<double>::infinity();
  const double scale = d.cwiseAbs().maxCoeff();
  if (scale == 0) return 0;
  return scale * (d / scale).norm();
}

// Finite and within `limit` on every axis (false for NaN).
inline bool inCoordinateRange(const Vec3& x, double limit = kMaxCoordinate) {
  return std::abs(x.x()) <= limit && std::abs(x.y()) <= limit && std::abs(x.z()) <= limit;
}

// A float no smaller than x >= 0: x is raised by more than rounding to float can take off
// (2^-24 relative for normal floats, 2^-150 absolute below them); past the float range, +inf.
inline float floatAtLeast(double x) {
  const double y = x * (1 + 0x1p-23) + 0x1p-148;
  return y <= std::numeric_limits<float>::max() ? static_cast<float>(y) : std::numeric_limits<float>::infinity();
}
// The same for any sign: a float no smaller (floatAbove) or no larger (floatBelow) than x.
// Past the float range they saturate on the side that stays a bound: floatAbove of a value
// below -FLT_MAX is -FLT_MAX (a plain conversion gives -inf, which is no upper bound; found by
// an audit: a key frame 1e39 times its rest size), floatBelow of one above FLT_MAX is FLT_MAX.
inline float floatAbove(double x) {
  constexpr double kMax = std::numeric_limits<float>::max();
  if (x < -kMax) return -std::numeric_limits<float>::max();
  const double y = x + (x < 0 ? -x : x) * 0x1p-23 + 0x1p-148;
  return y > kMax ? std::numeric_limits<float>::infinity() : static_cast<float>(y);  // NaN stays NaN
}
inline float floatBelow(double x) {
  constexpr double kMax = std::numeric_limits<float>::max();
  if (x > kMax) return std::numeric_limits<float>::max();
  const double y = x - (x < 0 ? -x : x) * 0x1p-23 - 0x1p-148;
  return y < -kMax ? -std::numeric_limits<float>::infinity() : static_cast<float>(y);
}

}  // namespace meshsweeper
