// The coherent queries of a QueryStream (DESIGN.md section 2; paper section 5.1) against brute
// force, along paths of consecutive points:
//   closestCoherent (set certificate)          == bruteForceClosest on every step;
//   closestWithinCoherent(p, 0) (dynamic front) exact; closestWithinCoherent(p, tol) brackets
//   the truth with upper - lower <= tol;
//   kClosestCoherent(p, 5)                     distances == bruteForceKClosest;
//   closestCoherent(p, CoherentState)          (caller-held compact state) == brute force;
//   closestCoherent(p, CoherentState, cap)     == brute force within the cap, else no face;
//   sets a compact state gathers ahead of its point (lead_steps) hold their certificate;
//   a warm (coherent) answer equals a cold one (a fresh QueryStream::closest).
// Paths (fixed seeds) on armadillo, holes, a torus, an icosphere and a random soup: steps of
// 0.05% and 0.5% of the bounding-box diagonal, points 0-5% of the diagonal from the surface,
// some crossing the surface, a large jump (to a random near-surface point, usually across the
// mesh) every 50 steps. Also: the coherence counters, reset(), a stationary point, one stream
// used for every coherent kind, and extreme CoherenceOptions.
//
// Distances are compared to 1e-12 relative plus 1e-14 of the diagonal absolute: two faces that
// share the closest edge or vertex give the same distance up to the rounding of coordinates of
// the size of the mesh (~1e-16 of the diagonal), which is far from 1e-12 relative for a point a
// hair off the surface.
#include "core/brute_force.h"
#include "core/hierarchy.h"
#include "core/mesh_io.h"
#include "core/sweep_query.h"
#include "core/triangle_distance.h"
#include "scenes/procedural.h"

#include "tests/oracle.h"

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

using namespace meshsweeper;
using namespace meshsweeper::oracle;
using scenes::Random;

namespace {

constexpr double kRelative = 1e-12;
constexpr double kAbsolute = 1e-14;  // times the diagonal

Vec3 randomUnit(Random& random) {
  while (true) {
    const Vec3 v(random.uniform(-1, 1), random.uniform(-1, 1), random.uniform(-1, 1));
    const double n = v.norm();
    if (n > 1e-3 && n <= 1) return v / n;
  }
}

// Two lists of hits (TriangleHit or BruteHit): the same triangles at the same distances, in
// order; and the pairs side by side for a message, " [triangle distance | triangle distance]".
template <class A, class B>
bool sameHits(const std::vector<A>& a, const std::vector<B>& b) {
  bool same = a.size() == b.size();
  for (size_t j = 0; same && j < a.size(); ++j) same = a[j].triangle == b[j].triangle && a[j].distance == b[j].distance;
  return same;
}
template <class A, class B>
std::string hitPairs(const std::vector<A>& a, const std::vector<B>& b) {
  std::ostringstream list;
  for (size_t j = 0; j < std::min(a.size(), b.size()); ++j)
    list << " [" << a[j].triangle << " " << num(a[j].distance) << " | " << b[j].triangle << " " << num(b[j].distance) << "]";
  return list.str();
}

// ---- Paths ----------------------------------------------------------------------------------

struct PathSpec {
  const char* name;
  double step;        // step length, fraction of the diagonal
  double near, far;   // steer away from the surface below `near`, back toward it beyond `far`
                      // (fractions of the diagonal); near == 0 lets the path cross the surface
  size_t steps;
  size_t jump_every;  // 0: no jumps
  uint64_t seed;
};

// Consecutive points: a walk whose direction turns smoothly at random, steered back toward the
// closest surface point when farther than spec.far and away from it when closer than
// spec.near, with a jump to a random near-surface point every spec.jump_every steps.
// `jumps` receives the indices of the jump steps.
std::vector<Vec3> makePath(const Mesh& mesh, const std::shared_ptr<const Hierarchy>& h, const PathSpec& spec,
                           std::vector<size_t>* jumps = nullptr) {
  const double diagonal = meshDiagonal(mesh);
  const double step = spec.step * diagonal;
  Random random(spec.seed);
  QueryStream steer(h);
  const size_t jump_count = spec.jump_every ? spec.steps / spec.jump_every + 1 : 0;
  const std::vector<Vec3> targets =
      scenes::nearSurfacePoints(mesh, jump_count + 1, std::max(spec.far, 1e-4), spec.seed + 17);
  size_t next_target = 0;
  Vec3 p = targets[next_target++];
  Vec3 direction = randomUnit(random);
  std::vector<Vec3> path;
  path.reserve(spec.steps);
  for (size_t i = 0; i < spec.steps; ++i) {
    if (i > 0 && spec.jump_every && i % spec.jump_every == 0) {
      p = targets[next_target++];
      if (jumps) jumps->push_back(i);
    } else if (i > 0) {
      const ClosestPoint c = steer.closest(p);
      Vec3 toward = c.point - p;
      const double d = toward.norm();
      toward = d > 0 ? Vec3(toward / d) : Vec3::Zero();
      direction += 0.35 * randomUnit(random);
      if (d > spec.far * diagonal) direction += 1.5 * toward;
      if (d < spec.near * diagonal) direction -= 1.5 * toward;
      if (direction.norm() < 1e-6) direction = randomUnit(random);
      direction.normalize();
      p += step * direction;
    }
    path.push_back(p);
  }
  return path;
}

// ---- Checks ---------------------------------------------------------------------------------

struct Truth {
  std::vector<BruteHit> k;  // bruteForceKClosest(mesh, p, 5): k[0] is the closest
  double closest() const { return k.front().distance; }
};

struct Checker {
  const Mesh& mesh;
  double diagonal;

  bool same(double got, double expected) const {
    return std::abs(got - expected) <=
           kRelative * std::max(std::abs(got), std::abs(expected)) + kAbsolute * diagonal;
  }
  // Distance from p to face f, computed as brute force does.
  double faceDistance(TriangleIndex f, const Vec3& p) const {
    const Triangle& t = mesh.triangles[f];
    return std::sqrt(closestPointOnTriangle(p, mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]])
                         .squared_distance);
  }
  // An exact answer: distance == brute force, a valid face at that distance, the point at that
  // distance from p and on that face.
  void exact(const ClosestPoint& r, const Vec3& p, const Truth& truth, Failures& f) const {
    const double expected = truth.closest();
    f.check(same(r.distance, expected), [&] {
      return "distance " + num(r.distance) + ", brute force " + num(expected) + " (triangle " +
             std::to_string(truth.k.front().triangle) + "), got triangle " + std::to_string(r.triangle);
    });
    const bool valid = r.triangle < mesh.triangles.size();
    f.check(valid, [&] { return "triangle " + std::to_string(r.triangle) + " out of range"; });
    if (!valid) return;
    f.check(same(faceDistance(r.triangle, p), r.distance), [&] {
      return "triangle " + std::to_string(r.triangle) + " is at " + num(faceDistance(r.triangle, p)) +
             ", reported " + num(r.distance);
    });
    f.check(same((r.point - p).norm(), r.distance),
            [&] { return "point " + text(r.point) + " is at " + num((r.point - p).norm()); });
    f.check(faceDistance(r.triangle, r.point) <= kAbsolute * diagonal,
            [&] { return "point " + text(r.point) + " is off its triangle " + std::to_string(r.triangle); });
    // Exact answers carry their distance as both bounds (the dynamic front's keys, offset by the
    // drift, can be an ulp off: the bounds must not be).
    f.check(r.lower == r.distance && r.upper == r.distance, [&] {
      return "bounds [" + num(r.lower) + ", " + num(r.upper) + "] of an exact distance " + num(r.distance);
    });
  }
  // An anytime answer: lower <= truth <= upper == distance, upper - lower <= tolerance, a
  // surface point of the reported triangle at distance upper.
  void bracket(const ClosestPoint& r, const Vec3& p, const Truth& truth, double tolerance, Failures& f) const {
    const double t = truth.closest();
    const double slack = kRelative * t + kAbsolute * diagonal;
    f.check(r.lower <= t + slack && r.upper >= t - slack && r.distance == r.upper, [&] {
      return "[" + num(r.lower) + ", " + num(r.upper) + "] (distance " + num(r.distance) +
             ") misses the truth " + num(t);
    });
    f.check(r.upper - r.lower <= tolerance + slack, [&] {
      return "upper - lower = " + num(r.upper - r.lower) + " > tolerance " + num(tolerance);
    });
    const bool valid = r.triangle < mesh.triangles.size();
    f.check(valid, [&] { return "triangle " + std::to_string(r.triangle) + " out of range"; });
    if (!valid) return;
    f.check(same((r.point - p).norm(), r.upper) && faceDistance(r.triangle, r.point) <= kAbsolute * diagonal,
            [&] {
              return "point " + text(r.point) + " (at " + num((r.point - p).norm()) + ") is not a point of triangle " +
                     std::to_string(r.triangle) + " at distance upper " + num(r.upper);
            });
  }
  void kClosest(const std::vector<TriangleHit>& got, const Vec3& p, const Truth& truth, Failures& f) const {
    f.check(got.size() == truth.k.size(), [&] {
      return "k closest: " + std::to_string(got.size()) + " hits, brute force " + std::to_string(truth.k.size());
    });
    for (size_t i = 0; i < std::min(got.size(), truth.k.size()); ++i) {
      f.check(same(got[i].distance, truth.k[i].distance), [&] {
        return "rank " + std::to_string(i) + ": distance " + num(got[i].distance) + " (triangle " +
               std::to_string(got[i].triangle) + "), brute force " + num(truth.k[i].distance) + " (triangle " +
               std::to_string(truth.k[i].triangle) + ")";
      });
      if (got[i].triangle < mesh.triangles.size())
        f.check(same(faceDistance(got[i].triangle, p), got[i].distance),
                [&] { return "rank " + std::to_string(i) + ": triangle's own distance differs"; });
    }
    // Sorted by exact distance (see the exact-order case below).
    for (size_t i = 0; i + 1 < got.size(); ++i)
      f.check(got[i].distance <= got[i + 1].distance || same(got[i].distance, got[i + 1].distance), [&] {
        return "k closest not sorted at " + std::to_string(i) + ": " + num(got[i].distance) + " (triangle " +
               std::to_string(got[i].triangle) + ") before " + num(got[i + 1].distance) + " (triangle " +
               std::to_string(got[i + 1].triangle) + ")";
      });
    for (size_t i = 0; i < got.size(); ++i)
      for (size_t j = i + 1; j < got.size(); ++j)
        f.check(got[i].triangle != got[j].triangle,
                [&] { return "triangle " + std::to_string(got[i].triangle) + " reported twice"; });
  }
};

