#pragma once
// Peer libraries wrapped for benchmarks: the same closest-point question answered by Embree 3
// and by CGAL's AABB tree, on the same meshes and points as Meshsweeper. Shared by every
// benchmark in bench/ (closest point, coherent paths, deformation, Hausdorff, service).
//
// Both wrappers are single-threaded and exact in the sense the benchmarks check: the distance
// they return is the double-precision distance to the closest original triangle, as
// bruteForceClosest computes it (up to rounding, relative ~1e-14).
#include <cstdint>
#include <memory>

#include "core/mesh.h"

namespace meshsweeper::bench {

// One closest-point answer from a peer.
struct PeerHit {
  double distance = 0;
  TriangleIndex triangle = kInvalidIndex;  // original face index (file order)
  Vec3 point = Vec3::Zero();
  uint32_t triangles_tested = 0;  // exact point-triangle evaluations (Embree only; CGAL: 0)
};

// The exact kernel the Embree callback runs on each triangle (see peers_embree.cpp).
enum class EmbreeKernel {
  kEricson,      // textbook Voronoi regions; flagged degenerate triangles use kMeshsweeper's
  kMeshsweeper,  // meshsweeper::squaredDistanceToTriangle for every triangle
};

// Embree 3 closest-point queries (rtcPointQuery) over one triangle geometry.
//
// The BVH is Embree's (float vertices, float boxes); the callback computes the exact squared
// distance in double on the original vertices (EmbreeKernel), and the closest point of the
// winning triangle comes from closestPointOnTriangle at the end. Embree culls nodes with
// the float query radius, so the radius the callback writes back is the best double distance
// plus a slack that covers the float rounding of the vertices and of the query point, and a
// relative margin for Embree's float box arithmetic: no node that can hold the true closest
// triangle is ever culled (see the .cpp). The result therefore equals brute force.
class EmbreeClosest {
 public:
  // Creates a device ("threads=1"), a scene with one RTC_GEOMETRY_TYPE_TRIANGLE geometry
  // (float vertex buffer, uint index buffer) and commits it; with kEricson, also flags the
  // triangles that need the robust kernel. Keeps a reference to `mesh`: the mesh must outlive
  // this object. Throws std::runtime_error if Embree reports an error.
  explicit EmbreeClosest(const Mesh& mesh, EmbreeKernel kernel = EmbreeKernel::kEricson);
  ~EmbreeClosest();
  EmbreeClosest(const EmbreeClosest&) = delete;
  EmbreeClosest& operator=(const EmbreeClosest&) = delete;

  // Exact closest point on the mesh to p.
  PeerHit closest(const Vec3& p) const;

  // Largest |float(v) - v| over the mesh's vertices (Euclidean): the slack added to the radius.
  double vertexRoundingError() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// CGAL 5 AABB tree (Simple_cartesian<double>, AABB_triangle_primitive over a triangle vector),
// built with build() and accelerate_distance_queries(); queries with
// closest_point_and_primitive(p). Compiled in its own translation unit (peers_cgal.cpp).
class CgalClosest {
 public:
  // Copies the mesh into a vector of CGAL triangles and builds the tree and its KD-tree of
  // hints. The mesh is not referenced afterwards.
  explicit CgalClosest(const Mesh& mesh);
  ~CgalClosest();
  CgalClosest(const CgalClosest&) = delete;
  CgalClosest& operator=(const CgalClosest&) = delete;

  // Closest point on the mesh to p; distance = |p - point| computed in double.
  PeerHit closest(const Vec3& p) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace meshsweeper::bench
