// Shared per-mesh tables of the distance service: topology, closedness, pseudonormals
// (Baerentzen & Aanaes 2005; see body.h).
#include "collision/body.h"

#include "collision/broadphase.h"
#include "collision/self_intersection.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace meshsweeper {
namespace {

constexpr double kPi = 3.14159265358979323846;

// The solid angle of triangle (a, b, c) seen from p, signed by its orientation (van Oosterom and
// Strackee): summed over a closed surface, 4 pi times its winding number about p.
double solidAngle(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& p) {
  const Vec3 u = a - p, v = b - p, w = c - p;
  const double lu = u.norm(), lv = v.norm(), lw = w.norm();
  return 2 * std::atan2(u.dot(v.cross(w)), lu * lv * lw + u.dot(v) * lw + v.dot(w) * lu + w.dot(u) * lv);
}

// The angle of triangle (a, b, c) at corner a, robust for short edges (atan2, not acos).
double cornerAngle(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 u = b - a, v = c - a;
  return std::atan2(u.cross(v).norm(), u.dot(v));
}

// True when corner c holds a vertex that no earlier corner of t holds (a face with a repeated
// index lists the vertex once).
bool firstOccurrence(const Triangle& t, int c) {
  return c == 0 || (c == 1 && t[1] != t[0]) || (c == 2 && t[2] != t[0] && t[2] != t[1]);
}

Vec3 vertexPseudonormal(const Mesh& mesh, const Vec3* positions, VertexIndex vertex,
                        const TriangleIndex* faces_begin, const TriangleIndex* faces_end) {
  Vec3 sum = Vec3::Zero();
  for (const TriangleIndex* f = faces_begin; f != faces_end; ++f) {
    const Triangle& t = mesh.triangles[*f];
    for (int c = 0; c < 3; ++c) {
      if (t[c] != vertex) continue;
      const Vec3& a = positions[t[c]];
      const Vec3& b = positions[t[(c + 1) % 3]];
      const Vec3& d = positions[t[(c + 2) % 3]];
      sum += cornerAngle(a, b, d) * unitFaceNormal(positions[t[0]], positions[t[1]], positions[t[2]]);
    }
  }
  return sum;
}

// Six times the volume the faces enclose at `positions`, each face's tetrahedron taken from a
// vertex of its own component (origin[component[f]]): the sum of a closed component does not
// depend on the point, and one on the component keeps it accurate wherever the parts lie (about
// one point, parts far apart cancel in rounding). Positive when the faces point outward.
// `magnitude` (optional) receives the sum of the terms' corner products, for their rounding;
// `per_component` (optional) each component's own sum.
double enclosedVolume6(const Mesh& mesh, const Vec3* positions, const std::vector<uint32_t>& component,
                       const std::vector<VertexIndex>& origin, double* magnitude = nullptr,
                       std::vector<double>* per_component = nullptr) {
  double volume6 = 0, size = 0;
  if (per_component) per_component->assign(origin.size(), 0.0);
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    const Triangle& t = mesh.triangles[f];
    const Vec3& o = positions[origin[component[f]]];
    const Vec3 a = positions[t[0]] - o, b = positions[t[1]] - o, c = positions[t[2]] - o;
    const double term = a.dot(b.cross(c));
    volume6 += term;
    if (per_component) (*per_component)[component[f]] += term;
    if (magnitude) size += a.cwiseAbs().maxCoeff() * b.cwiseAbs().maxCoeff() * c.cwiseAbs().maxCoeff();
  }
  if (magnitude) *magnitude = size;
  return volume6;
}

// The components of a closed surface: faces joined across edges (edge_neighbor, every edge of a
// closed surface has its neighbour). component[f] numbers them in order of their first face;
// first_face[c] is that face.
void labelComponents(const Mesh& mesh, const std::vector<TriangleIndex>& edge_neighbor,
                     std::vector<uint32_t>& component, std::vector<TriangleIndex>& first_face) {
  const size_t face_count = mesh.triangles.size();
  constexpr uint32_t kNone = 0xffffffffu;
  component.assign(face_count, kNone);
  first_face.clear();
  std::vector<TriangleIndex> stack;
  for (size_t seed = 0; seed < face_count; ++seed) {
    if (component[seed] != kNone) continue;
    const uint32_t c = static_cast<uint32_t>(first_face.size());
    first_face.push_back(static_cast<TriangleIndex>(seed));
    component[seed] = c;
    stack.assign(1, static_cast<TriangleIndex>(seed));
    while (!stack.empty()) {
      const TriangleIndex f = stack.back();
      stack.pop_back();
      for (int k = 0; k < 3; ++k) {
        const TriangleIndex g = edge_neighbor[3 * static_cast<size_t>(f) + k];
        if (g != kInvalidIndex && component[g] == kNone) {
          component[g] = c;
          stack.push_back(g);
        }
      }
    }
  }
}

