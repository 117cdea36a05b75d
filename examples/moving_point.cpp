// A moving query point: one QueryStream follows the point and reuses its work between steps.
// Usage: moving_point_example MESH [STEPS]
// The point circles the mesh at 60% of half its bounding-box diagonal from the centre;
// closestCoherent answers every step exactly (the same answer as closest()) and is cheapest
// when consecutive points are close. Built with the project (tools/CMakeLists.txt) and by the
// install check (examples/CMakeLists.txt).
#include "core/mesh_io.h"
#include "core/sweep_query.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

int main(int argc, char** argv) {
  using namespace meshsweeper;
  if (argc < 2 || argc > 3) {
    std::fprintf(stderr, "usage: moving_point_example MESH [STEPS]\n");
    return 2;
  }
  try {
    const Mesh mesh = readMesh(argv[1]);
    const int steps = argc == 3 ? std::atoi(argv[2]) : 2000;
    std::shared_ptr<const Hierarchy> hierarchy = Hierarchy::build(mesh);
    QueryStream stream(hierarchy);  // one stream per moving point (and per thread)
    QueryStream fresh(hierarchy);   // for comparison only

    Vec3 lower, upper;
    meshBounds(mesh, lower, upper);
    const Vec3 centre = 0.5 * (lower + upper);
    const double radius = 0.3 * (upper - lower).norm();
    double worst_difference = 0;
    for (int i = 0; i < steps; ++i) {
      const double angle = 2 * 3.14159265358979323846 * i / steps;
      const Vec3 p = centre + radius * Vec3(std::cos(angle), std::sin(angle), 0.1 * std::sin(3 * angle));
      const ClosestPoint c = stream.closestCoherent(p);  // exact, warm from the previous step
      if (i % (steps / 4 > 0 ? steps / 4 : 1) == 0)
        std::printf("step %d: distance %.9g, triangle %u, point (%.6g, %.6g, %.6g)\n", i, c.distance, c.triangle,
                    c.point.x(), c.point.y(), c.point.z());
      worst_difference = std::max(worst_difference, std::abs(fresh.closest(p).distance - c.distance));
    }
    const CoherenceCounters& counters = stream.coherence();
    std::printf("%llu steps: %llu answered from the cached candidate set, %llu sets gathered anew, "
                "%llu plain searches; largest difference from a fresh query %.3g\n",
                static_cast<unsigned long long>(counters.steps), static_cast<unsigned long long>(counters.certified),
                static_cast<unsigned long long>(counters.rebuilds), static_cast<unsigned long long>(counters.searched),
                worst_difference);
  } catch (const MeshError& e) {
    std::fprintf(stderr, "moving_point_example: %s\n", e.what());
    return 1;
  }
  return 0;
}
