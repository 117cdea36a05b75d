// The distance-query service: a cloth-like sheet of points moving over several bodies, step by
// step, with the closest hit of every point within a distance (signed for closed bodies).
// Usage: service_example MESH [STEPS]
// Two rigid copies of MESH share one hierarchy; a third copy deforms freely. Every step moves the
// bodies, moves the sheet down a little and asks for the closest hit within 2% of the diagonal.
// Built with the project (tools/CMakeLists.txt) and by the install check (examples/CMakeLists.txt
// through find_package), so it stays in step with the API.
#include "collision/distance_service.h"
#include "core/mesh_io.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <stdexcept>

int main(int argc, char** argv) {
  using namespace meshsweeper;
  if (argc < 2 || argc > 3) {
    std::fprintf(stderr, "usage: service_example MESH [STEPS]\n");
    return 2;
  }
  // STEPS is checked whole: atoi would read "abc" or "-3" as 0 or less and run no step at all.
  int steps = 20;
  if (argc == 3) {
    const char* text = argv[2];
    char* end = nullptr;
    errno = 0;
    const long long value = std::strtoll(text, &end, 10);
    if (!std::isdigit(static_cast<unsigned char>(text[0])) || *end != '\0' || errno == ERANGE ||
        value < 1 || value > std::numeric_limits<int>::max()) {
      std::fprintf(stderr, "service_example: STEPS must be a positive integer (got '%s')\n", text);
      return 2;
    }
    steps = static_cast<int>(value);
  }
  try {
    const Mesh mesh = readMesh(argv[1]);
    Vec3 lower, upper;
    meshBounds(mesh, lower, upper);
    const double diagonal = (upper - lower).norm();
    const Vec3 size = upper - lower;

    DistanceService service;  // threads: TBB's default; service.setThreads(n) to change
    // One hierarchy (built once, cached by the mesh's address and contents) for every body of this mesh.
    std::shared_ptr<const Hierarchy> hierarchy = service.hierarchyFor(mesh);
    Eigen::Isometry3d left = Eigen::Isometry3d::Identity(), right = Eigen::Isometry3d::Identity();
    left.translation() = Vec3(-0.6 * size.x(), 0, 0);
    right.translation() = Vec3(0.6 * size.x(), 0, 0);
    const BodyHandle a = service.addRigid(hierarchy, left);
    const BodyHandle b = service.addRigid(hierarchy, right);
    // Vertices may move 0.5% of the diagonal before the body re-anchors (automatically).
    const BodyHandle soft = service.addDeforming(hierarchy, 0.005 * diagonal);

    // A 100 x 100 sheet above the bodies.
    const int n = 100;
    PointMatrix sheet(n * n, 3);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j)
        sheet.row(i * n + j) << lower.x() - 0.8 * size.x() + 2.6 * size.x() * j / (n - 1),
            lower.y() + size.y() * i / (n - 1), upper.z() + 0.02 * diagonal;

    StepResult result;  // reused: no allocation once warm
    for (int step = 0; step < steps; ++step) {
      Eigen::Isometry3d pose = left;
      pose.linear() = Eigen::AngleAxisd(0.01 * step, Vec3::UnitZ()).toRotationMatrix();
      service.setPose(a, pose);
      Eigen::Isometry3d slide = right;
      slide.translation().y() += 0.001 * diagonal * step;
      service.setPose(b, slide);
      std::vector<Vec3> positions = mesh.positions;
      for (Vec3& x : positions) x.z() += 0.001 * diagonal * std::sin(0.3 * step + x.x() / diagonal);
      const PositionsUpdate update = service.setPositions(soft, positions);
      sheet.col(2).array() -= 0.002 * diagonal;  // the sheet falls

      service.step(sheet, 0.02 * diagonal, QueryMode::kClosest, result);
      size_t hits = 0, inside = 0;
      double nearest = 0.02 * diagonal;
      for (size_t i = 0; i < result.size(); ++i) {
        const DistanceHit* hit = result.closest(i);
        if (!hit) continue;
        ++hits;
        inside += hit->sign == HitSign::kInside;
        nearest = std::min(nearest, hit->signed_distance);
      }
      const StepStats& s = result.stats();
      std::printf("step %2d: %zu of %zu points within reach, %zu inside a body, nearest signed distance %.4g; "
                  "pairs %llu (certified %llu)%s, %.2f ms\n",
                  step, hits, result.size(), inside, nearest, static_cast<unsigned long long>(s.pairs),
                  static_cast<unsigned long long>(s.certified_pairs), update.reanchored ? ", re-anchored" : "",
                  1e3 * (s.bounds_seconds + s.query_seconds));
    }
  } catch (const MeshError& e) {
    std::fprintf(stderr, "service_example: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "service_example: %s\n", e.what());
    return 1;
  }
  return 0;
}