// Why the surface is not embedded (two of its faces intersect), "" when it is. A mesh the test
// cannot take (CGAL's Surface_mesh refused a face: never seen for a closed, manifold one) is
// not trusted either.
std::string crossingFaces(const Mesh& mesh) {
  try {
    if (const auto pair = firstSelfIntersection(mesh))
      return "faces " + std::to_string(pair->first) + " and " + std::to_string(pair->second) +
             " intersect (a self-intersecting surface)";
  } catch (const std::runtime_error& e) {
    return std::string("not checked for self-intersections: ") + e.what();
  }
  return "";
}

// Why the components of a closed, embedded surface (no face crossing another) do not bound one
// solid, "" when they do. Faces point outward as given when `orientation` is +1 (inward: -1).
// Every point off the surface must then have winding number 0 (outside) or 1 (inside), so a
// component facing out must lie outside every other (winding number 0 of the others at its
// vertices) and one facing in, a cavity, inside them (1). A ball inside a ball, both facing
// out, fails: between them the inner ball's faces say outside. The winding number (van
// Oosterom & Strackee solid angles) counts only the components whose box holds the vertex, and
// is taken at three vertices of each component (of its first, middle and last face): each must
// agree, so one that lies within rounding of another component's face (where a solid angle of
// about 2 pi can take either sign) cannot pass a wrong nesting. Bounded work: a mesh of more
// than kMaxComponents components, or whose test would take more than kMaxSolidAngles solid
// angles, is not checked (and not trusted).
// volume6[c]: component c's enclosed volume (enclosedVolume6's per_component).
std::string nestingProblem(const Mesh& mesh, const std::vector<uint32_t>& component,
                           const std::vector<TriangleIndex>& first_face, const std::vector<double>& volume6,
                           double orientation) {
  const size_t face_count = mesh.triangles.size();
  const size_t count = first_face.size();
  if (count == 1) return "";
  // Pairs of boxes are compared: a bound on the work for meshes of very many components.
  constexpr size_t kMaxComponents = 20000;
  constexpr uint64_t kMaxSolidAngles = 60'000'000;
  if (count > kMaxComponents)
    return std::to_string(count) + " components (more than " + std::to_string(kMaxComponents) +
           ": how they nest is not checked)";
  const auto& x = mesh.positions;
  std::vector<Vec3> lower(count, Vec3::Constant(std::numeric_limits<double>::infinity()));
  std::vector<Vec3> upper(count, Vec3::Constant(-std::numeric_limits<double>::infinity()));
  std::vector<uint32_t> begin(count + 1, 0);
  for (size_t f = 0; f < face_count; ++f) {
    const uint32_t c = component[f];
    ++begin[c + 1];
    for (VertexIndex v : mesh.triangles[f]) {
      lower[c] = lower[c].cwiseMin(x[v]);
      upper[c] = upper[c].cwiseMax(x[v]);
    }
  }
  for (size_t c = 0; c < count; ++c) begin[c + 1] += begin[c];
  std::vector<TriangleIndex> faces(face_count);
  {
    std::vector<uint32_t> fill(begin.begin(), begin.end() - 1);
    for (size_t f = 0; f < face_count; ++f) faces[fill[component[f]]++] = static_cast<TriangleIndex>(f);
  }
  uint64_t solid_angles = 0;
  for (size_t c = 0; c < count; ++c) {
    const double own = volume6[c] * orientation;
    if (!(own != 0))
      return "the component of face " + std::to_string(first_face[c]) + " encloses no volume";
    const double expected = own > 0 ? 0.0 : 1.0;
    const uint32_t middle = begin[c] + (begin[c + 1] - begin[c]) / 2;
    for (const TriangleIndex face : {first_face[c], faces[middle], faces[begin[c + 1] - 1]}) {
      const Vec3& p = x[mesh.triangles[face][0]];
      double winding = 0;
      for (size_t d = 0; d < count; ++d) {
        if (d == c || (p.array() < lower[d].array()).any() || (p.array() > upper[d].array()).any()) continue;
        solid_angles += begin[d + 1] - begin[d];
        if (solid_angles > kMaxSolidAngles)
          return std::to_string(count) + " components, nested too deep to check how (more than " +
                 std::to_string(kMaxSolidAngles) + " solid angles)";
        for (uint32_t i = begin[d]; i < begin[d + 1]; ++i) {
          const Triangle& t = mesh.triangles[faces[i]];
          winding += solidAngle(x[t[0]], x[t[1]], x[t[2]], p);
        }
      }
      winding *= orientation / (4 * kPi);
      if (!(std::abs(winding - expected) < 0.5))
        return "the component of face " + std::to_string(first_face[c]) + " lies " +
               (own > 0 ? "inside another component, both facing out" : "outside the others, facing in") +
               " (winding number " + std::to_string(static_cast<long>(std::lround(winding))) +
               " of the others at a vertex of face " + std::to_string(face) + ")";
    }
  }
  return "";
}

}  // namespace

