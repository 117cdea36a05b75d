// Hausdorff distances (core/hausdorff.h) against known answers and against brute force.
//
// Known answers:
//  - two concentric geodesic spheres built from the same icosahedron, radii r < R (the outer
//    one is the inner one scaled by R/r; both convex, the outer contains the inner):
//      h(outer, inner) = R - r exactly: the distance to a convex set is convex, so over a face
//        of the outer mesh it peaks at a corner, and a corner (R/r) v lies on the ray through
//        the inner vertex v, whose normal cone holds that ray (the inner mesh is inscribed in
//        the sphere of radius r, so the tangent plane at v supports it);
//      h(inner, outer) = max over x of the inner mesh of min over faces F of the outer mesh of
//        (R/r h_F - n_F . x), h_F the distance of face F's plane (of the inner mesh) from the
//        centre; it lies in [(R/r - 1) min_F h_F, (R/r - 1) max_F h_F] (each term is at least
//        (R/r - 1) h_F since n_F . x <= h_F; the term of x's own face is (R/r - 1) h_t), which
//        is one number for the icosahedron (every face at the inradius: the distance is that
//        constant over the whole inner surface);
//  - a square grid and the same grid with its centre vertex raised by z: h(raised, flat) = z
//    (the distance to the plane is the height, largest at the raised vertex, and the mean and
//    RMS are exact: the height is linear on each triangle);
//  - identical meshes: 0; a square translated along its normal by t: t both ways.
// Brute force (core/brute_force.h): on procedural and real meshes, the brute-force distance of
// every vertex and of dense random surface samples of A is <= upper, the distance at the
// reported point equals lower, lower <= upper, and upper - lower <= tolerance.
// Determinism: 1 and 2 threads give bit-identical results.
#include "core/hausdorff.h"

#include "core/brute_force.h"
#include "core/mesh_io.h"
#include "scenes/procedural.h"
#include "tools/bound_text.h"

#include <catch2/catch.hpp>

#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <tuple>

using namespace meshsweeper;

namespace {

// The inradius over the circumradius of a regular icosahedron.
const double kIcosahedronInradius =
    std::sqrt(3.0) * (3 + std::sqrt(5.0)) / (3 * std::sqrt(10 + 2 * std::sqrt(5.0)));

Mesh translated(Mesh mesh, const Vec3& offset) {
  for (Vec3& p : mesh.positions) p += offset;
  return mesh;
}

// Largest and smallest distance from the origin to the planes of the faces.
std::pair<double, double> facePlaneDistances(const Mesh& mesh) {
  double lo = INFINITY, hi = 0;
  for (const Triangle& t : mesh.triangles) {
    const Vec3 a = mesh.positions[t[0]], b = mesh.positions[t[1]], c = mesh.positions[t[2]];
    const Vec3 n = (b - a).cross(c - a).normalized();
    const double h = std::abs(n.dot(a));
    lo = std::min(lo, h);
    hi = std::max(hi, h);
  }
  return {lo, hi};
}

// A coarse version of a mesh by vertex clustering on a grid of `cell` (each vertex moves to the
// first vertex of its cell, so every coarse vertex lies on the original surface); triangles
// that collapse are dropped. Non-manifold results are valid input.
Mesh clustered(const Mesh& mesh, double cell) {
  std::map<std::tuple<long, long, long>, VertexIndex> representative;
  std::vector<VertexIndex> map(mesh.positions.size());
  Mesh out;
  out.name = mesh.name + " clustered";
  for (VertexIndex v = 0; v < mesh.positions.size(); ++v) {
    const Vec3& p = mesh.positions[v];
    const auto key = std::make_tuple(std::lround(std::floor(p.x() / cell)),
                                     std::lround(std::floor(p.y() / cell)),
                                     std::lround(std::floor(p.z() / cell)));
    const auto found = representative.find(key);
    if (found != representative.end()) {
      map[v] = found->second;
    } else {
      map[v] = static_cast<VertexIndex>(out.positions.size());
      representative.emplace(key, map[v]);
      out.positions.push_back(p);
    }
  }
  for (const Triangle& t : mesh.triangles) {
    const Triangle c{map[t[0]], map[t[1]], map[t[2]]};
    if (c[0] != c[1] && c[1] != c[2] && c[2] != c[0]) out.triangles.push_back(c);
  }
  return out;
}

double bruteDistance(const Mesh& mesh, const Vec3& p) {
  return bruteForceClosest(mesh, p).distance;
}

// Checks one direction against brute force: every vertex and `samples` random surface points
// of `from` are within `upper` of `to`, and the reported point is at distance `lower`.
void checkAgainstBruteForce(const OneSidedHausdorff& h, const Mesh& from, const Mesh& to,
                            size_t samples, uint64_t seed) {
  REQUIRE(h.lower <= h.upper);
  const double slack = 1e-12 * (1 + h.upper);
  double vertex_max = 0;
  for (const Vec3& p : scenes::vertexPoints(from))
    vertex_max = std::max(vertex_max, bruteDistance(to, p));
  CHECK(vertex_max <= h.upper + slack);
  double sample_max = 0;
  for (const Vec3& p : scenes::surfacePoints(from, samples, seed))
    sample_max = std::max(sample_max, bruteDistance(to, p));
  CHECK(sample_max <= h.upper + slack);
  // lower is the exact distance of a point of A, reached at `at`, on triangle at_triangle.
  REQUIRE(h.at_triangle < from.triangles.size());
  const Triangle& t = from.triangles[h.at_triangle];
  CHECK(
      closestPointOnTriangle(h.at, from.positions[t[0]], from.positions[t[1]], from.positions[t[2]])
          .squared_distance <= 1e-24 * (1 + h.at.squaredNorm()));
  CHECK(std::abs(bruteDistance(to, h.at) - h.lower) <= slack);
  CHECK(std::abs((h.at - h.closest).norm() - h.lower) <= slack);
  REQUIRE(h.closest_triangle < to.triangles.size());
  // The brute-force maximum over the vertices never exceeds the certified upper bound, and
  // lower is at least the vertex maximum (every vertex is sampled).
  CHECK(h.lower >= vertex_max - slack);
}

HausdorffOptions absolute(double tolerance, unsigned threads = 0) {
  HausdorffOptions options;
  options.tolerance = tolerance;
  options.threads = threads;
  return options;
}

void requireIdentical(const OneSidedHausdorff& x, const OneSidedHausdorff& y) {
  CHECK(x.lower == y.lower);
  CHECK(x.upper == y.upper);
  CHECK(x.at == y.at);
  CHECK(x.at_triangle == y.at_triangle);
  CHECK(x.closest == y.closest);
  CHECK(x.closest_triangle == y.closest_triangle);
  CHECK(x.mean == y.mean);
  CHECK(x.rms == y.rms);
  CHECK(x.counters.samples == y.counters.samples);
  CHECK(x.counters.triangles_refined == y.counters.triangles_refined);
  CHECK(x.counters.cells == y.counters.cells);
  CHECK(x.counters.rounds == y.counters.rounds);
}

}  // namespace

