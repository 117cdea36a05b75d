// Tests for scenes/procedural: counts, closedness and orientation of the procedural meshes, the
// oddities of degenerateMesh, and the bounds and determinism of the point generators.
#include "scenes/procedural.h"

#include <Eigen/Geometry>
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdlib>
#include <map>
#include <stdexcept>
#include <utility>

using meshsweeper::Mesh;
using meshsweeper::Triangle;
using meshsweeper::Vec3;
using meshsweeper::VertexIndex;
namespace scenes = meshsweeper::scenes;

namespace {

constexpr double kPi = 3.14159265358979323846;

// [undirected edge] number of triangles using it.
std::map<std::pair<VertexIndex, VertexIndex>, int> edgeUses(const Mesh& mesh) {
  std::map<std::pair<VertexIndex, VertexIndex>, int> uses;
  for (const Triangle& t : mesh.triangles)
    for (int k = 0; k < 3; ++k)
      ++uses[std::minmax(t[k], t[(k + 1) % 3])];
  return uses;
}

// Closed and consistently oriented: every directed edge once, its reverse once.
bool closedAndOriented(const Mesh& mesh) {
  std::map<std::pair<VertexIndex, VertexIndex>, int> directed;
  for (const Triangle& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
  for (const auto& [edge, count] : directed) {
    if (count != 1) return false;
    const auto reverse = directed.find({edge.second, edge.first});
    if (reverse == directed.end() || reverse->second != 1) return false;
  }
  return true;
}

// Volume enclosed (positive when the triangles face outwards).
double signedVolume(const Mesh& mesh) {
  double six_volume = 0;
  for (const Triangle& t : mesh.triangles)
    six_volume += mesh.positions[t[0]].dot(mesh.positions[t[1]].cross(mesh.positions[t[2]]));
  return six_volume / 6;
}

double area(const Mesh& mesh, const Triangle& t) {
  return 0.5 * (mesh.positions[t[1]] - mesh.positions[t[0]])
                   .cross(mesh.positions[t[2]] - mesh.positions[t[0]])
                   .norm();
}

}  // namespace

TEST_CASE("Random maps mt19937_64 to [0, 1) the same way everywhere", "[procedural]") {
  // The standard fixes std::mt19937_64's first output for seed 5489: 14514284786278117030.
  scenes::Random random(5489);
  CHECK(random.uniform() == static_cast<double>(14514284786278117030ull >> 11) * 0x1.0p-53);
  scenes::Random a(7), b(7);
  for (int i = 0; i < 100; ++i) {
    const double u = a.uniform();
    CHECK(u == b.uniform());
    CHECK(u >= 0);
    CHECK(u < 1);
    CHECK(a.index(5) == b.index(5));
  }
}

TEST_CASE("icosphere: counts, vertices on the sphere, closed and outward", "[procedural]") {
  const Vec3 center(1, -2, 3);
  for (int s = 0; s <= 3; ++s) {
    INFO("subdivisions " << s);
    const Mesh mesh = scenes::icosphere(s, 2.5, center);
    const size_t power = size_t(1) << (2 * s);
    CHECK(mesh.positions.size() == 10 * power + 2);
    CHECK(mesh.triangles.size() == 20 * power);
    CHECK(meshsweeper::checkMesh(mesh).empty());
    for (const Vec3& p : mesh.positions) CHECK(std::abs((p - center).norm() - 2.5) < 1e-12);
    CHECK(closedAndOriented(mesh));
    Mesh centred = mesh;
    for (Vec3& p : centred.positions) p -= center;
    const double volume = signedVolume(centred), sphere = 4.0 / 3.0 * kPi * std::pow(2.5, 3);
    CHECK(volume > 0);
    CHECK(volume < sphere);
    if (s == 3) CHECK(volume > 0.98 * sphere);
  }
  CHECK_THROWS_AS(scenes::icosphere(-1), std::invalid_argument);
  CHECK_THROWS_AS(scenes::icosphere(2, 0), std::invalid_argument);
}

TEST_CASE("uvSphere: counts, poles, closed and outward", "[procedural]") {
  const Mesh mesh = scenes::uvSphere(16, 32, 2);
  CHECK(mesh.positions.size() == 2 + 15 * 32);
  CHECK(mesh.triangles.size() == 2 * 32 * 15);
  for (const Vec3& p : mesh.positions) CHECK(std::abs(p.norm() - 2) < 1e-12);
  CHECK(mesh.positions.front() == Vec3(0, 0, 2));
  CHECK(mesh.positions.back() == Vec3(0, 0, -2));
  CHECK(closedAndOriented(mesh));
  CHECK(signedVolume(mesh) > 0.95 * 4.0 / 3.0 * kPi * 8);
  CHECK(closedAndOriented(scenes::uvSphere(2, 3)));  // the coarsest: two triangular pyramids
  CHECK_THROWS_AS(scenes::uvSphere(1, 8), std::invalid_argument);
}

TEST_CASE("torus: counts, closed and outward, volume near 2 pi^2 R r^2", "[procedural]") {
  const Mesh mesh = scenes::torus(2, 0.5, 64, 32);
  CHECK(mesh.positions.size() == 64 * 32);
  CHECK(mesh.triangles.size() == 2 * 64 * 32);
  CHECK(closedAndOriented(mesh));
  const double expected = 2 * kPi * kPi * 2 * 0.25;
  CHECK(signedVolume(mesh) > 0.97 * expected);
  CHECK(signedVolume(mesh) < expected);
  for (const Vec3& p : mesh.positions) {
    const double ring = std::hypot(p.x(), p.y()) - 2;
    CHECK(std::abs(std::hypot(ring, p.z()) - 0.5) < 1e-12);
  }
}

TEST_CASE("gridPlane: counts, boundary, area, facing +z", "[procedural]") {
  const int n = 5;
  const Mesh mesh = scenes::gridPlane(n, 3);
  CHECK(mesh.positions.size() == 36);
  CHECK(mesh.triangles.size() == 50);
  int boundary = 0;
  for (const auto& [edge, count] : edgeUses(mesh)) {
    CHECK((count == 1 || count == 2));
    boundary += count == 1;
  }
  CHECK(boundary == 4 * n);
  double total = 0;
  for (const Triangle& t : mesh.triangles) {
    total += area(mesh, t);
    const Vec3 normal = (mesh.positions[t[1]] - mesh.positions[t[0]])
                            .cross(mesh.positions[t[2]] - mesh.positions[t[0]]);
    CHECK(normal.z() > 0);
  }
  CHECK(total == Approx(9.0));
  CHECK(mesh.positions[0] == Vec3(-1.5, -1.5, 0));
  CHECK(mesh.positions[35] == Vec3(1.5, 1.5, 0));
}

TEST_CASE("randomSoup: disconnected triangles in the unit box, reproducible", "[procedural]") {
  const Mesh mesh = scenes::randomSoup(500, 42);
  CHECK(mesh.positions.size() == 1500);
  REQUIRE(mesh.triangles.size() == 500);
  std::vector<int> uses(mesh.positions.size(), 0);
  for (const Triangle& t : mesh.triangles)
    for (VertexIndex v : t) ++uses[v];
  for (int u : uses) CHECK(u == 1);
  double smallest = 1e9, largest = 0;
  for (const Vec3& p : mesh.positions) {
    CHECK(p.minCoeff() >= 0);
    CHECK(p.maxCoeff() <= 1);
  }
  for (const Triangle& t : mesh.triangles) {
    const double edge = (mesh.positions[t[1]] - mesh.positions[t[0]]).norm();
    smallest = std::min(smallest, edge);
    largest = std::max(largest, edge);
  }
  CHECK(largest > 100 * smallest);  // sizes vary
  const Mesh again = scenes::randomSoup(500, 42);
  CHECK(again.positions == mesh.positions);
  CHECK(scenes::randomSoup(500, 43).positions != mesh.positions);
}

TEST_CASE("degenerateMesh holds every listed oddity and is valid", "[procedural]") {
  const Mesh mesh = scenes::degenerateMesh();
  CHECK(meshsweeper::checkMesh(mesh).empty());
  REQUIRE(mesh.triangles.size() == 11);
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    INFO("triangle " << t);
    if (t >= 2 && t <= 5) CHECK(area(mesh, mesh.triangles[t]) == 0);
    else CHECK(area(mesh, mesh.triangles[t]) > 0);
  }
  CHECK(area(mesh, mesh.triangles[7]) < 1e-9);  // sliver
  const Triangle repeated = mesh.triangles[2];
  CHECK((repeated[0] == repeated[1] || repeated[1] == repeated[2] || repeated[0] == repeated[2]));
  CHECK(mesh.positions[10] == mesh.positions[1]);  // duplicate vertex
  std::vector<bool> used(mesh.positions.size(), false);
  for (const Triangle& t : mesh.triangles)
    for (VertexIndex v : t) used[v] = true;
  CHECK_FALSE(used[11]);  // isolated
  // Among triangles with three distinct indices ((0,0,1) and (9,9,9) reuse edges trivially),
  // one edge is shared by three triangles: 15-16.
  Mesh distinct = mesh;
  distinct.triangles.clear();
  for (const Triangle& t : mesh.triangles)
    if (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) distinct.triangles.push_back(t);
  int non_manifold = 0;
  for (const auto& [edge, count] : edgeUses(distinct)) {
    non_manifold += count >= 3;
    if (count >= 3) CHECK(edge == std::pair<VertexIndex, VertexIndex>(15, 16));
  }
  CHECK(non_manifold == 1);
}