Vec3 unitFaceNormal(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const double length = n.norm();
  return length > 0 ? Vec3(n / length) : Vec3::Zero();
}

int featureCorner(Feature feature) {
  switch (feature) {
    case Feature::kVertex0: return 0;
    case Feature::kVertex1: return 1;
    case Feature::kVertex2: return 2;
    case Feature::kEdge01: return 0;
    case Feature::kEdge12: return 1;
    case Feature::kEdge20: return 2;
    case Feature::kFace: return -1;
  }
  return -1;
}

std::shared_ptr<const BodyShape> BodyShape::build(std::shared_ptr<const Hierarchy> hierarchy) {
  if (!hierarchy) throw std::invalid_argument("BodyShape: null hierarchy");
  std::shared_ptr<BodyShape> shape(new BodyShape());
  shape->hierarchy_ = std::move(hierarchy);
  const Mesh& mesh = shape->hierarchy_->mesh();
  const size_t vertex_count = mesh.positions.size();
  const size_t face_count = mesh.triangles.size();
  meshBounds(mesh, shape->rest_lower_, shape->rest_upper_);

  // [vertex] incident faces, CSR.
  auto& begin = shape->vertex_face_begin_;
  begin.assign(vertex_count + 1, 0);
  for (const Triangle& t : mesh.triangles)
    for (int c = 0; c < 3; ++c)
      if (firstOccurrence(t, c)) ++begin[t[c] + 1];
  for (size_t v = 0; v < vertex_count; ++v) begin[v + 1] += begin[v];
  shape->vertex_faces_.resize(begin[vertex_count]);
  {
    std::vector<uint32_t> fill(begin.begin(), begin.end() - 1);
    for (size_t f = 0; f < face_count; ++f) {
      const Triangle& t = mesh.triangles[f];
      for (int c = 0; c < 3; ++c)
        if (firstOccurrence(t, c)) shape->vertex_faces_[fill[t[c]]++] = static_cast<TriangleIndex>(f);
    }
  }

  // Edges: sort (min, max, directed?) records; a closed edge has exactly two, opposite.
  struct EdgeRecord {
    VertexIndex lo, hi;
    uint32_t half;   // 3 * face + edge
    bool forward;    // lo -> hi in the face's orientation
  };
  std::vector<EdgeRecord> edges;
  edges.reserve(3 * face_count);
  std::string reason;
  for (size_t f = 0; f < face_count; ++f) {
    const Triangle& t = mesh.triangles[f];
    if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) {
      if (reason.empty()) reason = "face " + std::to_string(f) + " repeats a vertex";
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      const VertexIndex a = t[k], b = t[(k + 1) % 3];
      edges.push_back({std::min(a, b), std::max(a, b), static_cast<uint32_t>(3 * f + k), a < b});
    }
  }
  std::sort(edges.begin(), edges.end(), [](const EdgeRecord& x, const EdgeRecord& y) {
    return x.lo != y.lo ? x.lo < y.lo : x.hi != y.hi ? x.hi < y.hi : x.half < y.half;
  });
  shape->edge_neighbor_.assign(3 * face_count, kInvalidIndex);
  for (size_t i = 0; i < edges.size();) {
    size_t j = i + 1;
    while (j < edges.size() && edges[j].lo == edges[i].lo && edges[j].hi == edges[i].hi) ++j;
    if (j - i == 2) {
      shape->edge_neighbor_[edges[i].half] = edges[i + 1].half / 3;
      shape->edge_neighbor_[edges[i + 1].half] = edges[i].half / 3;
      if (edges[i].forward == edges[i + 1].forward && reason.empty())
        reason = "faces " + std::to_string(edges[i].half / 3) + " and " +
                 std::to_string(edges[i + 1].half / 3) + " are oriented inconsistently";
    } else if (reason.empty()) {
      reason = "edge (" + std::to_string(edges[i].lo) + ", " + std::to_string(edges[i].hi) + ") has " +
               std::to_string(j - i) + (j - i == 1 ? " face (boundary)" : " faces (non-manifold)");
    }
    i = j;
  }

  // Every vertex's faces must form one fan (else two surfaces touch at the vertex).
  if (reason.empty()) {
    std::vector<TriangleIndex> stack;
    std::vector<TriangleIndex> seen;
    for (VertexIndex v = 0; v < vertex_count && reason.empty(); ++v) {
      const uint32_t first = begin[v], last = begin[v + 1];
      if (first == last) continue;
      seen.assign(1, shape->vertex_faces_[first]);
      stack.assign(1, shape->vertex_faces_[first]);
      while (!stack.empty()) {
        const TriangleIndex f = stack.back();
        stack.pop_back();
        const Triangle& t = mesh.triangles[f];
        const int c = t[0] == v ? 0 : t[1] == v ? 1 : 2;
        for (int k : {c, (c + 2) % 3}) {  // the two edges of f that hold v
          const TriangleIndex g = shape->edge_neighbor_[3 * f + k];
          if (g != kInvalidIndex && std::find(seen.begin(), seen.end(), g) == seen.end()) {
            seen.push_back(g);
            stack.push_back(g);
          }
        }
      }
      if (seen.size() != last - first)
        reason = "vertex " + std::to_string(v) + " joins several fans of faces (non-manifold vertex)";
    }
  }

  // Rest pseudonormals. A degenerate face (one the exact distance answers by its segments: zero
  // area, or a cap within about 2e-6 degree of 180) has no reliable normal, and where it is
  // closest the feature is decided by rounding: its pseudonormals would not decide the sign, so
  // a mesh with one is treated as open (unsigned answers, never a wrong sign).
  const auto& pos = mesh.positions;
  shape->face_normals_.resize(face_count);
  for (size_t f = 0; f < face_count; ++f) {
    const Triangle& t = mesh.triangles[f];
    shape->face_normals_[f] = unitFaceNormal(pos[t[0]], pos[t[1]], pos[t[2]]);
    if (reason.empty() && isDegenerateTriangle(pos[t[0]], pos[t[1]], pos[t[2]]))
      reason = "face " + std::to_string(f) +
               (shape->face_normals_[f].squaredNorm() == 0 ? " has zero area"
                                                            : " is degenerate (an angle within 2e-6 degree of 180)");
  }
  // Orientation: a closed surface whose faces point inward encloses a negative volume (summed
  // over the faces, each part about a vertex of its own). It is the same solid: its normals are flipped, so
  // that signs still say inside and outside. One enclosing no volume has no inside.
  // A surface that intersects itself encloses no one solid: the sides of its faces, and so its
  // pseudonormals, do not tell inside from outside (a point inside one part can lie outside
  // the faces of another, nearer part). So do components nested the wrong way (nestingProblem).
  // Both are treated as open too: unsigned answers, never a wrong sign.
  if (reason.empty()) {
    std::vector<TriangleIndex> first_face;
    labelComponents(mesh, shape->edge_neighbor_, shape->face_component_, first_face);
    shape->component_origin_.resize(first_face.size());
    for (size_t c = 0; c < first_face.size(); ++c) shape->component_origin_[c] = mesh.triangles[first_face[c]][0];
    std::vector<double> component_volume6;
    const double volume6 = enclosedVolume6(mesh, pos.data(), shape->face_component_, shape->component_origin_,
                                           nullptr, &component_volume6);
    if (!(volume6 != 0)) {
      reason = "the surface encloses no volume";
    } else if (const std::string crossing = crossingFaces(mesh); !crossing.empty()) {
      reason = crossing;
    } else if (std::string nested = nestingProblem(mesh, shape->face_component_, first_face, component_volume6,
                                                   volume6 < 0 ? -1.0 : 1.0);
               !nested.empty()) {
      reason = nested;
    } else {
      shape->orientation_ = volume6 < 0 ? -1.0 : 1.0;
      for (Vec3& n : shape->face_normals_) n *= shape->orientation_;
    }
  }
  shape->closed_ = reason.empty();
  shape->open_reason_ = reason;
  shape->edge_normals_.resize(3 * face_count);
  for (size_t h = 0; h < 3 * face_count; ++h) {
    const TriangleIndex g = shape->edge_neighbor_[h];
    shape->edge_normals_[h] = shape->face_normals_[h / 3] +
                              (g != kInvalidIndex ? shape->face_normals_[g] : Vec3::Zero());
  }
  shape->vertex_normals_.assign(vertex_count, Vec3::Zero());
  for (size_t f = 0; f < face_count; ++f) {
    const Triangle& t = mesh.triangles[f];
    if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) continue;
    for (int c = 0; c < 3; ++c)
      shape->vertex_normals_[t[c]] +=
          cornerAngle(pos[t[c]], pos[t[(c + 1) % 3]], pos[t[(c + 2) % 3]]) * shape->face_normals_[f];
  }
  return shape;
}

