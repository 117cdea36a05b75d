// Closest point on a triangle: exact hand-made cases for every feature in all six vertex orders,
// degenerate and near-degenerate triangles and random triangles against an independent
// reference in 113-bit (or long double) arithmetic, and the 8-wide block against the scalar
// function.
#include "core/triangle_distance.h"

#include <catch2/catch.hpp>
#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

using namespace meshsweeper;

namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();

// ---------------------------------------------------------------------------------------------
// Independent reference: the closest of the three segments, or the projection onto the plane
// when it falls inside the triangle, computed in extended precision.

#ifdef __SIZEOF_FLOAT128__
using Exact = __float128;
#else
using Exact = long double;
#endif

struct X3 {
  Exact x, y, z;
};
X3 toExact(const Vec3& v) { return {v.x(), v.y(), v.z()}; }
X3 operator-(const X3& a, const X3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
X3 operator+(const X3& a, const X3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
X3 operator*(Exact s, const X3& a) { return {s * a.x, s * a.y, s * a.z}; }
Exact dotExact(const X3& a, const X3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
X3 crossExact(const X3& a, const X3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

Exact referenceSegment(const X3& p, const X3& u, const X3& v) {
  const X3 d = v - u;
  const Exact len = dotExact(d, d);
  Exact t = 0;
  if (len > 0) t = std::min<Exact>(std::max<Exact>(dotExact(p - u, d) / len, 0), 1);
  const X3 r = p - (u + t * d);
  return dotExact(r, r);
}

// Squared distance from p to triangle (a, b, c), rounded to double at the end.
double referenceSquared(const Vec3& pe, const Vec3& ae, const Vec3& be, const Vec3& ce) {
  const X3 p = toExact(pe), a = toExact(ae), b = toExact(be), c = toExact(ce);
  Exact best = std::min(referenceSegment(p, a, b),
                        std::min(referenceSegment(p, b, c), referenceSegment(p, c, a)));
  const X3 n = crossExact(b - a, c - a);
  const Exact nn = dotExact(n, n);
  if (nn > 0) {
    const Exact h = dotExact(p - a, n);
    const X3 q = p - (h / nn) * n;
    const bool inside = dotExact(crossExact(b - a, q - a), n) >= 0 &&
                        dotExact(crossExact(c - b, q - b), n) >= 0 &&
                        dotExact(crossExact(a - c, q - c), n) >= 0;
    if (inside) best = std::min(best, h * h / nn);
  }
  return static_cast<double>(best);
}

// ---------------------------------------------------------------------------------------------
// Checks shared by every case.

std::string describe(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  std::ostringstream s;
  s.precision(17);
  s << "p = (" << p.transpose() << ")  a = (" << a.transpose() << ")  b = (" << b.transpose()
    << ")  c = (" << c.transpose() << ")";
  return s.str();
}

double maxAbs(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  return std::max({p.cwiseAbs().maxCoeff(), a.cwiseAbs().maxCoeff(), b.cwiseAbs().maxCoeff(),
                   c.cwiseAbs().maxCoeff()});
}

// Why the result is inconsistent, or "" when it is finite, its barycentric coordinates are
// valid, agree with the feature and give the returned point, the point lies on the triangle, the
// squared distance is |p - point|^2 and squaredDistanceToTriangle agrees (relative 1e-14).
std::string inconsistency(const TriangleClosest& r, const Vec3& p, const Vec3& a, const Vec3& b,
                          const Vec3& c) {
  const double m = maxAbs(p, a, b, c);
  if (!std::isfinite(r.squared_distance) || !r.point.allFinite() || !r.barycentric.allFinite())
    return "not finite";
  if (r.barycentric.minCoeff() < 0.0) return "negative barycentric coordinate";
  if (std::abs(r.barycentric.sum() - 1.0) > 4 * kEps) return "barycentric sum is not 1";
  // A face point of a thin triangle is its projection onto the plane, as computed; its
  // coordinates reproduce it only to their conditioning, the longest edge over the smallest
  // height (a needle's coordinates err by eps over the short edge, times the long ones).
  double conditioning = 1.0;
  if (r.feature == Feature::kFace) {
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const double twice_area = (b - a).cross(c - a).norm();
    if (twice_area > 0) conditioning = std::max(1.0, longest * longest / twice_area);
  }
  const Vec3 combined = r.barycentric[0] * a + r.barycentric[1] * b + r.barycentric[2] * c;
  if ((combined - r.point).cwiseAbs().maxCoeff() > 8 * kEps * m * conditioning)
    return "point != b0*a + b1*b + b2*c";
  if (std::abs(r.squared_distance - (p - r.point).squaredNorm()) > 4 * kEps * r.squared_distance)
    return "squared distance != |p - point|^2";
  if (referenceSquared(r.point, a, b, c) > (16 * kEps * m) * (16 * kEps * m))
    return "point is off the triangle";
  const int f = static_cast<int>(r.feature);
  if (f < 3) {
    if (r.barycentric[f] != 1.0) return "vertex feature without barycentric 1";
    if (r.point != (f == 0 ? a : (f == 1 ? b : c))) return "vertex feature, point != vertex";
  } else if (f < 6) {
    if (r.barycentric[(f - 3 + 2) % 3] != 0.0) return "edge feature, opposite corner weighs";
  }
  const double only = squaredDistanceToTriangle(p, a, b, c);
  if (std::abs(only - r.squared_distance) > 1e-14 * r.squared_distance)
    return "squaredDistanceToTriangle disagrees";
  return {};
}

// Checks inconsistency() in a Catch section, with the case described only on failure.
#define CHECK_CONSISTENT(r, p, a, b, c, context)        \
  do {                                                  \
    const std::string why = inconsistency(r, p, a, b, c); \
    if (!why.empty()) {                                 \
      INFO(context << " " << describe(p, a, b, c));     \
      FAIL_CHECK(why);                                  \
    }                                                   \
  } while (false)

// CHECK(cond) that builds its message only when cond fails (the loops run ~10^5 cases).
#define CHECK_WITH(cond, context) \
  do {                            \
    if (!(cond)) {                \
      INFO(context);              \
      CHECK(cond);                \
    }                             \
  } while (false)

// Agreement with the reference: relative 1e-12, plus the rounding of the returned point's
// coordinates (eps * |coordinates| each, moving the distance by about that much), which is
// larger than 1e-12 of the distance near the surface when the coordinates are far from the
// origin (about a fifth of the random cases need it; the largest error seen is 1.7 eps *
// |coordinates| * distance).
bool agrees(double value, double reference, double coordinate_scale) {
  const double rounding = 4 * kEps * coordinate_scale * std::sqrt(reference);
  return std::abs(value - reference) <= 1e-12 * reference + rounding;
}

// ---------------------------------------------------------------------------------------------
// Hand-made cases: triangle A = (0,0,0), B = (4,0,0), C = (0,4,0) (all answers exact in binary).

struct Expected {
  const char* name;
  Vec3 p;
  Vec3 point;
  Vec3 barycentric;  // over (A, B, C)
  int feature;       // over (A, B, C): 0..2 vertex, 3 AB, 4 BC, 5 CA, 6 face
  double squared_distance;
};

std::vector<Expected> handMadeCases() {
  return {
      {"vertex A region", {-1, -1, 2}, {0, 0, 0}, {1, 0, 0}, 0, 6},
      {"vertex B region", {6, -1, 1}, {4, 0, 0}, {0, 1, 0}, 1, 6},
      {"vertex C region", {-1, 6, -3}, {0, 4, 0}, {0, 0, 1}, 2, 14},
      {"edge AB region", {1, -2, 2}, {1, 0, 0}, {0.75, 0.25, 0}, 3, 8},
      {"edge BC region", {3, 3, 1}, {2, 2, 0}, {0, 0.5, 0.5}, 4, 3},
      {"edge CA region", {-3, 1, 1}, {0, 1, 0}, {0.75, 0, 0.25}, 5, 10},
      {"face region", {1, 1, 5}, {1, 1, 0}, {0.5, 0.25, 0.25}, 6, 25},
      {"face region below", {1, 2, -3}, {1, 2, 0}, {0.25, 0.25, 0.5}, 6, 9},
      {"on the plane inside", {1, 2, 0}, {1, 2, 0}, {0.25, 0.25, 0.5}, 6, 0},
      {"on the plane beyond BC", {3, 3, 0}, {2, 2, 0}, {0, 0.5, 0.5}, 4, 2},
      {"on the plane beyond A", {-2, -1, 0}, {0, 0, 0}, {1, 0, 0}, 0, 5},
      {"exactly on edge AB", {2, 0, 0}, {2, 0, 0}, {0.5, 0.5, 0}, 3, 0},
      {"exactly on edge BC", {1, 3, 0}, {1, 3, 0}, {0, 0.25, 0.75}, 4, 0},
      {"exactly on edge CA", {0, 3, 0}, {0, 3, 0}, {0.25, 0, 0.75}, 5, 0},
      {"exactly on vertex A", {0, 0, 0}, {0, 0, 0}, {1, 0, 0}, 0, 0},
      {"exactly on vertex B", {4, 0, 0}, {4, 0, 0}, {0, 1, 0}, 1, 0},
      {"exactly on vertex C", {0, 4, 0}, {0, 4, 0}, {0, 0, 1}, 2, 0},
  };
}

// The feature of a triangle given as corners (X0, X1, X2) = (P[order[0]], P[order[1]],
// P[order[2]]) for a feature named over (P0, P1, P2) = (A, B, C).
Feature permutedFeature(int feature, const std::array<int, 3>& order) {
  auto position = [&](int corner) {
    return static_cast<int>(std::find(order.begin(), order.end(), corner) - order.begin());
  };
  if (feature < 3) return static_cast<Feature>(position(feature));
  if (feature == 6) return Feature::kFace;
  const int i = position(feature - 3), j = position((feature - 3 + 1) % 3);
  const int lo = std::min(i, j), hi = std::max(i, j);
  if (lo == 0 && hi == 1) return Feature::kEdge01;
  if (lo == 1 && hi == 2) return Feature::kEdge12;
  return Feature::kEdge20;
}

const char* featureName(Feature f) {
  static const char* names[] = {"vertex0", "vertex1", "vertex2", "edge01",
                                "edge12",  "edge20",  "face"};
  return names[static_cast<int>(f)];
}

// Runs every hand-made case on the triangle mapped by `map` (applied to corners, queries and
// expected points) in all six vertex orders.
template <class Map>
void checkHandMade(const Map& map, double tolerance) {
  const Vec3 corners[3] = {map(Vec3(0, 0, 0)), map(Vec3(4, 0, 0)), map(Vec3(0, 4, 0))};
  std::array<int, 3> order = {0, 1, 2};
  do {
    const Vec3& x0 = corners[order[0]];
    const Vec3& x1 = corners[order[1]];
    const Vec3& x2 = corners[order[2]];
    for (const Expected& e : handMadeCases()) {
      const Vec3 p = map(e.p);
      const Vec3 point = map(e.point);
      const Feature feature = permutedFeature(e.feature, order);
      INFO(e.name << ", order " << order[0] << order[1] << order[2] << ", "
                  << describe(p, x0, x1, x2) << ", expected " << featureName(feature));
      const TriangleClosest r = closestPointOnTriangle(p, x0, x1, x2);
      INFO("got " << featureName(r.feature) << " point (" << r.point.transpose() << ") bary ("
                  << r.barycentric.transpose() << ") d2 " << r.squared_distance);
      // Rounded copies of "exactly on" cases may land a rounding off the boundary, on either side.
      const bool on_boundary = std::string(e.name).rfind("exactly on", 0) == 0;
      if (tolerance == 0.0 || !on_boundary) CHECK(r.feature == feature);
      CHECK((r.point - point).cwiseAbs().maxCoeff() <= tolerance);
      for (int k = 0; k < 3; ++k)
        CHECK(std::abs(r.barycentric[k] - e.barycentric[order[k]]) <= tolerance);
      CHECK(std::abs(r.squared_distance - e.squared_distance) <=
            tolerance * (1 + e.squared_distance));
      CHECK_CONSISTENT(r, p, x0, x1, x2, e.name);
    }
  } while (std::next_permutation(order.begin(), order.end()));
}

Vec3 randomVector(std::mt19937_64& rng, double scale) {
  std::uniform_real_distribution<double> u(-scale, scale);
  return Vec3(u(rng), u(rng), u(rng));
}

Vec3 randomPointOn(std::mt19937_64& rng, const Vec3& a, const Vec3& b, const Vec3& c) {
  std::uniform_real_distribution<double> u(0, 1);
  double s = u(rng), t = u(rng);
  if (s + t > 1) {
    s = 1 - s;
    t = 1 - t;
  }
  return a + s * (b - a) + t * (c - a);
}

Eigen::Matrix3d randomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0, 1);
  Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
  q.normalize();
  return q.toRotationMatrix();
}

// A query point for triangle (a, b, c) at `scale`: uniform in a box around it, or close to the
// surface (a point of the triangle moved by a random offset of random magnitude).
Vec3 randomQuery(std::mt19937_64& rng, const Vec3& a, const Vec3& b, const Vec3& c,
                 const Vec3& center, double scale) {
  std::uniform_int_distribution<int> kind(0, 2);
  std::uniform_real_distribution<double> u(0, 1);
  switch (kind(rng)) {
    case 0:
      return center + randomVector(rng, 2 * scale);
    case 1:
      return randomPointOn(rng, a, b, c) + randomVector(rng, scale * std::pow(10.0, -6 * u(rng)));
    default: {
      // Near an edge or a vertex.
      const Vec3 corners[3] = {a, b, c};
      const int i = std::uniform_int_distribution<int>(0, 2)(rng);
      const Vec3 on = corners[i] + u(rng) * (corners[(i + 1) % 3] - corners[i]);
      return on + randomVector(rng, scale * std::pow(10.0, -4 * u(rng)));
    }
  }
}

}  // namespace

TEST_CASE("closest point: every feature in all six vertex orders", "[triangle_distance]") {
  SECTION("triangle in the plane z = 0") {
    checkHandMade([](const Vec3& v) { return v; }, 0.0);
  }
  SECTION("moved by an exact signed axis permutation and translation") {
    checkHandMade([](const Vec3& v) { return Vec3(v.z() + 1, -v.x() + 2, v.y() - 3); }, 0.0);
  }
  SECTION("rotated and moved (rounded)") {
    std::mt19937_64 rng(11);
    for (int i = 0; i < 8; ++i) {
      const Eigen::Matrix3d rotation = randomRotation(rng);
      const Vec3 shift = randomVector(rng, 10);
      INFO("rotation " << i);
      checkHandMade([&](const Vec3& v) -> Vec3 { return rotation * v + shift; }, 1e-13);
    }
  }
}

TEST_CASE("closest point: a known failure of plain region tests", "[triangle_distance]") {
  // A == B: the region test for edge AB passes with |AB| = 0; the answer is on edge CA.
  const Vec3 a(0, 0, 0), b(0, 0, 0), c(4, 0, 0), p(2, 1, 0);
  for (int rotation = 0; rotation < 3; ++rotation) {
    const Vec3 corners[3] = {a, b, c};
    const Vec3& x0 = corners[rotation];
    const Vec3& x1 = corners[(rotation + 1) % 3];
    const Vec3& x2 = corners[(rotation + 2) % 3];
    INFO(describe(p, x0, x1, x2));
    const TriangleClosest r = closestPointOnTriangle(p, x0, x1, x2);
    CHECK(r.squared_distance == 1.0);
    CHECK(r.point == Vec3(2, 0, 0));
    CHECK(static_cast<int>(r.feature) >= 3);
    CHECK(static_cast<int>(r.feature) < 6);
    CHECK_CONSISTENT(r, p, x0, x1, x2, "A == B");
  }
}

TEST_CASE("closest point: degenerate triangles", "[triangle_distance]") {
  struct Shape {
    const char* name;
    Vec3 a, b, c;
  };
  const std::vector<Shape> shapes = {
      {"collinear, C beyond B", {0, 0, 0}, {2, 0, 0}, {5, 0, 0}},
      {"collinear, C between A and B", {0, 0, 0}, {5, 0, 0}, {2, 0, 0}},
      {"collinear, slanted", {1, 2, 3}, {3, 5, 7}, {-1, -1, -1}},
      {"A == B", {1, 1, 1}, {1, 1, 1}, {3, 1, 2}},
      {"B == C", {1, 1, 1}, {3, 1, 2}, {3, 1, 2}},
      {"C == A", {3, 1, 2}, {1, 1, 1}, {3, 1, 2}},
      {"all coincident", {1, -2, 3}, {1, -2, 3}, {1, -2, 3}},
      {"all zero", {0, 0, 0}, {0, 0, 0}, {0, 0, 0}},
  };
  std::mt19937_64 rng(7);
  for (const Shape& s : shapes) {
    SECTION(s.name) {
      std::array<Vec3, 3> corners = {s.a, s.b, s.c};
      std::array<int, 3> order = {0, 1, 2};
      do {
        const Vec3& x0 = corners[order[0]];
        const Vec3& x1 = corners[order[1]];
        const Vec3& x2 = corners[order[2]];
        for (int i = 0; i < 2000; ++i) {
          const Vec3 p = i < 3 ? corners[i] : Vec3(randomVector(rng, 6) + Vec3(1, 1, 1));
          const TriangleClosest r = closestPointOnTriangle(p, x0, x1, x2);
          CHECK_CONSISTENT(r, p, x0, x1, x2, s.name);
          const double reference = referenceSquared(p, x0, x1, x2);
          CHECK_WITH(agrees(r.squared_distance, reference, maxAbs(p, x0, x1, x2)),
                     s.name << " " << describe(p, x0, x1, x2) << " got " << r.squared_distance
                            << " reference " << reference);
        }
      } while (std::next_permutation(order.begin(), order.end()));
    }
  }
}

// A triangle collapsed to one point (every corner equal, as in a mesh whose vertices all
// coincide) is answered directly, not through the sliver path (a review measured 50 times a
// triangle's cost there): the point as vertex 0, the distance as the segments computed it.
TEST_CASE("closest point: a triangle collapsed to a point is that point, vertex 0", "[triangle_distance]") {
  std::mt19937_64 rng(11);
  for (int i = 0; i < 5000; ++i) {
    const double scale = std::pow(10.0, static_cast<double>(i % 41) - 20);
    const Vec3 a = randomVector(rng, scale);
    const Vec3 p = i % 5 == 0 ? a : Vec3(a + randomVector(rng, std::pow(10.0, static_cast<double>(i % 23) - 11)));
    const TriangleClosest r = closestPointOnTriangle(p, a, a, a);
    const Vec3 d = p - a;
    CHECK(r.point == a);
    CHECK(r.barycentric == Vec3(1, 0, 0));
    CHECK(r.feature == Feature::kVertex0);
    CHECK(r.squared_distance == Approx(d.squaredNorm()).epsilon(1e-15));
    CHECK(squaredDistanceToTriangle(p, a, a, a) == r.squared_distance);
    if (i % 5 == 0) CHECK(r.squared_distance == 0);
  }
}

TEST_CASE("closest point: near-degenerate slivers", "[triangle_distance]") {
  // Needles (one tiny angle, largest angle 90 degrees) and caps (largest angle near 180
  // degrees) are thin below sin^2 1e-3 of their smallest angle (decided on the projection onto
  // their plane); caps switch to segments below sin^2 1e-15 of their largest angle (thinness
  // about 1e-8 here), where the answer can be off by half the cap's height: only those get an
  // absolute allowance (it held from thinness 1e-5 down when the switch was at sin^2 1e-10).
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  for (int k = 0; k <= 32; ++k) {
    const double thinness = std::pow(10.0, -0.5 * k);  // 1 .. 1e-16
    for (int shape = 0; shape < 2; ++shape) {
      const bool cap = shape == 1;
      for (int i = 0; i < 400; ++i) {
        const Eigen::Matrix3d rotation = randomRotation(rng);
        const Vec3 shift = randomVector(rng, 3);
        const double length = std::pow(10.0, -3 + 6 * u(rng));
        const double x = u(rng);
        const Vec3 c_local = cap ? Vec3(x, thinness * std::min(x, 1 - x), 0) : Vec3(1, thinness, 0);
        const Vec3 a = shift;
        const Vec3 b = rotation * Vec3(length, 0, 0) + shift;
        const Vec3 c = rotation * (length * c_local) + shift;
        const Vec3 p = randomQuery(rng, a, b, c, a, length);
        const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
        CHECK_CONSISTENT(r, p, a, b, c, (cap ? "cap" : "needle") << " thinness " << thinness);
        const double reference = referenceSquared(p, a, b, c);
        const double m = maxAbs(p, a, b, c);
        const double allowance = cap && thinness < 1e-7 ? 1e-15 * length * length : 0.0;
        const bool ok = agrees(r.squared_distance, reference, m) ||
                        std::abs(r.squared_distance - reference) <= allowance;
        CHECK_WITH(ok,
                   (cap ? "cap" : "needle") << " thinness " << thinness << " "
                                            << describe(p, a, b, c) << " got "
                                            << r.squared_distance << " reference " << reference);
      }
    }
  }
}

TEST_CASE("closest point: points on a sliver are at distance 0", "[triangle_distance]") {
  // A sliver (largest angle 179.9993 degrees, sin^2 1.4e-10): the Gram system answered points
  // lying on it up to 7.6e-7 away; the projection onto its plane answers them exactly.
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0.5, 3e-6, 0);
  for (const Vec3& p : {Vec3(0.98, 1.6e-8, 0), Vec3(0.5, 2.9e-6, 0), Vec3(0.1, 1e-7, 0), Vec3(0.7, 1e-6, 0)}) {
    INFO(describe(p, a, b, c));
    const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
    CHECK(r.squared_distance <= 1e-30);
    CHECK(r.feature == Feature::kFace);
    CHECK_CONSISTENT(r, p, a, b, c, "on the sliver");
    // Above it: the height, to the reference's precision.
    const Vec3 above = p + Vec3(0, 0, 1e-3);
    const double expected = referenceSquared(above, a, b, c);
    CHECK(std::abs(squaredDistanceToTriangle(above, a, b, c) - expected) <= 1e-14 * expected);
  }
}

