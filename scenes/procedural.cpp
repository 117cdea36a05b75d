// Procedural meshes and seeded point sets (scenes/procedural.h).
#include "scenes/procedural.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <unordered_map>

#ifndef MESHSWEEPER_DEFAULT_DATA_DIR
#define MESHSWEEPER_DEFAULT_DATA_DIR "data/meshes"
#endif

namespace meshsweeper::scenes {
namespace {

constexpr double kPi = 3.14159265358979323846;

void require(bool condition, const char* what) {
  if (!condition) throw std::invalid_argument(what);
}

void requireUsable(const Mesh& mesh) {
  const std::string problem = checkMesh(mesh);
  if (!problem.empty()) throw std::invalid_argument(problem);
}

Vec3 cornerNormal(const Mesh& mesh, const Triangle& t) {
  return (mesh.positions[t[1]] - mesh.positions[t[0]])
      .cross(mesh.positions[t[2]] - mesh.positions[t[0]]);
}

// Picks triangles with probability proportional to their area (uniformly when all are zero).
class AreaSampler {
 public:
  explicit AreaSampler(const Mesh& mesh) : cumulative_(mesh.triangles.size()) {
    double total = 0;
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      total += 0.5 * cornerNormal(mesh, mesh.triangles[t]).norm();
      cumulative_[t] = total;
    }
    uniform_ = !(total > 0) || !std::isfinite(total);
  }

  TriangleIndex pick(Random& random) const {
    if (uniform_) return static_cast<TriangleIndex>(random.index(cumulative_.size()));
    const double target = random.uniform() * cumulative_.back();
    const auto it = std::upper_bound(cumulative_.begin(), cumulative_.end(), target);
    return static_cast<TriangleIndex>(
        std::min<size_t>(static_cast<size_t>(it - cumulative_.begin()), cumulative_.size() - 1));
  }

 private:
  std::vector<double> cumulative_;  // [triangle] area of triangles 0..t
  bool uniform_ = false;
};

// A uniform point on a triangle (square-root warp of two uniforms to barycentric coordinates).
Vec3 pointOnTriangle(const Mesh& mesh, const Triangle& t, Random& random) {
  const double s = std::sqrt(random.uniform());
  const double v = random.uniform();
  const double a = 1 - s, b = s * (1 - v), c = s * v;
  return a * mesh.positions[t[0]] + b * mesh.positions[t[1]] + c * mesh.positions[t[2]];
}

std::vector<Vec3> samplesNearSurface(const Mesh& mesh, size_t n, double max_offset,
                                     uint64_t seed) {
  Random random(seed);
  const AreaSampler sampler(mesh);
  std::vector<Vec3> points;
  points.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const Triangle& t = mesh.triangles[sampler.pick(random)];
    Vec3 p = pointOnTriangle(mesh, t, random);
    const double offset = max_offset * (2 * random.uniform() - 1);
    const Vec3 normal = cornerNormal(mesh, t);
    const double length = normal.norm();
    if (length > 0 && std::isfinite(length)) p += (offset / length) * normal;
    points.push_back(p);
  }
  return points;
}

}  // namespace

size_t Random::index(size_t n) {
  return std::min(static_cast<size_t>(uniform() * static_cast<double>(n)), n - 1);
}

Vec3 Random::inBox(const Vec3& lower, const Vec3& upper) {
  const double x = uniform(lower.x(), upper.x());
  const double y = uniform(lower.y(), upper.y());
  const double z = uniform(lower.z(), upper.z());
  return {x, y, z};
}

// ---- Meshes ---------------------------------------------------------------------------------