// Points of B as degenerate triangles (i, i, i).
Mesh pointCloud(const std::vector<Vec3>& points) {
  Mesh mesh;
  mesh.name = "points";
  mesh.positions = points;
  for (VertexIndex i = 0; i < points.size(); ++i) mesh.triangles.push_back({i, i, i});
  return mesh;
}

Mesh singleTriangle(const Vec3& a, const Vec3& b, const Vec3& c) {
  Mesh mesh;
  mesh.name = "triangle";
  mesh.positions = {a, b, c};
  mesh.triangles = {{0, 1, 2}};
  return mesh;
}

// Hand-drawn cases where the maximum of the bisector bound sits where only one kind of
// candidate finds it. The tolerance is chosen so that a bound that missed the candidate would
// stop at once with an upper bound below the true value.
TEST_CASE("bisector bound: the triple point and an edge crossing set the maximum") {
  const double h = 0.1;
  SECTION("triple point: equilateral triangle, B = the three points above its corners") {
    //        v2                  B: c_i = v_i + (0, 0, h)
    //       /  \                 the farthest point of t from {c_i} is the centre,
    //      / x  \                at sqrt(h^2 + 1/3) (circumradius 1/sqrt(3));
    //    v0 ---- v1              an edge midpoint is only at sqrt(h^2 + 1/4)
    const Vec3 v0(0, 0, 0), v1(1, 0, 0), v2(0.5, std::sqrt(0.75), 0);
    const Mesh a = singleTriangle(v0, v1, v2);
    const Mesh b = pointCloud({v0 + Vec3(0, 0, h), v1 + Vec3(0, 0, h), v2 + Vec3(0, 0, h)});
    const double exact = std::sqrt(h * h + 1.0 / 3);
    const HausdorffResult r = hausdorffOneSided(a, b, absolute(0.45));
    CHECK(r.lower <= exact + 1e-12);
    CHECK(r.upper >= exact - 1e-12);
    CHECK(r.upper - r.lower <= 0.45);
    const HausdorffResult tight = hausdorffOneSided(a, b, absolute(1e-6));
    CHECK(tight.lower == Approx(exact).epsilon(1e-6));
  }
  SECTION("edge crossing: B = points above two corners") {
    //   v2 (0.2, 0.5)            B: c0 above v0, c1 above v1 (height h)
    //    |  \                    bisector x = 0.5 crosses edge v1-v2 at (0.5, 0.3125):
    //    |    x                  the maximum, sqrt(h^2 + 0.25 + 0.3125^2); the corner v2
    //   v0 ------ v1 (1, 0)      is only at sqrt(h^2 + 0.04 + 0.25)
    const Vec3 v0(0, 0, 0), v1(1, 0, 0), v2(0.2, 0.5, 0);
    const Mesh a = singleTriangle(v0, v1, v2);
    const Mesh b = pointCloud({v0 + Vec3(0, 0, h), v1 + Vec3(0, 0, h)});
    const double exact = std::sqrt(h * h + 0.25 + 0.3125 * 0.3125);
    const HausdorffResult r = hausdorffOneSided(a, b, absolute(0.02));
    CHECK(r.lower <= exact + 1e-12);
    CHECK(r.upper >= exact - 1e-12);
    CHECK(r.upper - r.lower <= 0.02);
    const HausdorffResult tight = hausdorffOneSided(a, b, absolute(1e-6));
    CHECK(tight.lower == Approx(exact).epsilon(1e-6));
  }
}

TEST_CASE("concentric icosahedra: both one-sided distances exactly") {
  const double r = 1, R = 2;
  const Mesh inner = scenes::icosphere(0, r);
  const Mesh outer = scenes::icosphere(0, R);
  const double tol = 1e-6;
  const HausdorffResult result = hausdorff(inner, outer, absolute(tol));
  INFO("h(inner, outer) [" << result.a_to_b.lower << ", " << result.a_to_b.upper
                           << "], h(outer, inner) [" << result.b_to_a.lower << ", "
                           << result.b_to_a.upper << "]");
  // H = R - r from the outer mesh's vertices.
  CHECK(result.lower <= R - r + 1e-12);
  CHECK(result.upper >= R - r - 1e-12);
  CHECK(result.upper - result.lower <= tol);
  CHECK(result.converged);

  // Each direction to the tolerance.
  HausdorffOptions both = absolute(tol);
  both.tighten_both = true;
  const HausdorffResult tight = hausdorff(inner, outer, both);
  const double expected = (R / r - 1) * kIcosahedronInradius * r;
  const auto planes = facePlaneDistances(inner);
  CHECK(planes.first == Approx(kIcosahedronInradius).epsilon(1e-12));
  CHECK(planes.second == Approx(kIcosahedronInradius).epsilon(1e-12));
  CHECK(tight.a_to_b.lower <= expected + 1e-12);
  CHECK(tight.a_to_b.upper >= expected - 1e-12);
  CHECK(tight.a_to_b.upper - tight.a_to_b.lower <= tol);
  CHECK(tight.b_to_a.lower <= R - r + 1e-12);
  CHECK(tight.b_to_a.upper >= R - r - 1e-12);
  CHECK(tight.b_to_a.upper - tight.b_to_a.lower <= tol);
  CHECK(tight.lower == result.lower);
}

TEST_CASE("concentric geodesic spheres: known intervals and brute force") {
  const double r = 1, R = 1.25;
  const Mesh inner = scenes::icosphere(2, r);
  const Mesh outer = scenes::icosphere(2, R);
  const auto planes = facePlaneDistances(inner);
  REQUIRE(R / r * planes.first > r);  // the outer mesh contains the inner one
  HausdorffOptions options = absolute(1e-5);
  options.tighten_both = true;
  const HausdorffResult result = hausdorff(inner, outer, options);
  CHECK(result.b_to_a.lower <= R - r + 1e-12);
  CHECK(result.b_to_a.upper >= R - r - 1e-12);
  CHECK(result.a_to_b.upper >= (R / r - 1) * planes.first - 1e-12);
  CHECK(result.a_to_b.lower <= (R / r - 1) * planes.second + 1e-12);
  CHECK(result.a_to_b.upper - result.a_to_b.lower <= 1e-5);
  CHECK(result.b_to_a.upper - result.b_to_a.lower <= 1e-5);
  checkAgainstBruteForce(result.a_to_b, inner, outer, 3000, 1);
  checkAgainstBruteForce(result.b_to_a, outer, inner, 3000, 2);
}