TEST_CASE("closest point: points on a cap are at distance 0", "[triangle_distance]") {
  // A cap (largest angle 179.9994 degrees, sin^2 9.6e-11): answered by its segments when the
  // switch was at sin^2 1e-10, a point lying on it came out 2.45e-6 away (half its height) and
  // one 1e-3 above it 3e-6 too far, relatively (found by review).
  const Vec3 a(0, 0, 0), b(2, 0, 0), c(1, 4.9e-6, 0);
  REQUIRE_FALSE(isDegenerateTriangle(a, b, c));
  for (const Vec3& p : {Vec3(1, 2.45e-6, 0), Vec3(0.5, 1e-6, 0), Vec3(1.9, 2e-7, 0)}) {
    INFO(describe(p, a, b, c));
    const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
    CHECK(r.squared_distance <= 1e-30);
    CHECK_CONSISTENT(r, p, a, b, c, "on the cap");
    const Vec3 above = p + Vec3(0, 0, 1e-3);
    CHECK(std::abs(std::sqrt(squaredDistanceToTriangle(above, a, b, c)) - 1e-3) <= 1e-14);
  }
}

TEST_CASE("closest point: random triangles against the reference", "[triangle_distance]") {
  // 100k cases over scales 1e-6 .. 1e6 (and a few at 1e-60 and 1e60).
  std::mt19937_64 rng(2024);
  const double scales[] = {1e-6, 1e-3, 1.0, 1e3, 1e6, 1e-60, 1e60};
  const int counts[] = {20000, 20000, 20000, 20000, 20000, 2000, 2000};
  for (int s = 0; s < 7; ++s) {
    const double scale = scales[s];
    for (int i = 0; i < counts[s]; ++i) {
      const Vec3 center = randomVector(rng, 4 * scale);
      const Vec3 a = center + randomVector(rng, scale);
      const Vec3 b = center + randomVector(rng, scale);
      const Vec3 c = center + randomVector(rng, scale);
      const Vec3 p = randomQuery(rng, a, b, c, center, scale);
      const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
      const double reference = referenceSquared(p, a, b, c);
      CHECK_WITH(agrees(r.squared_distance, reference, maxAbs(p, a, b, c)),
                 "scale " << scale << " case " << i << " " << describe(p, a, b, c) << " got "
                          << r.squared_distance << " reference " << reference);
      CHECK_CONSISTENT(r, p, a, b, c, "scale " << scale << " case " << i);
    }
  }
}

