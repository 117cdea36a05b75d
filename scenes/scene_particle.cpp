// Scene "particle": the paper's Fig. 6, a particle falling onto a torus. The particle's
// closest point is followed with the dynamic front (QueryStream::closestWithinCoherent, exact:
// tolerance 0) along the whole fall; four frames of the fall are drawn side by side: the torus,
// the particle, its closest point joined to it by a line, and the front itself: coarse slot
// triangles as wireframe, original faces it reached in orange (QueryStream::frontTriangles).
// The number of faces within 1.2 times the distance (the region to refine) is printed.
#include "core/sweep_query.h"
#include "scenes/procedural.h"
#include "scenes/render.h"
#include "scenes/scene_demos.h"

#include <chrono>
#include <cmath>

namespace meshsweeper::scenes {

std::string particleScene(const std::string& out_dir, std::FILE* log) {
  using Clock = std::chrono::steady_clock;
  const Mesh mesh = torus(1.0, 0.4, 64, 32);
  const auto hierarchy = Hierarchy::build(mesh);
  QueryStream stream(hierarchy);

  // Straight down onto the top of the tube, slightly off its crest.
  const Vec3 start(0.95, 0.2, 1.7), end(0.95, 0.2, 0.42);
  const int steps = 400;
  const int frames[4] = {0, 200, 330, 385};
  const int panel = 400, title_height = 40, caption_height = 76;
  Image canvas(4 * panel, panel + title_height + caption_height);
  std::vector<TriangleHit> near;
  std::vector<FrontTriangle> front;
  double query_seconds = 0;
  int frame = 0;
  std::fprintf(log, "particle: torus %zu triangles, %d steps of the fall\n", mesh.triangles.size(),
               steps);
  std::fprintf(log, "particle: %6s %10s %8s %12s %12s\n", "step", "distance", "front", "within 1.2d",
               "tested");
  for (int step = 0; step <= steps; ++step) {
    const Vec3 p = start + (end - start) * (static_cast<double>(step) / steps);
    const auto t0 = Clock::now();
    const ClosestPoint c = stream.closestWithinCoherent(p, 0);
    query_seconds += std::chrono::duration<double>(Clock::now() - t0).count();
    if (step != frames[frame]) continue;

    stream.within(p, 1.2 * c.distance, near);
    stream.frontTriangles(front);
    size_t front_faces = 0;
    for (const FrontTriangle& t : front) front_faces += t.face ? 1 : 0;
    std::fprintf(log, "particle: %6d %10.4f %8zu %12zu %12u\n", step, c.distance,
                 stream.frontSize(), near.size(), c.counters.triangles_tested);

    Image view(panel, panel);
    const Camera camera = Camera::framing(Vec3(0.35, 0, 0.55), 1.55, Vec3(0.35, -1.0, 0.55),
                                          Vec3::UnitZ(), panel, panel, 35);
    // The front itself (the paper's refined mesh) over a pale torus: coarse slot triangles as
    // blue wireframe, the original faces the front has reached in orange.
    // The orange faces go first: the torus's own copy of each, drawn after at the same depth,
    // then fails the depth test everywhere (drawn the other way round, depth ties left the
    // orange speckled with grey, found by an audit).
    const Colour pale(0.9, 0.9, 0.92), orange(1.0, 0.55, 0.1), edge(0.25, 0.3, 0.55);
    for (const FrontTriangle& t : front) {
      if (!t.face) continue;
      const Vec3& a = mesh.positions[t.corners[0]];
      const Vec3& b = mesh.positions[t.corners[1]];
      const Vec3& d = mesh.positions[t.corners[2]];
      view.drawTriangle(camera, a, b, d, orange, orange, orange);
    }
    for (const Triangle& tri : mesh.triangles)
      view.drawTriangle(camera, mesh.positions[tri[0]], mesh.positions[tri[1]], mesh.positions[tri[2]],
                        pale, pale, pale);
    for (const FrontTriangle& t : front) {
      if (t.face) continue;
      const Vec3& a = mesh.positions[t.corners[0]];
      const Vec3& b = mesh.positions[t.corners[1]];
      const Vec3& d = mesh.positions[t.corners[2]];
      view.drawLine(camera, a, b, edge, 1);
      view.drawLine(camera, b, d, edge, 1);
      view.drawLine(camera, d, a, edge, 1);
    }
    view.drawLine(camera, start, p, Colour(0.6, 0.6, 0.6), 1);
    view.drawLine(camera, p, c.point, Colour(0.1, 0.1, 0.1), 2);
    view.drawDisc(camera, c.point, 5, Colour(0.1, 0.3, 1.0));
    view.drawSphere(camera, p, 0.05, Colour(0.85, 0.1, 0.1));
    canvas.paste(view, frame * panel, title_height);
    char caption[160];
    std::snprintf(caption, sizeof caption, "step %d: distance %.3f\nfront: %zu entries, %zu faces\nfaces within 1.2 d: %zu",
                  step, c.distance, stream.frontSize(), front_faces, near.size());
    canvas.drawText(frame * panel + 12, title_height + panel + 4, caption, Colour(0, 0, 0), 2);
    if (frame > 0) canvas.fillRect(frame * panel, title_height, frame * panel + 1, title_height + panel,
                                   Colour(0.6, 0.6, 0.6));
    ++frame;
    if (frame == 4) break;
  }
  const CoherenceCounters& coherence = stream.coherence();
  std::fprintf(log, "particle: %llu coherent queries in %.3f ms (%.2f us each), %llu front resets, "
               "%llu stale entries recomputed\n",
               static_cast<unsigned long long>(coherence.steps), 1e3 * query_seconds,
               1e6 * query_seconds / std::max<uint64_t>(1, coherence.steps),
               static_cast<unsigned long long>(coherence.front_resets),
               static_cast<unsigned long long>(coherence.recomputed));
  canvas.drawText(12, 8,
                  "Particle falling onto a torus (paper Fig. 6): the dynamic front (blue wireframe: "
                  "coarse triangles, orange: original faces), closest point (blue dot)",
                  Colour(0, 0, 0), 2);
  const std::string path = out_dir + "/particle.png";
  canvas.writePng(path);
  return path;
}

}  // namespace meshsweeper::scenes
