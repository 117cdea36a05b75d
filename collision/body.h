#pragma once
// The fixed, shared part of a body of the distance service (collision/): what a body's mesh
// needs besides its hierarchy, built once per mesh and shared read-only by every body that
// uses the mesh, like the hierarchy itself (STYLE.md: fixed, shared lifetime).
//
//  - Surface topology: [vertex] incident faces (CSR), [triangle edge] the face across the edge,
//    and whether the mesh is closed (every edge has exactly two faces, used in opposite
//    directions; every vertex's faces form one fan; no face repeats a vertex or is degenerate
//    (isDegenerateTriangle) at the rest positions; the surface encloses a volume; no two
//    faces intersect beyond what they share, at the rest positions: firstSelfIntersection();
//    its components nest as one solid's: one facing out outside the others, a cavity inside).
//    Only closed bodies get a sign (inside/outside). A closed surface whose faces point inward
//    (a negative enclosed volume) is the same solid: its pseudonormals are flipped (inward()).
//    Signs also assume what is not checked: a deformation that keeps the surface embedded and
//    its faces from degenerating (the pseudonormal test's precondition).
//  - Angle-weighted pseudonormals at the rest positions (Baerentzen & Aanaes, "Signed distance
//    computation using the angle weighted pseudonormal", IEEE TVCG 2005): the face normal; for
//    an edge the sum of its two unit face normals; for a vertex the sum of the unit normals of
//    its faces, each weighted by the face's angle at the vertex. For a closed surface and a
//    point p with closest surface point c on feature f, sign((p - c) . n_f) is the sign of the
//    distance (outside positive). Deformed positions use the same formulas on demand
//    (pseudonormal()): only the hit's feature is evaluated. Other positions can turn the
//    surface inside out (a mirror image): their orientation (orientationAt()) is that of the
//    volume they enclose, not the rest positions'.
#include "core/hierarchy.h"
#include "core/sweep_query.h"
#include "core/triangle_distance.h"

#include <memory>
#include <string>
#include <vector>

namespace meshsweeper {

// The orientation of one placement of a closed surface, and what keeps it: the enclosed volume
// moves at the flux of the vertices' motion through the surface, so while every vertex stays
// within delta of the placement (on straight paths, as linear interpolation and any new
// positions measured from it give) the volume changes by at most delta times the surface's
// area, bounded from the placement's faces and edges grown by 2 delta. A volume farther from
// zero than that keeps its sign.
struct PlacementOrientation {
  double orientation = 1;    // BodyShape::orientationAt() of the placement
  double volume6 = 0;        // 6 x the enclosed volume, faces as given
  double rounding = 0;       // bound on volume6's rounding
  double edge_products = 0;  // sum over faces of |ab x ac| (twice the area)
  double edge_sums = 0;      // sum over faces of |ab| + |ac|
  double faces = 0;
  bool closed = false;  // false: orientation is the shape's rest one, whatever the placement
  // Whether every placement with each vertex within delta of this one has its orientation.
  bool holdsWithin(double delta) const;
  // The same, given a bound on twice the area of every placement on the way (the edge fields
  // need not be filled).
  bool holdsWithin(double delta, double area2) const;
  // Twice the largest area of a placement with each vertex within delta of this one.
  double grownArea2(double delta) const;
};

class BodyShape {
 public:
  // Builds the tables of hierarchy->mesh(). Throws std::invalid_argument if hierarchy is null.
  // Costs O(faces log faces) (an edge sort); the hierarchy is kept alive by the shape.
  static std::shared_ptr<const BodyShape> build(std::shared_ptr<const Hierarchy> hierarchy);

  const std::shared_ptr<const Hierarchy>& hierarchy() const { return hierarchy_; }
  const Mesh& mesh() const { return hierarchy_->mesh(); }

  // True when the distance to this mesh can be signed (see the file comment).
  bool closed() const { return closed_; }
  // Why the mesh is not closed (the first problem found), "" when closed.
  const std::string& openReason() const { return open_reason_; }
  // A closed mesh whose faces point inward: every pseudonormal is flipped (see the file comment).
  bool inward() const { return orientation_ < 0; }

  // Box of the vertices used by faces, at the rest positions.
  const Vec3& restLower() const { return rest_lower_; }
  const Vec3& restUpper() const { return rest_upper_; }

  // [vertex + 1] CSR into vertexFaces(): the faces using each vertex, by increasing index.
  const std::vector<uint32_t>& vertexFaceBegin() const { return vertex_face_begin_; }
  const std::vector<TriangleIndex>& vertexFaces() const { return vertex_faces_; }
  // [3 * triangle + edge] the face across edge `edge` (corners edge, edge + 1 mod 3), or
  // kInvalidIndex on a boundary or non-manifold edge.
  const std::vector<TriangleIndex>& edgeNeighbor() const { return edge_neighbor_; }

  // Rest pseudonormals (flipped for an inward mesh): [triangle] unit face normal (zero for a
  // zero-area face);
  // [3 * triangle + edge] edge pseudonormal; [vertex] vertex pseudonormal. Not normalised
  // except the face normals; only their directions matter.
  const std::vector<Vec3>& restFaceNormals() const { return face_normals_; }
  const std::vector<Vec3>& restEdgeNormals() const { return edge_normals_; }
  const std::vector<Vec3>& restVertexNormals() const { return vertex_normals_; }