TEST_CASE("grid with a raised vertex: h(raised, flat) is the height, mean and RMS exact") {
  const int n = 8;
  const double height = 0.1;
  const Mesh flat = scenes::gridPlane(n, 1.0);
  Mesh raised = flat;
  const VertexIndex centre = (n / 2) * (n + 1) + n / 2;
  raised.positions[centre].z() = height;

  const double tol = 1e-5;
  HausdorffOptions options = absolute(tol);
  options.tighten_both = true;
  const HausdorffResult result = hausdorff(raised, flat, options);
  CHECK(result.a_to_b.lower == Approx(height).margin(1e-15));
  CHECK(result.a_to_b.upper >= height);
  CHECK(result.a_to_b.upper <= height + tol);
  CHECK((result.a_to_b.at - raised.positions[centre]).norm() == Approx(0).margin(1e-15));
  CHECK(
      (result.a_to_b.closest - Vec3(raised.positions[centre].x(), raised.positions[centre].y(), 0))
          .norm() == Approx(0).margin(1e-15));
  CHECK(result.lower == Approx(height).margin(1e-15));
  CHECK(result.upper - result.lower <= tol);

  // The height is linear on each triangle of the raised grid: mean and RMS are exact.
  double area = 0, sum = 0, sum2 = 0;
  for (const Triangle& t : raised.triangles) {
    const Vec3 a = raised.positions[t[0]], b = raised.positions[t[1]], c = raised.positions[t[2]];
    const double w = 0.5 * (b - a).cross(c - a).norm();
    const double z0 = a.z(), z1 = b.z(), z2 = c.z();
    area += w;
    sum += w * (z0 + z1 + z2) / 3;
    sum2 += w * (z0 * z0 + z1 * z1 + z2 * z2 + z0 * z1 + z1 * z2 + z2 * z0) / 6;
  }
  CHECK(result.a_to_b.mean == Approx(sum / area).epsilon(1e-12));
  CHECK(result.a_to_b.rms == Approx(std::sqrt(sum2 / area)).epsilon(1e-12));
  CHECK(result.a_to_b.area == Approx(area).epsilon(1e-12));

  // The flat grid's distance to the tent is below the height, and brute force agrees.
  CHECK(result.b_to_a.upper < height);
  checkAgainstBruteForce(result.a_to_b, raised, flat, 2000, 3);
  checkAgainstBruteForce(result.b_to_a, flat, raised, 2000, 4);

  // One-sided entry point: the same interval up to the tolerance.
  const HausdorffResult one = hausdorffOneSided(raised, flat, absolute(tol));
  CHECK(one.lower == Approx(height).margin(1e-15));
  CHECK(one.upper - one.lower <= tol);
  CHECK(std::isnan(one.b_to_a.lower));
}

// The coarse-to-fine direction, where the cover bound does most of the work: two triangles over
// a fine grid with one vertex sunk into a pit. Every corner of the coarse square is at distance
// 0 and its closest faces are flat ones far from the pit, so the maximum lies inside a coarse
// triangle, thousands of fine faces away from the corners' leaf blocks; a cover bound that
// covered a piece with a face that is not within reach of all its corners would stop at once
// with an upper bound near 0.
TEST_CASE("a coarse square over a fine grid with a pit: the maximum inside a coarse cell") {
  const int n = 48;
  const double depth = 0.05;
  const Mesh coarse = scenes::gridPlane(1, 1.0);
  Mesh fine = scenes::gridPlane(n, 1.0);
  const VertexIndex pit = 16 * (n + 1) + 32;  // x = 1/6, y = -1/6: inside coarse triangle 0
  fine.positions[pit].z() = -depth;
  const Vec3 above(fine.positions[pit].x(), fine.positions[pit].y(), 0);
  const double at_pit = bruteDistance(fine, above);
  REQUIRE(at_pit > 0.2 * depth);

  const double tol = 1e-6;
  HausdorffOptions options = absolute(tol, 1);
  options.tighten_both = true;
  const HausdorffResult result = hausdorff(coarse, fine, options);
  CHECK(result.converged);
  CHECK(result.a_to_b.upper >= at_pit);
  CHECK(result.a_to_b.lower >= at_pit - tol);
  CHECK(result.a_to_b.upper - result.a_to_b.lower <= tol);
  CHECK(result.b_to_a.lower == Approx(depth).margin(1e-15));  // the pit's vertex
  CHECK(result.upper - result.lower <= tol);
  checkAgainstBruteForce(result.a_to_b, coarse, fine, 2000, 11);
  checkAgainstBruteForce(result.b_to_a, fine, coarse, 2000, 12);
  // A dense grid of points of the coarse square around the pit: none is farther than upper.
  double around = 0;
  for (int i = -20; i <= 20; ++i)
    for (int j = -20; j <= 20; ++j)
      around = std::max(around, bruteDistance(fine, above + Vec3(i, j, 0) * (1.5 / n / 20)));
  CHECK(around <= result.a_to_b.upper + 1e-12);
  CHECK(around >= at_pit);

  options.threads = 2;
  const HausdorffResult two = hausdorff(coarse, fine, options);
  requireIdentical(result.a_to_b, two.a_to_b);
  requireIdentical(result.b_to_a, two.b_to_a);

  // Loose tolerances: the corners are at distance 0, so a bound that wrongly covered the pit's
  // neighbourhood would stop below the true value; pits in other places of the grid (the same
  // shape: at_pit is the same) move the maximum across the cells' midpoint pieces.
  for (const VertexIndex other : {VertexIndex(16 * (n + 1) + 32), VertexIndex(9 * (n + 1) + 21),
                                  VertexIndex(30 * (n + 1) + 13), VertexIndex(40 * (n + 1) + 7)}) {
    Mesh moved = scenes::gridPlane(n, 1.0);
    moved.positions[other].z() = -depth;
    for (const double loose : {0.2, 0.5, 0.8}) {
      INFO("pit vertex " << other << ", tolerance " << loose << " x the pit's distance");
      const HausdorffResult r = hausdorffOneSided(coarse, moved, absolute(loose * at_pit, 1));
      CHECK(r.upper >= at_pit);
      CHECK(r.lower <= at_pit + 1e-12);
      CHECK(r.upper - r.lower <= loose * at_pit);
    }
  }
}

