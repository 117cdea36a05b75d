#include "core/mesh.h"

#include <cmath>
#include <limits>
#include <sstream>

namespace meshsweeper {

std::string checkMesh(const Mesh& mesh) {
  const std::string name = mesh.name.empty() ? std::string("mesh") : mesh.name;
  if (mesh.triangles.empty()) return name + ": the mesh has no triangles";
  if (mesh.positions.size() >= kInvalidIndex)
    return name + ": too many vertices (" + std::to_string(mesh.positions.size()) + ")";
  if (mesh.triangles.size() >= static_cast<size_t>(INT32_MAX) / 2)
    return name + ": too many triangles (" + std::to_string(mesh.triangles.size()) + ")";
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    if (!mesh.positions[v].allFinite())
      return name + ": vertex " + std::to_string(v) + " has a non-finite coordinate";
    if (!inCoordinateRange(mesh.positions[v]))
      return name + ": vertex " + std::to_string(v) + " has a coordinate beyond 1e150 in magnitude (distances would overflow)";
  }
  const size_t n = mesh.positions.size();
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    for (VertexIndex v : mesh.triangles[t]) {
      if (v >= n)
        return name + ": triangle " + std::to_string(t) + " uses vertex " + std::to_string(v) +
               " but the mesh has " + std::to_string(n) + " vertices";
    }
  }
  // The exact distance's Gram terms are fourth powers of edge lengths (times a point's offset):
  // outside this range of sizes they overflow or underflow and faces would be taken for
  // segments (core/triangle_distance.cpp).
  const double diagonal = meshDiagonal(mesh);
  if (diagonal > kMaxMeshSize || (diagonal > 0 && diagonal < kMinMeshSize)) {
    std::ostringstream out;
    out << name << ": the mesh's size (bounding-box diagonal " << diagonal
        << ") is outside the supported range [1e-50, 1e50]; rescale it";
    return out.str();
  }
  return {};
}

namespace {

// The bounds of positions[v] over the vertices v of the triangles.
void usedBounds(const std::vector<Triangle>& triangles, const std::vector<Vec3>& positions, Vec3& lower, Vec3& upper) {
  Vec3 low = Vec3::Constant(std::numeric_limits<double>::infinity()), high = -low;
  for (const Triangle& t : triangles) {
    for (VertexIndex v : t) {
      low = low.cwiseMin(positions[v]);
      high = high.cwiseMax(positions[v]);
    }
  }
  lower = low;
  upper = high;
}

}  // namespace

void meshBounds(const Mesh& mesh, Vec3& lower, Vec3& upper) { usedBounds(mesh.triangles, mesh.positions, lower, upper); }

double triangleArea(const Mesh& mesh, size_t t) {
  const Triangle& f = mesh.triangles[t];
  const Vec3& a = mesh.positions[f[0]];
  return 0.5 * (mesh.positions[f[1]] - a).cross(mesh.positions[f[2]] - a).norm();
}

double surfaceArea(const Mesh& mesh) {
  double area = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) area += triangleArea(mesh, t);
  return area;
}

void positionsBounds(const std::vector<Vec3>& positions, Vec3& lower, Vec3& upper) {
  // In locals: the outputs could alias the positions, so writing them in the loop would store
  // and reload every step.
  Vec3 low = Vec3::Constant(std::numeric_limits<double>::infinity()), high = -low;
  for (const Vec3& x : positions) {
    low = low.cwiseMin(x);
    high = high.cwiseMax(x);
  }
  lower = low;
  upper = high;
}

double positionsDiagonal(const std::vector<Vec3>& positions) {
  if (positions.empty()) return 0;
  Vec3 lower, upper;
  positionsBounds(positions, lower, upper);
  return stableLength(upper - lower);  // no underflow to 0 below 1e-154, no overflow
}

double usedPositionsDiagonal(const Mesh& mesh, const std::vector<Vec3>& positions) {
  if (mesh.triangles.empty()) return 0;
  Vec3 lower, upper;
  usedBounds(mesh.triangles, positions, lower, upper);
  return stableLength(upper - lower);
}

bool withinMeshSize(const Mesh& mesh, const std::vector<Vec3>& positions) {
  return positionsDiagonal(positions) <= kMaxMeshSize || usedPositionsDiagonal(mesh, positions) <= kMaxMeshSize;
}

double meshDiagonal(const Mesh& mesh) {
  Vec3 lower, upper;
  meshBounds(mesh, lower, upper);
  // A plain norm's square underflows to 0 below about 1e-154: such a mesh passed checkMesh's
  // size check as a single point (found by review).
  return stableLength(upper - lower);
}

}  // namespace meshsweeper