// All the streams of one path, one per query kind, so each kind's counters are its own.
struct Streams {
  CoherenceOptions options;
  QueryStream coherent, exact, anytime, k, cold;
  CoherentState state;
  CoherentState capped[3];  // closestCoherent(p, state, ..., cap) for kCaps
  explicit Streams(const std::shared_ptr<const Hierarchy>& h, CoherenceOptions o = {})
      : options(o), coherent(h, o), exact(h, o), anytime(h, o), k(h, o), cold(h, o) {}
};

struct PathChecks {
  Failures coherent{"closestCoherent vs brute force"};
  Failures state{"closestCoherent(p, CoherentState) vs brute force"};
  size_t state_certified = 0;
  Failures set{"compact set just gathered: sorted, block bounds, certificate (brute force)"};
  size_t sets_checked = 0;
  Failures capped{"closestCoherent(p, CoherentState, max_distance) vs brute force"};
  size_t capped_certified = 0, capped_none = 0, capped_hits = 0;
  Failures exact{"closestWithinCoherent(p, 0) vs brute force"};
  Failures anytime{"closestWithinCoherent(p, tol)"};
  Failures k{"kClosestCoherent(p, 5) vs bruteForceKClosest"};
  Failures warm{"warm (coherent) answer != cold answer"};
  Failures jumps{"a jump did not restart the dynamic front"};
};

constexpr size_t kK = 5;
constexpr double kCaps[3] = {0.002, 0.01, 0.03};  // max_distance, fractions of the diagonal

// A compact state's set, right after it was gathered at state.anchor: faces by increasing
// distance from the anchor (as computed up to rounding), block_lower[b] at most the distance of
// every face of blocks b.., and the certificate: every face outside the set at least `reach`
// from the anchor (brute force over the mesh).
void checkSet(const Mesh& mesh, const CoherentState& state, Failures& failures) {
  const Vec3& a = state.anchor;
  auto distance = [&](TriangleIndex f) {
    const Triangle& t = mesh.triangles[f];
    return std::sqrt(squaredDistanceToTriangle(a, mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]));
  };
  const double slack = 1e-12;
  std::vector<uint8_t> in_set(mesh.triangles.size(), 0);
  for (uint32_t i = 0; i < state.count; ++i) {
    in_set[state.faces[i]] = 1;
    const double d = distance(state.faces[i]);
    if (i + 1 < state.count)
      failures.check(d <= distance(state.faces[i + 1]) * (1 + slack) + slack, [&] {
        return "faces " + std::to_string(i) + " and " + std::to_string(i + 1) + " out of order: " + num(d) + " > " +
               num(distance(state.faces[i + 1]));
      });
    for (uint32_t b = 0; b <= i / 8; ++b)
      failures.check(state.block_lower[b] <= d * (1 + slack) + slack, [&] {
        return "block_lower[" + std::to_string(b) + "] = " + num(state.block_lower[b]) + " above face " +
               std::to_string(i) + " at " + num(d);
      });
  }
  for (TriangleIndex f = 0; f < mesh.triangles.size(); ++f) {
    if (in_set[f]) continue;
    const double d = distance(f);
    failures.check(d >= state.reach * (1 - slack), [&] {
      return "face " + std::to_string(f) + " outside the set at " + num(d) + " < reach " + num(state.reach);
    });
  }
}

// Runs every coherent kind along `path` and checks each step against brute force.
void checkPath(const Mesh& mesh, const std::vector<Vec3>& path,
               Streams& s, PathChecks& checks, double tolerance) {
  const Checker checker{mesh, meshDiagonal(mesh)};
  std::vector<TriangleHit> hits;
  double previous_truth = -1;
  Vec3 previous = Vec3::Zero();
  for (size_t i = 0; i < path.size(); ++i) {
    const Vec3& p = path[i];
    INFO("step " << i << " of " << path.size() << ", point " << text(p));
    Truth truth{bruteForceKClosest(mesh, p, kK)};
    INFO("brute force distance " << num(truth.closest()) << " (triangle " << truth.k.front().triangle << ")");

    const ClosestPoint warm = s.coherent.closestCoherent(p);
    checker.exact(warm, p, truth, checks.coherent);
    // The caller-held compact state, the cold stream lending its scratch memory.
    bool certified = false;
    const ClosestPoint compact = s.cold.closestCoherent(p, s.state, &certified);
    checker.exact(compact, p, truth, checks.state);
    checks.state_certified += certified;
    // A set just gathered (every rebuild on small meshes, every 8th on large ones).
    if (!certified && s.state.has_set && (mesh.triangles.size() <= 20000 || i % 8 == 0)) {
      checkSet(mesh, s.state, checks.set);
      ++checks.sets_checked;
    }
    // With a cap: the exact answer within it, else none (and nothing closer than the cap).
    for (int c = 0; c < 3; ++c) {
      const double cap = kCaps[c] * checker.diagonal;
      bool capped_certified = false;
      const ClosestPoint r = s.cold.closestCoherent(p, s.capped[c], &capped_certified, cap);
      checks.capped_certified += capped_certified;
      const double t = truth.closest();
      if (t <= cap * (1 - 1e-9)) {
        checker.exact(r, p, truth, checks.capped);
        ++checks.capped_hits;
      } else if (t > cap * (1 + 1e-9)) {
        checks.capped.check(r.triangle == kInvalidIndex && r.distance == std::numeric_limits<double>::infinity() &&
                                r.lower <= t,
                            [&] {
                              return "cap " + num(cap) + ": brute force " + num(t) + ", got triangle " +
                                     std::to_string(r.triangle) + " at " + num(r.distance) + ", lower " + num(r.lower);
                            });
        ++checks.capped_none;
      }
    }
    const ClosestPoint cold = s.cold.closest(p);
    checks.warm.check(checker.same(warm.distance, cold.distance) &&
                          (warm.triangle != cold.triangle || (warm.point == cold.point && warm.barycentric == cold.barycentric)),
                      [&] {
                        return "warm " + num(warm.distance) + " (triangle " + std::to_string(warm.triangle) +
                               "), cold " + num(cold.distance) + " (triangle " + std::to_string(cold.triangle) + ")";
                      });

    const uint64_t resets = s.exact.coherence().front_resets;
    const ClosestPoint exact = s.exact.closestWithinCoherent(p, 0);
    checker.exact(exact, p, truth, checks.exact);
    checks.exact.check(exact.lower <= exact.upper && exact.upper == exact.distance &&
                           checker.same(exact.lower, exact.upper),
                       [&] { return "tolerance 0 gave [" + num(exact.lower) + ", " + num(exact.upper) + "]"; });
    // The front restarts when the point moves farther than jump_factor times its last
    // distance; the exact stream's last distance is the previous truth.
    if (previous_truth >= 0 && (p - previous).norm() > 1.01 * s.options.jump_factor * previous_truth) {
      checks.jumps.check(s.exact.coherence().front_resets == resets + 1, [&] {
        return "moved " + num((p - previous).norm()) + " from a point at distance " + num(previous_truth) +
               "; front_resets " + std::to_string(resets) + " -> " + std::to_string(s.exact.coherence().front_resets);
      });
    }

    const ClosestPoint approx = s.anytime.closestWithinCoherent(p, tolerance);
    checker.bracket(approx, p, truth, tolerance, checks.anytime);

    s.k.kClosestCoherent(p, kK, hits);
    checker.kClosest(hits, p, truth, checks.k);

    previous_truth = truth.closest();
    previous = p;
  }
}