// A known answer where the cover bound must combine many candidate faces: B is a grid of points
// (degenerate triangles) at height h with spacing g over the square A (two triangles), so
// h(A, B) = sqrt(h^2 + g^2 / 2), reached at the centres of the grid's squares, none of them a
// vertex or an edge midpoint of A. A piece of A is covered only by a point within target of all
// three of its corners; a cover bound that skipped a corner or a piece, or read another
// block's distances, would stop below the exact value at the looser tolerances.
// max_seconds: a computation stopped between rounds keeps a certified interval (here the pit's
// distance lies inside it), says it timed out, and is not converged; a run that meets its
// tolerance before the limit is not timed out. A negative or NaN limit is refused.
TEST_CASE("max_seconds stops refinement with a certified interval") {
  const int n = 48;
  const double depth = 0.05;
  const Mesh coarse = scenes::gridPlane(1, 1.0);
  Mesh fine = scenes::gridPlane(n, 1.0);
  const VertexIndex pit = 16 * (n + 1) + 32;
  fine.positions[pit].z() = -depth;
  const double at_pit = bruteDistance(fine, Vec3(fine.positions[pit].x(), fine.positions[pit].y(), 0));
  HausdorffOptions options = absolute(1e-9, 1);
  options.max_seconds = 1e-9;  // past at the first check: after the vertex pass and first bounds
  const HausdorffResult stopped = hausdorffOneSided(coarse, fine, options);
  CHECK(stopped.timed_out);
  CHECK_FALSE(stopped.converged);
  CHECK(stopped.upper - stopped.lower > stopped.tolerance);
  CHECK(stopped.lower <= at_pit);
  CHECK(stopped.upper >= at_pit);
  CHECK(stopped.counters.rounds == 0);
  options.max_seconds = 60;
  const HausdorffResult full = hausdorffOneSided(coarse, fine, options);
  CHECK_FALSE(full.timed_out);
  CHECK(full.converged);
  CHECK(full.counters.rounds > 0);
  CHECK(full.lower >= stopped.lower);
  CHECK(full.upper <= stopped.upper);
  for (const double bad : {-1.0, std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    options.max_seconds = bad;
    CHECK_THROWS_WITH(hausdorff(coarse, fine, options), Catch::Contains("max_seconds must be finite and >= 0"));
  }
}

// max_bytes (found by an audit: two triangulations of one square at a tolerance of 1e-9 took
// 2.6 GB within 25 s and kept growing): refinement stops before its tables pass the limit, with
// a certified interval (H is 0: the surfaces coincide), at the same point for any thread count;
// a limit above what the computation needs changes nothing.
TEST_CASE("max_bytes stops refinement with a certified interval, within the limit") {
  Mesh a, b;
  a.positions = b.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0)};
  a.triangles = {{0, 1, 2}, {0, 2, 3}};
  b.triangles = {{1, 2, 3}, {1, 3, 0}};
  HausdorffOptions options = absolute(1e-9, 1);
  options.max_bytes = uint64_t{24} << 20;
  const HausdorffResult stopped = hausdorff(a, b, options);
  CHECK(stopped.memory_limited);
  CHECK_FALSE(stopped.timed_out);
  CHECK_FALSE(stopped.converged);
  CHECK(stopped.table_bytes <= options.max_bytes);
  CHECK(stopped.table_bytes > options.max_bytes / 4);  // it went most of the way
  CHECK(stopped.counters.rounds > 10);
  CHECK(stopped.lower <= 1e-15);                    // the true H, 0, lies inside
  CHECK(stopped.upper - stopped.lower > stopped.tolerance);
  CHECK(stopped.upper < 1e-3);                      // and the interval is a useful one
  options.threads = 2;
  const HausdorffResult two = hausdorff(a, b, options);
  CHECK(two.memory_limited);
  CHECK(two.upper == stopped.upper);
  CHECK(two.lower == stopped.lower);
  CHECK(two.counters.samples == stopped.counters.samples);
  CHECK(two.table_bytes == stopped.table_bytes);
  // One byte: stopped at the first check (the vertex pass and the first bounds always run).
  options.max_bytes = 1;
  const HausdorffResult first = hausdorff(a, b, options);
  CHECK(first.memory_limited);
  CHECK(first.counters.rounds == 0);
  CHECK(first.lower <= 1e-15);
  CHECK(first.upper >= stopped.upper);

  // A computation that needs less than the limit: the same as without one.
  Mesh moved = scenes::gridPlane(8, 1.0);
  moved.positions[40].z() = 0.05;
  HausdorffOptions plain = absolute(1e-6, 1);
  HausdorffOptions limited = plain;
  limited.max_bytes = uint64_t{1} << 30;
  const HausdorffResult r0 = hausdorff(scenes::gridPlane(1, 1.0), moved, plain);
  const HausdorffResult r1 = hausdorff(scenes::gridPlane(1, 1.0), moved, limited);
  CHECK_FALSE(r1.memory_limited);
  CHECK(r1.converged);
  CHECK(r1.lower == r0.lower);
  CHECK(r1.upper == r0.upper);
  CHECK(r1.table_bytes == r0.table_bytes);
  CHECK(r1.table_bytes > 0);
}

TEST_CASE("a coarse square over a grid of points: the exact maximum between the points") {
  const double h = 0.01;
  for (const int n : {20, 23}) {
    const double g = 1.0 / n;
    std::vector<Vec3> points;
    for (int i = 0; i <= n; ++i)
      for (int j = 0; j <= n; ++j) points.emplace_back(-0.5 + j * g, -0.5 + i * g, h);
    const Mesh b = pointCloud(points);
    const Mesh a = scenes::gridPlane(1, 1.0);
    const double exact = std::sqrt(h * h + 0.5 * g * g);
    for (const double tol : {1e-7, 0.1 * (exact - h), 0.5 * (exact - h), 0.9 * (exact - h)}) {
      INFO(n << " x " << n << " points, tolerance " << tol);
      const HausdorffResult r = hausdorffOneSided(a, b, absolute(tol, 1));
      CHECK(r.upper >= exact - 1e-12);
      CHECK(r.lower <= exact + 1e-12);
      CHECK(r.upper - r.lower <= tol);
    }
  }
}

TEST_CASE("identical meshes: zero") {
  for (const Mesh& mesh :
       {scenes::icosphere(3), scenes::torus(1, 0.3, 24, 12), scenes::gridPlane(5)}) {
    INFO(mesh.name);
    const HausdorffResult result = hausdorff(mesh, mesh, HausdorffOptions{});
    CHECK(result.lower == Approx(0).margin(1e-15));
    CHECK(result.upper <= result.tolerance);
    CHECK(result.a_to_b.mean == Approx(0).margin(1e-15));
  }
}

TEST_CASE("a triangle lying inside a sliver: zero, within the tolerance") {
  // B is a sliver (largest angle 179.9993 degrees); A lies in it, in its plane: h(A, B) = 0.
  // The sliver's distances were once 7.6e-7 off, which put the certified lower bound above 0.
  Mesh sliver, inside;
  sliver.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 3e-6, 0)};
  sliver.triangles = {Triangle{0, 1, 2}};
  inside.positions = {Vec3(0.1, 1e-7, 0), Vec3(0.98, 1.6e-8, 0), Vec3(0.5, 2.9e-6, 0)};
  inside.triangles = {Triangle{0, 1, 2}};
  HausdorffOptions options;
  options.tolerance = 1e-9;
  const HausdorffResult r = hausdorffOneSided(inside, sliver, options);
  CHECK(r.lower <= 1e-15);
  CHECK(r.upper >= 0);
  CHECK(r.upper - r.lower <= options.tolerance);
}