TEST_CASE("concatenate appends positions and shifts indices", "[procedural]") {
  const Mesh a = scenes::icosphere(1), b = scenes::gridPlane(2), c = scenes::degenerateMesh();
  const Mesh all = scenes::concatenate({a, b, c});
  CHECK(all.positions.size() == a.positions.size() + b.positions.size() + c.positions.size());
  CHECK(all.triangles.size() == a.triangles.size() + b.triangles.size() + c.triangles.size());
  CHECK(meshsweeper::checkMesh(all).empty());
  const VertexIndex shift = static_cast<VertexIndex>(a.positions.size());
  const Triangle first_of_b = all.triangles[a.triangles.size()];
  CHECK(first_of_b == Triangle{b.triangles[0][0] + shift, b.triangles[0][1] + shift,
                               b.triangles[0][2] + shift});
  CHECK(all.positions[first_of_b[0]] == b.positions[b.triangles[0][0]]);
  CHECK(all.name == a.name + " + " + b.name + " + " + c.name);
  CHECK(scenes::concatenate({}).positions.empty());
}

TEST_CASE("randomPointsInBox: inside the grown box, off the plane of a flat mesh", "[procedural]") {
  const Mesh plane = scenes::gridPlane(4, 2);  // [-1, 1]^2 x {0}, diagonal 2 sqrt 2
  const auto points = scenes::randomPointsInBox(plane, 2000, 0.1, 5);
  REQUIRE(points.size() == 2000);
  const double flat_pad = 0.1 * 0.1 * 2 * std::sqrt(2.0);  // the z side counts as 10% of diagonal
  bool outside_bounds = false, off_plane = false;
  for (const Vec3& p : points) {
    CHECK(std::abs(p.x()) <= 1.2);
    CHECK(std::abs(p.y()) <= 1.2);
    CHECK(std::abs(p.z()) <= flat_pad);
    outside_bounds = outside_bounds || std::abs(p.x()) > 1 || std::abs(p.y()) > 1;
    off_plane = off_plane || p.z() != 0;
  }
  CHECK(outside_bounds);
  CHECK(off_plane);
  CHECK(scenes::randomPointsInBox(plane, 2000, 0.1, 5) == points);
  CHECK(scenes::randomPointsInBox(plane, 2000, 0.1, 6) != points);
}

