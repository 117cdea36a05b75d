// The oracle: every query kind of QueryStream (closest, closestWithin exact and anytime,
// kClosest, within) against brute force, on real meshes and procedural ones (closed, open,
// soups, degenerate), for points far away, in the box, near the surface, on the surface, on
// vertices and edges, and inside the shape. Also: warm streams answer like fresh ones; the
// paper's worst case (the centre of a finely tessellated sphere) stays correct with bounded work
// and no allocation once warm.
//
// The reference: one pass of closestPointOnTriangle over every face per point (what
// core/brute_force.cpp does), from which the closest face, the k closest and the faces within d
// are read; on a sample of the points, bruteForceClosest, bruteForceKClosest and
// bruteForceWithin themselves are compared with that pass. (One pass per point instead of six
// keeps the binary within its time budget on 75k-face meshes.)
#include "core/brute_force.h"
#include "core/hierarchy.h"
#include "core/mesh_io.h"
#include "core/sweep_query.h"
#include "core/triangle_distance.h"
#include "scenes/procedural.h"

#include "tests/oracle.h"

#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <new>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

using namespace meshsweeper;
using namespace meshsweeper::oracle;
using scenes::Random;

// Counts allocations of the whole binary, so a test can assert that warm queries allocate
// nothing (the stream is documented to be allocation-free once warm). Sanitizer builds keep
// their own allocator (replacing operator new there mixes the two): no counting there.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define MESHSWEEPER_COUNT_ALLOCATIONS 0
#else
#define MESHSWEEPER_COUNT_ALLOCATIONS 1
#endif
namespace {
std::atomic<size_t> g_allocations{0};
}  // namespace

#if MESHSWEEPER_COUNT_ALLOCATIONS
// (GCC cannot see that these free() calls match the malloc() of the operator new above.)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop
#endif

namespace {

// Relative agreement of distances; exact zero needs an exact zero (absolute 1e-300).
constexpr double kRelative = 1e-12;
constexpr double kZero = 1e-300;
constexpr double kDoubleEps = std::numeric_limits<double>::epsilon();

bool sameDistance(double got, double expected) {
  return std::abs(got - expected) <= kRelative * std::max(std::abs(got), std::abs(expected)) + kZero;
}

// ---- The reference ------------------------------------------------------------------------

// One brute-force pass: the distance from p to every face, and the faces in increasing
// (distance, index) order as far as `keep`.
struct Reference {
  std::vector<double> distance;      // [triangle]
  std::vector<TriangleIndex> order;  // the `keep` closest, by (distance, index)
  std::vector<TriangleIndex> scratch;