TEST_CASE("closest point: extreme magnitudes stay finite and on the triangle",
          "[triangle_distance]") {
  std::mt19937_64 rng(99);
  for (int e = -150; e <= 150; e += 10) {
    const double scale = std::pow(10.0, e);
    for (int i = 0; i < 200; ++i) {
      const Vec3 center = randomVector(rng, 4 * scale);
      const Vec3 a = center + randomVector(rng, scale);
      const Vec3 b = center + randomVector(rng, scale);
      const Vec3 c = i % 4 == 0 ? a : center + randomVector(rng, scale);
      const Vec3 p = randomQuery(rng, a, b, c, center, scale);
      const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
      const Vec3 lower = a.cwiseMin(b).cwiseMin(c), upper = a.cwiseMax(b).cwiseMax(c);
      const double slack = 4 * kEps * maxAbs(p, a, b, c);
      const bool ok = std::isfinite(r.squared_distance) && r.point.allFinite() &&
                      r.barycentric.allFinite() && r.barycentric.minCoeff() >= 0.0 &&
                      std::abs(r.barycentric.sum() - 1.0) <= 4 * kEps &&
                      (r.point.array() >= lower.array() - slack).all() &&
                      (r.point.array() <= upper.array() + slack).all();
      CHECK_WITH(ok, "scale 1e" << e << " " << describe(p, a, b, c) << " got point ("
                                << r.point.transpose() << ") bary ("
                                << r.barycentric.transpose() << ")");
    }
  }
}

