// Deforming bodies: the hierarchy is built once on the rest mesh; per frame only bounds change.
// Usage: deforming_body_example MESH [FRAMES]
//  1. KeyframeBody: positions interpolated between key frames (here the rest mesh and a
//     stretched, bent copy); setTime(t) updates positions and proven bounds.
//  2. DeformingBody: any motion, as long as each vertex stays within a displacement bound of
//     its anchor position; a step past a bound is refused, and the caller re-anchors.
// Queries go through a QueryStream that reads the body's geometry. Built with the project
// (tools/CMakeLists.txt) and by the install check (examples/).
#include "core/mesh_io.h"
#include "core/sweep_query.h"
#include "deform/inflated_bounds.h"
#include "deform/keyframe_bounds.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

int main(int argc, char** argv) {
  using namespace meshsweeper;
  if (argc < 2 || argc > 3) {
    std::fprintf(stderr, "usage: deforming_body_example MESH [FRAMES]\n");
    return 2;
  }
  try {
    const Mesh mesh = readMesh(argv[1]);
    const int frames = argc == 3 ? std::atoi(argv[2]) : 100;
    auto hierarchy = Hierarchy::build(mesh);
    Vec3 lower, upper;
    meshBounds(mesh, lower, upper);
    const Vec3 centre = 0.5 * (lower + upper);
    const double diagonal = (upper - lower).norm();
    const Vec3 p = centre + Vec3(0, 0, 0.6 * diagonal);  // a fixed query point

    // The same smooth deformation of every vertex, by an amount s in [0, 1].
    auto deformed = [&](double s) {
      std::vector<Vec3> out = mesh.positions;
      for (Vec3& x : out) {
        const double h = (x.z() - centre.z()) / diagonal;
        x.z() += s * 0.2 * (x.z() - centre.z());              // stretch along z
        x.x() += s * 0.1 * diagonal * std::sin(3.0 * h);      // bend
      }
      return out;
    };

    // 1. Key frames: rest and fully deformed; t in [0, 1] interpolates between them.
    KeyframeBody keyframes(hierarchy, {mesh.positions, deformed(1.0)});
    QueryStream stream(hierarchy);
    stream.setGeometry(&keyframes.geometry());
    for (int f = 0; f <= frames; ++f) {
      keyframes.setTime(static_cast<double>(f) / frames);  // per-frame cost: no rebuild
      const ClosestPoint c = stream.closestCoherent(p);
      if (f % (frames / 4 > 0 ? frames / 4 : 1) == 0)
        std::printf("key frames, t = %.2f: distance %.9g, triangle %u\n", keyframes.time(), c.distance, c.triangle);
    }

    // 2. Displacement bounds: every vertex may move up to 5% of the diagonal from its anchor.
    DeformingBody body(hierarchy);
    body.inflate(0.05 * diagonal);
    QueryStream body_stream(hierarchy);
    body_stream.setGeometry(&body.geometry());
    int anchors = 0;
    for (int f = 0; f <= frames; ++f) {
      const std::vector<Vec3> positions = deformed(static_cast<double>(f) / frames);
      if (!body.setPositions(positions).accepted) {  // moved past a bound: nothing changed
        body.reanchor(positions);                    // exact bounds at the new positions (the
                                                     // motion continues: coherent state kept) ...
        body.inflate(0.05 * diagonal);               // ... and room to move again
        ++anchors;
      }
      const ClosestPoint c = body_stream.closestCoherent(p);
      if (f % (frames / 4 > 0 ? frames / 4 : 1) == 0)
        std::printf("displacement bounds, frame %d: distance %.9g, triangle %u\n", f, c.distance, c.triangle);
    }
    std::printf("re-anchored %d times in %d frames\n", anchors, frames + 1);
  } catch (const MeshError& e) {
    std::fprintf(stderr, "deforming_body_example: %s\n", e.what());
    return 1;
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "deforming_body_example: %s\n", e.what());
    return 1;
  }
  return 0;
}