  void compute(const Mesh& mesh, const Vec3& p, size_t keep) {
    const size_t m = mesh.triangles.size();
    distance.resize(m);
    for (size_t t = 0; t < m; ++t) {
      const Triangle& f = mesh.triangles[t];
      distance[t] = std::sqrt(
          closestPointOnTriangle(p, mesh.positions[f[0]], mesh.positions[f[1]], mesh.positions[f[2]])
              .squared_distance);
    }
    scratch.resize(m);
    std::iota(scratch.begin(), scratch.end(), TriangleIndex(0));
    keep = std::min(keep, m);
    std::partial_sort(scratch.begin(), scratch.begin() + keep, scratch.end(),
                      [&](TriangleIndex a, TriangleIndex b) {
                        return distance[a] != distance[b] ? distance[a] < distance[b] : a < b;
                      });
    order.assign(scratch.begin(), scratch.begin() + keep);
  }
  double closest() const { return distance[order.front()]; }
};

// ---- Points ---------------------------------------------------------------------------------

struct PointSet {
  std::string kind;
  std::vector<Vec3> points;
};

struct Budget {
  size_t box, far, near, surface, vertex, edge, inside;
};

std::vector<Vec3> every(const std::vector<Vec3>& points, size_t n) {
  if (points.size() <= n) return points;
  std::vector<Vec3> out;
  for (size_t i = 0; i < n; ++i) out.push_back(points[i * points.size() / n]);
  return out;
}

std::vector<PointSet> pointSets(const Mesh& mesh, const Budget& b, uint64_t seed) {
  Vec3 lower, upper;
  meshBounds(mesh, lower, upper);
  const double diagonal = (upper - lower).norm();
  const Vec3 centre = 0.5 * (lower + upper);
  Random random(seed);
  std::vector<PointSet> sets;
  sets.push_back({"box+10%", scenes::randomPointsInBox(mesh, b.box, 0.1, seed + 1)});
  {
    // Far away: 100x and 1e6x the diagonal, and a few beyond the float range of the boxes.
    PointSet far{"far", {}};
    for (size_t i = 0; i < b.far; ++i) {
      Vec3 direction(random.uniform(-1, 1), random.uniform(-1, 1), random.uniform(-1, 1));
      if (direction.norm() < 1e-3) direction = Vec3(1, 0.5, 0.25);
      const double factor = i % 5 == 4 ? 1e16 : (i % 2 == 0 ? 100.0 : 1e6);
      far.points.push_back(centre + factor * diagonal * direction.normalized());
    }
    sets.push_back(far);
  }
  sets.push_back({"near+-1%", scenes::nearSurfacePoints(mesh, b.near, 0.01, seed + 2)});
  sets.push_back({"surface", scenes::surfacePoints(mesh, b.surface, seed + 3)});
  sets.push_back({"vertex", every(scenes::vertexPoints(mesh), b.vertex)});
  {
    PointSet edges{"edge", scenes::edgePoints(mesh, b.edge / 2, seed + 4)};
    for (size_t i = 0; i < b.edge - b.edge / 2; ++i) {  // exact midpoints
      const Triangle& t = mesh.triangles[random.index(mesh.triangles.size())];
      const size_t k = random.index(3);
      edges.points.push_back(0.5 * (mesh.positions[t[k]] + mesh.positions[t[(k + 1) % 3]]));
    }
    sets.push_back(edges);
  }
  {
    // Inside: the box centre and points along lines through it.
    PointSet inside{"inside", {centre}};
    const size_t lines = 3;
    const size_t per_line = b.inside > 1 ? (b.inside - 1) / lines : 0;
    for (size_t line = 0; line < lines; ++line) {
      const Vec3 direction = Vec3(random.uniform(-1, 1), random.uniform(-1, 1), random.uniform(-1, 1))
                                 .cwiseProduct(upper - lower);
      for (size_t i = 0; i < per_line; ++i) {
        const double t = per_line > 1 ? -0.45 + 0.9 * double(i) / double(per_line - 1) : 0.0;
        inside.points.push_back(centre + t * direction);
      }
    }
    sets.push_back(inside);
  }
  return sets;
}

// ---- Checks ---------------------------------------------------------------------------------

// Everything checked for one mesh, by kind of check, so failures are grouped and counted.
struct Checks {
  Failures closest{"closest() vs brute force"};
  Failures exact{"closestWithin(p, 0) vs brute force"};
  Failures anytime{"closestWithin(p, tol): bounds"};
  Failures k_closest{"kClosest vs bruteForceKClosest"};
  Failures within{"within vs bruteForceWithin"};
  Failures warm{"warm stream != fresh stream"};
  Failures counters{"query counters out of range"};
  Failures oracle{"reference pass != core/brute_force.h"};
  size_t points = 0;
};

// The answer's point lies on its triangle: point == b0*A + b1*B + b2*C, barycentric in the
// closed triangle.
bool onFace(const Mesh& mesh, TriangleIndex f, const Vec3& point, const Vec3& bary, double diagonal,
            std::string& why) {
  if (f >= mesh.triangles.size()) {
    why = "triangle " + std::to_string(f) + " out of range";
    return false;
  }
  const Triangle& t = mesh.triangles[f];
  const Vec3 combined =
      bary[0] * mesh.positions[t[0]] + bary[1] * mesh.positions[t[1]] + bary[2] * mesh.positions[t[2]];
  const bool bary_ok = bary.minCoeff() >= -1e-12 && std::abs(bary.sum() - 1) <= 1e-12;
  // 1e-9 of the diagonal, or the rounding of the combination itself for far-off coordinates.
  const double magnitude = std::max(point.cwiseAbs().maxCoeff(), combined.cwiseAbs().maxCoeff());
  const bool point_ok = (combined - point).norm() <= 1e-9 * diagonal + 16 * kDoubleEps * magnitude;
  if (!bary_ok || !point_ok) {
    why = "point " + text(point) + " is not b0*A + b1*B + b2*C of face " + std::to_string(f) +
          " (barycentric " + text(bary) + ", combination " + text(combined) + ")";
    return false;
  }
  return true;
}

struct ExactContext {
  const Mesh& mesh;
  const Reference& ref;
  const Vec3& p;
  double diagonal;
};

// An exact closest-point answer: distance as brute force, a valid face whose own distance is
// that distance, the point on that face at that distance, lower == upper == distance.
void checkExact(const ExactContext& c, const ClosestPoint& r, Failures& failures) {
  const double truth = c.ref.closest();
  failures.check(sameDistance(r.distance, truth), [&] {
    return "distance " + num(r.distance) + ", brute force " + num(truth) + " (face " +
           std::to_string(c.ref.order.front()) + "), got face " + std::to_string(r.triangle);
  });
  failures.check(r.lower == r.distance && r.upper == r.distance, [&] {
    return "exact answer with bounds [" + num(r.lower) + ", " + num(r.upper) + "] != distance " +
           num(r.distance);
  });
  if (r.triangle >= c.mesh.triangles.size()) {
    failures.check(false, [&] { return "invalid triangle index " + std::to_string(r.triangle); });
    return;
  }
  failures.check(sameDistance(c.ref.distance[r.triangle], r.distance), [&] {
    return "face " + std::to_string(r.triangle) + " is at " + num(c.ref.distance[r.triangle]) +
           ", reported " + num(r.distance);
  });
  std::string why;
  failures.check(onFace(c.mesh, r.triangle, r.point, r.barycentric, c.diagonal, why), [&] { return why; });
  const double to_point = (c.p - r.point).norm();
  failures.check(sameDistance(to_point, r.distance),
                 [&] { return "|p - point| = " + num(to_point) + " != distance " + num(r.distance); });
}

void checkAnytime(const ExactContext& c, const ClosestPoint& r, double tolerance, Failures& failures) {
  const double truth = c.ref.closest();
  const std::string tol = "tolerance " + num(tolerance) + ": ";
  failures.check(r.lower >= 0 && r.lower <= truth * (1 + kRelative) + kZero,
                 [&] { return tol + "lower " + num(r.lower) + " above the true distance " + num(truth); });
  failures.check(r.upper >= truth * (1 - kRelative) - kZero,
                 [&] { return tol + "upper " + num(r.upper) + " below the true distance " + num(truth); });
  failures.check(r.upper - r.lower <= tolerance + kRelative * r.upper, [&] {
    return tol + "upper - lower = " + num(r.upper - r.lower) + " ([" + num(r.lower) + ", " + num(r.upper) +
           "])";
  });
  failures.check(r.distance == r.upper,
                 [&] { return tol + "distance " + num(r.distance) + " != upper " + num(r.upper); });
  std::string why;
  failures.check(onFace(c.mesh, r.triangle, r.point, r.barycentric, c.diagonal, why),
                 [&] { return tol + why; });
  const double to_point = (c.p - r.point).norm();
  failures.check(sameDistance(to_point, r.upper),
                 [&] { return tol + "|p - point| = " + num(to_point) + " != upper " + num(r.upper); });
  if (r.triangle < c.mesh.triangles.size()) {
    failures.check(c.ref.distance[r.triangle] <= r.upper * (1 + kRelative) + kZero, [&] {
      return tol + "face " + std::to_string(r.triangle) + " is at " + num(c.ref.distance[r.triangle]) +
             " > upper " + num(r.upper);
    });
  }
}

// Distances of hits: each equals its own face's brute-force distance, the point is on the face
// at that distance, order by (distance, triangle), no face twice.
void checkHits(const ExactContext& c, const std::vector<TriangleHit>& hits, const std::string& what,
               Failures& failures) {
  std::vector<TriangleIndex> seen;
  for (size_t i = 0; i < hits.size(); ++i) {
    const TriangleHit& hit = hits[i];
    if (hit.triangle >= c.mesh.triangles.size()) {
      failures.check(false, [&] { return what + ": invalid triangle " + std::to_string(hit.triangle); });
      continue;
    }
    seen.push_back(hit.triangle);
    failures.check(sameDistance(hit.distance, c.ref.distance[hit.triangle]), [&] {
      return what + ": hit " + std::to_string(i) + " face " + std::to_string(hit.triangle) + " reported at " +
             num(hit.distance) + ", brute force " + num(c.ref.distance[hit.triangle]);
    });
    std::string why;
    failures.check(onFace(c.mesh, hit.triangle, hit.point, hit.barycentric, c.diagonal, why),
                   [&] { return what + ": " + why; });
    failures.check(sameDistance((c.p - hit.point).norm(), hit.distance),
                   [&] { return what + ": |p - point| != distance for hit " + std::to_string(i); });
    if (i > 0) {
      const TriangleHit& prev = hits[i - 1];
      failures.check(
          prev.distance < hit.distance || (prev.distance == hit.distance && prev.triangle < hit.triangle),
          [&] {
            return what + ": hits " + std::to_string(i - 1) + ", " + std::to_string(i) +
                   " out of (distance, triangle) order: (" + num(prev.distance) + ", " +
                   std::to_string(prev.triangle) + "), (" + num(hit.distance) + ", " +
                   std::to_string(hit.triangle) + ")";
          });
    }
  }
  std::sort(seen.begin(), seen.end());
  failures.check(std::adjacent_find(seen.begin(), seen.end()) == seen.end(),
                 [&] { return what + ": a face reported twice"; });
}

void checkKClosest(const ExactContext& c, const std::vector<TriangleHit>& hits, size_t k,
                   Failures& failures) {
  const std::string what = "k = " + std::to_string(k);
  const size_t expected = std::min(k, c.mesh.triangles.size());
  failures.check(hits.size() == expected, [&] {
    return what + ": " + std::to_string(hits.size()) + " hits, expected " + std::to_string(expected);
  });
  checkHits(c, hits, what, failures);
  const auto& order = c.ref.order;  // at least k + 1 entries when the mesh has them
  const auto d = [&](size_t i) { return c.ref.distance[order[i]]; };
  for (size_t i = 0; i < std::min(hits.size(), expected); ++i) {
    failures.check(sameDistance(hits[i].distance, d(i)), [&] {
      return what + ": hit " + std::to_string(i) + " at " + num(hits[i].distance) + " (face " +
             std::to_string(hits[i].triangle) + "), brute force " + num(d(i)) + " (face " +
             std::to_string(order[i]) + ")";
    });
    // Where the i-th distance is separated from its neighbours, the face is determined.
    const bool apart_before = i == 0 || !sameDistance(d(i - 1), d(i));
    const bool apart_after = i + 1 >= order.size() || !sameDistance(d(i + 1), d(i));
    if (apart_before && apart_after) {
      failures.check(hits[i].triangle == order[i], [&] {
        return what + ": hit " + std::to_string(i) + " is face " + std::to_string(hits[i].triangle) + " at " +
               num(hits[i].distance) + ", brute force face " + std::to_string(order[i]) + " at " + num(d(i));
      });
    }
  }
}

void checkWithin(const ExactContext& c, const std::vector<TriangleHit>& hits, double radius,
                 Failures& failures) {
  const std::string what = "within d = " + num(radius);
  checkHits(c, hits, what, failures);
  std::vector<uint8_t> reported(c.mesh.triangles.size(), 0);
  for (const TriangleHit& hit : hits) {
    if (hit.triangle < reported.size()) reported[hit.triangle] = 1;
    failures.check(hit.distance <= radius, [&] {
      return what + ": face " + std::to_string(hit.triangle) + " at " + num(hit.distance);
    });
  }
  size_t missing = 0, extra = 0;
  TriangleIndex first = kInvalidIndex;
  for (size_t t = 0; t < reported.size(); ++t) {
    const double dt = c.ref.distance[t];
    const bool inside = dt <= radius;
    if (inside == static_cast<bool>(reported[t])) continue;
    if (std::abs(dt - radius) <= kRelative * radius) continue;  // a tie with d: either answer is right
    (inside ? missing : extra) += 1;
    if (first == kInvalidIndex) first = static_cast<TriangleIndex>(t);
  }
  failures.check(missing == 0 && extra == 0, [&] {
    return what + ": " + std::to_string(missing) + " faces missing, " + std::to_string(extra) +
           " extra (first: face " + std::to_string(first) + " at " + num(c.ref.distance[first]) + ")";
  });
}

bool sameHits(const std::vector<TriangleHit>& a, const std::vector<TriangleHit>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].distance != b[i].distance || a[i].triangle != b[i].triangle || a[i].point != b[i].point ||
        a[i].barycentric != b[i].barycentric)
      return false;
  return true;
}

