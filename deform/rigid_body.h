#pragma once
// A rigid body: a shared hierarchy placed in the world by a pose (rotation + translation).
// Queries transform the point into the body frame, where the hierarchy is untouched
// (paper section 5.2; DESIGN.md section 3): distances are preserved, answers stay exact.
#include "core/sweep_query.h"

#include <Eigen/Geometry>

namespace meshsweeper {

class RigidBody {
 public:
  // Places `hierarchy` at `pose`. Throws std::invalid_argument if the pose is not rigid
  // (rotation not orthonormal with determinant 1, to 1e-9; matrix()'s last row not 0 0 0 1),
  // not finite, or translated beyond 1e150. A rotation off
  // orthonormal by more than rounding (one composed over many steps) is re-orthonormalised:
  // pose() returns the pose the body has, for which every answer is exact.
  explicit RigidBody(std::shared_ptr<const Hierarchy> hierarchy,
                     const Eigen::Isometry3d& pose = Eigen::Isometry3d::Identity());

  // Moves the body. Same checks as the constructor.
  void setPose(const Eigen::Isometry3d& pose);
  const Eigen::Isometry3d& pose() const { return pose_; }
  const std::shared_ptr<const Hierarchy>& hierarchy() const { return hierarchy_; }

  Vec3 toBody(const Vec3& world) const { return inverse_ * world; }
  Vec3 toWorld(const Vec3& body) const { return pose_ * body; }

  // Exact closest point to a world-space point; the result's point is in world space,
  // triangle and barycentric coordinates are the mesh's. `stream` must be on this body's
  // hierarchy. closestCoherent keeps the stream's coherence while body and point move
  // (the point moves by its motion relative to the body). The query runs at toBody(world): a
  // point whose body-frame coordinates pass kMaxQueryCoordinate (1e153, core/types.h) is
  // answered like any point out of range (NaN distance, no triangle), e.g. the world point 1e153
  // with a translation of -1e150 (found by review). Points and translations within the
  // service's range (1e150) never get there.
  ClosestPoint closest(QueryStream& stream, const Vec3& world) const;
  ClosestPoint closestCoherent(QueryStream& stream, const Vec3& world) const;

 private:
  ClosestPoint toWorld(ClosestPoint result) const;
  std::shared_ptr<const Hierarchy> hierarchy_;
  Eigen::Isometry3d pose_;
  Eigen::Isometry3d inverse_;
};

}  // namespace meshsweeper