// The counters of a stream that answered only closestCoherent, `steps` times.
void checkSetCounters(const QueryStream& s, uint64_t steps, bool expect_certified) {
  const CoherenceCounters& c = s.coherence();
  INFO("steps " << c.steps << ", certified " << c.certified << ", rebuilds " << c.rebuilds << ", searched "
                << c.searched << ", candidates " << c.candidates);
  CHECK(c.steps == steps);
  CHECK(c.certified + c.rebuilds + c.searched == c.steps);
  CHECK(c.rebuilds >= 1);  // the first step has no set
  CHECK(c.front_resets == 0);
  CHECK(c.recomputed == 0);
  if (expect_certified) CHECK(c.certified > 0);
}

struct Case {
  std::string name;
  const Mesh* mesh;
};

// Three paths per mesh: small steps kept 0.1%-5% off the surface; small steps within 0.5% of
// the surface, crossing it; large steps (0.5%) within 5%, crossing it. Jumps every 50 steps.
void checkMesh(const Case& c, size_t steps, uint64_t seed) {
  REQUIRE(c.mesh != nullptr);
  const Mesh& mesh = *c.mesh;
  const double diagonal = meshDiagonal(mesh);
  const auto h = Hierarchy::build(mesh);
  const PathSpec specs[] = {
      {"step 0.05%, 0.1-5% off", 0.0005, 0.001, 0.05, steps, 50, seed},
      {"step 0.05%, within 0.5%, crossing", 0.0005, 0.0, 0.005, steps, 50, seed + 1},
      {"step 0.5%, within 5%, crossing", 0.005, 0.0, 0.05, steps, 50, seed + 2},
  };
  for (const PathSpec& spec : specs) {
    INFO("mesh " << c.name << " (" << mesh.triangles.size() << " triangles), path " << spec.name << ", seed "
                 << spec.seed);
    std::vector<size_t> jumps;
    const std::vector<Vec3> path = makePath(mesh, h, spec, &jumps);
    Streams s(h);
    PathChecks checks;
    checkPath(mesh, path, s, checks, 1e-3 * diagonal);
    checkSetCounters(s.coherent, path.size(), spec.step < 0.001);
    if (spec.step < 0.001) CHECK(checks.state_certified > 0);
    CHECK(checks.sets_checked > 0);
    // The capped queries saw both answers, and certified some.
    CHECK(checks.capped_hits > 0);
    CHECK(checks.capped_none > 0);
    if (spec.step < 0.001) CHECK(checks.capped_certified > 0);
    // Every jump restarts the dynamic front (plus the first step).
    CHECK(s.exact.coherence().front_resets >= jumps.size() + 1);
    CHECK(s.k.coherence().front_resets >= jumps.size() + 1);
    CHECK(s.exact.coherence().recomputed > 0);
    CHECK(s.exact.coherence().steps == path.size());
    CHECK(s.exact.coherence().certified + s.exact.coherence().rebuilds == 0);
  }
}

}  // namespace

TEST_CASE("coherent queries along paths on real meshes", "[coherent][real]") {
  for (const char* name : {"armadillo", "holes"}) {
    const Case c{name, realMesh(name)};
    if (!c.mesh) continue;
    checkMesh(c, std::string(name) == "armadillo" ? 500 : 800, 0xc0ffee01);
  }
}

TEST_CASE("coherent queries along paths on procedural meshes", "[coherent]") {
  const Mesh torus = scenes::torus(1.0, 0.3, 96, 48);
  const Mesh sphere = scenes::icosphere(4);
  const Mesh soup = scenes::randomSoup(3000, 7);
  for (const Case& c : {Case{"torus 96x48", &torus}, Case{"icosphere 4", &sphere}, Case{"random soup 3000", &soup}})
    checkMesh(c, 500, 0xc0ffee11);
}

// The cap of closestCoherent(p, state, ..., max_distance): 0 on and off the surface, negative
// and NaN caps (taken as 0), caps a hair either side of the truth, and a cap that changes at
// every step of a path while one state follows the point.
TEST_CASE("coherent queries: capped compact states", "[coherent]") {
  const Mesh mesh = scenes::torus(1.0, 0.3, 64, 32);
  const auto h = Hierarchy::build(mesh);
  const double diagonal = meshDiagonal(mesh);
  const Checker checker{mesh, diagonal};
  QueryStream stream(h);
  const double inf = std::numeric_limits<double>::infinity();
  auto none = [&](const ClosestPoint& r, double cap) {
    return r.triangle == kInvalidIndex && r.distance == inf && r.upper == inf && r.lower == cap;
  };
  {
    INFO("cap 0 on a vertex: the vertex's faces are at distance 0");
    const Vec3 p = mesh.positions[mesh.triangles[10][1]];
    CoherentState state;
    const ClosestPoint r = stream.closestCoherent(p, state, nullptr, 0.0);
    CHECK(r.triangle < mesh.triangles.size());
    CHECK(r.distance == 0);
  }
  {
    INFO("cap 0, negative or NaN off the surface: none, lower bound 0");
    const Vec3 p(1.0, 0.1, 0.35);
    for (double cap : {0.0, -1.0, std::numeric_limits<double>::quiet_NaN()}) {
      CoherentState state;
      CHECK(none(stream.closestCoherent(p, state, nullptr, cap), 0.0));
    }
  }
  {
    INFO("caps a hair either side of the truth");
    const Vec3 p(1.0, 0.1, 0.35);
    const double truth = bruteForceClosest(mesh, p).distance;
    CoherentState below, above;
    CHECK(none(stream.closestCoherent(p, below, nullptr, truth * (1 - 1e-6)), truth * (1 - 1e-6)));
    CHECK(stream.closestCoherent(p, above, nullptr, truth * (1 + 1e-6)).distance == Approx(truth).epsilon(1e-12));
  }
  {
    INFO("one state along a path, a new cap at every step");
    const PathSpec spec{"step 0.05%, within 3%, crossing", 0.0005, 0.0, 0.03, 1500, 0, 0xcab5};
    const std::vector<Vec3> path = makePath(mesh, h, spec);
    Random random(0xcab6);
    CoherentState state;
    Failures f("closestCoherent with a changing cap");
    size_t certified_steps = 0, hits = 0, nones = 0;
    for (size_t i = 0; i < path.size(); ++i) {
      const Vec3& p = path[i];
      const double cap = random.uniform(0, 0.03) * diagonal;
      INFO("step " << i << ", point " << text(p) << ", cap " << num(cap));
      const Truth truth{bruteForceKClosest(mesh, p, 1)};
      bool certified = false;
      const ClosestPoint r = stream.closestCoherent(p, state, &certified, cap);
      certified_steps += certified;
      if (truth.closest() <= cap * (1 - 1e-9)) {
        checker.exact(r, p, truth, f);
        ++hits;
      } else if (truth.closest() > cap * (1 + 1e-9)) {
        f.check(none(r, cap), [&] { return "brute force " + num(truth.closest()) + ", got a face at " + num(r.distance); });
        ++nones;
      }
    }
    CHECK(hits > 100);
    CHECK(nones > 100);
    CHECK(certified_steps > 100);
  }
}