bool sameAnswer(const ClosestPoint& a, const ClosestPoint& b) {
  return a.distance == b.distance && a.lower == b.lower && a.upper == b.upper && a.triangle == b.triangle &&
         a.point == b.point && a.barycentric == b.barycentric;
}

// Compares the one-pass reference with core/brute_force.h on this point.
void checkOracle(const ExactContext& c, const std::vector<double>& radii, Failures& failures) {
  const BruteHit best = bruteForceClosest(c.mesh, c.p);
  failures.check(best.triangle == c.ref.order.front() && best.distance == c.ref.closest(), [&] {
    return "bruteForceClosest face " + std::to_string(best.triangle) + " at " + num(best.distance) +
           ", reference face " + std::to_string(c.ref.order.front()) + " at " + num(c.ref.closest());
  });
  const size_t k = std::min<size_t>(20, c.ref.order.size());
  const std::vector<BruteHit> kbest = bruteForceKClosest(c.mesh, c.p, 20);
  bool same = kbest.size() == k;
  for (size_t i = 0; same && i < k; ++i)
    same = kbest[i].triangle == c.ref.order[i] && kbest[i].distance == c.ref.distance[c.ref.order[i]];
  failures.check(same, [&] { return std::string("bruteForceKClosest(20) != reference"); });
  for (double radius : radii) {
    const std::vector<BruteHit> near = bruteForceWithin(c.mesh, c.p, radius);
    size_t expected = 0;
    for (double dt : c.ref.distance) expected += dt <= radius;
    bool ok = near.size() == expected;
    for (const BruteHit& hit : near) ok = ok && hit.distance == c.ref.distance[hit.triangle];
    failures.check(ok, [&] { return "bruteForceWithin(" + num(radius) + ") != reference"; });
  }
}

