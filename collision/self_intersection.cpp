// CGAL 5.5's self-intersection test (Polygon Mesh Processing), kept in its own file: its headers
// are heavy, and only BodyShape::build needs them.
#include "collision/self_intersection.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Surface_mesh.h>

#include <stdexcept>
#include <vector>

namespace meshsweeper {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using SurfaceMesh = CGAL::Surface_mesh<Kernel::Point_3>;
using FaceIndex = SurfaceMesh::Face_index;

// Thrown by the output iterator at the first pair: the search stops there.
struct FoundPair {
  TriangleIndex first, second;
};

struct StopAtFirst {
  using iterator_category = std::output_iterator_tag;
  using value_type = void;
  using difference_type = std::ptrdiff_t;
  using pointer = void;
  using reference = void;
  StopAtFirst& operator*() { return *this; }
  StopAtFirst& operator++() { return *this; }
  StopAtFirst operator++(int) { return *this; }
  StopAtFirst& operator=(const std::pair<FaceIndex, FaceIndex>& pair) {
    const TriangleIndex a = static_cast<TriangleIndex>(pair.first), b = static_cast<TriangleIndex>(pair.second);
    throw FoundPair{std::min(a, b), std::max(a, b)};
  }
};

}  // namespace

std::optional<std::pair<TriangleIndex, TriangleIndex>> firstSelfIntersection(const Mesh& mesh) {
  SurfaceMesh surface;
  surface.reserve(static_cast<SurfaceMesh::size_type>(mesh.positions.size()),
                  static_cast<SurfaceMesh::size_type>(3 * mesh.triangles.size() / 2),
                  static_cast<SurfaceMesh::size_type>(mesh.triangles.size()));
  for (const Vec3& x : mesh.positions) surface.add_vertex(Kernel::Point_3(x.x(), x.y(), x.z()));
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    const Triangle& t = mesh.triangles[f];
    const FaceIndex added = surface.add_face(SurfaceMesh::Vertex_index(t[0]), SurfaceMesh::Vertex_index(t[1]),
                                             SurfaceMesh::Vertex_index(t[2]));
    if (added == SurfaceMesh::null_face() || static_cast<size_t>(added) != f)
      throw std::runtime_error("self-intersection test: face " + std::to_string(f) +
                               " does not fit a surface (CGAL Surface_mesh)");
  }
  try {
    CGAL::Polygon_mesh_processing::self_intersections<CGAL::Sequential_tag>(faces(surface), surface, StopAtFirst{});
  } catch (const FoundPair& pair) {
    return std::make_pair(pair.first, pair.second);
  }
  return std::nullopt;
}

}  // namespace meshsweeper