Mesh icosphere(int subdivisions, double radius, const Vec3& center) {
  require(subdivisions >= 0 && subdivisions <= 10, "icosphere: subdivisions must be in [0, 10]");
  require(radius > 0, "icosphere: radius must be positive");
  // The icosahedron: corners (0, +-1, +-g) and their cyclic permutations, g the golden ratio.
  const double g = (1 + std::sqrt(5.0)) / 2;
  std::vector<Vec3> unit = {{-1, g, 0}, {1, g, 0},   {-1, -g, 0}, {1, -g, 0},
                            {0, -1, g}, {0, 1, g},   {0, -1, -g}, {0, 1, -g},
                            {g, 0, -1}, {g, 0, 1},   {-g, 0, -1}, {-g, 0, 1}};
  for (Vec3& p : unit) p.normalize();
  std::vector<Triangle> triangles = {
      {0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},  {4, 9, 5},  {2, 4, 11},  {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int level = 0; level < subdivisions; ++level) {
    // One midpoint per edge, shared by the two triangles on it.
    std::unordered_map<uint64_t, VertexIndex> midpoints;
    const auto midpoint = [&](VertexIndex a, VertexIndex b) {
      const uint64_t key = (uint64_t(std::min(a, b)) << 32) | std::max(a, b);
      const auto [it, inserted] = midpoints.emplace(key, static_cast<VertexIndex>(unit.size()));
      if (inserted) unit.push_back((unit[a] + unit[b]).normalized());
      return it->second;
    };
    std::vector<Triangle> finer;
    finer.reserve(4 * triangles.size());
    for (const Triangle& t : triangles) {
      const VertexIndex ab = midpoint(t[0], t[1]), bc = midpoint(t[1], t[2]),
                        ca = midpoint(t[2], t[0]);
      finer.push_back({t[0], ab, ca});
      finer.push_back({t[1], bc, ab});
      finer.push_back({t[2], ca, bc});
      finer.push_back({ab, bc, ca});
    }
    triangles.swap(finer);
  }
  Mesh mesh;
  mesh.name = "icosphere(" + std::to_string(subdivisions) + ")";
  mesh.positions.reserve(unit.size());
  for (const Vec3& p : unit) mesh.positions.push_back(center + radius * p);
  mesh.triangles = std::move(triangles);
  return mesh;
}

Mesh uvSphere(int rings, int segments, double radius) {
  require(rings >= 2 && segments >= 3, "uvSphere: needs rings >= 2 and segments >= 3");
  require(radius > 0, "uvSphere: radius must be positive");
  Mesh mesh;
  mesh.name = "uvSphere(" + std::to_string(rings) + "," + std::to_string(segments) + ")";
  // Vertex 0: north pole; then rings 1 .. rings-1 of `segments` vertices; last: south pole.
  mesh.positions.push_back({0, 0, radius});
  for (int i = 1; i < rings; ++i) {
    const double theta = kPi * i / rings;
    for (int j = 0; j < segments; ++j) {
      const double phi = 2 * kPi * j / segments;
      mesh.positions.push_back(radius * Vec3(std::sin(theta) * std::cos(phi),
                                             std::sin(theta) * std::sin(phi), std::cos(theta)));
    }
  }
  const VertexIndex south = static_cast<VertexIndex>(mesh.positions.size());
  mesh.positions.push_back({0, 0, -radius});
  const auto ring = [&](int i, int j) {  // vertex j of ring i (1-based ring, wrapping j)
    return static_cast<VertexIndex>(1 + (i - 1) * segments + (j % segments));
  };
  for (int j = 0; j < segments; ++j) mesh.triangles.push_back({0, ring(1, j), ring(1, j + 1)});
  for (int i = 1; i + 1 < rings; ++i) {
    for (int j = 0; j < segments; ++j) {
      mesh.triangles.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
      mesh.triangles.push_back({ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
  }
  for (int j = 0; j < segments; ++j)
    mesh.triangles.push_back({ring(rings - 1, j), south, ring(rings - 1, j + 1)});
  return mesh;
}

Mesh torus(double R, double r, int nu, int nv) {
  require(r > 0 && R >= 0, "torus: needs r > 0 and R >= 0");
  require(nu >= 3 && nv >= 3, "torus: needs nu >= 3 and nv >= 3");
  Mesh mesh;
  mesh.name = "torus(" + std::to_string(nu) + "," + std::to_string(nv) + ")";
  for (int i = 0; i < nu; ++i) {
    const double u = 2 * kPi * i / nu;
    for (int j = 0; j < nv; ++j) {
      const double v = 2 * kPi * j / nv;
      const double w = R + r * std::cos(v);
      mesh.positions.push_back({w * std::cos(u), w * std::sin(u), r * std::sin(v)});
    }
  }
  const auto at = [&](int i, int j) {
    return static_cast<VertexIndex>((i % nu) * nv + (j % nv));
  };
  for (int i = 0; i < nu; ++i) {
    for (int j = 0; j < nv; ++j) {  // d/du x d/dv points out of the tube
      mesh.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      mesh.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  }
  return mesh;
}

Mesh gridPlane(int n, double size) {
  require(n >= 1 && size > 0, "gridPlane: needs n >= 1 and size > 0");
  Mesh mesh;
  mesh.name = "gridPlane(" + std::to_string(n) + ")";
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j)
      mesh.positions.push_back({size * (double(j) / n - 0.5), size * (double(i) / n - 0.5), 0});
  const auto at = [&](int i, int j) { return static_cast<VertexIndex>(i * (n + 1) + j); };
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      mesh.triangles.push_back({at(i, j), at(i, j + 1), at(i + 1, j + 1)});
      mesh.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i + 1, j)});
    }
  }
  return mesh;
}