namespace {

void setLane(TriangleBlock8& block, int lane, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3* corners[3] = {&a, &b, &c};
  for (int k = 0; k < 3; ++k)
    for (int axis = 0; axis < 3; ++axis) block.v[k][axis][lane] = (*corners[k])[axis];
}

Vec3 laneCorner(const TriangleBlock8& block, int lane, int k) {
  return Vec3(block.v[k][0][lane], block.v[k][1][lane], block.v[k][2][lane]);
}

bool sameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }
bool sameBits(const Vec3& a, const Vec3& b) {
  return sameBits(a.x(), b.x()) && sameBits(a.y(), b.y()) && sameBits(a.z(), b.z());
}

// closestPointsInBlock and blockLaneClosest against the scalar function, lane by lane: the
// same bits (point, coordinates, squared distance), the same feature, and the block's squared
// distances those of squaredDistancesToBlock. Returns the lanes that differ.
int blockClosestMismatches(const Vec3& p, const TriangleBlock8& block) {
  double plain[8], detailed[8];
  BlockClosest8 details;
  squaredDistancesToBlock(p, block, plain);
  closestPointsInBlock(p, block, detailed, details);
  int mismatches = 0;
  for (int lane = 0; lane < 8; ++lane) {
    const TriangleClosest got = blockLaneClosest(p, block, details, lane);
    const TriangleClosest want =
        closestPointOnTriangle(p, laneCorner(block, lane, 0), laneCorner(block, lane, 1), laneCorner(block, lane, 2));
    const bool same = sameBits(plain[lane], detailed[lane]) && sameBits(got.squared_distance, want.squared_distance) &&
                      sameBits(got.point, want.point) && sameBits(got.barycentric, want.barycentric) &&
                      got.feature == want.feature;
    if (!same && mismatches < 3) {
      INFO("lane " << lane << " " << describe(p, laneCorner(block, lane, 0), laneCorner(block, lane, 1),
                                               laneCorner(block, lane, 2))
                   << " feature " << int(got.feature) << " / " << int(want.feature) << " squared "
                   << got.squared_distance << " / " << want.squared_distance);
      CHECK(same);
    }
    mismatches += !same;
  }
  return mismatches;
}

}  // namespace