TEST_CASE("nearSurfacePoints: offsets bounded by the fraction of the diagonal", "[procedural]") {
  SECTION("flat grid: the offset is the z coordinate") {
    const Mesh plane = scenes::gridPlane(8, 2);
    const double max_offset = 0.01 * 2 * std::sqrt(2.0);
    const auto points = scenes::nearSurfacePoints(plane, 5000, 0.01, 9);
    double largest = 0;
    for (const Vec3& p : points) {
      CHECK(std::abs(p.x()) <= 1);
      CHECK(std::abs(p.y()) <= 1);
      CHECK(std::abs(p.z()) <= max_offset);
      largest = std::max(largest, std::abs(p.z()));
    }
    CHECK(largest > 0.9 * max_offset);  // offsets fill the range
    for (const Vec3& p : scenes::surfacePoints(plane, 1000, 9)) CHECK(p.z() == 0);
  }
  SECTION("icosphere: between the planes' distance and the radius, give or take the offset") {
    const Mesh sphere = scenes::icosphere(2, 3);
    double inner = 3;
    for (const Triangle& t : sphere.triangles) {
      const Vec3 normal = (sphere.positions[t[1]] - sphere.positions[t[0]])
                              .cross(sphere.positions[t[2]] - sphere.positions[t[0]])
                              .normalized();
      inner = std::min(inner, std::abs(normal.dot(sphere.positions[t[0]])));
    }
    const double max_offset = 0.02 * meshsweeper::meshDiagonal(sphere);
    for (const Vec3& p : scenes::nearSurfacePoints(sphere, 3000, 0.02, 1)) {
      CHECK(p.norm() <= 3 + max_offset + 1e-12);
      CHECK(p.norm() >= inner - max_offset - 1e-12);
    }
  }
  SECTION("area weighting: a square of area 1 next to one of area 9 gets about 1/10") {
    Mesh big = scenes::gridPlane(1, 3);
    for (Vec3& p : big.positions) p.x() += 10;
    const Mesh both = scenes::concatenate({scenes::gridPlane(1, 1), big});
    int in_small = 0;
    for (const Vec3& p : scenes::surfacePoints(both, 20000, 3)) in_small += p.x() < 5;
    CHECK(in_small / 20000.0 == Approx(0.1).margin(0.01));
  }
  SECTION("all triangles degenerate: points stay on them") {
    Mesh flat;
    flat.positions = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};
    flat.triangles = {{0, 1, 2}};
    for (const Vec3& p : scenes::nearSurfacePoints(flat, 100, 0.1, 2)) {
      CHECK(p.y() == 0);
      CHECK(p.z() == 0);
    }
  }
}

