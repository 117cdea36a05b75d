#pragma once
// The reference: every query answered by visiting all triangles. Slow, simple, exact; the oracle
// for tests and a baseline in benchmarks.
#include "core/mesh.h"
#include "core/triangle_distance.h"

#include <vector>

namespace meshsweeper {

struct BruteHit {
  double distance = 0;
  TriangleIndex triangle = kInvalidIndex;
  Vec3 point = Vec3::Zero();
  Vec3 barycentric = Vec3::Zero();
  Feature feature = Feature::kFace;
};

// Closest triangle (lowest index among exact ties). Precondition: mesh has a triangle.
BruteHit bruteForceClosest(const Mesh& mesh, const Vec3& p);
// The k closest triangles, by increasing distance (ties by triangle index); fewer if the mesh
// has fewer triangles.
std::vector<BruteHit> bruteForceKClosest(const Mesh& mesh, const Vec3& p, size_t k);
// Every triangle at distance <= d, by increasing distance (ties by triangle index).
std::vector<BruteHit> bruteForceWithin(const Mesh& mesh, const Vec3& p, double d);

}  // namespace meshsweeper