  // The pseudonormal of `feature` of `triangle` at the rest positions (table look-up).
  Vec3 restPseudonormal(TriangleIndex triangle, Feature feature) const;
  // Starts loading what restPseudonormal(triangle, feature) reads (a cache hint, no effect).
  void prefetchRestPseudonormal(TriangleIndex triangle, Feature feature) const;
  // The same at other positions ([vertex], as many as the mesh has, same connectivity),
  // computed from the feature's faces only, for positions of the given orientation (+1: the
  // faces point outward as given, -1: inward; orientationAt()). Equals restPseudonormal() at
  // the rest positions (with their orientation) up to rounding.
  Vec3 pseudonormal(TriangleIndex triangle, Feature feature, const Vec3* positions, double orientation) const;
  // +1 when the closed surface at `positions` encloses a positive volume with its faces as
  // given (they point outward), -1 when a negative one (inward: a mirror image of the rest
  // positions, or an inward mesh); the rest orientation when the volume is zero or not finite
  // (no inside: signs mean nothing there), and for a shape that is not closed(). O(faces).
  double orientationAt(const Vec3* positions) const;
  // orientationAt(positions) with what keeps it under motion (PlacementOrientation); without
  // `with_area`, the volume only (the edge fields stay 0). O(faces).
  PlacementOrientation placementOrientation(const Vec3* positions, bool with_area = true) const;
  // The rest positions' orientation (inward() ? -1 : +1).
  double restOrientation() const { return orientation_; }

  // Memory of the tables in bytes (not counting the hierarchy).
  size_t bytes() const;

 private:
  BodyShape() = default;
  // The table entry restPseudonormal() returns.
  const Vec3& restPseudonormalEntry(TriangleIndex triangle, Feature feature) const;
  // The pseudonormal for the faces' own orientation.
  Vec3 pseudonormalAsGiven(TriangleIndex triangle, Feature feature, const Vec3* positions) const;
  double orientation_ = 1;  // -1: faces point inward, normals flipped
  std::shared_ptr<const Hierarchy> hierarchy_;
  bool closed_ = false;
  std::string open_reason_;
  Vec3 rest_lower_ = Vec3::Zero(), rest_upper_ = Vec3::Zero();
  std::vector<uint32_t> vertex_face_begin_;    // [vertex + 1]
  std::vector<TriangleIndex> vertex_faces_;    // CSR
  std::vector<TriangleIndex> edge_neighbor_;   // [3 * triangle + edge]
  std::vector<Vec3> face_normals_;             // [triangle]
  std::vector<Vec3> edge_normals_;             // [3 * triangle + edge]
  std::vector<Vec3> vertex_normals_;           // [vertex]
  // Closed shapes: [face] its component (faces joined across edges), [component] a vertex of it,
  // the origin of its faces' volume terms (enclosedVolume6 in body.cpp).
  std::vector<uint32_t> face_component_;
  std::vector<VertexIndex> component_origin_;
};

// The side of a query point p of a shape at its rest positions (a body that does not move),
// from p's exact closest point: `closest` on `triangle`, `feature` holding it, at `distance`
// (QueryStream::closest()'s answer, or the first hit of kClosest() or within()). Returns -1
// inside, +1 outside, 0 when the shape is not closed() (no sign). The rule of the service's
// hits (DistanceHit::sign): the closest feature's pseudonormal (any closest point gives the same
// side on a closed surface). A point within 16 eps times the coordinates involved (its own and
// the triangle's) of the surface is on it, and outside: its distance is made of rounding. So
// is a point outside the rest box by more than that (far away, the distances of opposite faces
// tie in doubles).
int restSide(const BodyShape& shape, const Vec3& p, TriangleIndex triangle, Feature feature, const Vec3& closest,
             double distance);
// The same from an exact answer (not an anytime one with a tolerance: its point is not the
// closest), or the first hit of kClosest() or within().
inline int restSide(const BodyShape& shape, const Vec3& p, const ClosestPoint& c) {
  return restSide(shape, p, c.triangle, c.feature, c.point, c.distance);
}
inline int restSide(const BodyShape& shape, const Vec3& p, const TriangleHit& first) {
  return restSide(shape, p, first.triangle, first.feature, first.point, first.distance);
}
// restSide() checked against the faces whose distance to p lies within rounding of the closest
// one (`stream` lists them: any stream of shape.hierarchy(), not one following a path): where
// their sides disagree, the closest face was picked by rounding (beside a needle thinner than
// the rounding of the coordinates, say) and the generalised winding number decides, O(faces).
// Costs a within() query more than restSide(), listed into `hits` (scratch, reused from call
// to call). What `meshsweep closest --signed` prints.
int checkedRestSide(const BodyShape& shape, QueryStream& stream, const Vec3& p, const ClosestPoint& c,
                    std::vector<TriangleHit>& hits);

// The unit normal of triangle (a, b, c) (right-hand rule), zero when its area is zero.
Vec3 unitFaceNormal(const Vec3& a, const Vec3& b, const Vec3& c);

// The corner (0, 1, 2) of a vertex feature, or the first corner of an edge feature
// (kEdge01 -> 0, kEdge12 -> 1, kEdge20 -> 2); -1 for kFace.
int featureCorner(Feature feature);
inline bool isVertexFeature(Feature f) { return f <= Feature::kVertex2; }
inline bool isEdgeFeature(Feature f) { return f >= Feature::kEdge01 && f <= Feature::kEdge20; }

}  // namespace meshsweeper