// A compact state gathers its set lead_steps mean steps ahead of the point (the point must
// still be certified by that set, else it is gathered at the point). Along a steady path over
// a torus, and along one that turns back every 7 steps, the answers stay exact, every set
// gathered holds its certificate (brute force), and on the steady path the sets gathered ahead
// last longer than sets gathered at the point. (On the path that turns back, how many sets
// are rebuilt depends on where the first ones happen to be anchored, with or without a lead:
// not compared.)
TEST_CASE("coherent queries: sets gathered ahead of a moving point", "[coherent]") {
  const Mesh mesh = scenes::torus(1.0, 0.3, 96, 48);
  const auto h = Hierarchy::build(mesh);
  const Checker checker{mesh, meshDiagonal(mesh)};
  QueryStream stream(h);
  for (bool zigzag : {false, true}) {
    INFO((zigzag ? "turning back every 7 steps" : "steady path"));
    size_t rebuilds[2] = {0, 0}, ahead[2] = {0, 0}, certified_steps[2] = {0, 0};
    for (int lead = 0; lead < 2; ++lead) {
      INFO("lead_steps " << (lead ? 3 : 0));
      CoherentState state;
      state.lead_steps = lead ? 3.0f : 0.0f;
      Failures f("closestCoherent(p, CoherentState) with sets gathered ahead");
      Failures sets("a set gathered ahead: sorted, block bounds, certificate (brute force)");
      // Over the top of the tube, along the ring, 0.002 a step, bobbing 0.01-0.015 above it.
      double angle = 0;
      for (int i = 0; i < 600; ++i) {
        angle += zigzag && (i / 7) % 2 ? -0.002 : 0.002;
        const double height = 0.3 + 0.0125 + 0.0025 * std::sin(0.05 * i);
        const Vec3 p(std::cos(angle), std::sin(angle), height);
        INFO("step " << i << ", point " << text(p));
        bool certified = false;
        const ClosestPoint r = stream.closestCoherent(p, state, &certified);
        checker.exact(r, p, Truth{bruteForceKClosest(mesh, p, 1)}, f);
        certified_steps[lead] += certified;
        if (certified) continue;
        ++rebuilds[lead];
        if (!state.has_set) continue;
        checkSet(mesh, state, sets);
        ahead[lead] += state.anchor != p;
      }
    }
    INFO("rebuilds " << rebuilds[0] << " at the point, " << rebuilds[1] << " with lead_steps 3 (" << ahead[1]
                     << " sets gathered ahead)");
    CHECK(ahead[0] == 0);
    CHECK(ahead[1] > 0);
    CHECK(certified_steps[0] > 300);
    CHECK(certified_steps[1] > 300);
    if (!zigzag) CHECK(rebuilds[1] < rebuilds[0]);
  }
}

// A point whose motion outruns the sets it gathers (every fourth step a jump of 0.2 along the
// ring and back, so a set gathered at either end fails within two tests) searches from its
// warm start without gathering for six steps after such a failure, then tries again, waiting
// twice as long while its sets keep failing: a gather that saves nothing is not repeated at
// every step. Every answer exact.
TEST_CASE("coherent queries: a point too fast for its sets", "[coherent]") {
  const Mesh mesh = scenes::torus(1.0, 0.3, 96, 48);
  const auto h = Hierarchy::build(mesh);
  const Checker checker{mesh, meshDiagonal(mesh)};
  QueryStream stream(h);
  CoherentState state;
  Failures f("closestCoherent(p, CoherentState) on a jumping point");
  Failures waiting("no gather within six steps of a set that failed within two tests");
  size_t failed_young = 0, plain = 0, plain_run = 0, longest_plain_run = 0;
  int no_gather = 0;  // steps left that must not gather
  for (int i = 0; i < 200; ++i) {
    const double angle = 0.004 * i + (i % 4 == 3 ? 0.2 : 0.0);
    const Vec3 p(std::cos(angle), std::sin(angle), 0.3 + 0.01);
    INFO("step " << i << ", point " << text(p));
    const bool young = state.has_set && state.set_steps < 2;  // certified fewer than two steps
    bool certified = false;
    const ClosestPoint r = stream.closestCoherent(p, state, &certified);
    checker.exact(r, p, Truth{bruteForceKClosest(mesh, p, 1)}, f);
    const bool gathered = !certified && state.has_set;
    plain += !certified && !state.has_set;
    plain_run = !certified && !state.has_set ? plain_run + 1 : 0;
    longest_plain_run = std::max(longest_plain_run, plain_run);
    if (no_gather > 0) {
      waiting.check(!gathered, [&] { return "step " + std::to_string(i) + " gathered a set"; });
      --no_gather;
    }
    if (young && !certified) {  // this step and the next five search plainly
      ++failed_young;
      waiting.check(!gathered, [&] { return "step " + std::to_string(i) + " gathered a set"; });
      no_gather = 5;
    }
  }
  INFO(failed_young << " sets failed within two tests, " << plain << " plain searches, at most "
                     << longest_plain_run << " in a row");
  CHECK(failed_young > 3);
  CHECK(plain >= 4 * failed_young);
  CHECK(longest_plain_run >= 12);  // the wait doubled: the sets kept failing

  // The stream's own closestCoherent(p) backs off the same way (found by an audit: it gathered
  // a set for every query of a jumping point, 4.6 times a plain search); every answer exact.
  QueryStream own(h);
  Failures g("closestCoherent(p) on a jumping point");
  Random random(5);
  for (int i = 0; i < 300; ++i) {
    const Vec3 p = random.inBox(Vec3(-1.5, -1.5, -0.5), Vec3(1.5, 1.5, 0.5));
    checker.exact(own.closestCoherent(p), p, Truth{bruteForceKClosest(mesh, p, 1)}, g);
  }
  const CoherenceCounters& c = own.coherence();
  INFO("certified " << c.certified << ", rebuilds " << c.rebuilds << ", searched " << c.searched);
  CHECK(c.certified + c.rebuilds + c.searched == 300);
  CHECK(c.rebuilds < 60);
  CHECK(c.searched > 200);
}

// One jump far away (1e40: query points go to 1e153) and back. Found by an audit: the state's
// running mean step, a float, became +inf for good and every later query gathered afresh. The
// jump now counts for at most a thousand rest sizes: the mean decays, and the sets certify again
// as often as a state that never jumped. Every answer exact.
TEST_CASE("coherent queries: a state recovers from a jump past the float range", "[coherent]") {
  const Mesh mesh = scenes::torus(1.0, 0.3, 96, 48);
  const auto h = Hierarchy::build(mesh);
  const Checker checker{mesh, meshDiagonal(mesh)};
  QueryStream stream(h);
  CoherentState jumped, steady;
  Failures f("closestCoherent after a jump to 1e40");
  const auto at = [](int i) {
    const double angle = 0.002 * i;
    return Vec3(1.32 * std::cos(angle), 1.32 * std::sin(angle), 0.05);
  };
  for (int i = 0; i < 10; ++i) {
    stream.closestCoherent(at(i), jumped);
    stream.closestCoherent(at(i), steady);
  }
  const Vec3 far(1e40, 0, 0);
  checker.exact(stream.closestCoherent(far, jumped), far, Truth{bruteForceKClosest(mesh, far, 1)}, f);
  size_t certified_jumped = 0, certified_steady = 0;
  for (int i = 10; i < 400; ++i) {
    const Vec3 p = at(i);
    bool a = false, b = false;
    const ClosestPoint r = stream.closestCoherent(p, jumped, &a);
    stream.closestCoherent(p, steady, &b);
    if (i % 10 == 0) checker.exact(r, p, Truth{bruteForceKClosest(mesh, p, 1)}, f);
    if (i >= 300) {
      certified_jumped += a;
      certified_steady += b;
    }
  }
  INFO("certified over the last 100 steps: " << certified_jumped << " after the jump, " << certified_steady
                                             << " without; mean step " << jumped.mean_step);
  CHECK(std::isfinite(jumped.mean_step));
  CHECK(jumped.mean_step < 0.01f);
  CHECK(certified_steady > 80);
  CHECK(certified_jumped + 5 >= certified_steady);
}