struct MeshCase {
  const Mesh* mesh;
  std::shared_ptr<const Hierarchy> hierarchy;
};

struct Summary {
  size_t points = 0;
  size_t checks = 0;
};

// Runs every query kind on every point of every set, against the reference.
Summary runOracle(const Mesh& mesh, const std::shared_ptr<const Hierarchy>& h,
                  const std::vector<PointSet>& sets, size_t fresh_every, size_t oracle_every) {
  INFO("mesh " << mesh.name << " (" << mesh.triangles.size() << " triangles)");
  const double diagonal = meshDiagonal(mesh);
  const size_t m = mesh.triangles.size();
  const size_t nodes = h->nodes().size();
  const size_t leaves = h->leafCount();
  Checks checks;
  Reference ref;
  QueryStream stream(h);  // warm: one stream for every point and every query kind of this mesh
  std::vector<TriangleHit> hits, fresh_hits;
  size_t index = 0;
  for (const PointSet& set : sets) {
    for (size_t i = 0; i < set.points.size(); ++i, ++index) {
      const Vec3& p = set.points[i];
      INFO(set.kind << " point " << i << " " << text(p));
      ref.compute(mesh, p, 21);
      const ExactContext c{mesh, ref, p, diagonal};
      const double truth = ref.closest();
      ++checks.points;

      const ClosestPoint closest = stream.closest(p);
      checkExact(c, closest, checks.closest);
      const QueryCounters& n = closest.counters;
      checks.counters.check(n.nodes_visited <= nodes && n.leaves_tested <= leaves && n.triangles_tested <= m,
                            [&] {
                              return "closest: " + std::to_string(n.nodes_visited) + " nodes, " +
                                     std::to_string(n.leaves_tested) + " leaves, " +
                                     std::to_string(n.triangles_tested) + " triangles";
                            });

      const ClosestPoint exact = stream.closestWithin(p, 0);
      checkExact(c, exact, checks.exact);
      CHECK(exact.triangle == closest.triangle);  // ties go to the lowest index in both
      const QueryCounters& e = exact.counters;
      // The priority process, then a depth-first search from its answer for a tie with a lower
      // index: each visits every node and leaf at most once (far points: nearly all).
      checks.counters.check(e.nodes_visited <= 2 * nodes && e.leaves_tested <= 2 * leaves &&
                                e.triangles_tested <= 2 * m && e.heap_max <= 8 * nodes + leaves,
                            [&] {
                              return "closestWithin(p, 0): " + std::to_string(e.nodes_visited) + " nodes, " +
                                     std::to_string(e.leaves_tested) + " leaves, heap " +
                                     std::to_string(e.heap_max);
                            });

      for (double fraction : {1e-2, 1e-4}) {
        const ClosestPoint anytime = stream.closestWithin(p, fraction * diagonal);
        checkAnytime(c, anytime, fraction * diagonal, checks.anytime);
      }

      for (size_t k : {1, 5, 20}) {
        stream.kClosest(p, k, hits);
        checkKClosest(c, hits, k, checks.k_closest);
      }

      const std::vector<double> radii = {1.5 * truth, 0.005 * diagonal};
      for (double radius : radii) {
        stream.within(p, radius, hits);
        checkWithin(c, hits, radius, checks.within);
      }

      if (index % fresh_every == 0) {
        // Warm == cold: the same queries on a fresh stream give bit-identical answers.
        QueryStream fresh(h);
        checks.warm.check(sameAnswer(fresh.closest(p), closest), [&] { return std::string("closest"); });
        checks.warm.check(sameAnswer(fresh.closestWithin(p, 0), exact),
                          [&] { return std::string("closestWithin(p, 0)"); });
        QueryStream fresh2(h);
        const ClosestPoint a = fresh2.closestWithin(p, 1e-2 * diagonal);
        checks.warm.check(sameAnswer(a, stream.closestWithin(p, 1e-2 * diagonal)),
                          [&] { return std::string("closestWithin(p, 1e-2 diagonal)"); });
        QueryStream fresh3(h);
        fresh3.kClosest(p, 20, fresh_hits);
        stream.kClosest(p, 20, hits);
        checks.warm.check(sameHits(fresh_hits, hits), [&] { return std::string("kClosest(20)"); });
        QueryStream fresh4(h);
        fresh4.within(p, radii[0], fresh_hits);
        stream.within(p, radii[0], hits);
        checks.warm.check(sameHits(fresh_hits, hits), [&] { return std::string("within(1.5 d)"); });
      }
      if (index % oracle_every == 0) checkOracle(c, radii, checks.oracle);
    }
  }
  Summary summary;
  summary.points = checks.points;
  summary.checks = checks.closest.checks() + checks.exact.checks() + checks.anytime.checks() +
                   checks.k_closest.checks() + checks.within.checks() + checks.warm.checks() +
                   checks.counters.checks() + checks.oracle.checks();
  if (std::getenv("MESHSWEEPER_TEST_VERBOSE"))
    std::cout << mesh.name << ": " << summary.points << " points, " << summary.checks << " checks\n";
  return summary;
}

}  // namespace

