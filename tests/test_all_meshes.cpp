// Every bundled mesh (data/meshes: CGAL's scanned and CAD meshes, about 140 files of OFF, PLY
// and STL) against a reference that shares no code with the library: the distance to each
// triangle in long double (64-bit significand), as the projection onto its plane where that
// falls inside it, and the nearest of its three edges always (no Voronoi regions, no frame, no
// guards for thin triangles).
//
// Per mesh, points near the surface (within 1% of the diagonal, and within 1e-8 of it), on it
// (face points, vertices, edge midpoints), in the box grown by 10% and far away (10 diagonals).
// closest() must give the reference distance (1e-12 relative, plus 1e-14 of the coordinates'
// magnitude: what the rounding of the inputs to double allows), a point on the reported
// triangle, and that point at the reported distance from the query. A coherent stream and a
// compact coherent state, each walked along a short path from every point, must answer like
// closest(), bit for bit. A file that cannot be read must fail with a MeshError naming it.
#include "core/hierarchy.h"
#include "core/mesh_io.h"
#include "core/sweep_query.h"
#include "scenes/procedural.h"

#include "tests/oracle.h"

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

using namespace meshsweeper;
using namespace meshsweeper::oracle;
using scenes::Random;

namespace {

using Real = long double;

struct V3 {
  Real x, y, z;
};
V3 operator-(const V3& a, const V3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
V3 operator*(const V3& a, Real s) { return {a.x * s, a.y * s, a.z * s}; }
Real dot(const V3& a, const V3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
V3 cross(const V3& a, const V3& b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
V3 wide(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

// Squared distance from p to the segment [a, b].
Real segmentDistance2(const V3& p, const V3& a, const V3& b) {
  const V3 ab = b - a, ap = p - a;
  const Real length2 = dot(ab, ab);
  Real t = length2 > 0 ? dot(ap, ab) / length2 : 0;
  t = std::clamp<Real>(t, 0, 1);
  const V3 d = ap - ab * t;
  return dot(d, d);
}

// Squared distance from p to the triangle abc: its plane's where p projects inside it, else
// (and always, which never hurts a minimum) its edges'.
Real triangleDistance2(const V3& p, const V3& a, const V3& b, const V3& c) {
  Real best = std::min({segmentDistance2(p, a, b), segmentDistance2(p, b, c), segmentDistance2(p, c, a)});
  const V3 ab = b - a, ac = c - a, ap = p - a;
  const V3 n = cross(ab, ac);
  const Real n2 = dot(n, n);
  if (n2 > 0) {
    const Real h = dot(ap, n);
    const V3 q = ap - n * (h / n2);  // the projection, relative to a
    const bool inside = dot(cross(ab, q), n) >= 0 && dot(cross(q, ac), n) >= 0 && dot(cross(c - b, q - ab), n) >= 0;
    if (inside) best = std::min(best, h * h / n2);
  }
  return best;
}

Real referenceDistance(const Mesh& mesh, const Vec3& p) {
  const V3 q = wide(p);
  Real best = std::numeric_limits<Real>::infinity();
  for (const Triangle& t : mesh.triangles)
    best = std::min(best, triangleDistance2(q, wide(mesh.positions[t[0]]), wide(mesh.positions[t[1]]),
                                            wide(mesh.positions[t[2]])));
  return std::sqrt(best);
}

Real distanceToFace(const Mesh& mesh, TriangleIndex face, const Vec3& p) {
  const Triangle& t = mesh.triangles[face];
  return std::sqrt(triangleDistance2(wide(p), wide(mesh.positions[t[0]]), wide(mesh.positions[t[1]]),
                                     wide(mesh.positions[t[2]])));
}

bool sameAnswer(const ClosestPoint& a, const ClosestPoint& b) {
  return a.distance == b.distance && a.triangle == b.triangle && a.point == b.point;
}

}  // namespace

TEST_CASE("every bundled mesh: closest points against a long-double reference", "[queries][real][all]") {
  const std::filesystem::path dir = scenes::dataDir();
  REQUIRE(std::filesystem::is_directory(dir));  // the test command extracts the meshes first
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    const std::string ext = entry.path().extension().string();
    if (ext == ".off" || ext == ".ply" || ext == ".stl") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  REQUIRE(files.size() >= 100);  // CGAL's data set: about 140 meshes

  Failures distance("distance"), point("closest point"), coherent("coherent"), unreadable("unreadable file");
  size_t meshes = 0, points_checked = 0;
  uint64_t seed = 2026;
  for (const auto& file : files) {
    Mesh mesh;
    try {
      mesh = readMesh(file.string());
    } catch (const MeshError& e) {
      // Only a clear refusal: it names the file.
      const std::string message = e.what();
      unreadable.check(message.find(file.string()) != std::string::npos,
                       [&] { return "error without the file name: " + message; });
      continue;
    }
    ++meshes;
    INFO("mesh " << file.string());
    const auto h = Hierarchy::build(mesh);
    const size_t faces = mesh.triangles.size();
    Vec3 lower = mesh.positions[mesh.triangles[0][0]], upper = lower;
    for (const Triangle& t : mesh.triangles)
      for (VertexIndex v : t) {
        lower = lower.cwiseMin(mesh.positions[v]);
        upper = upper.cwiseMax(mesh.positions[v]);
      }
    const double diagonal = (upper - lower).norm();
    const double magnitude = std::max(lower.cwiseAbs().maxCoeff(), upper.cwiseAbs().maxCoeff());

    // About 2 million reference evaluations per mesh, at least 24 points.
    const size_t budget = std::clamp<size_t>(2'000'000 / faces, 24, 240);
    Random random(seed += 17);
    std::vector<Vec3> points;
    auto facePoint = [&](const Triangle& t, Vec3* normal) {
      double u = random.uniform(0, 1), v = random.uniform(0, 1);
      if (u + v > 1) {
        u = 1 - u;
        v = 1 - v;
      }
      const Vec3 &a = mesh.positions[t[0]], &b = mesh.positions[t[1]], &c = mesh.positions[t[2]];
      if (normal) {
        *normal = (b - a).cross(c - a);
        const double length = normal->norm();
        *normal = length > 0 ? Vec3(*normal / length) : Vec3::Zero();
      }
      return Vec3(a + u * (b - a) + v * (c - a));
    };
    for (size_t i = 0; points.size() < budget; ++i) {
      const Triangle& t = mesh.triangles[random.index(faces)];
      Vec3 normal;
      const Vec3 on = facePoint(t, &normal);
      switch (i % 8) {
        case 0: case 1: case 2:  // near: within 1% of the diagonal, either side
          points.push_back(on + random.uniform(-0.01, 0.01) * diagonal * normal);
          break;
        case 3:  // very near
          points.push_back(on + random.uniform(-1e-8, 1e-8) * diagonal * normal);
          break;
        case 4:  // on a face, a vertex, an edge's midpoint
          points.push_back(on);
          points.push_back(mesh.positions[t[random.index(3)]]);
          points.push_back(0.5 * (mesh.positions[t[0]] + mesh.positions[t[1]]));
          break;
        case 5: case 6: {  // in the box grown by 10%
          Vec3 p;
          for (int axis = 0; axis < 3; ++axis)
            p[axis] = random.uniform(lower[axis] - 0.1 * (upper[axis] - lower[axis]),
                                     upper[axis] + 0.1 * (upper[axis] - lower[axis]));
          points.push_back(p);
          break;
        }
        default: {  // far
          const Vec3 direction(random.uniform(-1, 1), random.uniform(-1, 1), random.uniform(-1, 1));
          points.push_back(0.5 * (lower + upper) + 10 * diagonal * direction.normalized());
        }
      }
    }

    QueryStream stream(h), walker(h);
    CoherentState state;
    const Vec3 stride = Vec3(1e-3, 2e-3, -1.5e-3) * diagonal;
    for (size_t i = 0; i < points.size(); ++i) {
      const Vec3& p = points[i];
      INFO("point " << i << " " << text(p));
      const ClosestPoint c = stream.closest(p);
      const Real reference = referenceDistance(mesh, p);
      const Real scale = std::max<Real>(magnitude, p.cwiseAbs().maxCoeff());
      distance.check(std::abs(static_cast<Real>(c.distance) - reference) <= 1e-12L * reference + 1e-14L * scale, [&] {
        return "distance " + num(c.distance) + ", reference " + num(static_cast<double>(reference));
      });
      const bool valid_face = c.triangle < faces;
      const Real on_face = valid_face ? distanceToFace(mesh, c.triangle, c.point) : Real(1);
      const Real to_point = std::sqrt(dot(wide(p) - wide(c.point), wide(p) - wide(c.point)));
      point.check(valid_face && on_face <= 1e-13L * scale &&
                      std::abs(to_point - static_cast<Real>(c.distance)) <= 1e-12L * reference + 1e-14L * scale,
                  [&] {
                    return "triangle " + std::to_string(c.triangle) + ", point " + text(c.point) + " " +
                           num(static_cast<double>(on_face)) + " off it and " +
                           num(static_cast<double>(to_point)) + " from the query";
                  });
      // A short path from p: both coherent forms answer like closest().
      for (int k = 0; k < 4; ++k) {
        const Vec3 q = p + k * stride;
        const ClosestPoint fresh = k == 0 ? c : stream.closest(q);
        const ClosestPoint a = walker.closestCoherent(q);
        const ClosestPoint b = stream.closestCoherent(q, state);
        coherent.check(sameAnswer(a, fresh) && sameAnswer(b, fresh), [&] {
          return "step " + std::to_string(k) + ": closest " + num(fresh.distance) + " face " +
                 std::to_string(fresh.triangle) + ", stream " + num(a.distance) + " face " +
                 std::to_string(a.triangle) + ", compact state " + num(b.distance) + " face " +
                 std::to_string(b.triangle);
        });
      }
    }
    points_checked += points.size();
  }
  CHECK(meshes + 2 >= files.size());  // b9.ply (points only) and prim.off (one face too many) are refused
  INFO(meshes << " meshes, " << points_checked << " points");
  if (std::getenv("MESHSWEEPER_TEST_VERBOSE")) std::cout << meshes << " meshes, " << points_checked << " points\n";
  CHECK(points_checked >= 24 * meshes);
  CHECK(distance.count() == 0);
  CHECK(point.count() == 0);
  CHECK(coherent.count() == 0);
}
