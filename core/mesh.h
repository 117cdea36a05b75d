#pragma once
// A triangle mesh as read from a file: positions and triangles in file order.
// Any triangle set is valid: several components, holes, non-manifold edges, duplicate or
// isolated vertices, degenerate triangles (repeated indices or collinear corners).
#include "core/types.h"

#include <stdexcept>
#include <string>
#include <vector>

namespace meshsweeper {

struct Mesh {
  std::vector<Vec3> positions;       // [vertex]
  std::vector<Triangle> triangles;   // [triangle] polygons triangulated in face order
  std::string name;                  // file path or a procedural name, for messages
};

// Errors from reading or validating untrusted input. what() names the file (or mesh name) and
// the problem, e.g. "bunny.off: face 12 uses vertex 9000 but the file has 3000 vertices".
class MeshError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The sizes of mesh supported (bounding-box diagonal; 0, a mesh of one point, too): within
// them, and with query points within kMaxQueryCoordinate, no step of the exact distance
// overflows, and only distances below about 1.5e-154 underflow (their squares): those are
// exact to about 2e-162 absolute (README "Errors").
inline constexpr double kMaxMeshSize = 1e50;
inline constexpr double kMinMeshSize = 1e-50;

// Checks what every builder needs: at least one triangle, finite coordinates within
// kMaxCoordinate, indices in range, a size within [kMinMeshSize, kMaxMeshSize] (or 0).
// Returns an empty string when the mesh is usable, else "NAME: problem".
std::string checkMesh(const Mesh& mesh);

// Area of triangle t (0 for a degenerate one), and of all triangles.
double triangleArea(const Mesh& mesh, size_t t);
double surfaceArea(const Mesh& mesh);

// Axis-aligned bounds of all `positions` (lower = +inf, upper = -inf for none).
void positionsBounds(const std::vector<Vec3>& positions, Vec3& lower, Vec3& upper);
// The bounding-box diagonal of all `positions`. 0 for none.
double positionsDiagonal(const std::vector<Vec3>& positions);
// The same over the vertices `mesh`'s triangles use (positions: one per vertex of the mesh,
// e.g. moved ones), as meshDiagonal() measures the mesh: a vertex no triangle uses, which no
// query sees, does not count. 0 for a mesh without triangles.
double usedPositionsDiagonal(const Mesh& mesh, const std::vector<Vec3>& positions);
// Whether moved `positions` (one per vertex of `mesh`) span at most kMaxMeshSize over the
// vertices the triangles use: deform/ and the distance service refuse positions that do not,
// as checkMesh refuses such a mesh. A pass over the positions; the triangles are read only
// when all the positions span more (an unused vertex far away).
bool withinMeshSize(const Mesh& mesh, const std::vector<Vec3>& positions);

// Axis-aligned bounds of the vertices used by triangles. Precondition: checkMesh() passed.
void meshBounds(const Mesh& mesh, Vec3& lower, Vec3& upper);
// Length of the bounding-box diagonal. Precondition: checkMesh() passed.
double meshDiagonal(const Mesh& mesh);

}  // namespace meshsweeper
