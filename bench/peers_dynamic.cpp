// Dynamic peers (see peers_dynamic.h): Embree warm-started and refitted, CGAL hinted and rebuilt.
//
// Exactness of the Embree variants: the argument of peers_embree.cpp. Embree culls a node when
// the float distance from float(p) to its box exceeds the float radius; every box bounds the
// float vertices, which are within e_v of the double ones, so
//   dist(float(p), box) <= dist(p, triangle) + e_v + e_p
// for every triangle below the box. The radius is always (d + e_v + e_p) * (1 + 1e-6) rounded
// up to float, where d is an exact double distance to some triangle. A warm start only changes
// the first d: the distance to the hint triangle, which is >= the true minimum, so the node of
// the true closest triangle is never culled. A refit changes the boxes, not the argument; e_v is
// recomputed for every new set of positions.
#include "bench/peers_dynamic.h"

#include "core/triangle_distance.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>
#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>

namespace meshsweeper::bench {
namespace {

// One single-threaded device for this file's scenes, created on first use.
RTCDevice dynamicDevice() {
  static RTCDevice device = [] {
    RTCDevice d = rtcNewDevice("threads=1");
    if (!d) throw std::runtime_error("Embree: rtcNewDevice(\"threads=1\") failed");
    return d;
  }();
  return device;
}

float roundUpToFloat(double x) {
  float f = static_cast<float>(x);
  if (static_cast<double>(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

// The search radius that keeps every triangle at distance <= d (see the top of the file).
float searchRadius(double d, double slack) { return roundUpToFloat((d + slack) * (1.0 + 1e-6)); }

// The callback's kernel, as EmbreeClosest's default (EmbreeKernel::kEricson, peers.h): the
// Voronoi-region test of Ericson (Real-Time Collision Detection, 5.1.5) for well-shaped
// triangles, meshsweeper::squaredDistanceToTriangle for flagged thin ones. The callback tests
// one triangle at a time, so this kernel sets Embree's speed; both Embree peers use the same.
inline double voronoiSquaredDistance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return ap.squaredNorm();
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return bp.squaredNorm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return (ap - (d1 / (d1 - d3)) * ab).squaredNorm();
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return cp.squaredNorm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return (ap - (d2 / (d2 - d6)) * ac).squaredNorm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) return (bp - ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b)).squaredNorm();
  const double inv = 1.0 / (va + vb + vc);
  return (ap - (vb * inv) * ab - (vc * inv) * ac).squaredNorm();
}

// Thin triangles (smallest angle with sin^2 <= 1e-10, or a zero edge) go to the robust kernel.
std::vector<uint8_t> thinTriangles(const Mesh& mesh) {
  std::vector<uint8_t> thin(mesh.triangles.size());
  for (size_t t = 0; t < thin.size(); ++t) {
    const Vec3& a = mesh.positions[mesh.triangles[t][0]];
    const Vec3& b = mesh.positions[mesh.triangles[t][1]];
    const Vec3& c = mesh.positions[mesh.triangles[t][2]];
    const double ab = (b - a).squaredNorm(), ac = (c - a).squaredNorm(), bc = (c - b).squaredNorm();
    thin[t] = !((b - a).cross(c - a).squaredNorm() > 1e-10 * std::max({ab * ac, ab * bc, ac * bc}));
  }
  return thin;
}

struct QueryState {
  const Mesh* mesh;
  const uint8_t* thin;  // [triangle] 1: squaredDistanceToTriangle
  Vec3 p;
  double slack;  // e_v + e_p
  double best_squared = std::numeric_limits<double>::infinity();
  TriangleIndex best_triangle = kInvalidIndex;
  uint32_t tested = 0;
};

bool closestTriangleCallback(RTCPointQueryFunctionArguments* args) {
  auto* state = static_cast<QueryState*>(args->userPtr);
  const TriangleIndex t = args->primID;
  const Triangle& tri = state->mesh->triangles[t];
  const auto& pos = state->mesh->positions;
  const double sq = state->thin[t] ? squaredDistanceToTriangle(state->p, pos[tri[0]], pos[tri[1]], pos[tri[2]])
                                   : voronoiSquaredDistance(state->p, pos[tri[0]], pos[tri[1]], pos[tri[2]]);
  ++state->tested;
  if (sq < state->best_squared || (sq == state->best_squared && t < state->best_triangle)) {
    state->best_squared = sq;
    state->best_triangle = t;
    const float r = searchRadius(std::sqrt(sq), state->slack);
    if (r < args->query->radius) {
      args->query->radius = r;
      return true;
    }
  }
  return false;
}

// Writes float vertices; returns max |float(v) - v| (Euclidean), rounded up a little.
double writeVertices(const std::vector<Vec3>& positions, float* vertices) {
  double max_error_squared = 0;
  for (size_t v = 0; v < positions.size(); ++v) {
    double error_squared = 0;
    for (int axis = 0; axis < 3; ++axis) {
      const float f = static_cast<float>(positions[v][axis]);
      vertices[3 * v + axis] = f;
      const double e = static_cast<double>(f) - positions[v][axis];
      error_squared += e * e;
    }
    if (error_squared > max_error_squared) max_error_squared = error_squared;
  }
  return std::sqrt(max_error_squared) * (1.0 + 1e-12);
}

// A scene with one triangle geometry. `quality`: scene build quality; `dynamic`: the scene
// flag and REFIT geometry quality. Returns the scene; *vertices is the geometry's float buffer.
RTCScene makeScene(const Mesh& mesh, bool dynamic, float** vertices_out, RTCGeometry* geometry_out, double* error) {
  RTCDevice device = dynamicDevice();
  RTCScene scene = rtcNewScene(device);
  if (dynamic) {
    rtcSetSceneFlags(scene, RTC_SCENE_FLAG_DYNAMIC);
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_LOW);
  }
  RTCGeometry geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  if (dynamic) rtcSetGeometryBuildQuality(geometry, RTC_BUILD_QUALITY_REFIT);
  auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), mesh.positions.size()));
  auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), mesh.triangles.size()));
  if (!vertices || !indices) {
    rtcReleaseGeometry(geometry);
    rtcReleaseScene(scene);
    throw std::runtime_error("Embree: cannot allocate geometry buffers for " + mesh.name);
  }
  *error = writeVertices(mesh.positions, vertices);
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (int c = 0; c < 3; ++c) indices[3 * t + c] = mesh.triangles[t][c];
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene, geometry);
  rtcCommitScene(scene);
  const RTCError status = rtcGetDeviceError(device);
  if (status != RTC_ERROR_NONE) {
    rtcReleaseGeometry(geometry);
    rtcReleaseScene(scene);
    throw std::runtime_error("Embree: scene commit failed for " + mesh.name + " (error " +
                             std::to_string(static_cast<int>(status)) + ")");
  }
  *vertices_out = vertices;
  *geometry_out = geometry;  // still referenced by the caller (released in its destructor)
  return scene;
}