// A cold state's first set is gathered before the point's motion is known (the least margin):
// when it fails at the next step, that says nothing about the motion, so the state gathers a
// set with the measured motion at once instead of waiting six steps, and that set certifies the
// steps after it. Every answer exact.
TEST_CASE("coherent queries: a cold state's first set fails without a wait", "[coherent]") {
  const Mesh mesh = scenes::torus(1.0, 0.3, 96, 48);
  const auto h = Hierarchy::build(mesh);
  const Checker checker{mesh, meshDiagonal(mesh)};
  QueryStream stream(h);
  Failures f("closestCoherent(p, CoherentState) on a point starting at speed");
  for (const double speed : {0.02, 0.03}) {
    CoherentState state;
    std::vector<bool> certified_at, set_after;
    for (int i = 0; i < 12; ++i) {
      const double angle = speed * i;
      const Vec3 p(std::cos(angle), std::sin(angle), 0.3 + 0.01);
      INFO("speed " << speed << ", step " << i << ", point " << text(p));
      bool certified = false;
      const ClosestPoint r = stream.closestCoherent(p, state, &certified);
      checker.exact(r, p, Truth{bruteForceKClosest(mesh, p, 1)}, f);
      certified_at.push_back(certified);
      set_after.push_back(state.has_set);
    }
    INFO("speed " << speed);
    CHECK(set_after[0]);         // the first set, gathered cold
    CHECK_FALSE(certified_at[1]);  // too small a margin for this speed
    CHECK(set_after[1]);         // gathered again at once, no wait
    for (int i = 2; i < 6; ++i) CHECK(certified_at[i]);
  }
}

// withinCoherent answers from a compact state's set while its certificate holds: the same faces,
// hits and order as within() (bitwise) at every step, along paths with a radius that changes
// every step (sometimes 0, sometimes so large that no set can hold the faces within it, NaN,
// negative or infinite), with the same state also serving closestCoherent in between, on real
// and procedural meshes (a soup included).
bool sameWithin(const std::vector<TriangleHit>& a, const std::vector<TriangleHit>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].distance != b[i].distance || a[i].triangle != b[i].triangle || a[i].point != b[i].point ||
        a[i].barycentric != b[i].barycentric || a[i].feature != b[i].feature)
      return false;
  return true;
}