TEST_CASE("block of eight equals the scalar function", "[triangle_distance]") {
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> u(0, 1);
  std::uniform_int_distribution<int> kind(0, 9);
  const double scales[] = {1e-6, 1e-2, 1.0, 1e2, 1e6};
  int lanes_checked = 0;
  int detail_mismatches = 0;
  for (double scale : scales) {
    for (int round = 0; round < 4000; ++round) {
      TriangleBlock8 block;
      const Vec3 center = randomVector(rng, 4 * scale);
      const int used = 1 + round % 8;  // unused lanes copy lane 0
      for (int lane = 0; lane < 8; ++lane) {
        Vec3 a = center + randomVector(rng, scale);
        Vec3 b = center + randomVector(rng, scale);
        Vec3 c = center + randomVector(rng, scale);
        switch (kind(rng)) {
          case 0: c = a + 0.37 * (b - a); break;                   // collinear (rounded)
          case 1: c = a + 2.5 * (b - a); break;                    // collinear, outside
          case 2: b = a; break;                                    // two coincident corners
          case 3: b = a; c = a; break;                             // a point
          case 4: c = b; break;                                    // two coincident corners
          case 5: {                                                // cap
            const Vec3 n = (b - a).cross(randomVector(rng, 1.0)).normalized();
            c = a + u(rng) * (b - a) + n * scale * std::pow(10.0, -12 * u(rng));
            break;
          }
          case 6: {                                                // needle
            const Vec3 n = (b - a).cross(randomVector(rng, 1.0)).normalized();
            c = b + n * scale * std::pow(10.0, -12 * u(rng));
            break;
          }
          default: break;                                          // plain triangle
        }
        setLane(block, lane, a, b, c);
      }
      for (int lane = used; lane < 8; ++lane)
        setLane(block, lane, laneCorner(block, 0, 0), laneCorner(block, 0, 1),
                laneCorner(block, 0, 2));
      const int target = std::uniform_int_distribution<int>(0, 7)(rng);
      const Vec3 p = randomQuery(rng, laneCorner(block, target, 0), laneCorner(block, target, 1),
                                 laneCorner(block, target, 2), center, scale);
      double out[8];
      squaredDistancesToBlock(p, block, out);
      detail_mismatches += blockClosestMismatches(p, block);
      // Points on the lanes' vertices and edges too (the exact vertex, the edges' parameters).
      detail_mismatches += blockClosestMismatches(laneCorner(block, target, round % 3), block);
      detail_mismatches += blockClosestMismatches(
          laneCorner(block, target, 0) + u(rng) * (laneCorner(block, target, 1) - laneCorner(block, target, 0)), block);
      for (int lane = 0; lane < 8; ++lane) {
        const Vec3 a = laneCorner(block, lane, 0), b = laneCorner(block, lane, 1),
                   c = laneCorner(block, lane, 2);
        const double scalar = squaredDistanceToTriangle(p, a, b, c);
        // The header promises relative 1e-14; by construction the values are identical.
        CHECK_WITH(std::abs(out[lane] - scalar) <= 1e-14 * scalar,
                   "scale " << scale << " round " << round << " lane " << lane << " "
                            << describe(p, a, b, c) << " block " << out[lane] << " scalar "
                            << scalar);
        ++lanes_checked;
      }
    }
  }
  CHECK(lanes_checked == 5 * 4000 * 8);
  CHECK(detail_mismatches == 0);
}