const Vec3& BodyShape::restPseudonormalEntry(TriangleIndex triangle, Feature feature) const {
  if (feature == Feature::kFace) return face_normals_[triangle];
  const int corner = featureCorner(feature);
  if (isEdgeFeature(feature)) return edge_normals_[3 * static_cast<size_t>(triangle) + corner];
  return vertex_normals_[mesh().triangles[triangle][corner]];
}

Vec3 BodyShape::restPseudonormal(TriangleIndex triangle, Feature feature) const {
  return restPseudonormalEntry(triangle, feature);
}

void BodyShape::prefetchRestPseudonormal(TriangleIndex triangle, Feature feature) const {
  const Vec3* where = &restPseudonormalEntry(triangle, feature);
  __builtin_prefetch(where);
  __builtin_prefetch(reinterpret_cast<const char*>(where + 1) - 1);  // a Vec3 may straddle two lines
}

Vec3 BodyShape::pseudonormal(TriangleIndex triangle, Feature feature, const Vec3* positions,
                              double orientation) const {
  return orientation * pseudonormalAsGiven(triangle, feature, positions);
}

double PlacementOrientation::grownArea2(double delta) const {
  // A face's area grows to at most (|ab x ac| + 2 delta (|ab| + |ac|) + 4 delta^2) / 2: each
  // edge moves by 2 delta at most.
  return edge_products + 2 * delta * edge_sums + 4 * delta * delta * faces;
}