TEST_CASE("queries agree with brute force on real meshes", "[queries][real]") {
  // ~150 points per kind on the large meshes; brute force costs about 0.1 us per face here.
  const Budget budget{150, 30, 150, 150, 100, 100, 25};
  uint64_t seed = 100;
  std::vector<Vec3> foreign;  // points of the previous mesh, asked of the next one's stream
  for (const char* name : {"armadillo", "bunny00", "holes", "blobby_3cc", "fandisk", "mannequin-devil"}) {
    const Mesh* mesh = realMesh(name);
    if (!mesh) continue;
    const auto h = Hierarchy::build(*mesh);
    std::vector<PointSet> sets = pointSets(*mesh, budget, seed += 10);
    if (!foreign.empty()) sets.push_back({"foreign", foreign});
    runOracle(*mesh, h, sets, 8, 16);
    foreign = every(sets[2].points, 20);
  }
}

TEST_CASE("queries agree with brute force on procedural meshes", "[queries]") {
  std::vector<Mesh> meshes;
  meshes.push_back(scenes::icosphere(4));
  meshes.push_back(scenes::torus(1.0, 0.3, 64, 32));
  meshes.push_back(scenes::randomSoup(3000, 21));
  meshes.push_back(scenes::degenerateMesh());
  meshes.push_back(scenes::gridPlane(40));
  meshes.push_back(scenes::uvSphere(24, 48));
  {
    Mesh parts = scenes::concatenate({scenes::icosphere(3, 0.5, Vec3(3, 0, 0)),
                                      scenes::torus(1.0, 0.25, 32, 16), scenes::randomSoup(300, 5),
                                      scenes::gridPlane(10, 2.0), scenes::degenerateMesh()});
    parts.name = "concatenated components";
    meshes.push_back(parts);
  }
  for (size_t count : {1, 2, 8, 9, 65}) {
    Mesh small = scenes::icosphere(2);
    small.triangles.resize(count);
    small.name = "icosphere patch of " + std::to_string(count);
    meshes.push_back(small);
  }
  {
    Mesh far = scenes::icosphere(3, 1.0, Vec3(1e6, -2e6, 3e6));
    far.name = "icosphere(3) at 1e6";
    meshes.push_back(far);
    Mesh tiny = scenes::torus(1e-6, 3e-7, 32, 16);
    tiny.name = "torus of size 1e-6";
    meshes.push_back(tiny);
    Mesh offset = scenes::gridPlane(20);
    for (Vec3& x : offset.positions) x += Vec3(1e8, -1e8, 0);
    offset.name = "gridPlane(20) at 1e8";
    meshes.push_back(offset);
  }
  const Budget budget{400, 60, 400, 300, 300, 200, 40};
  uint64_t seed = 500;
  for (const Mesh& mesh : meshes) {
    const auto h = Hierarchy::build(mesh);
    runOracle(mesh, h, pointSets(mesh, budget, seed += 10), 4, 4);
  }
}

