// Scene "cloth": a sheet of cloth points falls onto a key-framed body (an icosphere that swells
// into an egg between two key frames) standing on a floor, and drapes over it. Every step the
// points are queried through the distance service (collision/distance_service.h, closest
// mode, coherent states carried between steps) and the ones closer than the cloth thickness,
// or inside the body, are projected out along the direction away from their closest point.
// The cloth itself is Verlet particles with distance constraints between grid neighbours
// (position-based dynamics, 20 Gauss-Seidel sweeps): just enough to look like cloth; it is
// not a simulator (no bending, no self-collision).
#include "collision/distance_service.h"
#include "scenes/procedural.h"
#include "scenes/render.h"
#include "scenes/scene_demos.h"

#include <chrono>
#include <cmath>

namespace meshsweeper::scenes {

std::string clothScene(const std::string& out_dir, std::FILE* log) {
  using Clock = std::chrono::steady_clock;
  // The body: key frame 0 a sphere of radius 0.5, key frame 1 an egg, taller and wider.
  const Mesh body = icosphere(4, 0.5);
  std::vector<std::vector<Vec3>> frames(2, body.positions);
  for (Vec3& p : frames[1]) {
    const double up = std::max(0.0, p.z() / 0.5);
    p = Vec3(1.15 * p.x(), 0.95 * p.y(), p.z() * (1.0 + 0.5 * up * up));
  }
  ServiceOptions options;
  options.threads = 1;
  DistanceService service(options);
  const auto hierarchy = Hierarchy::build(body);
  const BodyHandle handle = service.addKeyframed(hierarchy, frames, 0);

  // The cloth: n x n points, spacing `rest`, starting flat above the body.
  const int cells = 47, n = cells + 1;
  const double size = 2.4, rest = size / cells, thickness = 0.02, query_distance = 0.1;
  const double floor = -0.5;  // the body stands on the floor z = -0.5
  Mesh cloth = gridPlane(cells, size);
  // Off to one side, so that it slides off the body on that side and the body stays visible.
  for (Vec3& p : cloth.positions) p = Vec3(p.x() + 0.6, p.y() - 0.03, 0.85);
  std::vector<Vec3> previous = cloth.positions;
  PointMatrix points(cloth.positions.size(), 3);
  StepResult result;

  const int steps = 300, swell_steps = 150;
  const double dt = 1.0 / 120, damping = 0.995;
  const Vec3 gravity(0, 0, -9.8);
  double total_ms = 0, worst_ms = 0;
  std::fprintf(log, "cloth: body %zu triangles (2 key frames), cloth %zu points, %d steps\n",
               body.triangles.size(), cloth.positions.size(), steps);
  std::fprintf(log, "cloth: %6s %8s %8s %8s %8s %10s\n", "step", "points", "pairs", "hits",
               "pushed", "query ms");
  for (int step = 0; step < steps; ++step) {
    service.setTime(handle, std::min(1.0, static_cast<double>(step) / swell_steps));
    // Verlet integration.
    for (size_t i = 0; i < cloth.positions.size(); ++i) {
      Vec3& p = cloth.positions[i];
      const Vec3 velocity = (p - previous[i]) * damping;
      previous[i] = p;
      p += velocity + gravity * dt * dt;
    }
    // Distance constraints between horizontal and vertical neighbours.
    for (int sweep = 0; sweep < 20; ++sweep) {
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
          const int v = i * n + j;
          for (int w : {j + 1 < n ? v + 1 : -1, i + 1 < n ? v + n : -1}) {
            if (w < 0) continue;
            const Vec3 d = cloth.positions[w] - cloth.positions[v];
            const double length = d.norm();
            if (!(length > 0)) continue;
            const Vec3 fix = 0.5 * (length - rest) / length * d;
            cloth.positions[v] += fix;
            cloth.positions[w] -= fix;
          }
        }
      }
    }
    // Collision: query every point, push the close ones out to the thickness.
    for (size_t i = 0; i < cloth.positions.size(); ++i) points.row(i) = cloth.positions[i].transpose();
    const auto t0 = Clock::now();
    service.step(points, query_distance, QueryMode::kClosest, result);
    const double ms = 1e3 * std::chrono::duration<double>(Clock::now() - t0).count();
    total_ms += ms;
    worst_ms = std::max(worst_ms, ms);
    size_t pushed = 0;
    for (size_t i = 0; i < cloth.positions.size(); ++i) {
      const DistanceHit* hit = result.closest(i);
      if (!hit) continue;
      const bool inside = hit->sign == HitSign::kInside;
      if (!inside && hit->distance >= thickness) continue;
      const Vec3 outward = inside ? Vec3(-hit->direction) : hit->direction;
      cloth.positions[i] = hit->point + thickness * outward;
      previous[i] = cloth.positions[i];  // friction: the point sticks where it touched
      ++pushed;
    }
    for (size_t i = 0; i < cloth.positions.size(); ++i) {
      if (cloth.positions[i].z() >= floor + thickness) continue;
      cloth.positions[i].z() = floor + thickness;
      previous[i] = cloth.positions[i];
    }
    if (step % 25 == 0 || step == steps - 1)
      std::fprintf(log, "cloth: %6d %8llu %8llu %8llu %8zu %10.3f\n", step,
                   static_cast<unsigned long long>(result.stats().points),
                   static_cast<unsigned long long>(result.stats().pairs),
                   static_cast<unsigned long long>(result.stats().hits), pushed, ms);
  }
  std::fprintf(log, "cloth: %d steps, query time %.1f ms in all, %.3f ms per step (worst %.3f), "
               "%.0f ns per point\n", steps, total_ms, total_ms / steps, worst_ms,
               1e6 * total_ms / (static_cast<double>(steps) * cloth.positions.size()));

  // Final frame: the body at its last key-frame time, cloth coloured by distance to it.
  std::vector<Vec3> body_positions(body.positions.size());
  for (size_t v = 0; v < body_positions.size(); ++v) body_positions[v] = frames[1][v];
  // Coloured at the positions drawn: one more query (untimed) after the last push-out.
  for (size_t i = 0; i < cloth.positions.size(); ++i) points.row(i) = cloth.positions[i].transpose();
  service.step(points, query_distance, QueryMode::kClosest, result);
  std::vector<Colour> colours(cloth.positions.size());
  for (size_t i = 0; i < cloth.positions.size(); ++i) {
    const DistanceHit* hit = result.closest(i);
    colours[i] = rampColour(hit ? hit->distance / query_distance : 1.0);
  }
  const int width = 900, height = 760, title_height = 44;
  Image canvas(width, height);
  Image view(width - 150, height - title_height);
  const Camera camera = Camera::framing(Vec3(0.45, 0, -0.15), 1.75, Vec3(-0.6, -1.5, 0.75), Vec3::UnitZ(),
                                        view.width(), view.height(), 35);
  // The floor: a light checkerboard.
  const Mesh floor_mesh = gridPlane(10, 3.6);
  for (size_t t = 0; t < floor_mesh.triangles.size(); ++t) {
    const size_t cell = t / 2, row = cell / 10, column = cell % 10;
    const Colour colour = (row + column) % 2 ? Colour(0.95, 0.95, 0.93) : Colour(0.86, 0.86, 0.84);
    const Vec3 lift(0.45, 0, floor);
    const Triangle& tri = floor_mesh.triangles[t];
    view.drawTriangle(camera, floor_mesh.positions[tri[0]] + lift, floor_mesh.positions[tri[1]] + lift,
                      floor_mesh.positions[tri[2]] + lift, colour, colour, colour, 0.85);
  }
  view.drawMesh(camera, body, body_positions, {}, Colour(0.75, 0.75, 0.8));
  view.drawMesh(camera, cloth, {}, colours, Colour(), 0.35);
  for (size_t i = 0; i < cloth.positions.size(); ++i)
    view.drawDisc(camera, cloth.positions[i], 1.2, 0.6 * colours[i]);
  canvas.paste(view, 0, title_height);
  char title[200];
  std::snprintf(title, sizeof title,
                "Cloth (%zu points) on a key-framed body, %d steps: queries %.2f ms/step",
                cloth.positions.size(), steps, total_ms / steps);
  canvas.drawText(10, 10, title, Colour(0, 0, 0), 2);
  char top[32];
  std::snprintf(top, sizeof top, ">= %.2f", query_distance);
  canvas.drawColourBar(width - 120, title_height + 60, width - 90, height - 80, "0", top, 2);
  canvas.drawText(width - 140, title_height + 20, "distance", Colour(0, 0, 0), 2);
  const std::string path = out_dir + "/cloth.png";
  canvas.writePng(path);
  return path;
}

}  // namespace meshsweeper::scenes