bool PlacementOrientation::holdsWithin(double delta) const { return holdsWithin(delta, grownArea2(delta)); }

bool PlacementOrientation::holdsWithin(double delta, double area2) const {
  if (!closed) return true;
  if (!(delta >= 0)) return false;
  // |d volume6| <= 6 delta area.
  return std::abs(volume6) - rounding > 3 * delta * area2 * (1 + 1e-12);
}

PlacementOrientation BodyShape::placementOrientation(const Vec3* positions, bool with_area) const {
  PlacementOrientation out;
  out.orientation = orientation_;
  const Mesh& m = mesh();
  if (!closed_ || m.triangles.empty()) return out;
  out.closed = true;
  // About a vertex of each face's own component: the sum stays well conditioned wherever the
  // body is placed and however far apart its parts lie.
  double magnitude = 0;
  out.volume6 = enclosedVolume6(m, positions, face_component_, component_origin_, &magnitude);
  if (with_area) {
    for (const Triangle& t : m.triangles) {
      const Vec3 ab = positions[t[1]] - positions[t[0]], ac = positions[t[2]] - positions[t[0]];
      out.edge_products += ab.cross(ac).norm();
      out.edge_sums += ab.norm() + ac.norm();
    }
  }
  out.faces = static_cast<double>(m.triangles.size());
  // Each term (at most 6 times the product of its corners' largest coordinates) errs by a few
  // eps of that, the sum by eps per term at most.
  out.rounding = 6 * (out.faces + 16) * std::numeric_limits<double>::epsilon() * magnitude;
  if (out.volume6 > 0) out.orientation = 1.0;
  else if (out.volume6 < 0) out.orientation = -1.0;
  return out;
}

