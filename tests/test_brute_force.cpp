// Brute force on tiny hand-drawn meshes with exact expected answers: closest triangle (ties by
// index), k-closest order and within-d sets.
#include "core/brute_force.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

using namespace meshsweeper;

namespace {

// A square in the plane z = 0 cut along its diagonal, a copy of the lower-left half lifted to
// z = 3, and a degenerate triangle lying on the square's right side:
//
//   y                                   t0 = (0, 1, 2)   z = 0
//   2  3---------2                      t1 = (0, 2, 3)   z = 0
//      |      /  |                      t2 = (4, 5, 6)   z = 3, above the left half of t0/t1:
//      |  t1 /   |  t3 = (1, 1, 2)           4 (0,0,3)  5 (2,0,3)  6 (0,2,3)
//      |    /    |  (the segment 1-2)   t3 = (1, 1, 2)   z = 0, degenerate
//      |   /  t0 |
//   0  0---------1
//      0         2   x
Mesh squareMesh() {
  Mesh mesh;
  mesh.name = "square";
  mesh.positions = {{0, 0, 0}, {2, 0, 0}, {2, 2, 0}, {0, 2, 0},
                    {0, 0, 3}, {2, 0, 3}, {0, 2, 3}};
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}, {4, 5, 6}, {1, 1, 2}};
  return mesh;
}

std::vector<TriangleIndex> indices(const std::vector<BruteHit>& hits) {
  std::vector<TriangleIndex> out;
  for (const BruteHit& h : hits) out.push_back(h.triangle);
  return out;
}

void checkHit(const BruteHit& hit, TriangleIndex triangle, double squared_distance,
              const Vec3& point) {
  INFO("triangle " << hit.triangle << " distance " << hit.distance << " point ("
                   << hit.point.transpose() << ")");
  CHECK(hit.triangle == triangle);
  CHECK(std::abs(hit.distance - std::sqrt(squared_distance)) <= 1e-15);
  CHECK((hit.point - point).cwiseAbs().maxCoeff() <= 1e-15);
}

}  // namespace

TEST_CASE("brute force: closest triangle", "[brute_force]") {
  const Mesh mesh = squareMesh();
  SECTION("above the interior of t0") {
    const BruteHit hit = bruteForceClosest(mesh, Vec3(1.5, 0.5, 1));
    checkHit(hit, 0, 1.0, Vec3(1.5, 0.5, 0));
    CHECK(hit.feature == Feature::kFace);
    CHECK((hit.barycentric - Vec3(0.25, 0.5, 0.25)).cwiseAbs().maxCoeff() <= 1e-15);
  }
  SECTION("above the diagonal: t0 and t1 tie, the lower index wins") {
    const BruteHit hit = bruteForceClosest(mesh, Vec3(1, 1, 1));
    checkHit(hit, 0, 1.0, Vec3(1, 1, 0));
    CHECK(hit.feature == Feature::kEdge20);
  }
  SECTION("just below the lifted triangle") {
    checkHit(bruteForceClosest(mesh, Vec3(0.5, 0.5, 2.5)), 2, 0.25, Vec3(0.5, 0.5, 3));
  }
  SECTION("right of the square: t0's edge and the degenerate t3 tie, t0 wins") {
    const BruteHit hit = bruteForceClosest(mesh, Vec3(3, 1, 0));
    checkHit(hit, 0, 1.0, Vec3(2, 1, 0));
    CHECK(hit.feature == Feature::kEdge12);
  }
  SECTION("duplicate triangles: the lower index wins") {
    Mesh twice = mesh;
    twice.triangles = {{4, 5, 6}, {0, 1, 2}, {0, 1, 2}};
    checkHit(bruteForceClosest(twice, Vec3(1.5, 0.5, -1)), 1, 1.0, Vec3(1.5, 0.5, 0));
  }
}