TEST_CASE("a square translated along its normal: the translation both ways") {
  const Mesh square = scenes::gridPlane(6, 2.0);
  const double t = 0.37;
  const Mesh moved = translated(square, Vec3(0, 0, t));
  HausdorffOptions options = absolute(1e-6);
  options.tighten_both = true;
  const HausdorffResult result = hausdorff(square, moved, options);
  for (const OneSidedHausdorff* h : {&result.a_to_b, &result.b_to_a}) {
    CHECK(h->lower == Approx(t).epsilon(1e-14));
    CHECK(h->upper >= t);
    CHECK(h->upper <= t + 1e-6);
    CHECK(h->mean == Approx(t).epsilon(1e-12));
    CHECK(h->rms == Approx(t).epsilon(1e-12));
  }
}

// Found by an audit: far from the origin the tolerance was raised to 4e-12 of the coordinates
// (the bundled elephant moved by 1e9: 4e-3 instead of the 1.4e-4 asked for), still
// "converged". The Mesh entry points compute about the centre of the meshes' joint box: the
// tolerance asked for holds, the bounds bracket the exact distance (also where the translation
// rounds: y - 0.3 below), and the witnesses are points of the given meshes. The Hierarchy entry
// points compute in place and say that they raised the tolerance.
TEST_CASE("meshes far from the origin: the tolerance asked for, witnesses in place") {
  const Mesh square = scenes::gridPlane(6, 2.0);  // z = 0
  for (const Vec3& far : {Vec3(1e9 + 0.1, 0.3, -0.7), Vec3(-3e12, 5e11, 7.25), Vec3(1e15, 1e15, 1e15)}) {
    INFO("far " << far.transpose());
    const Mesh a = translated(square, far);
    Mesh b = a;
    for (Vec3& p : b.positions) p.z() += 0.37;
    // Every vertex of A sits at one height and moved by the same rounded step: B is A moved
    // along its normal by exactly that step, which is both one-sided distances.
    const double step = b.positions[0].z() - a.positions[0].z();
    for (size_t v = 0; v < a.positions.size(); ++v) REQUIRE(b.positions[v].z() - a.positions[v].z() == step);
    const double tolerance = 1e-6;
    const HausdorffResult both = hausdorff(a, b, absolute(tolerance));
    const HausdorffResult one = hausdorffOneSided(a, b, absolute(tolerance));
    for (const HausdorffResult* r : {&both, &one}) {
      CHECK(r->requested_tolerance == tolerance);
      CHECK(r->tolerance <= tolerance * (1 + 1e-12));
      CHECK(r->converged);
      CHECK(r->lower <= step);
      CHECK(r->upper >= step);
      CHECK(r->upper - r->lower <= r->tolerance);
      const OneSidedHausdorff& h = r->a_to_b;
      const double slack = 4 * std::numeric_limits<double>::epsilon() * far.cwiseAbs().maxCoeff();
      CHECK(std::abs(h.at.z() - a.positions[0].z()) <= slack);
      CHECK(std::abs(h.closest.z() - b.positions[0].z()) <= slack);
      CHECK((h.at - far).cwiseAbs().maxCoeff() <= 1 + slack);
    }
    CHECK(both.b_to_a.lower <= step);
    CHECK(both.b_to_a.upper >= step);
    // In place: the floor of coordinates this far, reported as raised.
    const HausdorffResult in_place = hausdorff(Hierarchy::build(a), Hierarchy::build(b), absolute(tolerance));
    CHECK(in_place.requested_tolerance == tolerance);
    CHECK(in_place.tolerance == Approx(4e-12 * far.cwiseAbs().maxCoeff() + 4e-12).epsilon(0.01));
    CHECK(in_place.lower <= step);
    CHECK(in_place.upper >= step);
  }
  // Found by review: an unused vertex moved with the others could leave the coordinate range
  // (the mesh was then refused); unused vertices stay where they are.
  Mesh dot;
  dot.positions = {Vec3::Constant(6e149), Vec3::Constant(6e149), Vec3::Constant(6e149), Vec3(-6e149, 0, 0)};
  dot.triangles = {Triangle{0, 1, 2}};
  const HausdorffResult dots = hausdorff(dot, dot, absolute(1e-3));
  CHECK(dots.lower == 0);
  CHECK(dots.upper <= dots.tolerance);
  CHECK(dots.a_to_b.at == Vec3::Constant(6e149));
}

TEST_CASE("relative tolerance, degenerate triangles and several components") {
  const Mesh a = scenes::concatenate({scenes::icosphere(2), scenes::degenerateMesh()});
  const Mesh b = scenes::concatenate({translated(scenes::icosphere(1, 1.1), Vec3(0.05, 0, 0)),
                                      translated(scenes::torus(0.5, 0.1, 12, 6), Vec3(-3, -3, 0))});
  HausdorffOptions options;
  options.relative_tolerance = 1e-3;
  const HausdorffResult result = hausdorff(a, b, options);
  CHECK(result.tolerance == Approx(1e-3 * meshDiagonal(a)));
  CHECK(result.upper - result.lower <= result.tolerance);
  CHECK(result.converged);
  checkAgainstBruteForce(result.a_to_b, a, b, 2000, 5);
  checkAgainstBruteForce(result.b_to_a, b, a, 2000, 6);
  // vertex_distance: brute force for used vertices, NaN for the isolated one (degenerateMesh's
  // vertex 11, shifted by the icosphere's vertices).
  const size_t isolated = scenes::icosphere(2).positions.size() + 11;
  REQUIRE(result.a_to_b.vertex_distance.size() == a.positions.size());
  CHECK(std::isnan(result.a_to_b.vertex_distance[isolated]));
  for (VertexIndex v = 0; v < a.positions.size(); v += 7) {
    if (v == isolated) continue;
    CHECK(result.a_to_b.vertex_distance[v] ==
          Approx(bruteDistance(b, a.positions[v])).margin(1e-14));
  }
}