TEST_CASE("queries: a part far from the rest of its mesh keeps tight boxes", "[queries][far-parts]") {
  // Node boxes are float offsets from each node's own origin: a detailed part far from another
  // part (a stray vertex of a scan, two objects in one file) keeps boxes as tight as alone. With
  // offsets from the mesh's centre, the float margin grew with the mesh's extent, and at 1e9
  // every box of the sphere below covered the whole sphere: each query tested its 5120 faces.
  const Mesh sphere = scenes::icosphere(4);
  const auto alone = Hierarchy::build(sphere);
  const Budget budget{100, 20, 200, 100, 50, 50, 10};
  const std::vector<PointSet> sets = pointSets(sphere, budget, 900);
  auto meanTested = [&](const std::shared_ptr<const Hierarchy>& h) {
    QueryStream stream(h);
    double tested = 0;
    size_t count = 0;
    for (const PointSet& set : sets) {
      if (set.kind == "far") continue;
      for (const Vec3& p : set.points) {
        tested += static_cast<double>(stream.closest(p).counters.triangles_tested);
        ++count;
      }
    }
    return tested / static_cast<double>(count);
  };
  const double tested_alone = meanTested(alone);
  INFO("faces tested per query near the sphere alone: " << tested_alone);
  struct Case {
    const char* name;
    std::vector<Vec3> offsets;  // a small icosphere at each
  };
  const std::vector<Case> cases = {{"one part at 1e9", {Vec3(1e9, 0, 0)}},
                                   {"one part at -1e12 (y)", {Vec3(0, -1e12, 0)}},
                                   {"parts at +-1e12", {Vec3(1e12, 0, 0), Vec3(-1e12, 0, 0)}},
                                   {"parts at 3e7 and 1e11", {Vec3(3e7, 3e7, 0), Vec3(0, 0, 1e11)}}};
  for (const Case& c : cases) {
    std::vector<Mesh> parts = {sphere};
    for (const Vec3& offset : c.offsets) parts.push_back(scenes::icosphere(1, 0.5, offset));
    Mesh mesh = scenes::concatenate(parts);
    mesh.name = std::string("icosphere(4) and ") + c.name;
    const auto h = Hierarchy::build(mesh);
    CHECK(validate(*h).empty());
    runOracle(mesh, h, sets, 8, 8);  // exact against every face of the whole mesh
    const double tested = meanTested(h);
    INFO(mesh.name << ": faces tested per query near the sphere " << tested);
    CHECK(tested <= 1.5 * tested_alone + 8);
  }
}