TEST_CASE("coherent queries: withinCoherent equals within along paths", "[coherent]") {
  struct Case {
    std::string name;
    Mesh mesh;
  };
  std::vector<Case> cases;
  for (const char* name : {"holes", "armadillo"})
    if (const Mesh* m = realMesh(name)) cases.push_back({name, *m});
  cases.push_back({"torus", scenes::torus(1.0, 0.3, 64, 32)});
  cases.push_back({"soup", scenes::randomSoup(1500, 11)});
  for (const Case& c : cases) {
    INFO("mesh " << c.name);
    const auto h = Hierarchy::build(c.mesh);
    const double diagonal = meshDiagonal(c.mesh);
    const PathSpec spec{"step 0.05%, 0.2-3% off", 0.0005, 0.002, 0.03, 700, 250, 0x3e11};
    const std::vector<Vec3> path = makePath(c.mesh, h, spec);
    QueryStream coherent(h), plain(h);
    Random random(0x3e12);
    CoherentState state;
    Failures same("withinCoherent == within"), brute("within count vs brute force"),
        closest("closestCoherent on the shared state");
    const Checker checker{c.mesh, diagonal};
    std::vector<TriangleHit> got, expected;
    size_t certified_steps = 0, hits = 0;
    for (size_t i = 0; i < path.size(); ++i) {
      const Vec3& p = path[i];
      // Mostly a steady radius (the set lasts), now and then a new one.
      double d = (i / 40) % 2 ? 0.01 * diagonal : 0.02 * diagonal;
      if (i % 97 == 5) d = 0;
      if (i % 97 == 50) d = 0.5 * diagonal;  // more faces within d than a set holds
      if (i % 131 == 7) d = random.uniform(0, 0.05) * diagonal;
      INFO("step " << i << ", point " << text(p) << ", d " << num(d));
      bool certified = false;
      coherent.withinCoherent(p, d, state, got, &certified);
      plain.within(p, d, expected);
      certified_steps += certified;
      hits += got.size();
      same.check(sameWithin(got, expected), [&] {
        return "got " + std::to_string(got.size()) + " faces, within() " + std::to_string(expected.size());
      });
      if (i % 50 == 0) {
        // Faces clearly inside or outside d (not within 1e-9 relative of it) are decided alike.
        const std::vector<BruteHit> truth = bruteForceWithin(c.mesh, p, d * (1 + 1e-9));
        size_t sure = 0;
        for (const BruteHit& t : truth) sure += t.distance <= d * (1 - 1e-9);
        brute.check(got.size() >= sure && got.size() <= truth.size(), [&] {
          return std::to_string(got.size()) + " faces, brute force " + std::to_string(sure) + "-" +
                 std::to_string(truth.size());
        });
      }
      if (i % 3 == 0) checker.exact(coherent.closestCoherent(p, state), p, Truth{bruteForceKClosest(c.mesh, p, 1)}, closest);
    }
    // Odd radii and points: the same answers as within(), and the state goes on.
    const Vec3 p = path.back();
    for (double d : {-1.0, std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
      coherent.withinCoherent(p, d, state, got);
      plain.within(p, d, expected);
      CHECK(sameWithin(got, expected));
    }
    coherent.withinCoherent(Vec3(std::numeric_limits<double>::quiet_NaN(), 0, 0), 1.0, state, got);
    CHECK(got.empty());
    CHECK(state.lineage == 0);  // restarted
    coherent.withinCoherent(p, 0.01 * diagonal, state, got);
    plain.within(p, 0.01 * diagonal, expected);
    CHECK(sameWithin(got, expected));
    CHECK(same.checks() == path.size());
    CHECK(hits > 1000);
    CHECK(certified_steps > path.size() / 2);  // the sets answer most steps
  }
}

// The dynamic front keys its entries by bound + drift: after an excursion far away and back
// along the same ray (no single move is a jump), the drift is huge against the distance, and
// the front must start over rather than answer from keys rounded at that magnitude.
TEST_CASE("coherent queries: the dynamic front after a far excursion", "[coherent]") {
  const Mesh mesh = scenes::icosphere(3);
  const auto h = Hierarchy::build(mesh);
  const Vec3 near(1.28, 0.93, 0.13);
  const double truth = bruteForceClosest(mesh, near).distance;
  std::vector<TriangleHit> hits;
  for (double far : {1e6, 1e14, 1e15, 1e16, 1e100}) {
    INFO("far " << far);
    const Vec3 away = near * (far / near.norm());
    QueryStream k(h), anytime(h), exact(h);
    for (const Vec3& p : {near, away, near}) {
      k.kClosestCoherent(p, 7, hits);
      const ClosestPoint a = anytime.closestWithinCoherent(p, 0.01);
      const ClosestPoint e = exact.closestWithinCoherent(p, 0);
      const std::vector<BruteHit> expected = bruteForceKClosest(mesh, p, 7);
      REQUIRE(hits.size() == 7);
      for (size_t i = 0; i < 7; ++i) CHECK(hits[i].distance == Approx(expected[i].distance).epsilon(1e-12));
      CHECK(a.lower <= expected[0].distance * (1 + 1e-12));
      CHECK(a.upper >= expected[0].distance * (1 - 1e-12));
      CHECK(a.upper - a.lower <= 0.01);
      CHECK(e.distance == Approx(expected[0].distance).epsilon(1e-12));
    }
    CHECK(hits[0].distance == Approx(truth).epsilon(1e-12));
  }
}

// An infinite tolerance still answers with a surface point (the first upper bound found).
TEST_CASE("coherent queries: anytime queries with an infinite tolerance", "[coherent]") {
  const Mesh mesh = scenes::torus(1.0, 0.3, 32, 16);
  const auto h = Hierarchy::build(mesh);
  QueryStream stream(h), front(h);
  const double inf = std::numeric_limits<double>::infinity();
  for (const Vec3& p : {Vec3(0.2, 0.1, 0.5), Vec3(1.0, 0.0, 0.31), Vec3(30, -20, 5)}) {
    const double truth = bruteForceClosest(mesh, p).distance;
    for (const ClosestPoint& r : {stream.closestWithin(p, inf), front.closestWithinCoherent(p, inf)}) {
      CHECK(std::isfinite(r.distance));
      CHECK(r.lower <= truth);
      CHECK(r.upper >= truth * (1 - 1e-12));
      CHECK(r.distance == r.upper);
      CHECK((r.point - p).norm() == Approx(r.upper).epsilon(1e-9));
    }
  }
}

TEST_CASE("coherent queries: a stationary point", "[coherent]") {
  const Mesh mesh = scenes::torus(1.0, 0.3, 64, 32);
  const auto h = Hierarchy::build(mesh);
  const Checker checker{mesh, meshDiagonal(mesh)};
  const std::vector<Vec3> points = {
      Vec3(1.0, 0.1, 0.35),                                   // off the surface
      scenes::surfacePoints(mesh, 1, 3).front(),              // on the surface
      mesh.positions[mesh.triangles[10][1]],                  // on a vertex
      Vec3(0, 0, 0),                                          // the centre: every ring face at ~0.7
  };
  for (size_t i = 0; i < points.size(); ++i) {
    const Vec3& p = points[i];
    INFO("mesh torus 64x32, stationary point " << i << " " << text(p));
    Streams s(h);
    PathChecks checks;
    const Truth truth{bruteForceKClosest(mesh, p, kK)};
    std::vector<TriangleHit> hits;
    for (int repeat = 0; repeat < 20; ++repeat) {
      INFO("repeat " << repeat);
      checker.exact(s.coherent.closestCoherent(p), p, truth, checks.coherent);
      checker.exact(s.exact.closestWithinCoherent(p, 0), p, truth, checks.exact);
      checker.bracket(s.anytime.closestWithinCoherent(p, 0.01), p, truth, 0.01, checks.anytime);
      s.k.kClosestCoherent(p, kK, hits);
      checker.kClosest(hits, p, truth, checks.k);
    }
    CHECK(s.coherent.coherence().certified + s.coherent.coherence().rebuilds == 20);
    CHECK(s.coherent.coherence().searched == 0);  // a still point: its sets never fail
    // The point never moves: the front starts once and is never restarted.
    CHECK(s.exact.coherence().front_resets == 1);
    CHECK(s.k.coherence().front_resets == 1);
    CHECK(s.exact.coherence().recomputed == 0);
  }
}

TEST_CASE("coherent queries: reset() forgets the coherent state", "[coherent]") {
  const Mesh* mesh = realMesh("holes");
  REQUIRE(mesh);
  const auto h = Hierarchy::build(*mesh);
  const Checker checker{*mesh, meshDiagonal(*mesh)};
  const PathSpec spec{"step 0.05%, 0.1-5% off", 0.0005, 0.001, 0.05, 120, 0, 99};
  const std::vector<Vec3> path = makePath(*mesh, h, spec);
  INFO("mesh holes, path " << spec.name << ", seed " << spec.seed);
  Streams s(h);
  PathChecks checks;
  std::vector<TriangleHit> hits;
  for (size_t i = 0; i < path.size(); ++i) {
    const Vec3& p = path[i];
    INFO("step " << i << " " << text(p));
    const Truth truth{bruteForceKClosest(*mesh, p, kK)};
    if (i % 40 == 20) {
      // After reset(): the next closestCoherent rebuilds its set and the next front query
      // starts from the roots; answers stay exact.
      s.coherent.reset();
      s.exact.reset();
      s.k.reset();
      // reset() zeroes the counters (see the case below); the next
      // queries count from there.
      const CoherenceCounters before_set = s.coherent.coherence();
      const CoherenceCounters before_front = s.exact.coherence();
      const CoherenceCounters before_k = s.k.coherence();
      checker.exact(s.coherent.closestCoherent(p), p, truth, checks.coherent);
      checker.exact(s.exact.closestWithinCoherent(p, 0), p, truth, checks.exact);
      s.k.kClosestCoherent(p, kK, hits);
      checker.kClosest(hits, p, truth, checks.k);
      CHECK(s.coherent.coherence().rebuilds == before_set.rebuilds + 1);
      CHECK(s.coherent.coherence().certified == before_set.certified);
      CHECK(s.exact.coherence().front_resets == before_front.front_resets + 1);
      CHECK(s.k.coherence().front_resets == before_k.front_resets + 1);
      CHECK(s.exact.frontSize() > 0);
    } else {
      checker.exact(s.coherent.closestCoherent(p), p, truth, checks.coherent);
      checker.exact(s.exact.closestWithinCoherent(p, 0), p, truth, checks.exact);
      s.k.kClosestCoherent(p, kK, hits);
      checker.kClosest(hits, p, truth, checks.k);
    }
  }
}

// The header says the coherence counters count "since the stream was created or reset";
// QueryStream::reset() (core/sweep_query.cpp) leaves them untouched. Kept as a known failure
// until the contract and the code agree.
TEST_CASE("coherent queries: reset() zeroes the coherence counters", "[coherent]") {
  const Mesh mesh = scenes::icosphere(3);
  const auto h = Hierarchy::build(mesh);
  QueryStream s(h);
  std::vector<TriangleHit> hits;
  for (int i = 0; i < 10; ++i) {
    const Vec3 p(1.2 + 0.001 * i, 0.1, 0.2);
    s.closestCoherent(p);
    s.closestWithinCoherent(p, 0);
    s.kClosestCoherent(p, 3, hits);
  }
  REQUIRE(s.coherence().steps == 30);
  s.reset();
  const CoherenceCounters& c = s.coherence();
  INFO("after reset(): steps " << c.steps << ", certified " << c.certified << ", rebuilds " << c.rebuilds
                               << ", front_resets " << c.front_resets << ", recomputed " << c.recomputed);
  CHECK(c.steps == 0);
  CHECK(c.certified == 0);
  CHECK(c.rebuilds == 0);
  CHECK(c.candidates == 0);
  CHECK(c.front_resets == 0);
  CHECK(c.recomputed == 0);
}

TEST_CASE("coherent queries: one stream for every coherent kind", "[coherent]") {
  const Mesh* mesh = realMesh("holes");
  REQUIRE(mesh);
  const auto h = Hierarchy::build(*mesh);
  const double diagonal = meshDiagonal(*mesh);
  const Checker checker{*mesh, diagonal};
  const PathSpec spec{"step 0.5%, within 5%, crossing", 0.005, 0.0, 0.05, 300, 50, 5};
  const std::vector<Vec3> path = makePath(*mesh, h, spec);
  INFO("mesh holes, path " << spec.name << ", seed " << spec.seed);
  QueryStream s(h);
  PathChecks checks;
  std::vector<TriangleHit> hits;
  for (size_t i = 0; i < path.size(); ++i) {
    const Vec3& p = path[i];
    INFO("step " << i << " " << text(p));
    const Truth truth{bruteForceKClosest(*mesh, p, kK)};
    // Varying order and kinds on the same stream; also the fresh queries in between.
    switch (i % 4) {
      case 0:
        checker.exact(s.closestCoherent(p), p, truth, checks.coherent);
        s.kClosestCoherent(p, kK, hits);
        checker.kClosest(hits, p, truth, checks.k);
        break;
      case 1:
        checker.exact(s.closestWithinCoherent(p, 0), p, truth, checks.exact);
        checker.exact(s.closestCoherent(p), p, truth, checks.coherent);
        break;
      case 2:
        checker.bracket(s.closestWithinCoherent(p, 0.01 * diagonal), p, truth, 0.01 * diagonal, checks.anytime);
        checker.exact(s.closest(p), p, truth, checks.warm);
        s.kClosestCoherent(p, kK, hits);
        checker.kClosest(hits, p, truth, checks.k);
        break;
      default:
        s.kClosestCoherent(p, kK, hits);
        checker.kClosest(hits, p, truth, checks.k);
        checker.exact(s.closestWithinCoherent(p, 0), p, truth, checks.exact);
        checker.exact(s.closestCoherent(p), p, truth, checks.coherent);
        break;
    }
  }
}

TEST_CASE("coherent queries: extreme CoherenceOptions stay exact", "[coherent]") {
  const Mesh mesh = scenes::torus(1.0, 0.3, 64, 32);
  const auto h = Hierarchy::build(mesh);
  const double diagonal = meshDiagonal(mesh);
  struct Named {
    const char* name;
    CoherenceOptions options;
  };
  std::vector<Named> variants;
  variants.push_back({"one candidate", CoherenceOptions{6, 1, 4096, 1.0}});
  variants.push_back({"no reach", CoherenceOptions{0, 96, 4096, 1.0}});
  variants.push_back({"huge reach, few candidates", CoherenceOptions{1000, 8, 4096, 1.0}});
  variants.push_back({"tiny front budget", CoherenceOptions{6, 96, 16, 1.0}});
  variants.push_back({"never jump", CoherenceOptions{6, 96, 1u << 30, 1e300}});
  variants.push_back({"always jump", CoherenceOptions{6, 96, 4096, 0.0}});
  const PathSpec specs[] = {
      {"step 0.05%, within 0.5%, crossing", 0.0005, 0.0, 0.005, 200, 50, 31},
      {"step 0.5%, within 5%, crossing", 0.005, 0.0, 0.05, 200, 50, 32},
  };
  for (const PathSpec& spec : specs) {
    const std::vector<Vec3> path = makePath(mesh, h, spec);
    for (const Named& v : variants) {
      INFO("mesh torus 64x32, path " << spec.name << ", options: " << v.name);
      Streams s(h, v.options);
      PathChecks checks;
      checkPath(mesh, path, s, checks, 1e-3 * diagonal);
      checkSetCounters(s.coherent, path.size(), false);
    }
  }
}

// kClosest's contract: by increasing distance, ties by triangle index. kClosestCoherent keys its
// front by bound + drift (core/sweep_query.cpp), so two faces whose distances differ by less
// than the rounding of that sum (faces sharing the closest vertex, ~1 ulp apart) come out in
// triangle-index order instead of distance order. Known failure until the output is sorted.
// Found by review: the front's keys (distance plus drift) merge or swap distances a few ulps
// apart, so the k faces taken at the top could leave out one strictly closer than a face kept.
TEST_CASE("coherent queries: kClosestCoherent keeps the same k faces as kClosest", "[coherent]") {
  const Mesh sphere = scenes::icosphere(3, 1.0);
  const auto h = Hierarchy::build(sphere);
  for (size_t k : {size_t(1), size_t(3), size_t(5)}) {
    INFO("k = " << k);
    QueryStream coherent(h), fresh(h);
    Random random(7);
    Vec3 p(1.5, 0.2, 0.1), v(0, 0.01, 0.003);
    std::vector<TriangleHit> a, b;
    size_t differ = 0;
    for (int i = 0; i < 3000; ++i) {
      v = (v + 0.002 * Vec3(random.uniform(-1, 1), random.uniform(-1, 1), random.uniform(-1, 1))).normalized() * 0.01;
      p += v;
      if (p.norm() > 3) v = -0.01 * p.normalized();
      coherent.kClosestCoherent(p, k, a);
      fresh.kClosest(p, k, b);
      if (!sameHits(a, b) && ++differ <= 3)
        FAIL_CHECK("step " << i << " " << text(p) << ": kClosestCoherent | kClosest" << hitPairs(a, b));
    }
    CHECK(differ == 0);
  }
}

TEST_CASE("coherent queries: kClosestCoherent's exact order", "[coherent]") {
  const Mesh* mesh = realMesh("holes");
  REQUIRE(mesh);
  const auto h = Hierarchy::build(*mesh);
  const PathSpec spec{"step 0.5%, within 5%, crossing", 0.005, 0.0, 0.05, 300, 50, 5};
  const std::vector<Vec3> path = makePath(*mesh, h, spec);
  QueryStream s(h);
  std::vector<TriangleHit> hits;
  size_t misordered = 0;
  for (size_t i = 0; i < path.size(); ++i) {
    s.kClosestCoherent(path[i], kK, hits);
    for (size_t j = 0; j + 1 < hits.size(); ++j) {
      const bool ordered = hits[j].distance < hits[j + 1].distance ||
                           (hits[j].distance == hits[j + 1].distance && hits[j].triangle < hits[j + 1].triangle);
      if (!ordered && ++misordered <= 3)
        FAIL_CHECK("mesh holes, path " << spec.name << ", seed " << spec.seed << ", step " << i << " "
                                       << text(path[i]) << ": rank " << j << " " << num(hits[j].distance)
                                       << " (triangle " << hits[j].triangle << ") before "
                                       << num(hits[j + 1].distance) << " (triangle " << hits[j + 1].triangle << ")");
    }
  }
  CHECK(misordered == 0);
}

// Meshes of duplicate, near-duplicate (1e-9) and collinear vertices, repeated faces, at scales
// from 1e-6 to 1e6 and far from the origin; points on faces, edges and vertices, a hair off
// them, and in the box. The priority queries (kClosestCoherent, closestWithinCoherent,
// closestWithin) bound a slot by its triangle's distance less eps: those bounds must cover the
// rounding of a distance at the coordinates' size, or a face at distance 0 hides behind a
// bound of 1e-16 (found by an audit: kClosestCoherent took a farther face first, or a tied one
// of a higher index, about 1 query in 500 here).
TEST_CASE("coherent queries: priority queries on meshes of degenerate and duplicate faces", "[coherent][degenerate]") {
  Random random(2026);
  size_t meshes = 0, queries = 0, k_wrong = 0, exact_wrong = 0, bracket_wrong = 0;
  for (int it = 0; it < 300; ++it) {
    const size_t vertex_count = 3 + random.index(30), face_count = 1 + random.index(50);
    const double scale = std::pow(10.0, static_cast<double>(random.index(13)) - 6);
    const double offset = random.index(3) == 0 ? std::pow(10.0, static_cast<double>(random.index(7))) * scale * 10 : 0.0;
    Mesh mesh;
    mesh.name = "degenerate " + std::to_string(it);
    std::vector<Vec3>& x = mesh.positions;
    while (x.size() < vertex_count) {
      const size_t kind = random.index(5);
      if (kind == 0 && !x.empty()) {
        x.push_back(x[random.index(x.size())]);
      } else if (kind == 1 && x.size() >= 2) {
        const double t = random.uniform(-1, 1);
        x.push_back(t * x[random.index(x.size())] + (1 - t) * x[random.index(x.size())]);
      } else if (kind == 2 && !x.empty()) {
        x.push_back(x[random.index(x.size())] + 1e-9 * Vec3(random.uniform(-1, 1), random.uniform(-1, 1), random.uniform(-1, 1)));
      } else {
        x.emplace_back(random.uniform(-1, 1), random.uniform(-1, 1), random.index(2) ? 0.0 : random.uniform(-1, 1));
      }
    }
    for (Vec3& v : x) v = scale * v + Vec3(offset, 0.5 * offset, -offset);
    for (size_t f = 0; f < face_count; ++f)
      mesh.triangles.push_back({static_cast<VertexIndex>(random.index(vertex_count)),
                                static_cast<VertexIndex>(random.index(vertex_count)),
                                static_cast<VertexIndex>(random.index(vertex_count))});
    if (random.index(4) == 0)
      for (size_t f = 0; f < face_count / 2; ++f) mesh.triangles.push_back(mesh.triangles[random.index(face_count)]);
    if (!checkMesh(mesh).empty()) continue;
    ++meshes;
    const auto h = Hierarchy::build(mesh);
    QueryStream k_stream(h), exact_stream(h), plain(h);
    const double diagonal = meshDiagonal(mesh);
    for (int q = 0; q < 60; ++q) {
      // On a face, an edge or a vertex, a hair off the surface, or anywhere in the box.
      const Triangle& t = mesh.triangles[random.index(mesh.triangles.size())];
      double b0 = random.uniform(), b1 = random.uniform();
      if (b0 + b1 > 1) { b0 = 1 - b0; b1 = 1 - b1; }
      const size_t where = random.index(5);
      if (where == 1) b1 = 1 - b0;                 // an edge
      if (where == 2) { b0 = 1; b1 = 0; }          // a vertex
      Vec3 p = b0 * x[t[0]] + b1 * x[t[1]] + (1 - b0 - b1) * x[t[2]];
      if (where == 3) p += 1e-9 * diagonal * Vec3(random.uniform(-1, 1), random.uniform(-1, 1), random.uniform(-1, 1));
      if (where == 4) p = x[random.index(x.size())] + diagonal * Vec3(random.uniform(-1, 1), random.uniform(-1, 1), random.uniform(-1, 1));
      ++queries;
      const std::vector<BruteHit> truth = bruteForceKClosest(mesh, p, 3);
      std::vector<TriangleHit> hits;
      k_stream.kClosestCoherent(p, 3, hits);
      if (!sameHits(hits, truth) && ++k_wrong <= 3)
        FAIL_CHECK(mesh.name << " " << text(p) << ": kClosestCoherent(p, 3) | brute force" << hitPairs(hits, truth));
      const ClosestPoint exact = exact_stream.closestWithinCoherent(p, 0);
      if (!(exact.triangle == truth[0].triangle && exact.distance == truth[0].distance && exact.lower <= exact.distance) &&
          ++exact_wrong <= 3)
        FAIL_CHECK(mesh.name << " " << text(p) << ": closestWithinCoherent(p, 0) triangle " << exact.triangle << " at "
                             << num(exact.distance) << " (lower " << num(exact.lower) << "), brute force "
                             << truth[0].triangle << " at " << num(truth[0].distance));
      // The bounds bracket the truth up to the rounding of a distance (an upper bound is a face's
      // computed distance: relative 1e-14 of brute force's, or a few ulps of the coordinates
      // near 0).
      const ClosestPoint anytime = plain.closestWithin(p, 0.01 * diagonal);
      const double coordinates = std::max(std::abs(offset) + scale, p.cwiseAbs().maxCoeff());
      const double slack = 1e-12 * truth[0].distance + 64 * std::numeric_limits<double>::epsilon() * coordinates;
      if (!(anytime.lower <= truth[0].distance + slack && truth[0].distance <= anytime.upper + slack) && ++bracket_wrong <= 3)
        FAIL_CHECK(mesh.name << " " << text(p) << ": closestWithin(p, 1% of the diagonal) [" << num(anytime.lower)
                             << ", " << num(anytime.upper) << "], brute force " << num(truth[0].distance));
    }
  }
  INFO(meshes << " meshes, " << queries << " queries");
  CHECK(meshes > 200);
  CHECK(k_wrong == 0);
  CHECK(exact_wrong == 0);
  CHECK(bracket_wrong == 0);
}

// Found by an audit: on a mesh far from the origin relative to its size, a set's test and
// certificate were decided by margins relative to the distances (1e-9), not to the
// coordinates, whose rounding (a few eps of them) then decides ties. On a grid of size 1 at
// 1e14, paths along its diagonals, closestCoherent returned the other face of an exact tie at
// distance 0 in about 1 step of 300, withinCoherent left out faces within(p, d) lists in about
// 1 of 25. The coherent answers must equal the plain ones, bit for bit, at any offset.
TEST_CASE("coherent queries: ties on a mesh far from the origin go as in the plain queries", "[coherent][far]") {
  constexpr int kN = 40;
  for (const double offset : {0.0, 1e7, 1e14}) {
    Mesh grid;
    grid.name = "grid at " + std::to_string(offset);
    const Vec3 origin(offset, offset, 0);
    for (int i = 0; i <= kN; ++i)
      for (int j = 0; j <= kN; ++j) grid.positions.push_back(origin + Vec3(i, j, 0) / kN);
    for (uint32_t i = 0; i < kN; ++i)
      for (uint32_t j = 0; j < kN; ++j) {
        const uint32_t a = i * (kN + 1) + j, b = a + 1, c = a + kN + 1, d = c + 1;
        grid.triangles.push_back({a, b, d});  // cells split along their diagonals: exact ties
        grid.triangles.push_back({a, d, c});
      }
    const auto hierarchy = Hierarchy::build(grid);
    uint64_t seed = 11;
    auto next = [&seed] {  // splitmix64: the same paths on every platform
      uint64_t z = (seed += 0x9e3779b97f4a7c15ULL);
      z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
      z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
      return z ^ (z >> 31);
    };
    size_t steps = 0, closest_wrong = 0, state_wrong = 0, within_wrong = 0, front_wrong = 0;
    std::vector<TriangleHit> got, expected;
    for (int path = 0; path < 150; ++path) {
      QueryStream coherent(hierarchy), with_state(hierarchy), plain(hierarchy), front(hierarchy);
      CoherentState closest_state, within_state;
      // From one grid vertex to another: the path crosses vertices, edges and diagonals.
      const Vec3 a = grid.positions[next() % grid.positions.size()];
      const Vec3 b = grid.positions[next() % grid.positions.size()];
      const double d = path % 2 ? 0.0 : 0.001 * static_cast<double>(next() % 100);
      for (int i = 0; i < 40; ++i, ++steps) {
        const Vec3 p = (1 - i / 40.0) * a + (i / 40.0) * b;
        const ClosestPoint truth = plain.closest(p);
        const ClosestPoint c = coherent.closestCoherent(p);
        closest_wrong += c.triangle != truth.triangle || c.distance != truth.distance;
        const ClosestPoint s = with_state.closestCoherent(p, closest_state);
        state_wrong += s.triangle != truth.triangle || s.distance != truth.distance;
        with_state.withinCoherent(p, d, within_state, got);
        plain.within(p, d, expected);
        within_wrong += !sameWithin(got, expected);
        // The exact dynamic front: a tolerance of 0, negative or NaN is an exact query, ties
        // included (found by an audit: NaN skipped the tie rule, the answer another face an ulp
        // farther).
        const double tolerance = i % 3 == 0 ? std::numeric_limits<double>::quiet_NaN() : i % 3 == 1 ? -1.0 : 0.0;
        const ClosestPoint f = front.closestWithinCoherent(p, tolerance);
        front_wrong += f.triangle != truth.triangle || f.distance != truth.distance || f.lower != f.upper;
      }
    }
    INFO(grid.name << ": " << steps << " steps");
    CHECK(closest_wrong == 0);
    CHECK(state_wrong == 0);
    CHECK(within_wrong == 0);
    CHECK(front_wrong == 0);
  }
}

// Found by an audit: closestWithinCoherent with a NaN tolerance refined as far as with 0 but
// skipped the tie rule, so where two faces' distances differed by an ulp it answered the
// farther one (3torus, hedra_open, icosahedron, ... about 1 step in 1,300). 0, negative and
// NaN tolerances are all the exact query: the same answer as closest(), bit for bit.
TEST_CASE("coherent queries: the exact dynamic front for a tolerance of 0 or less or NaN", "[coherent][front]") {
  size_t meshes = 0, steps = 0;
  for (const char* name : {"3torus", "hedra_open", "icosahedron", "eight", "bones"}) {
    const Mesh* mesh = realMesh(name);
    if (!mesh) continue;
    ++meshes;
    const auto hierarchy = Hierarchy::build(*mesh);
    Vec3 lower, upper;
    meshBounds(*mesh, lower, upper);
    const double diagonal = (upper - lower).norm();
    Random random(7);
    for (int path = 0; path < 60; ++path) {
      QueryStream plain(hierarchy);
      QueryStream fronts[3] = {QueryStream(hierarchy), QueryStream(hierarchy), QueryStream(hierarchy)};
      const double tolerances[3] = {0.0, -1.0, std::numeric_limits<double>::quiet_NaN()};
      // Straight between two vertices (through vertices, edges and faces) or a smooth wiggle.
      const Vec3 a = mesh->positions[mesh->triangles[random.index(mesh->triangles.size())][0]];
      const Vec3 b = mesh->positions[mesh->triangles[random.index(mesh->triangles.size())][1]];
      for (int i = 0; i < 24; ++i, ++steps) {
        const double t = i / 24.0;
        Vec3 p = (1 - t) * a + t * b;
        if (path % 2) p += 0.01 * diagonal * Vec3(std::sin(20 * t), std::cos(17 * t), std::sin(13 * t));
        const ClosestPoint truth = plain.closest(p);
        for (int k = 0; k < 3; ++k) {
          const ClosestPoint f = fronts[k].closestWithinCoherent(p, tolerances[k]);
          INFO(name << " path " << path << " step " << i << ", tolerance " << tolerances[k]);
          REQUIRE(f.triangle == truth.triangle);
          REQUIRE(f.distance == truth.distance);
          REQUIRE(f.lower == f.upper);
        }
      }
    }
  }
  INFO(steps << " steps");
  CHECK(meshes == 5);
}