// Found by review: a degenerate triangle of A (a repeated corner, or three collinear ones) was
// split in four children that overlap along its segment (three of them half of it each), so a
// tight tolerance ran into gigabytes. Such a cell is split as the segment it is, in two.
TEST_CASE("degenerate triangles of A at tight tolerances: the segment, split in two") {
  Mesh b;  // two triangles, at right angles
  b.positions = {Vec3(0.25, 0.5, 0.75), Vec3(0.25, 0.5, 1.0), Vec3(0.5, 0.5, 1.0),
                 Vec3(0.5, 0.75, 0.75), Vec3(0.5, 0.75, 0.5), Vec3(0.5, 0.5, 0.5)};
  b.triangles = {{0, 1, 2}, {3, 4, 5}};
  // The segment from (1.25, 0.5, 1) to (1.25, 0.5, 0.5), three ways.
  Mesh repeated;
  repeated.positions = {Vec3(1.25, 0.5, 1.0), Vec3(1.25, 0.5, 0.5)};
  repeated.triangles = {{0, 1, 0}};
  Mesh coincident = repeated;
  coincident.positions.push_back(Vec3(1.25, 0.5, 1.0));
  coincident.triangles = {{0, 1, 2}};
  Mesh collinear = repeated;
  collinear.positions.push_back(Vec3(1.25, 0.5, 0.75));
  collinear.triangles = {{0, 1, 2}};
  // A dense brute force along the segment: its maximum is within half a spacing of h(A, B).
  double sampled = 0;
  const int n = 20000;
  for (int i = 0; i <= n; ++i) sampled = std::max(sampled, bruteDistance(b, Vec3(1.25, 0.5, 1.0 - 0.5 * i / n)));
  for (const Mesh* a : {&repeated, &coincident, &collinear}) {
    for (double relative : {1e-10, 1e-12}) {
      INFO("mesh " << (a == &repeated ? "repeated" : a == &coincident ? "coincident" : "collinear")
                   << ", relative tolerance " << relative);
      HausdorffOptions options;
      options.relative_tolerance = relative;
      const HausdorffResult r = hausdorffOneSided(*a, b, options);
      CHECK(r.converged);
      CHECK(r.upper - r.lower <= r.tolerance);
      CHECK(r.upper >= sampled);
      CHECK(r.lower <= sampled + 0.25 / n);
      CHECK(r.counters.cells < 1000);  // about 2 per level: 60 at 1e-12 (gigabytes before)
    }
  }
}

// Found by review of the thin split: a thin cell with area (a sliver) lost its area to its
// segments (area 0, the mean fell back to the vertices'), and at 1e45 its width overflowed a
// float margin, so every bound was infinite and refinement ran out of memory.
TEST_CASE("thin triangles of A: area kept, any scale") {
  for (double scale : {1.0, 1e45, 1e-45}) {
    INFO("scale " << scale);
    Mesh a;  // a sliver of width 5e-7: thin at tolerance 1e-3
    a.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 5e-7, 0)};
    a.triangles = {{0, 1, 2}};
    Mesh b;
    b.positions = {Vec3(0, 0, 0.1), Vec3(0.01, 0, 0.1), Vec3(0, 0.01, 0.1),
                   Vec3(1, 0, 0.1), Vec3(0.99, 0, 0.1), Vec3(1, 0.01, 0.1)};
    b.triangles = {{0, 1, 2}, {3, 5, 4}};
    for (Vec3& x : a.positions) x *= scale;
    for (Vec3& x : b.positions) x *= scale;
    HausdorffOptions options;
    options.tolerance = 1e-3 * scale;
    const HausdorffResult r = hausdorffOneSided(a, b, options);
    CHECK(r.converged);
    CHECK(r.upper - r.lower <= r.tolerance);
    CHECK(r.a_to_b.area == Approx(0.5 * 5e-7 * scale * scale).epsilon(1e-9));
    CHECK(r.counters.cells < 100);
    double sampled = 0;  // along the long edge, where the distance peaks at its middle
    for (int i = 0; i <= 1000; ++i) sampled = std::max(sampled, bruteDistance(b, Vec3(scale * i / 1000.0, 0, 0)));
    CHECK(r.upper >= sampled);
  }
}