PeerHit query(RTCScene scene, const Mesh& mesh, const uint8_t* thin, double vertex_error, const Vec3& p,
              TriangleIndex hint) {
  QueryState state;
  state.mesh = &mesh;
  state.thin = thin;
  state.p = p;
  RTCPointQuery q;
  q.x = static_cast<float>(p.x());
  q.y = static_cast<float>(p.y());
  q.z = static_cast<float>(p.z());
  q.time = 0.f;
  const Vec3 pf(q.x, q.y, q.z);
  state.slack = vertex_error + (pf - p).norm() * (1.0 + 1e-12);
  q.radius = std::numeric_limits<float>::infinity();
  if (hint != kInvalidIndex) {
    const Triangle& tri = mesh.triangles[hint];
    const Vec3 &a = mesh.positions[tri[0]], &b = mesh.positions[tri[1]], &c = mesh.positions[tri[2]];
    state.best_squared = thin[hint] ? squaredDistanceToTriangle(p, a, b, c) : voronoiSquaredDistance(p, a, b, c);
    state.best_triangle = hint;
    ++state.tested;
    q.radius = searchRadius(std::sqrt(state.best_squared), state.slack);
  }
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(scene, &q, &context, closestTriangleCallback, &state);

  PeerHit hit;
  hit.triangles_tested = state.tested;
  hit.triangle = state.best_triangle;
  if (state.best_triangle == kInvalidIndex) {
    hit.distance = std::numeric_limits<double>::infinity();
    return hit;
  }
  const Triangle& tri = mesh.triangles[state.best_triangle];
  const TriangleClosest c = closestPointOnTriangle(p, mesh.positions[tri[0]], mesh.positions[tri[1]], mesh.positions[tri[2]]);
  hit.point = c.point;
  hit.distance = std::sqrt(c.squared_distance);
  return hit;
}

}  // namespace

// ---- EmbreeWarmClosest ------------------------------------------------------------------------

struct EmbreeWarmClosest::Impl {
  const Mesh* mesh = nullptr;
  std::vector<uint8_t> thin;  // [triangle]
  RTCScene scene = nullptr;
  RTCGeometry geometry = nullptr;
  double vertex_error = 0;
};

EmbreeWarmClosest::EmbreeWarmClosest(const Mesh& mesh) : impl_(std::make_unique<Impl>()) {
  impl_->mesh = &mesh;
  impl_->thin = thinTriangles(mesh);
  float* vertices = nullptr;
  impl_->scene = makeScene(mesh, false, &vertices, &impl_->geometry, &impl_->vertex_error);
}

EmbreeWarmClosest::~EmbreeWarmClosest() {
  if (impl_->geometry) rtcReleaseGeometry(impl_->geometry);
  if (impl_->scene) rtcReleaseScene(impl_->scene);
}

PeerHit EmbreeWarmClosest::closest(const Vec3& p, TriangleIndex hint) const {
  return query(impl_->scene, *impl_->mesh, impl_->thin.data(), impl_->vertex_error, p, hint);
}