TEST_CASE("queries: the centre of a finely tessellated sphere", "[queries][worst]") {
  // Every triangle is at nearly the same distance from the centre: the paper's worst case.
  const Mesh sphere = scenes::uvSphere(200, 400);
  INFO(sphere.name << ": " << sphere.triangles.size() << " triangles");
  const auto h = Hierarchy::build(sphere);
  REQUIRE(validate(*h) == "");
  const size_t m = sphere.triangles.size();
  const size_t nodes = h->nodes().size();
  const size_t leaves = h->leafCount();
  const double diagonal = meshDiagonal(sphere);
  QueryStream stream(h);
  Reference ref;
  std::vector<TriangleHit> hits;
  const std::vector<Vec3> points = {Vec3::Zero(), Vec3(1e-9, -2e-9, 3e-9), Vec3(0.01, 0.02, -0.03),
                                    Vec3(0, 0, 0.5)};
  for (const Vec3& p : points) {
    INFO("point " << text(p));
    ref.compute(sphere, p, 21);
    const ExactContext c{sphere, ref, p, diagonal};
    Failures failures("centre of the sphere");
    const ClosestPoint closest = stream.closest(p);
    checkExact(c, closest, failures);
    const ClosestPoint exact = stream.closestWithin(p, 0);
    checkExact(c, exact, failures);
    for (double fraction : {1e-2, 1e-4})
      checkAnytime(c, stream.closestWithin(p, fraction * diagonal), fraction * diagonal, failures);
    stream.kClosest(p, 20, hits);
    checkKClosest(c, hits, 20, failures);
    // Bounded work: no node or leaf twice in a pass, the front never holds more than every
    // slot (closestWithin(p, 0): the priority pass, then the depth-first tie search).
    CHECK(closest.counters.nodes_visited <= nodes);
    CHECK(closest.counters.leaves_tested <= leaves);
    CHECK(closest.counters.triangles_tested <= m);
    CHECK(exact.triangle == closest.triangle);
    CHECK(exact.counters.nodes_visited <= 2 * nodes);
    CHECK(exact.counters.leaves_tested <= 2 * leaves);
    CHECK(exact.counters.heap_max <= 8 * nodes + leaves);
    const QueryCounters& kc = stream.counters();
    CHECK(kc.heap_max <= 8 * nodes + 8 * leaves);
    CHECK(kc.nodes_visited <= nodes);
  }

  // Repeated queries: the same answers and counters, and no allocation once warm.
  const Vec3 centre = Vec3::Zero();
  const ClosestPoint first = stream.closest(centre);
  const ClosestPoint first_exact = stream.closestWithin(centre, 0);
  const ClosestPoint first_anytime = stream.closestWithin(centre, 1e-4 * diagonal);
  stream.kClosest(centre, 20, hits);
  const std::vector<TriangleHit> first_k = hits;
  std::vector<TriangleHit> near;
  near.reserve(m);
  stream.within(centre, 0.005 * diagonal, near);
  size_t differ = 0;
  const size_t before = g_allocations.load();
  // Each exact query at the centre visits the whole tree (a brute-force pass): 100 of the two
  // exact kinds, 10 of the others, to keep the binary's run time reasonable.
  for (int i = 0; i < 100; ++i) {
    const ClosestPoint a = stream.closest(centre);
    const ClosestPoint b = stream.closestWithin(centre, 0);
    differ += !sameAnswer(a, first) || !sameAnswer(b, first_exact) ||
              a.counters.nodes_visited != first.counters.nodes_visited ||
              b.counters.heap_max != first_exact.counters.heap_max;
    if (i % 10 != 0) continue;
    const ClosestPoint c = stream.closestWithin(centre, 1e-4 * diagonal);
    stream.kClosest(centre, 20, hits);
    stream.within(centre, 0.005 * diagonal, near);
    differ += !sameAnswer(c, first_anytime) || !sameHits(hits, first_k);
  }
  const size_t allocations = g_allocations.load() - before;
  CHECK(differ == 0);
  if (MESHSWEEPER_COUNT_ALLOCATIONS)
    CHECK(allocations == 0);
  else
    WARN("allocation counting is off in sanitizer builds");
}

TEST_CASE("queries: a stream moved between meshes' points answers like a fresh one", "[queries][warm]") {
  // Two hierarchies; each stream alternates points from both meshes' boxes (far for the other
  // mesh), every query kind in turn; each answer must equal a fresh stream's.
  const Mesh a = scenes::torus(1.0, 0.3, 48, 24);
  const Mesh b = scenes::concatenate({scenes::icosphere(3, 0.7, Vec3(4, 1, 0)), scenes::randomSoup(500, 9)});
  const auto ha = Hierarchy::build(a);
  const auto hb = Hierarchy::build(b);
  std::vector<Vec3> points = scenes::nearSurfacePoints(a, 100, 0.01, 1);
  const std::vector<Vec3> others = scenes::nearSurfacePoints(b, 100, 0.01, 2);
  points.insert(points.end(), others.begin(), others.end());
  std::sort(points.begin(), points.end(), [](const Vec3& x, const Vec3& y) { return x.x() < y.x(); });
  QueryStream wa(ha), wb(hb);
  std::vector<TriangleHit> warm_hits, cold_hits;
  size_t differ = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    const Vec3& p = points[i];
    for (auto* pair : {&wa, &wb}) {
      QueryStream& warm = *pair;
      const auto& h = pair == &wa ? ha : hb;
      QueryStream cold(h);
      const double tolerance = (i % 3) * 1e-3;
      bool same = sameAnswer(warm.closest(p), QueryStream(h).closest(p));
      same = same && sameAnswer(warm.closestWithin(p, tolerance), QueryStream(h).closestWithin(p, tolerance));
      warm.kClosest(p, 1 + i % 7, warm_hits);
      cold.kClosest(p, 1 + i % 7, cold_hits);
      same = same && sameHits(warm_hits, cold_hits);
      warm.within(p, 0.05, warm_hits);
      QueryStream(h).within(p, 0.05, cold_hits);
      same = same && sameHits(warm_hits, cold_hits);
      if (!same && ++differ <= 5) FAIL_CHECK("point " << i << " " << text(p) << ": warm != cold");
    }
  }
  CHECK(differ == 0);
}