double BodyShape::orientationAt(const Vec3* positions) const {
  return placementOrientation(positions, false).orientation;
}

Vec3 BodyShape::pseudonormalAsGiven(TriangleIndex triangle, Feature feature, const Vec3* positions) const {
  const Mesh& m = mesh();
  const Triangle& t = m.triangles[triangle];
  if (feature == Feature::kFace) return unitFaceNormal(positions[t[0]], positions[t[1]], positions[t[2]]);
  const int corner = featureCorner(feature);
  if (isEdgeFeature(feature)) {
    Vec3 n = unitFaceNormal(positions[t[0]], positions[t[1]], positions[t[2]]);
    const TriangleIndex g = edge_neighbor_[3 * triangle + corner];
    if (g != kInvalidIndex) {
      const Triangle& u = m.triangles[g];
      n += unitFaceNormal(positions[u[0]], positions[u[1]], positions[u[2]]);
    }
    return n;
  }
  const VertexIndex v = t[corner];
  return vertexPseudonormal(m, positions, v, vertex_faces_.data() + vertex_face_begin_[v],
                            vertex_faces_.data() + vertex_face_begin_[v + 1]);
}

int restSide(const BodyShape& shape, const Vec3& p, TriangleIndex triangle, Feature feature, const Vec3& closest,
             double distance) {
  if (!shape.closed()) return 0;
  const Triangle& t = shape.mesh().triangles[triangle];
  double scale = p.cwiseAbs().maxCoeff();
  for (int k = 0; k < 3; ++k) scale = std::max(scale, shape.mesh().positions[t[k]].cwiseAbs().maxCoeff());
  const double touch = 16 * std::numeric_limits<double>::epsilon() * scale;
  const Vec3 offset = p - closest;
  if (!(distance > touch) || !(offset.squaredNorm() > 0)) return 1;  // on the surface
  if (squaredBoxDistance(Box3{shape.restLower(), shape.restUpper()}, p) > touch * touch) return 1;
  return offset.dot(shape.restPseudonormal(triangle, feature)) < 0 ? -1 : 1;
}

int checkedRestSide(const BodyShape& shape, QueryStream& stream, const Vec3& p, const ClosestPoint& c,
                    std::vector<TriangleHit>& hits) {
  const int side = restSide(shape, p, c);
  if (side == 0 || c.triangle == kInvalidIndex) return side;
  // The rounding of a computed distance: a few eps times the coordinates of p and of the mesh.
  const double scale = std::max({p.cwiseAbs().maxCoeff(), shape.restLower().cwiseAbs().maxCoeff(),
                                 shape.restUpper().cwiseAbs().maxCoeff()});
  const double rounding = 64 * std::numeric_limits<double>::epsilon() * scale;
  stream.within(p, c.distance + rounding, hits);
  bool agree = true;
  for (const TriangleHit& h : hits) agree = agree && restSide(shape, p, h) == side;
  if (agree) return side;
  // The generalised winding number: about +-1 inside (its sign follows the faces' orientation),
  // 0 outside, also in a cavity.
  const Mesh& mesh = shape.mesh();
  double total = 0;
  for (const Triangle& t : mesh.triangles)
    total += solidAngle(mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]], p);
  return std::abs(total) > 2 * kPi ? -1 : 1;  // |winding number| > 1/2
}

size_t BodyShape::bytes() const {
  return vertex_face_begin_.size() * sizeof(uint32_t) + vertex_faces_.size() * sizeof(TriangleIndex) +
         edge_neighbor_.size() * sizeof(TriangleIndex) +
         (face_normals_.size() + edge_normals_.size() + vertex_normals_.size()) * sizeof(Vec3) +
         face_component_.size() * sizeof(uint32_t) + component_origin_.size() * sizeof(VertexIndex);
}

}  // namespace meshsweeper