// ---- EmbreeRefitScene -------------------------------------------------------------------------

struct EmbreeRefitScene::Impl {
  Mesh mesh;  // current positions (double), read by the exact callback
  std::vector<uint8_t> thin;  // [triangle] at the current positions
  RTCScene scene = nullptr;
  RTCGeometry geometry = nullptr;
  float* vertices = nullptr;
  double vertex_error = 0;
};

EmbreeRefitScene::EmbreeRefitScene(const Mesh& mesh) : impl_(std::make_unique<Impl>()) {
  impl_->mesh = mesh;
  impl_->thin = thinTriangles(mesh);
  impl_->scene = makeScene(impl_->mesh, true, &impl_->vertices, &impl_->geometry, &impl_->vertex_error);
}

EmbreeRefitScene::~EmbreeRefitScene() {
  if (impl_->geometry) rtcReleaseGeometry(impl_->geometry);
  if (impl_->scene) rtcReleaseScene(impl_->scene);
}

void EmbreeRefitScene::setPositions(const std::vector<Vec3>& positions) {
  if (positions.size() != impl_->mesh.positions.size())
    throw std::invalid_argument("EmbreeRefitScene: wrong number of positions");
  impl_->mesh.positions = positions;
  impl_->thin = thinTriangles(impl_->mesh);
  impl_->vertex_error = writeVertices(positions, impl_->vertices);
  rtcUpdateGeometryBuffer(impl_->geometry, RTC_BUFFER_TYPE_VERTEX, 0);
}

void EmbreeRefitScene::commit() {
  rtcCommitGeometry(impl_->geometry);
  rtcCommitScene(impl_->scene);
  const RTCError status = rtcGetDeviceError(dynamicDevice());
  if (status != RTC_ERROR_NONE)
    throw std::runtime_error("Embree: refit commit failed (error " + std::to_string(static_cast<int>(status)) + ")");
}

PeerHit EmbreeRefitScene::closest(const Vec3& p) const {
  return query(impl_->scene, impl_->mesh, impl_->thin.data(), impl_->vertex_error, p, kInvalidIndex);
}

const Mesh& EmbreeRefitScene::mesh() const { return impl_->mesh; }

// ---- CgalHintedClosest ------------------------------------------------------------------------

namespace {
using Kernel = CGAL::Simple_cartesian<double>;
using CgalPoint = Kernel::Point_3;
using CgalTriangle = Kernel::Triangle_3;
using TriangleIterator = std::vector<CgalTriangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<Kernel, TriangleIterator>;
using Traits = CGAL::AABB_traits<Kernel, Primitive>;
using Tree = CGAL::AABB_tree<Traits>;

CgalPoint toCgal(const Vec3& v) { return CgalPoint(v.x(), v.y(), v.z()); }
}  // namespace

struct CgalHintedClosest::Impl {
  std::vector<Triangle> faces;          // [triangle] the mesh's corner indices
  std::vector<CgalTriangle> triangles;  // [triangle] current coordinates; primitives point here
  Tree tree;

  void fill(const std::vector<Vec3>& positions) {
    triangles.clear();
    for (const Triangle& t : faces)
      triangles.emplace_back(toCgal(positions[t[0]]), toCgal(positions[t[1]]), toCgal(positions[t[2]]));
  }
  PeerHit hit(const Tree::Point_and_primitive_id& pp, const Vec3& p) const {
    PeerHit out;
    out.point = Vec3(pp.first.x(), pp.first.y(), pp.first.z());
    out.distance = (out.point - p).norm();
    out.triangle = static_cast<TriangleIndex>(pp.second - triangles.cbegin());
    return out;
  }
};

CgalHintedClosest::CgalHintedClosest(const Mesh& mesh) : impl_(std::make_unique<Impl>()) {
  impl_->faces = mesh.triangles;
  impl_->triangles.reserve(mesh.triangles.size());
  impl_->fill(mesh.positions);
  impl_->tree.insert(impl_->triangles.cbegin(), impl_->triangles.cend());
  impl_->tree.build();
  impl_->tree.accelerate_distance_queries();
}

CgalHintedClosest::~CgalHintedClosest() = default;

PeerHit CgalHintedClosest::closest(const Vec3& p) const {
  return impl_->hit(impl_->tree.closest_point_and_primitive(toCgal(p)), p);
}

PeerHit CgalHintedClosest::closest(const Vec3& p, const PeerHit& hint) const {
  const Tree::Point_and_primitive_id h(toCgal(hint.point), impl_->triangles.cbegin() + hint.triangle);
  return impl_->hit(impl_->tree.closest_point_and_primitive(toCgal(p), h), p);
}

void CgalHintedClosest::rebuild(const std::vector<Vec3>& positions) {
  impl_->fill(positions);  // same size: no reallocation, the iterators stay valid
  impl_->tree.rebuild(impl_->triangles.cbegin(), impl_->triangles.cend());
  impl_->tree.accelerate_distance_queries();
}

}  // namespace meshsweeper::bench