// Found by review: closest() compared squared distances, so of two faces whose squared
// distances differ by an ulp but whose distances (the roots, as reported) are equal it took the
// higher index, where kClosest(p, 1) and the brute force take the lower.
TEST_CASE("queries: ties at one reported distance go to the lowest index", "[queries][ties]") {
  Mesh twice;  // one triangle listed twice, the copy reversed: equal distances, computed apart
  twice.positions = {Vec3(0, 0, 0), Vec3(1, 0.1, 0), Vec3(0.2, 0.9, 0.3)};
  twice.triangles = {{0, 1, 2}, {2, 1, 0}};
  Mesh reversed_first = twice;
  std::swap(reversed_first.triangles[0], reversed_first.triangles[1]);
  for (const Mesh* mesh : {&twice, &reversed_first}) {
    const auto h = Hierarchy::build(*mesh);
    QueryStream s(h), coherent(h);
    CoherentState state;
    Random random(5);
    std::vector<TriangleHit> one;
    Failures failures("ties");
    size_t split = 0;  // points whose squared distances differ while the distances tie
    for (int i = 0; i < 20000; ++i) {
      const Vec3 p = random.inBox(Vec3(-2, -2, -2), Vec3(2, 2, 2));
      const BruteHit b = bruteForceClosest(*mesh, p);
      const Triangle& t0 = mesh->triangles[0];
      const Triangle& t1 = mesh->triangles[1];
      const double d0 = squaredDistanceToTriangle(p, mesh->positions[t0[0]], mesh->positions[t0[1]], mesh->positions[t0[2]]);
      const double d1 = squaredDistanceToTriangle(p, mesh->positions[t1[0]], mesh->positions[t1[1]], mesh->positions[t1[2]]);
      split += d0 != d1 && std::sqrt(d0) == std::sqrt(d1);
      s.kClosest(p, 1, one);
      const TriangleIndex answers[] = {s.closest(p).triangle, s.closestWithin(p, 0).triangle,
                                       coherent.closestCoherent(p).triangle, coherent.closestCoherent(p, state).triangle,
                                       one.at(0).triangle};
      for (TriangleIndex t : answers)
        failures.check(t == b.triangle, [&] {
          return "point " + text(p) + ": triangle " + std::to_string(t) + ", brute force " + std::to_string(b.triangle);
        });
    }
    CHECK(split > 50);  // the case arises
  }
}

TEST_CASE("queries: a stream on a null hierarchy throws", "[queries][errors]") {
  CHECK_THROWS_WITH(QueryStream(std::shared_ptr<const Hierarchy>()), Catch::Contains("null hierarchy"));
}

TEST_CASE("queries: points that are not finite or beyond 1e153 are answered without a search", "[queries][errors]") {
  // Every query kind gives NaN / no faces for them (squared distances would overflow), restarts
  // coherent state, and answers the next point in range as a fresh stream does.
  const Mesh mesh = scenes::icosphere(2);
  const auto h = Hierarchy::build(mesh);
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  QueryStream qs(h);
  CoherentState state;
  std::vector<TriangleHit> hits;
  const Vec3 near(1.2, 0.1, 0.0);
  qs.closestCoherent(near);
  qs.closestCoherent(near, state);
  qs.closestWithinCoherent(near, 0.0);
  for (const Vec3& bad : {Vec3(nan, 0, 0), Vec3(0, inf, 0), Vec3(0, 0, 2e153), Vec3(-1e160, 0, 0)}) {
    INFO(text(bad));
    for (const ClosestPoint& c : {qs.closest(bad), qs.closestWithin(bad, 0.0), qs.closestCoherent(bad),
                                  qs.closestCoherent(bad, state, nullptr, inf), qs.closestWithinCoherent(bad, 0.0)}) {
      CHECK(std::isnan(c.distance));
      CHECK(std::isnan(c.lower));
      CHECK(std::isnan(c.upper));
      CHECK(c.triangle == kInvalidIndex);
    }
    qs.kClosest(bad, 3, hits);
    CHECK(hits.empty());
    qs.within(bad, inf, hits);
    CHECK(hits.empty());
    qs.kClosestCoherent(bad, 3, hits);
    CHECK(hits.empty());
    // The next point in range: the same answers as a fresh stream.
    CHECK(sameAnswer(qs.closestCoherent(near), QueryStream(h).closest(near)));
    CHECK(sameAnswer(qs.closestCoherent(near, state), QueryStream(h).closest(near)));
  }
  // Up to the limit, answered exactly (1e152 away: the distance is 1e152 to 1e-12).
  const Vec3 far(1e152, 0, 0);
  const ClosestPoint c = qs.closest(far);
  REQUIRE(c.triangle != kInvalidIndex);
  CHECK(std::abs(c.distance - bruteForceClosest(mesh, far).distance) <= 1e-12 * c.distance);
}

// The documented floor (README "Errors", found by an audit): a face and a point within about
// 1e-154 of the origin, where squared distances underflow, are exact to about 2e-162 absolute.
TEST_CASE("queries: distances below 1.5e-154 are exact to 2e-162 absolute", "[queries][underflow]") {
  Mesh mesh;
  mesh.positions = {Vec3(1e-300, 0, 0), Vec3(0, 1e-300, 0), Vec3(0, 0, 1e-300),
                    Vec3(0, 0, 1), Vec3(1, 0, 1), Vec3(0, 1, 1)};
  mesh.triangles = {Triangle{0, 1, 2}, Triangle{3, 4, 5}};
  QueryStream stream(Hierarchy::build(mesh));
  // The plane x + y + z = 1e-300, from (s, s, s): (3 s - 1e-300) / sqrt(3).
  for (double s : {1e-140, 1e-155, 1e-160, 1e-170, 1e-295}) {
    const double expected = (3 * s - 1e-300) / std::sqrt(3.0);
    const ClosestPoint c = stream.closest(Vec3(s, s, s));
    CHECK(c.triangle == 0);
    CHECK(std::abs(c.distance - expected) <= 2e-162 + 1e-12 * expected);
    if (s >= 1e-154) CHECK(std::abs(c.distance - expected) <= 1e-12 * expected);
  }
}