Mesh randomSoup(size_t triangles, uint64_t seed) {
  require(triangles >= 1, "randomSoup: needs at least one triangle");
  require(triangles < kInvalidIndex / 3, "randomSoup: too many triangles");
  Random random(seed);
  Mesh mesh;
  mesh.name = "randomSoup(" + std::to_string(triangles) + ")";
  mesh.positions.reserve(3 * triangles);
  mesh.triangles.reserve(triangles);
  const Vec3 lower = Vec3::Zero(), upper = Vec3::Ones();
  for (size_t t = 0; t < triangles; ++t) {
    const Vec3 centre = random.inBox(lower, upper);
    const double size = 0.001 * std::pow(200.0, random.uniform());  // 0.001 .. 0.2
    const VertexIndex first = static_cast<VertexIndex>(mesh.positions.size());
    for (int k = 0; k < 3; ++k) {
      const Vec3 offset = random.inBox(-Vec3::Ones(), Vec3::Ones());
      mesh.positions.push_back((centre + size * offset).cwiseMax(lower).cwiseMin(upper));
    }
    mesh.triangles.push_back({first, first + 1, first + 2});
  }
  return mesh;
}

// The vertices (z = 0 unless given; "x" marks no position):
//
//   y
//   4 |                 17
//     |               /    \          15-16 is shared by triangles 8 (wing 17), 9 (wing 18,
//   3 | 15 --------- 16                z = +1) and 10 (wing 19, z = -1)
//     |
//   2 |                  12 ------ 13     sliver 7: 12, 13, 14 (14 is 1e-9 above the base)
//     |                        14
//   1 | 2 ------ 3
//     | |  0,1 / |
//   0 | 0 ------ 1=10   4 -- 5 -- 6       collinear 3: 4, 5, 6
//     +------------------------------ x
//   7, 8, 9 all at (0, 0, 1); 11 at (5, 5, 5), isolated.
Mesh degenerateMesh() {
  Mesh mesh;
  mesh.name = "degenerate";
  mesh.positions = {
      {0, 0, 0},   {1, 0, 0},   {0, 1, 0},          {1, 1, 0},           // 0-3 square
      {2, 0, 0},   {3, 0, 0},   {4, 0, 0},                               // 4-6 collinear
      {0, 0, 1},   {0, 0, 1},   {0, 0, 1},                               // 7-9 coincident
      {1, 0, 0},                                                         // 10 duplicate of 1
      {5, 5, 5},                                                         // 11 isolated
      {2, 2, 0},   {3, 2, 0},   {2.5, 2 + 1e-9, 0},                      // 12-14 sliver
      {0, 3, 0},   {1, 3, 0},   {0.5, 4, 0},        {0.5, 2.5, 1}, {0.5, 2.5, -1},  // 15-19
  };
  mesh.triangles = {
      {0, 1, 3},   {0, 3, 2},                 // 0, 1: proper square
      {0, 0, 1},                              // 2: repeated index
      {4, 5, 6},                              // 3: collinear corners
      {7, 8, 9},                              // 4: coincident corners, distinct indices
      {9, 9, 9},                              // 5: one index three times
      {10, 3, 2},                             // 6: proper, on duplicate vertex 10
      {12, 13, 14},                           // 7: sliver
      {15, 16, 17}, {16, 15, 18}, {15, 16, 19},  // 8-10: non-manifold edge 15-16
  };
  return mesh;
}

