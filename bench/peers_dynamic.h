#pragma once
// Peers for the dynamic benchmark (bench_dynamic.cpp): the coherent and deforming variants of
// the closest-point question, answered by Embree 3 and CGAL's AABB tree.
//
// - EmbreeWarmClosest: Embree's point query warm-started from the previous answer: the query
//   radius starts at the exact distance to the hint triangle (plus the float slack of
//   EmbreeClosest, peers.h), so only nodes that can hold a closer triangle are visited.
// - EmbreeRefitScene: an Embree scene made for deformation (RTC_SCENE_FLAG_DYNAMIC, scene build
//   quality LOW, geometry build quality REFIT): new vertex positions, then a commit that refits
//   the BVH instead of rebuilding it.
// - CgalHintedClosest: CGAL's AABB tree queried with the previous closest point and primitive as
//   the hint (closest_point_and_primitive(p, hint)); rebuilt for new positions.
//
// Every query here is exact in the sense of peers.h: the returned distance is the double
// distance to the closest original triangle, as bruteForceClosest computes it. The Embree
// callbacks run the same per-triangle kernel as EmbreeClosest's default (EmbreeKernel::kEricson),
// so fresh, warm-started and refitted Embree differ only in what the benchmark compares.
#include "bench/peers.h"
#include "core/mesh.h"

#include <memory>
#include <vector>

namespace meshsweeper::bench {

// Embree closest point with an optional warm start. Same BVH settings as EmbreeClosest
// (default build quality, float vertices); own single-threaded device ("threads=1").
class EmbreeWarmClosest {
 public:
  // Builds the scene; keeps a reference to `mesh`, which must outlive this object.
  // Throws std::runtime_error if Embree reports an error.
  explicit EmbreeWarmClosest(const Mesh& mesh);
  ~EmbreeWarmClosest();
  EmbreeWarmClosest(const EmbreeWarmClosest&) = delete;
  EmbreeWarmClosest& operator=(const EmbreeWarmClosest&) = delete;

  // Exact closest point to p. `hint`: a triangle whose distance starts the search radius (the
  // previous answer of a path), or kInvalidIndex for a cold query.
  PeerHit closest(const Vec3& p, TriangleIndex hint) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// An Embree scene for a deforming mesh: RTC_SCENE_FLAG_DYNAMIC, rtcSetSceneBuildQuality LOW,
// rtcSetGeometryBuildQuality REFIT, so a commit after new vertex positions refits the BVH.
class EmbreeRefitScene {
 public:
  // Copies the mesh (its positions change with setPositions) and commits the first build.
  explicit EmbreeRefitScene(const Mesh& mesh);
  ~EmbreeRefitScene();
  EmbreeRefitScene(const EmbreeRefitScene&) = delete;
  EmbreeRefitScene& operator=(const EmbreeRefitScene&) = delete;

  // Writes new positions (as many as the mesh has) into the float vertex buffer and the double
  // copy the exact callback reads, and marks the buffer updated (rtcUpdateGeometryBuffer).
  // Not the refit: call commit() next.
  void setPositions(const std::vector<Vec3>& positions);
  // rtcCommitGeometry + rtcCommitScene: the refit. Throws std::runtime_error on an Embree error.
  void commit();

  // Exact closest point on the mesh at its current (committed) positions.
  PeerHit closest(const Vec3& p) const;
  const Mesh& mesh() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// CGAL AABB tree (as CgalClosest) with hinted queries and rebuilds for new positions.
class CgalHintedClosest {
 public:
  explicit CgalHintedClosest(const Mesh& mesh);
  ~CgalHintedClosest();
  CgalHintedClosest(const CgalHintedClosest&) = delete;
  CgalHintedClosest& operator=(const CgalHintedClosest&) = delete;

  // Cold query: CGAL picks its own hint (the KD-tree of accelerate_distance_queries()).
  PeerHit closest(const Vec3& p) const;
  // Warm query: closest_point_and_primitive(p, hint) with hint = (hint.point, hint.triangle),
  // a previous answer.
  PeerHit closest(const Vec3& p, const PeerHit& hint) const;

  // New positions (as many as the mesh has): refills the triangles, tree.rebuild() and
  // accelerate_distance_queries(), as a user of a deforming mesh would.
  void rebuild(const std::vector<Vec3>& positions);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace meshsweeper::bench