TEST_CASE("block of eight: hand-made lanes", "[triangle_distance]") {
  // Every feature of the hand-made triangle, plus degenerate lanes, all in one block.
  TriangleBlock8 block;
  setLane(block, 0, {0, 0, 0}, {4, 0, 0}, {0, 4, 0});
  setLane(block, 1, {4, 0, 0}, {0, 4, 0}, {0, 0, 0});
  setLane(block, 2, {0, 4, 0}, {0, 0, 0}, {4, 0, 0});
  setLane(block, 3, {0, 0, 0}, {0, 0, 0}, {4, 0, 0});  // A == B
  setLane(block, 4, {0, 0, 0}, {2, 0, 0}, {5, 0, 0});  // collinear
  setLane(block, 5, {1, 1, 1}, {1, 1, 1}, {1, 1, 1});  // a point
  setLane(block, 6, {0, 0, 0}, {4, 0, 0}, {2, 1e-9, 0});  // cap
  setLane(block, 7, {0, 0, 0}, {4, 0, 0}, {4, 1e-9, 0});  // needle
  for (const Expected& e : handMadeCases()) {
    double out[8];
    squaredDistancesToBlock(e.p, block, out);
    CHECK(blockClosestMismatches(e.p, block) == 0);
    for (int lane = 0; lane < 8; ++lane) {
      const Vec3 a = laneCorner(block, lane, 0), b = laneCorner(block, lane, 1),
                 c = laneCorner(block, lane, 2);
      INFO(e.name << " lane " << lane << " " << describe(e.p, a, b, c));
      const double scalar = squaredDistanceToTriangle(e.p, a, b, c);
      CHECK(std::abs(out[lane] - scalar) <= 1e-14 * scalar);
      if (lane < 3) CHECK(out[lane] == e.squared_distance);
    }
  }
}

TEST_CASE("block of eight: closest points at negative zeros and exact corners", "[triangle_distance]") {
  // A corner with negative zero coordinates is returned as it is (o + 0 * edge would make it
  // +0), as the scalar function returns a vertex.
  TriangleBlock8 block;
  setLane(block, 0, {-0.0, -0.0, -0.0}, {4, 0, 0}, {0, 4, 0});
  setLane(block, 1, {4, -0.0, 0}, {-0.0, 4, -0.0}, {-0.0, -0.0, 1});
  setLane(block, 2, {-1, -0.0, -0.0}, {-0.0, -1, -0.0}, {-0.0, -0.0, -1});
  setLane(block, 3, {1e300, 0, 0}, {0, 1e300, 0}, {0, 0, 1e300});  // Gram terms overflow: thin
  setLane(block, 4, {0, 0, 0}, {std::numeric_limits<double>::infinity(), 0, 0}, {0, 1, 0});  // not finite
  setLane(block, 5, {-0.0, 3, -0.0}, {-0.0, 5, -0.0}, {2, 3, -0.0});
  setLane(block, 6, {0, 0, 0}, {1, 0, 0}, {0.5, 1e-9, 0});  // thin
  setLane(block, 7, {-2, -2, -0.0}, {2, -2, -0.0}, {-0.0, 2, -0.0});
  int mismatches = 0;
  for (const Vec3& p : {Vec3(-1, -1, -1), Vec3(-0.0, -0.0, 5), Vec3(5, -0.0, -0.0), Vec3(-0.0, 5, -0.0),
                        Vec3(1, 1, 1), Vec3(-0.0, -0.0, -0.0), Vec3(0.5, 0.5, -0.0), Vec3(-3, 7, 0)})
    mismatches += blockClosestMismatches(p, block);
  CHECK(mismatches == 0);
}

TEST_CASE("closest point: tiny slivers stay finite", "[triangle_distance]") {
  // Slivers with edges near 1e-80 (a mesh of size 1 may hold one): their edge functions
  // underflow to 0, which once made the projection 0/0 (NaN). Answers must be finite, within
  // the triangle's size of the reference (its fourth powers underflow: the documented limit),
  // and the block must equal the scalar function.
  {  // a case found by review: its edge functions are all exactly 0
    const Vec3 a(-4.5877928646206372e-81, 7.2786827057852286e-81, 1.1675703099028055e-81);
    const Vec3 b(1.2497609489270366e-84, -8.3276747600802813e-81, -8.440317063740134e-81);
    const Vec3 c(-2.4907803541389413e-81, 6.3141392710899746e-83, -3.3771890547080823e-81);
    const Vec3 p(-2.492000854729793e-81, 3.9121507941943645e-82, -3.1522205528864487e-81);
    const double reference = referenceSquared(p, a, b, c);
    const double got = squaredDistanceToTriangle(p, a, b, c);
    REQUIRE(std::isfinite(got));
    INFO("got " << got << " reference " << reference);
    // Edge lengths near 1e-80 put the kernel's fourth powers below the doubles: the triangle is
    // answered by its segments (the documented limit), off by at most its own size.
    CHECK(std::abs(std::sqrt(got) - std::sqrt(reference)) <= (b - a).norm() + (c - a).norm());
  }
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 2000; ++i) {
    const double scale = std::pow(10.0, -79 - 3 * u(rng));
    const double x = 0.2 + 0.6 * u(rng);
    const Vec3 a(0, 0, 0), b(scale, 0, 0), c(x * scale, 1e-3 * scale * std::min(x, 1 - x), 0);
    const Vec3 p = Vec3(u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5) * 2 * scale;
    const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
    INFO(describe(p, a, b, c));
    REQUIRE(std::isfinite(r.squared_distance));
    const double reference = referenceSquared(p, a, b, c);
    CHECK(std::abs(std::sqrt(r.squared_distance) - std::sqrt(reference)) <= 2 * scale);
    TriangleBlock8 block;
    for (int lane = 0; lane < 8; ++lane) setLane(block, lane, a, b, c);
    double out[8];
    squaredDistancesToBlock(p, block, out);
    CHECK(out[0] == squaredDistanceToTriangle(p, a, b, c));
  }
}