TEST_CASE("1 and 2 threads give identical results") {
  const Mesh a = scenes::icosphere(3, 1.0);
  const Mesh b = translated(scenes::torus(0.8, 0.35, 30, 14), Vec3(0.1, 0.05, 0));
  const HausdorffResult one = hausdorff(a, b, absolute(1e-4, 1));
  const HausdorffResult two = hausdorff(a, b, absolute(1e-4, 2));
  REQUIRE(one.counters.triangles_refined > 0);
  requireIdentical(one.a_to_b, two.a_to_b);
  requireIdentical(one.b_to_a, two.b_to_a);
  CHECK(one.lower == two.lower);
  CHECK(one.upper == two.upper);
  CHECK(one.threads == 1);
  // Counts past TBB's limit (the cores; TBB warned on standard error, and crashed from 65536
  // threads on) are capped at it.
  const auto limit = static_cast<unsigned>(
      tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
  CHECK(two.threads == std::min(2u, limit));
  for (unsigned threads : {limit + 1, 70000u, 4000000000u}) {
    const HausdorffResult many = hausdorff(a, b, absolute(1e-4, threads));
    CHECK(many.threads == limit);
    CHECK(many.lower == one.lower);
    CHECK(many.upper == one.upper);
  }
}

TEST_CASE("bad input: clear errors") {
  Mesh empty;
  empty.name = "empty";
  const Mesh sphere = scenes::icosphere(1);
  CHECK_THROWS_AS(hausdorff(empty, sphere), MeshError);
  CHECK_THROWS_AS(hausdorff(sphere, empty), MeshError);
  Mesh bad = sphere;
  bad.triangles[0][1] = 100000;
  CHECK_THROWS_AS(hausdorff(sphere, bad), MeshError);
  HausdorffOptions negative;
  negative.tolerance = -1;
  CHECK_THROWS_AS(hausdorff(sphere, sphere, negative), std::invalid_argument);
  HausdorffOptions nan_relative;
  nan_relative.relative_tolerance = NAN;
  CHECK_THROWS_AS(hausdorff(sphere, sphere, nan_relative), std::invalid_argument);
  // A relative tolerance that overflows over A's diagonal (found by an audit: an infinite one).
  HausdorffOptions huge_relative;
  huge_relative.relative_tolerance = 1e308;
  CHECK_THROWS_WITH(hausdorff(sphere, sphere, huge_relative), Catch::Contains("beyond the largest double"));
  CHECK_THROWS_WITH(hausdorffOneSided(sphere, sphere, huge_relative), Catch::Contains("beyond the largest double"));
  // A mesh of zero extent needs an absolute tolerance.
  Mesh point;
  point.positions = {Vec3(1, 1, 1)};
  point.triangles = {Triangle{0, 0, 0}};
  CHECK_THROWS_AS(hausdorff(point, sphere), std::invalid_argument);
  CHECK_THROWS_WITH(hausdorff(point, sphere), Catch::Contains("mesh A has zero extent"));  // unnamed
  point.name = "dot.off";
  CHECK_THROWS_WITH(hausdorff(point, sphere), Catch::Contains("dot.off has zero extent"));
  // Null hierarchies are refused, not dereferenced.
  const auto sphere_h = Hierarchy::build(sphere);
  CHECK_THROWS_AS(hausdorff(nullptr, sphere_h), std::invalid_argument);
  CHECK_THROWS_AS(hausdorff(sphere_h, nullptr), std::invalid_argument);
  CHECK_THROWS_AS(hausdorffOneSided(sphere, std::shared_ptr<const Hierarchy>()), std::invalid_argument);
  const HausdorffResult r = hausdorff(point, sphere, absolute(1e-6));
  CHECK(r.a_to_b.lower == Approx(bruteDistance(sphere, Vec3(1, 1, 1))).epsilon(1e-14));
}

TEST_CASE("real mesh against a coarse version: brute force inside the bounds") {
  const std::string path = scenes::meshPath("mannequin-devil");
  if (!std::filesystem::exists(path)) {
    WARN("real mesh missing: " << path << " (run scripts/fetch_data.sh)");
    return;
  }
  const Mesh fine = readMesh(path);
  const Mesh coarse = clustered(fine, 0.03 * meshDiagonal(fine));
  INFO(fine.triangles.size() << " against " << coarse.triangles.size() << " triangles");
  REQUIRE(coarse.triangles.size() > 500);
  REQUIRE(coarse.triangles.size() < fine.triangles.size() / 4);
  HausdorffOptions options;
  options.relative_tolerance = 4e-4;
  options.threads = 1;
  const HausdorffResult result = hausdorff(fine, coarse, options);
  CHECK(result.upper - result.lower <= result.tolerance);
  CHECK(result.tolerance == Approx(4e-4 * meshDiagonal(fine)));
  checkAgainstBruteForce(result.a_to_b, fine, coarse, 1500, 7);
  checkAgainstBruteForce(result.b_to_a, coarse, fine, 1500, 8);

  options.threads = 2;
  const HausdorffResult two = hausdorff(fine, coarse, options);
  requireIdentical(result.a_to_b, two.a_to_b);
  requireIdentical(result.b_to_a, two.b_to_a);
}

// Dense brute force over every triangle of `from` (a barycentric grid of `steps` per edge): the
// largest distance to `to` found at those points.
double denseMaximum(const Mesh& from, const Mesh& to, int steps) {
  double best = 0;
  for (const Triangle& t : from.triangles) {
    const Vec3 a = from.positions[t[0]], b = from.positions[t[1]], c = from.positions[t[2]];
    for (int i = 0; i <= steps; ++i)
      for (int j = 0; i + j <= steps; ++j) {
        const double u = static_cast<double>(i) / steps, v = static_cast<double>(j) / steps;
        best = std::max(best, bruteDistance(to, a + u * (b - a) + v * (c - a)));
      }
  }
  return best;
}

// A few large triangles over a folded surface (creased valleys): the distance peaks in many
// spots inside each triangle, away from its corners, where the closest faces switch, so the
// bounds come from covers of pieces, the corner bound and the extra queries. The upper bound
// must stay above the dense brute-force maximum at tolerances far below the folds' depth (a
// cover bound that ignores a piece's third corner fails here, as in the valley case below).
TEST_CASE("large triangles over a folded surface: upper bound above dense brute force") {
  const int n = 24;
  Mesh folded = scenes::gridPlane(n, 1.0);
  for (Vec3& p : folded.positions)
    p.z() = -0.01 - 0.03 * (1 - std::abs(std::sin(9 * p.x() + 1))) * (1 - std::abs(std::sin(8 * p.y() + 2)));
  const Mesh coarse = scenes::gridPlane(2, 0.9);
  for (const double tolerance : {1e-7, 1e-5}) {
    const HausdorffResult one = hausdorffOneSided(coarse, folded, absolute(tolerance, 1));
    INFO("tolerance " << tolerance);
    CHECK(one.upper - one.lower <= tolerance);
    const double dense = denseMaximum(coarse, folded, 80);
    CHECK(one.upper >= dense - 1e-12);
    checkAgainstBruteForce(one.a_to_b, coarse, folded, 500, 11);
  }
  // Both directions, symmetric, with the fine side covered by the coarse one.
  const HausdorffResult both = hausdorff(folded, coarse, absolute(1e-6, 1));
  CHECK(both.upper - both.lower <= 1e-6);
  CHECK(both.b_to_a.upper >= denseMaximum(coarse, folded, 60) - 1e-12);
  const HausdorffResult two = hausdorff(folded, coarse, absolute(1e-6, 2));
  requireIdentical(both.a_to_b, two.a_to_b);
  requireIdentical(both.b_to_a, two.b_to_a);
}

// A triangle over a V-shaped valley of two large faces: its corners are closest to the walls
// (two corners to one wall, one to the other) and the distance peaks above the crease, inside
// the triangle, at 1/sqrt(1 + k^2) for walls z = k|x| - 1. The leaf block holding both walls
// covers the two corners on one side with that wall, so a cover bound that ignored a piece's
// third corner would make the triangle final at once with an upper bound of its corners'
// distance, 0.8/sqrt(1 + k^2).
TEST_CASE("a triangle over a valley: the maximum above the crease, away from the corners") {
  const double k = 0.2;
  Mesh valley;
  valley.name = "valley";
  valley.positions = {Vec3(0, -10, -1), Vec3(0, 10, -1), Vec3(10, 0, 10 * k - 1),
                      Vec3(-10, 0, 10 * k - 1)};
  valley.triangles = {{0, 1, 2}, {1, 0, 3}};
  const Mesh triangle = singleTriangle(Vec3(1, -1, 0), Vec3(1, 1, 0), Vec3(-1, 0, 0));
  const double exact = 1 / std::sqrt(1 + k * k);
  for (const double tolerance : {1e-9, 1e-4, 0.05}) {
    INFO("tolerance " << tolerance);
    const HausdorffResult r = hausdorffOneSided(triangle, valley, absolute(tolerance, 1));
    CHECK(r.upper >= exact - 1e-12);
    CHECK(r.lower <= exact + 1e-12);
    CHECK(r.upper - r.lower <= tolerance);
    checkAgainstBruteForce(r.a_to_b, triangle, valley, 200, 5);
  }
}

// Certified bounds printed with few digits (tools/bound_text.h, used by `meshsweep hausdorff`
// and the Hausdorff scene) round outward, judged against the exact value: "0.1" is below the
// double 0.1 (found by review: the read-back in double took them for equal), subnormals and
// the largest doubles included.
TEST_CASE("printed bounds round outward") {
  using meshsweeper::cli::outwardBound;
  using meshsweeper::cli::outwardFixed;
  CHECK(outwardBound(0.1, 7, true) == "0.1000001");
  CHECK(outwardBound(0.1, 7, false) == "0.1");
  CHECK(outwardBound(0.3, 7, false) == "0.2999999");
  CHECK(outwardBound(-0.1, 7, false) == "-0.1000001");
  CHECK(outwardBound(1.0, 7, true) == "1");
  CHECK(outwardFixed(0.25, 5, false) == "0.25000");
  CHECK(outwardFixed(std::numeric_limits<double>::max(), 5, false).find("inf") == std::string::npos);
  // Short decimals a long double read-back takes for the double they round to, though they lie
  // on one side of it (found by review: "0.110499" was printed as a lower bound of the double
  // 0.110499, 0.11049899999999999999911, and "0.106003" as an upper bound of the double
  // 0.106003, 0.10600300000000000000266).
  using meshsweeper::cli::compareDecimal;
  CHECK(compareDecimal("0.110499", 0.110499) == 1);
  CHECK(compareDecimal("0.106003", 0.106003) == -1);
  CHECK(compareDecimal("0.1", 0.1) == -1);
  CHECK(compareDecimal("0.375", 0.375) == 0);
  CHECK(compareDecimal("-3.75e-1", -0.375) == 0);
  CHECK(compareDecimal("-0.1", -0.1) == 1);
  CHECK(compareDecimal("0", 0.0) == 0);
  CHECK(compareDecimal("0", -1e-300) == 1);
  CHECK(compareDecimal("4.9406564584124654e-324", std::numeric_limits<double>::denorm_min()) == -1);
  CHECK(outwardBound(0.110499, 7, false) == "0.1104989");
  CHECK(outwardBound(0.110499, 7, true) == "0.110499");
  CHECK(outwardBound(0.106003, 7, true) == "0.1060031");
  CHECK(outwardBound(0.106003, 7, false) == "0.106003");
  // Just above a power of ten (found by review: the step was taken from log10, an ulp short of
  // -3 there, so the text never moved and the bound came out in 767 digits).
  CHECK(outwardBound(std::nextafter(0.001, 1.0), 7, true) == "0.001000001");
  CHECK(outwardBound(1.00000000100009998e-03, 7, true) == "0.001000001");
  CHECK(outwardBound(std::nextafter(1e-30, 1.0), 3, true) == "1.01e-30");
  CHECK(outwardBound(-std::nextafter(0.001, 1.0), 7, false) == "-0.001000001");
  std::mt19937_64 rng(3);
  for (int i = 0; i < 20000; ++i) {
    const double x = std::ldexp(static_cast<double>(rng() >> 11), static_cast<int>(rng() % 200) - 150) *
                     (rng() & 1 ? 1 : -1);
    for (bool up : {false, true}) {
      const std::string b = outwardBound(x, 7, up), f = outwardFixed(x, 5, up);
      CHECK(b.size() <= 16);  // 7 digits, a sign, a point and an exponent: never the expansion
      CHECK((up ? compareDecimal(b, x) >= 0 : compareDecimal(b, x) <= 0));
      CHECK((up ? compareDecimal(f, x) >= 0 : compareDecimal(f, x) <= 0));
      // Where long double decides (the text more than an ulp of it away), it agrees.
      const long double lb = std::strtold(b.c_str(), nullptr);
      if (std::fabs(lb - x) > 1e-18L * std::fabs(lb)) CHECK(compareDecimal(b, x) == (lb < x ? -1 : 1));
    }
  }
  // Short decimals next to the doubles they read back as: the side is decided exactly.
  for (int i = 0; i < 20000; ++i) {
    char text[32];
    std::snprintf(text, sizeof text, "0.%06llu", static_cast<unsigned long long>(rng() % 1000000));
    const double x = std::strtod(text, nullptr);
    for (bool up : {false, true}) {
      const std::string b = outwardBound(x, 7, up);
      CHECK((up ? compareDecimal(b, x) >= 0 : compareDecimal(b, x) <= 0));
      if (compareDecimal(text, x) == 0 || (compareDecimal(text, x) > 0) == up) CHECK(std::strtod(b.c_str(), nullptr) == x);
    }
  }
}

namespace {

void addSheetAt(Mesh& m, double z, int nx, int ny, double x0, double x1, double y0, double y1) {
  const VertexIndex base = static_cast<VertexIndex>(m.positions.size());
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i)
      m.positions.emplace_back(x0 + (x1 - x0) * i / nx, y0 + (y1 - y0) * j / ny, z);
  auto id = [&](int i, int j) { return base + static_cast<VertexIndex>(j * (nx + 1) + i); };
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
}

}  // namespace