Mesh concatenate(const std::vector<Mesh>& meshes) {
  Mesh result;
  size_t vertices = 0, triangles = 0;
  for (const Mesh& m : meshes) {
    vertices += m.positions.size();
    triangles += m.triangles.size();
  }
  require(vertices < kInvalidIndex, "concatenate: too many vertices");
  result.positions.reserve(vertices);
  result.triangles.reserve(triangles);
  for (const Mesh& m : meshes) {
    const VertexIndex shift = static_cast<VertexIndex>(result.positions.size());
    result.positions.insert(result.positions.end(), m.positions.begin(), m.positions.end());
    for (const Triangle& t : m.triangles)
      result.triangles.push_back({t[0] + shift, t[1] + shift, t[2] + shift});
    result.name += (result.name.empty() ? "" : " + ") + m.name;
  }
  return result;
}

// ---- Point sets -----------------------------------------------------------------------------

std::vector<Vec3> randomPointsInBox(const Mesh& mesh, size_t n, double enlarge, uint64_t seed) {
  requireUsable(mesh);
  require(enlarge >= 0, "randomPointsInBox: enlarge must be >= 0");
  Vec3 lower, upper;
  meshBounds(mesh, lower, upper);
  const double diagonal = (upper - lower).norm();
  const Vec3 sides = (upper - lower).cwiseMax(Vec3::Constant(0.1 * diagonal));
  lower -= enlarge * sides;
  upper += enlarge * sides;
  Random random(seed);
  std::vector<Vec3> points;
  points.reserve(n);
  for (size_t i = 0; i < n; ++i) points.push_back(random.inBox(lower, upper));
  return points;
}

std::vector<Vec3> nearSurfacePoints(const Mesh& mesh, size_t n,
                                    double max_offset_fraction_of_diagonal, uint64_t seed) {
  requireUsable(mesh);
  require(max_offset_fraction_of_diagonal >= 0, "nearSurfacePoints: offset must be >= 0");
  return samplesNearSurface(mesh, n, max_offset_fraction_of_diagonal * meshDiagonal(mesh), seed);
}

std::vector<Vec3> surfacePoints(const Mesh& mesh, size_t n, uint64_t seed) {
  requireUsable(mesh);
  return samplesNearSurface(mesh, n, 0, seed);
}

std::vector<Vec3> vertexPoints(const Mesh& mesh) {
  requireUsable(mesh);
  std::vector<bool> used(mesh.positions.size(), false);
  for (const Triangle& t : mesh.triangles)
    for (VertexIndex v : t) used[v] = true;
  std::vector<Vec3> points;
  for (size_t v = 0; v < used.size(); ++v)
    if (used[v]) points.push_back(mesh.positions[v]);
  return points;
}

std::vector<Vec3> edgePoints(const Mesh& mesh, size_t n, uint64_t seed) {
  requireUsable(mesh);
  Random random(seed);
  std::vector<Vec3> points;
  points.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const Triangle& t = mesh.triangles[random.index(mesh.triangles.size())];
    const size_t k = random.index(3);
    const Vec3& a = mesh.positions[t[k]];
    const Vec3& b = mesh.positions[t[(k + 1) % 3]];
    points.push_back(a + random.uniform() * (b - a));
  }
  return points;
}

// ---- Real meshes ----------------------------------------------------------------------------

std::string dataDir() {
  const char* env = std::getenv("MESHSWEEPER_DATA");
  if (env != nullptr && env[0] != '\0') return env;
  return MESHSWEEPER_DEFAULT_DATA_DIR;
}

std::string meshPath(const std::string& name) { return dataDir() + "/" + name + ".off"; }

}  // namespace meshsweeper::scenes
