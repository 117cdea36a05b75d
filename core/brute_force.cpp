// Brute force: closestPointOnTriangle on every triangle, then sort or filter. The reference for
// tests and the baseline for benchmarks; no acceleration, no allocation tricks.
#include "core/brute_force.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace meshsweeper {
namespace {

BruteHit hitFor(const Mesh& mesh, TriangleIndex t, const Vec3& p) {
  const Triangle& tri = mesh.triangles[t];
  const TriangleClosest c =
      closestPointOnTriangle(p, mesh.positions[tri[0]], mesh.positions[tri[1]],
                             mesh.positions[tri[2]]);
  BruteHit hit;
  hit.distance = std::sqrt(c.squared_distance);
  hit.triangle = t;
  hit.point = c.point;
  hit.barycentric = c.barycentric;
  hit.feature = c.feature;
  return hit;
}

// Increasing distance, ties by triangle index.
bool closerThan(const BruteHit& x, const BruteHit& y) {
  return x.distance < y.distance || (x.distance == y.distance && x.triangle < y.triangle);
}

}  // namespace

BruteHit bruteForceClosest(const Mesh& mesh, const Vec3& p) {
  assert(!mesh.triangles.empty() && "bruteForceClosest: the mesh has no triangle");
  BruteHit best = hitFor(mesh, 0, p);
  const TriangleIndex n = static_cast<TriangleIndex>(mesh.triangles.size());
  for (TriangleIndex t = 1; t < n; ++t) {
    const BruteHit hit = hitFor(mesh, t, p);
    if (hit.distance < best.distance) best = hit;
  }
  return best;
}

std::vector<BruteHit> bruteForceKClosest(const Mesh& mesh, const Vec3& p, size_t k) {
  const TriangleIndex n = static_cast<TriangleIndex>(mesh.triangles.size());
  std::vector<BruteHit> hits;
  hits.reserve(n);
  for (TriangleIndex t = 0; t < n; ++t) hits.push_back(hitFor(mesh, t, p));
  const size_t keep = std::min(k, hits.size());
  std::partial_sort(hits.begin(), hits.begin() + keep, hits.end(), closerThan);
  hits.resize(keep);
  return hits;
}

std::vector<BruteHit> bruteForceWithin(const Mesh& mesh, const Vec3& p, double d) {
  const TriangleIndex n = static_cast<TriangleIndex>(mesh.triangles.size());
  std::vector<BruteHit> hits;
  for (TriangleIndex t = 0; t < n; ++t) {
    BruteHit hit = hitFor(mesh, t, p);
    if (hit.distance <= d) hits.push_back(hit);
  }
  std::sort(hits.begin(), hits.end(), closerThan);
  return hits;
}

}  // namespace meshsweeper