// Needles: two long edges and a short one (short / long from 1e-3 to 1e-12), points just off
// the plane over the needle, near its tip or anywhere along it. Their barycentric coordinates
// lose eps * |ap| / (short edge), which the long edges multiply, so a needle's face point is
// its projection onto the plane (an accurate normal: the largest angle is near 90 degrees).
// Found by review: a point 1e-11 from a needle's tip was answered 6.8e-3 away. The block
// agrees bit for bit.
TEST_CASE("closest point: needles", "[triangle_distance]") {
  {
    const Vec3 a(-0.96739614839096744, -0.76718814336701169, -0.55325255795829409);
    const Vec3 b(0.4193105400949646, 0.438351028214504, -0.43800765110134121);
    const Vec3 c(-0.96739614838610011, -0.76718814336337771, -0.55325255795786554);
    const Vec3 p(0.41931054009613633, 0.43835102821410477, -0.43800765111126427);
    const double reference = referenceSquared(p, a, b, c);
    const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
    INFO("got " << r.squared_distance << " reference " << reference);
    CHECK(agrees(r.squared_distance, reference, maxAbs(p, a, b, c)));
    CHECK(std::sqrt(r.squared_distance) < 1e-10);
  }
  std::mt19937_64 rng(0x2eed1e);
  std::uniform_real_distribution<double> u(0, 1);
  for (double ratio : {1e-3, 1e-5, 1e-7, 1e-9, 1e-12}) {
    size_t failures = 0;
    for (int i = 0; i < 500; ++i) {
      const Eigen::Matrix3d rotation = randomRotation(rng);
      const Vec3 shift = randomVector(rng, 2);
      const double length = std::pow(10.0, -2 + 3 * u(rng));
      // Tip at the origin of the local frame, base (short edge) at x = length.
      const Vec3 tip = shift;
      const Vec3 base0 = rotation * Vec3(length, 0, 0) + shift;
      const Vec3 base1 = rotation * Vec3(length * (1 + ratio * (u(rng) - 0.5)), length * ratio, 0) + shift;
      // A point over the needle (near the tip half the time), 1e-12 to 1e-3 of its length off.
      const double along = i % 2 ? std::pow(10.0, -9 * u(rng)) : u(rng);
      const double across = u(rng);
      const Vec3 on = rotation * Vec3(length * along, length * ratio * along * across, 0) + shift;
      const double off = length * std::pow(10.0, -12 + 9 * u(rng)) * (u(rng) < 0.5 ? -1 : 1);
      const Vec3 p = on + rotation * Vec3(0, 0, off);
      const Vec3 corners[3] = {tip, base0, base1};
      const int first = i % 3;  // every labelling
      const Vec3 &a = corners[first], &b = corners[(first + 1) % 3], &c = corners[(first + 2) % 3];
      const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
      const double reference = referenceSquared(p, a, b, c);
      const bool ok = agrees(r.squared_distance, reference, maxAbs(p, a, b, c));
      failures += !ok;
      if (!ok && failures <= 3) {
        INFO("ratio " << ratio << " " << describe(p, a, b, c) << " got " << r.squared_distance << " reference "
                      << reference);
        CHECK(ok);
      }
      CHECK_CONSISTENT(r, p, a, b, c, "needle ratio " << ratio);
      TriangleBlock8 block;
      for (int lane = 0; lane < 8; ++lane) setLane(block, lane, a, b, c);
      double out[8];
      squaredDistancesToBlock(p, block, out);
      CHECK(out[0] == r.squared_distance);
    }
    INFO("ratio " << ratio);
    CHECK(failures == 0);
  }
}