// A sliver (width about 8e-6, below 1e-3 of the tolerance: a thin cell) crossing the mid-plane
// between two sheets, 0.5 from each: h(A, B) = 0.5 exactly, at the line where it crosses, while
// every sample (corners, midpoints of the long edge) lies at 0.5 - 4e-6. The upper bound must
// still cover 0.5: a thin cell's children are bounded with its thickness (a mutation test:
// without it no other test failed).
TEST_CASE("hausdorff: a sliver crossing the mid-plane between two sheets", "[hausdorff]") {
  const double t = 4e-6, w = 1e-6, tol = 0.01;
  Mesh a;
  a.name = "sliver";
  a.positions = {Vec3(0, 0, 0.5 - t), Vec3(10, 0, 0.5 - t), Vec3(5, w, 0.5 + t)};
  a.triangles = {{0, 1, 2}};
  Mesh b;
  b.name = "sheets";
  // Cells 0.625 wide, aligned with x = 0 and with the row boundary y = 0: the pieces of the
  // sliver's halves (the cover bound's 1/8 pieces of a 5-long segment) each lie over one face,
  // exactly at distance 0.5 - t, while the sliver's own pieces (1.25 long) straddle two.
  addSheetAt(b, 0.0, 20, 2, -1.25, 11.25, -1, 1);
  addSheetAt(b, 1.0, 20, 2, -1.25, 11.25, -1, 1);
  HausdorffOptions options;
  options.tolerance = tol;
  options.threads = 1;
  // The exact h(A, B): the point of A on z = 0.5 (A's edge from a to c crosses it).
  const double exact = 0.5;
  for (bool one_sided : {true, false}) {
    const HausdorffResult r = one_sided ? hausdorffOneSided(a, b, options) : hausdorff(a, b, options);
    INFO("one_sided " << one_sided << " lower " << r.a_to_b.lower << " upper " << r.a_to_b.upper);
    CHECK(r.a_to_b.lower <= exact);
    CHECK(r.a_to_b.upper >= exact);  // certified: h(A, B) <= upper
    CHECK(r.upper >= exact);
    CHECK(r.upper - r.lower <= r.tolerance * (1 + 1e-9));
  }
}
