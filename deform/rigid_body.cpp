#include "deform/rigid_body.h"

#include <cassert>
#include <stdexcept>

namespace meshsweeper {

RigidBody::RigidBody(std::shared_ptr<const Hierarchy> hierarchy, const Eigen::Isometry3d& pose)
    : hierarchy_(std::move(hierarchy)) {
  setPose(pose);
}

void RigidBody::setPose(const Eigen::Isometry3d& pose) {
  const Eigen::Matrix3d r = pose.linear();
  if (!pose.matrix().allFinite())
    throw std::invalid_argument("RigidBody: the pose has a non-finite entry");
  if (!inCoordinateRange(pose.translation()))
    throw std::invalid_argument("RigidBody: the pose's translation is beyond 1e150 in magnitude");
  // Queries map points by the inverse isometry (R^T): a rotation off orthonormal by e moves a
  // world answer by about e times the point's distance from the body's origin, so only the
  // rounding of a computed rotation is accepted.
  if (!(r.transpose() * r).isIdentity(1e-12) || std::abs(r.determinant() - 1) > 1e-12)
    throw std::invalid_argument(
        "RigidBody: the pose's rotation is not orthonormal to 1e-12 (a rigid pose has no scale or shear; "
        "re-orthonormalise a rotation composed over many steps, e.g. through a normalised quaternion)");
  pose_ = pose;
  inverse_ = pose.inverse(Eigen::Isometry);
}

ClosestPoint RigidBody::toWorld(ClosestPoint result) const {
  result.point = pose_ * result.point;
  return result;
}

ClosestPoint RigidBody::closest(QueryStream& stream, const Vec3& world) const {
  assert(&stream.hierarchy() == hierarchy_.get());
  return toWorld(stream.closest(toBody(world)));
}

ClosestPoint RigidBody::closestCoherent(QueryStream& stream, const Vec3& world) const {
  assert(&stream.hierarchy() == hierarchy_.get());
  return toWorld(stream.closestCoherent(toBody(world)));
}

}  // namespace meshsweeper
