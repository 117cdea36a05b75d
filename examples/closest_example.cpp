// The README's library example: the closest point of a mesh to one point.
// Usage: closest_example MESH X Y Z
// Built with the project (tools/CMakeLists.txt) and by the install check (examples/CMakeLists.txt
// through find_package), so it stays in step with the API.
#include "core/mesh_io.h"
#include "core/sweep_query.h"

#include <cstdio>
#include <cstdlib>

int main(int argc, char** argv) {
  using namespace meshsweeper;
  if (argc != 5) {
    std::fprintf(stderr, "usage: closest_example MESH X Y Z\n");
    return 2;
  }
  try {
    const Mesh mesh = readMesh(argv[1]);  // OFF/OBJ/PLY/STL; throws MeshError
    // Built once per mesh, immutable, shareable between threads.
    std::shared_ptr<const Hierarchy> hierarchy = Hierarchy::build(mesh);
    // The per-stream query state: one per thread, reused for every query of that thread.
    QueryStream stream(hierarchy);

    const Vec3 p(std::atof(argv[2]), std::atof(argv[3]), std::atof(argv[4]));
    const ClosestPoint c = stream.closest(p);
    std::printf("distance %.17g, triangle %u, point (%.17g, %.17g, %.17g)\n", c.distance,
                c.triangle, c.point.x(), c.point.y(), c.point.z());
  } catch (const MeshError& e) {
    std::fprintf(stderr, "closest_example: %s\n", e.what());
    return 1;
  }
  return 0;
}
