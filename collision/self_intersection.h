#pragma once
// Whether a closed surface intersects itself, for the signs of the distance service
// (collision/body.h): the angle-weighted pseudonormals tell inside from outside only on an
// embedded surface.
#include "core/mesh.h"

#include <optional>
#include <utility>

namespace meshsweeper {

// A pair of faces (f < g) of `mesh` that intersect anywhere but along the vertex or edge they
// share, found with CGAL's exact predicates (Polygon Mesh Processing's self_intersections on
// the mesh as a Surface_mesh, faces in file order); nullopt when there is none. The same pair
// for the same mesh every time (a sequential search that stops at its first pair).
// Precondition: every edge has exactly two faces, used in opposite directions, every vertex's
// faces form one fan and no face is degenerate (what BodyShape checks first). Throws
// std::runtime_error if CGAL cannot take the mesh as a surface.
std::optional<std::pair<TriangleIndex, TriangleIndex>> firstSelfIntersection(const Mesh& mesh);

}  // namespace meshsweeper
