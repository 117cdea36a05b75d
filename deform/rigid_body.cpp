#include "deform/rigid_body.h"

#include <cassert>
#include <stdexcept>

namespace meshsweeper {

RigidBody::RigidBody(std::shared_ptr<const Hierarchy> hierarchy, const Eigen::Isometry3d& pose)
    : hierarchy_(std::move(hierarchy)) {
  if (!hierarchy_) throw std::invalid_argument("RigidBody: null hierarchy");
  setPose(pose);
}

void RigidBody::setPose(const Eigen::Isometry3d& pose) {
  const Eigen::Matrix3d r = pose.linear();
  if (!pose.matrix().allFinite())
    throw std::invalid_argument("RigidBody: the pose has a non-finite entry");
  // Eigen keeps the fourth row of an Isometry3d without reading it; one set to something else
  // (through matrix()) would make pose().matrix() no rigid transform (found by an audit).
  if (pose.matrix().row(3) != Eigen::RowVector4d(0, 0, 0, 1))
    throw std::invalid_argument("RigidBody: the pose's last row is not (0, 0, 0, 1)");
  if (!inCoordinateRange(pose.translation()))
    throw std::invalid_argument("RigidBody: the pose's translation is beyond 1e150 in magnitude");
  // A rotation composed over many steps drifts from orthonormal (R = R * dR: 1e-12 after some
  // 15,000 steps), and a scale or shear is no rigid pose. Up to 1e-9 the body is placed at the
  // rotation re-orthonormalised (through a normalised quaternion: pose() returns it), so that
  // answers stay exact for the pose the body has; beyond, the pose is refused.
  const Eigen::Matrix3d gram = r.transpose() * r;
  if (!gram.isIdentity(1e-9))
    throw std::invalid_argument(
        "RigidBody: the pose's rotation is not orthonormal to 1e-9 (a rigid pose has no scale or shear)");
  // Orthonormal to 1e-9, its determinant is within 2e-9 of 1 or of -1: the sign tells (a test
  // of det - 1 to 1e-9 refused a rotation scaled by 1 + 4e-10, which the test above accepts, as
  // a reflection; found by an audit).
  if (r.determinant() < 0)
    throw std::invalid_argument(
        "RigidBody: the pose's rotation is a reflection (determinant -1): a rigid pose turns, it does not mirror "
        "(mirror the mesh itself instead)");
  pose_ = pose;
  if (!gram.isIdentity(1e-15))
    pose_.linear() = Eigen::Quaterniond(r).normalized().toRotationMatrix();
  inverse_ = pose_.inverse(Eigen::Isometry);
}

ClosestPoint RigidBody::toWorld(ClosestPoint result) const {
  result.point = pose_ * result.point;
  return result;
}

namespace {
void checkStream(const QueryStream& stream, const Hierarchy* hierarchy) {
  if (&stream.hierarchy() != hierarchy)
    throw std::invalid_argument("RigidBody: the query stream is built on another hierarchy than the body's");
}
}  // namespace

ClosestPoint RigidBody::closest(QueryStream& stream, const Vec3& world) const {
  checkStream(stream, hierarchy_.get());
  return toWorld(stream.closest(toBody(world)));
}

ClosestPoint RigidBody::closestCoherent(QueryStream& stream, const Vec3& world) const {
  checkStream(stream, hierarchy_.get());
  return toWorld(stream.closestCoherent(toBody(world)));
}

}  // namespace meshsweeper