TEST_CASE("vertexPoints and edgePoints lie on vertices and edges", "[procedural]") {
  const Mesh odd = scenes::degenerateMesh();
  const auto vertices = scenes::vertexPoints(odd);
  CHECK(vertices.size() == odd.positions.size() - 1);  // isolated vertex 11 left out
  for (const Vec3& p : vertices) CHECK(p != Vec3(5, 5, 5));

  // Grid edges of gridPlane(4, 4) lie on x = k, y = k or x - y = k for integers k.
  const Mesh plane = scenes::gridPlane(4, 4);
  const auto onInteger = [](double v) { return std::abs(v - std::round(v)) < 1e-12; };
  for (const Vec3& p : scenes::edgePoints(plane, 1000, 4)) {
    CHECK((onInteger(p.x()) || onInteger(p.y()) || onInteger(p.x() - p.y())));
    CHECK(std::abs(p.x()) <= 2);
    CHECK(std::abs(p.y()) <= 2);
  }
  CHECK(scenes::edgePoints(plane, 10, 4) == scenes::edgePoints(plane, 10, 4));
  Mesh empty;
  CHECK_THROWS_AS(scenes::vertexPoints(empty), std::invalid_argument);
}

TEST_CASE("dataDir follows MESHSWEEPER_DATA, meshPath appends name.off", "[procedural]") {
  const char* saved = std::getenv("MESHSWEEPER_DATA");
  const std::string previous = saved != nullptr ? saved : "";
  setenv("MESHSWEEPER_DATA", "/somewhere/meshes", 1);
  CHECK(scenes::dataDir() == "/somewhere/meshes");
  CHECK(scenes::meshPath("armadillo") == "/somewhere/meshes/armadillo.off");
  unsetenv("MESHSWEEPER_DATA");
  CHECK(scenes::dataDir() == MESHSWEEPER_DEFAULT_DATA_DIR);
  setenv("MESHSWEEPER_DATA", "", 1);
  CHECK(scenes::dataDir() == MESHSWEEPER_DEFAULT_DATA_DIR);
  if (saved != nullptr) setenv("MESHSWEEPER_DATA", previous.c_str(), 1);
  else unsetenv("MESHSWEEPER_DATA");
}