// Slivers and caps (largest angle near 180 degrees) get their plane from quadruple precision:
// a point on a cap 1e-8 high was answered 3.7e-9 away (the segments, half its height), which
// also put a certified Hausdorff interval above the true value (found by review). Random caps
// and slivers of heights 1e-2 .. 1e-17 of their length, and needles lying along their long
// edges, at every orientation; points on them, just off them and beyond their edges, against
// the quadruple-precision reference: the distance to 1e-12 relative plus 4 eps of the
// coordinates, the result consistent, the block equal to the scalar function.
TEST_CASE("closest point: slivers and caps in quadruple precision", "[triangle_distance]") {
  const auto within = [](const TriangleClosest& r, const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
    const double reference = std::sqrt(referenceSquared(p, a, b, c));
    return std::abs(std::sqrt(r.squared_distance) - reference) <= 1e-12 * reference + 4 * kEps * maxAbs(p, a, b, c);
  };
  {  // the review's cap and point (distance 1.2765e-17, exact rational arithmetic)
    const Vec3 a(0, 0, 0), b(-0.076712757796519204, 0.40579110923776673, 0.91074075809465993),
        c(-0.031772925221473985, 0.16807071695731035, 0.37721094628955709);
    const Vec3 p(-0.032372725090242499, 0.17124352226620193, 0.3843318639022969);
    const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
    INFO("got " << std::sqrt(r.squared_distance));
    CHECK(std::sqrt(r.squared_distance) < 1e-15);
    CHECK(r.feature == Feature::kFace);
    CHECK_CONSISTENT(r, p, a, b, c, "review's cap");
  }
  std::mt19937_64 rng(0x51175);
  std::uniform_real_distribution<double> u(0, 1);
  int failures = 0, cases = 0;
  for (int i = 0; i < 6000; ++i) {
    const Eigen::Matrix3d rotation = randomRotation(rng);
    const Vec3 shift = i % 3 == 0 ? Vec3::Zero() : randomVector(rng, std::pow(10.0, 3 * u(rng)));
    const double length = std::pow(10.0, -2 + 4 * u(rng));
    const double height = length * std::pow(10.0, -2 - 15 * u(rng));
    // A cap (apex over the long edge's inside), a sliver (apex past its end) or a needle whose
    // short edge lies along the long ones (apex just past the end, further along).
    const int kind = i % 3;
    const double x = kind == 0 ? u(rng) : (kind == 1 ? 1 + 0.5 * u(rng) : 1 + 1e-3 * u(rng));
    const Vec3 local[3] = {Vec3(0, 0, 0), Vec3(length, 0, 0), Vec3(x * length, height, 0)};
    Vec3 corners[3];
    for (int k = 0; k < 3; ++k) corners[k] = rotation * local[k] + shift;
    const int first = i % 7 % 3;
    const Vec3 &a = corners[first], &b = corners[(first + 1) % 3], &c = corners[(first + 2) % 3];
    TriangleBlock8 block;
    for (int lane = 0; lane < 8; ++lane) setLane(block, lane, a, b, c);
    for (int j = 0; j < 4; ++j) {
      // On the triangle (random coordinates), off it along the normal, or beyond an edge.
      const double w1 = u(rng), w2 = u(rng) * (1 - w1);
      Vec3 on = a + w1 * (b - a) + w2 * (c - a);
      if (j == 3) on = a + (1 + 1e-6 * u(rng)) * (b - a);
      const double off = j == 0 ? 0.0 : length * std::pow(10.0, -15 + 13 * u(rng)) * (u(rng) < 0.5 ? -1 : 1);
      const Vec3 p = on + off * (rotation * Vec3(0, 0, 1));
      const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
      const bool ok = within(r, p, a, b, c);
      failures += !ok;
      ++cases;
      if (!ok && failures <= 3) {
        INFO("kind " << kind << " height " << height / length << " " << describe(p, a, b, c) << " got "
                     << std::sqrt(r.squared_distance) << " reference " << std::sqrt(referenceSquared(p, a, b, c)));
        CHECK(ok);
      }
      CHECK_CONSISTENT(r, p, a, b, c, "kind " << kind << " height " << height / length);
      double out[8];
      squaredDistancesToBlock(p, block, out);
      CHECK(out[0] == r.squared_distance);
    }
  }
  CHECK(cases == 24000);
  CHECK(failures == 0);
}

// A point just beyond a needle's tip lies near the lines of both long edges, where the double
// edge functions cannot tell inside from outside: quadruple precision decides (found by
// review: 1.4e-13 beyond the apex of a needle of angle 6.3e-5 was answered 6.3e-14 away, on
// the face, 1.3e-13 off the triangle).
TEST_CASE("closest point: beyond a needle's tip", "[triangle_distance]") {
  {
    const Vec3 a(0, 0, 0.5), b(-0.70701791794492674, -0.70719563326198565, 0),
        c(-0.70697348213723654, -0.70724005511194743, 0);
    const Vec3 p(1e-13, 1e-13, 0.5);
    const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
    CHECK(r.squared_distance == (p - a).squaredNorm());
    CHECK(r.feature == Feature::kVertex0);
    CHECK(r.point == a);
  }
  std::mt19937_64 rng(0x71b);
  std::uniform_real_distribution<double> u(0, 1);
  int failures = 0;
  for (int i = 0; i < 4000; ++i) {
    const Eigen::Matrix3d rotation = randomRotation(rng);
    const double length = std::pow(10.0, -1 + 2 * u(rng));
    const double angle = std::pow(10.0, -8 + 6 * u(rng));
    const Vec3 tip = randomVector(rng, 1.0);
    const Vec3 b = tip + rotation * Vec3(length, -0.5 * angle * length, 0);
    const Vec3 c = tip + rotation * Vec3(length, 0.5 * angle * length, 0);
    // Beyond the tip along the axis, a little to the side, a little off the plane.
    const double back = length * std::pow(10.0, -14 + 6 * u(rng));
    const Vec3 p = tip + rotation * Vec3(-back, back * angle * (u(rng) - 0.5), back * (u(rng) - 0.5));
    const TriangleClosest r = closestPointOnTriangle(p, tip, b, c);
    const double reference = std::sqrt(referenceSquared(p, tip, b, c));
    const bool ok = std::abs(std::sqrt(r.squared_distance) - reference) <=
                    1e-12 * reference + 4 * kEps * maxAbs(p, tip, b, c);
    failures += !ok;
    if (!ok && failures <= 3) {
      INFO(describe(p, tip, b, c) << " got " << std::sqrt(r.squared_distance) << " reference " << reference);
      CHECK(ok);
    }
    CHECK_CONSISTENT(r, p, tip, b, c, "needle tip");
  }
  CHECK(failures == 0);
}

// A needle's face point comes with barycentric coordinates that rebuild it (found by review:
// its edge functions cross the short edge, and b0 came out 2e-5 off on a needle whose short
// edge is 1e-12 of its long ones).
TEST_CASE("closest point: a needle's barycentric coordinates rebuild its point", "[triangle_distance]") {
  const Vec3 p(-0.72876749816808017, -0.23087227880763431, 0.1271013318562918);
  const Vec3 a(-0.80749165079414742, -0.082485078605954776, 0.25392983879380648);
  const Vec3 b(-0.43346918998343714, -0.78748022838924214, -0.34863886068463545);
  const Vec3 c(-0.43346918998268497, -0.78748022838839005, -0.34863886068489092);
  const TriangleClosest r = closestPointOnTriangle(p, a, b, c);
  const Vec3 rebuilt = r.barycentric[0] * a + r.barycentric[1] * b + r.barycentric[2] * c;
  CHECK((rebuilt - r.point).norm() <= 1e-14);
  CHECK(r.barycentric[0] == Approx(0.78952025379530655).epsilon(1e-12));
  CHECK(agrees(r.squared_distance, referenceSquared(p, a, b, c), maxAbs(p, a, b, c)));
}