TEST_CASE("brute force: k closest", "[brute_force]") {
  const Mesh mesh = squareMesh();
  SECTION("above the interior of t0") {
    // t0: 1 (face); t3: (2, 0.5, 0), 1.25; t1: (1, 1, 0) on the diagonal, 1.5; t2: 2 (its edge
    // 5-6 passes above the query), 4.
    const Vec3 p(1.5, 0.5, 1);
    const std::vector<BruteHit> hits = bruteForceKClosest(mesh, p, 4);
    REQUIRE(indices(hits) == std::vector<TriangleIndex>{0, 3, 1, 2});
    checkHit(hits[0], 0, 1.0, Vec3(1.5, 0.5, 0));
    checkHit(hits[1], 3, 1.25, Vec3(2, 0.5, 0));
    checkHit(hits[2], 1, 1.5, Vec3(1, 1, 0));
    checkHit(hits[3], 2, 4.0, Vec3(1.5, 0.5, 3));
    CHECK(hits[1].feature != Feature::kFace);
    CHECK(indices(bruteForceKClosest(mesh, p, 2)) == std::vector<TriangleIndex>{0, 3});
    CHECK(bruteForceKClosest(mesh, p, 0).empty());
    CHECK(indices(bruteForceKClosest(mesh, p, 10)) == std::vector<TriangleIndex>{0, 3, 1, 2});
  }
  SECTION("ties are ordered by triangle index") {
    // t0 and t1 at 1 (the diagonal), t3 at 2 ((2, 1, 0)), t2 at 4 ((1, 1, 3) on its edge 5-6).
    const std::vector<BruteHit> hits = bruteForceKClosest(mesh, Vec3(1, 1, 1), 4);
    REQUIRE(indices(hits) == std::vector<TriangleIndex>{0, 1, 3, 2});
    checkHit(hits[0], 0, 1.0, Vec3(1, 1, 0));
    checkHit(hits[1], 1, 1.0, Vec3(1, 1, 0));
    checkHit(hits[2], 3, 2.0, Vec3(2, 1, 0));
    checkHit(hits[3], 2, 4.0, Vec3(1, 1, 3));
  }
  SECTION("below the lifted triangle") {
    // t2 at 0.25; t0 and t1 at 6.25 (tie); t3 at (2, 0.5, 0): 2.25 + 6.25.
    const std::vector<BruteHit> hits = bruteForceKClosest(mesh, Vec3(0.5, 0.5, 2.5), 3);
    REQUIRE(indices(hits) == std::vector<TriangleIndex>{2, 0, 1});
    checkHit(hits[1], 0, 6.25, Vec3(0.5, 0.5, 0));
  }
}

TEST_CASE("brute force: within distance", "[brute_force]") {
  const Mesh mesh = squareMesh();
  const Vec3 p(1.5, 0.5, 1);  // distances 1 (t0), sqrt(1.25) (t3), sqrt(1.5) (t1), 2 (t2)
  CHECK(bruteForceWithin(mesh, p, 0.999).empty());
  CHECK(indices(bruteForceWithin(mesh, p, 1.0)) == std::vector<TriangleIndex>{0});
  CHECK(indices(bruteForceWithin(mesh, p, 1.2)) == std::vector<TriangleIndex>{0, 3});
  CHECK(indices(bruteForceWithin(mesh, p, 1.9)) == std::vector<TriangleIndex>{0, 3, 1});
  CHECK(indices(bruteForceWithin(mesh, p, 2.0)) == std::vector<TriangleIndex>{0, 3, 1, 2});
  CHECK(indices(bruteForceWithin(mesh, p, 1e300)) == std::vector<TriangleIndex>{0, 3, 1, 2});
  CHECK(bruteForceWithin(mesh, p, -1.0).empty());

  // Ties by index; a query on the surface is at distance 0 from both halves of the square.
  CHECK(indices(bruteForceWithin(mesh, Vec3(1, 1, 1), 1.0)) == std::vector<TriangleIndex>{0, 1});
  const std::vector<BruteHit> on = bruteForceWithin(mesh, Vec3(1, 1, 0), 0.0);
  REQUIRE(indices(on) == std::vector<TriangleIndex>{0, 1});
  CHECK(on[0].distance == 0.0);
  CHECK(on[1].distance == 0.0);
}

TEST_CASE("brute force: agrees with closestPointOnTriangle on every triangle", "[brute_force]") {
  const Mesh mesh = squareMesh();
  const Vec3 queries[] = {{1.5, 0.5, 1}, {-1, -1, -1}, {3, 3, 3}, {2, 1, 0}, {0.2, 1.9, 1.5}};
  for (const Vec3& p : queries) {
    INFO("p = (" << p.transpose() << ")");
    const std::vector<BruteHit> hits = bruteForceKClosest(mesh, p, mesh.triangles.size());
    REQUIRE(hits.size() == mesh.triangles.size());
    for (const BruteHit& h : hits) {
      const Triangle& t = mesh.triangles[h.triangle];
      const TriangleClosest c = closestPointOnTriangle(p, mesh.positions[t[0]],
                                                       mesh.positions[t[1]], mesh.positions[t[2]]);
      CHECK(h.distance == std::sqrt(c.squared_distance));
      CHECK(h.point == c.point);
      CHECK(h.barycentric == c.barycentric);
      CHECK(h.feature == c.feature);
    }
    for (size_t i = 1; i < hits.size(); ++i) {
      CHECK((hits[i - 1].distance < hits[i].distance ||
             (hits[i - 1].distance == hits[i].distance &&
              hits[i - 1].triangle < hits[i].triangle)));
    }
    CHECK(bruteForceClosest(mesh, p).triangle == hits[0].triangle);
  }
}
