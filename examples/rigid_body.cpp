// A moving rigid body: the hierarchy stays in the body's frame, a pose places it in the world,
// and queries take world-space points. Usage: rigid_body_example MESH [STEPS]
// The body spins about the z axis and drifts along x while a world point stays still; the
// stream keeps its coherence because the point moves little in the body's frame.
// Built with the project (tools/CMakeLists.txt) and by the install check (examples/).
#include "core/mesh_io.h"
#include "deform/rigid_body.h"

#include <Eigen/Geometry>

#include <cstdio>
#include <cstdlib>
#include <stdexcept>

int main(int argc, char** argv) {
  using namespace meshsweeper;
  if (argc < 2 || argc > 3) {
    std::fprintf(stderr, "usage: rigid_body_example MESH [STEPS]\n");
    return 2;
  }
  try {
    const Mesh mesh = readMesh(argv[1]);
    const int steps = argc == 3 ? std::atoi(argv[2]) : 1000;
    auto hierarchy = Hierarchy::build(mesh);
    RigidBody body(hierarchy);      // pose: identity
    QueryStream stream(hierarchy);  // the stream's state is in the body's frame

    Vec3 lower, upper;
    meshBounds(mesh, lower, upper);
    const double diagonal = (upper - lower).norm();
    const Vec3 world_point = 0.5 * (lower + upper) + Vec3(0.4 * diagonal, 0, 0);
    for (int i = 0; i < steps; ++i) {
      Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
      pose.linear() = Eigen::AngleAxisd(0.002 * i, Vec3::UnitZ()).toRotationMatrix();
      pose.translation() = Vec3(0.0001 * diagonal * i, 0, 0);
      body.setPose(pose);  // throws std::invalid_argument for a pose with scale or shear
      const ClosestPoint c = body.closestCoherent(stream, world_point);  // c.point in world space
      if (i % (steps / 4 > 0 ? steps / 4 : 1) == 0)
        std::printf("step %d: distance %.9g, triangle %u, world point (%.6g, %.6g, %.6g)\n", i, c.distance,
                    c.triangle, c.point.x(), c.point.y(), c.point.z());
    }
    std::printf("%llu steps, %llu from the cached candidate set\n",
                static_cast<unsigned long long>(stream.coherence().steps),
                static_cast<unsigned long long>(stream.coherence().certified));
  } catch (const MeshError& e) {
    std::fprintf(stderr, "rigid_body_example: %s\n", e.what());
    return 1;
  }
  return 0;
}
