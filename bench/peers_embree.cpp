// Embree 3 closest-point peer (see peers.h).
//
// Exactness argument. Embree traverses a BVH whose boxes bound the float copies of the vertices
// and culls a node when the float distance from the float query point to its box exceeds the
// float query radius. Let e_v = max |float(v) - v| over the vertices and e_p = |float(p) - p|.
// Every point of a double triangle is within e_v of the same barycentric point of its float
// triangle, which lies in every box that holds that triangle, so
//   dist(float(p), box) <= dist(p, triangle) + e_v + e_p.
// The callback keeps the best exact double distance d; it writes back the radius
//   r = round_up_to_float((d + e_v + e_p) * (1 + 1e-6)),
// the relative margin covering the few float roundings of Embree's box-distance arithmetic
// (relative error ~1e-7 at most). A node holding a triangle at distance <= d is thus never
// culled, and the minimum found is the exact minimum over all triangles.
//
// Kernels. The callback evaluates one triangle at a time, so its scalar kernel sets Embree's
// speed. EmbreeKernel::kEricson (default) is the textbook Voronoi-region test (Ericson,
// Real-Time Collision Detection, 5.1.5), written here; triangles whose smallest angle has
// sin^2 <= 1e-10 (needles, caps, segments, points) are flagged at build time and go to
// meshsweeper::squaredDistanceToTriangle, which is robust for them. EmbreeKernel::kMeshsweeper
// uses squaredDistanceToTriangle for every triangle.
#include "bench/peers.h"

#include "core/triangle_distance.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace meshsweeper::bench {
namespace {

// One single-threaded device for the process, created on first use (not part of build time).
RTCDevice sharedDevice() {
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

// Squared distance from p to a non-degenerate triangle (a, b, c): Ericson's Voronoi regions.
inline double ericsonSquaredDistance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return ap.squaredNorm();  // vertex a
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return bp.squaredNorm();  // vertex b
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return (ap - (d1 / (d1 - d3)) * ab).squaredNorm();  // ab
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return cp.squaredNorm();  // vertex c
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return (ap - (d2 / (d2 - d6)) * ac).squaredNorm();  // ac
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0)  // edge bc
    return (bp - ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b)).squaredNorm();
  const double inv = 1.0 / (va + vb + vc);  // face
  return (ap - (vb * inv) * ab - (vc * inv) * ac).squaredNorm();
}

// True when the triangle's smallest angle has sin^2 <= 1e-10 (or an edge has length 0):
// Ericson's divisions lose accuracy there.
bool needsRobustKernel(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double ab = (b - a).squaredNorm(), ac = (c - a).squaredNorm(), bc = (c - b).squaredNorm();
  const double twice_area_squared = (b - a).cross(c - a).squaredNorm();
  const double largest_product = std::max({ab * ac, ab * bc, ac * bc});
  return !(twice_area_squared > 1e-10 * largest_product);
}

// Per-query state handed to the callback through userPtr.
struct QueryState {
  const Mesh* mesh;
  const uint8_t* robust;  // [triangle] 1: use squaredDistanceToTriangle (kEricson only)
  Vec3 p;
  double slack;  // e_v + e_p
  double best_squared = std::numeric_limits<double>::infinity();
  TriangleIndex best_triangle = kInvalidIndex;
  uint32_t tested = 0;
};

template <EmbreeKernel kKernel>
bool closestTriangleCallback(RTCPointQueryFunctionArguments* args) {
  auto* state = static_cast<QueryState*>(args->userPtr);
  const TriangleIndex t = args->primID;
  const Triangle& tri = state->mesh->triangles[t];
  const auto& pos = state->mesh->positions;
  const Vec3 &a = pos[tri[0]], &b = pos[tri[1]], &c = pos[tri[2]];
  const double sq = kKernel == EmbreeKernel::kEricson && !state->robust[t]
                        ? ericsonSquaredDistance(state->p, a, b, c)
                        : squaredDistanceToTriangle(state->p, a, b, c);
  ++state->tested;
  if (sq < state->best_squared || (sq == state->best_squared && t < state->best_triangle)) {
    state->best_squared = sq;
    state->best_triangle = t;
    const float r = roundUpToFloat((std::sqrt(sq) + state->slack) * (1.0 + 1e-6));
    if (r < args->query->radius) {
      args->query->radius = r;
      return true;  // the radius shrank: Embree re-culls with it
    }
  }
  return false;
}

}  // namespace

struct EmbreeClosest::Impl {
  const Mesh* mesh = nullptr;
  EmbreeKernel kernel = EmbreeKernel::kEricson;
  std::vector<uint8_t> robust;  // [triangle] kEricson: 1 where the robust kernel is needed
  RTCScene scene = nullptr;
  double vertex_error = 0;
};

EmbreeClosest::EmbreeClosest(const Mesh& mesh, EmbreeKernel kernel)
    : impl_(std::make_unique<Impl>()) {
  impl_->mesh = &mesh;
  impl_->kernel = kernel;
  if (kernel == EmbreeKernel::kEricson) {
    impl_->robust.resize(mesh.triangles.size());
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      const Triangle& tri = mesh.triangles[t];
      impl_->robust[t] =
          needsRobustKernel(mesh.positions[tri[0]], mesh.positions[tri[1]], mesh.positions[tri[2]]);
    }
  }
  RTCDevice device = sharedDevice();
  RTCScene scene = rtcNewScene(device);
  RTCGeometry geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  const size_t vertex_count = mesh.positions.size();
  const size_t triangle_count = mesh.triangles.size();
  auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), vertex_count));
  auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), triangle_count));
  if (!vertices || !indices) {
    rtcReleaseGeometry(geometry);
    rtcReleaseScene(scene);
    throw std::runtime_error("Embree: cannot allocate geometry buffers for " + mesh.name);
  }
  double max_error_squared = 0;
  for (size_t v = 0; v < vertex_count; ++v) {
    const Vec3& x = mesh.positions[v];
    double error_squared = 0;
    for (int axis = 0; axis < 3; ++axis) {
      const float f = static_cast<float>(x[axis]);
      vertices[3 * v + axis] = f;
      const double e = static_cast<double>(f) - x[axis];
      error_squared += e * e;
    }
    if (error_squared > max_error_squared) max_error_squared = error_squared;
  }
  // Round the slack up a little: the sqrt and the squares above are double-rounded.
  impl_->vertex_error = std::sqrt(max_error_squared) * (1.0 + 1e-12);
  for (size_t t = 0; t < triangle_count; ++t)
    for (int c = 0; c < 3; ++c) indices[3 * t + c] = mesh.triangles[t][c];
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(scene);
  const RTCError error = rtcGetDeviceError(device);
  if (error != RTC_ERROR_NONE) {
    rtcReleaseScene(scene);
    throw std::runtime_error("Embree: scene commit failed for " + mesh.name + " (error " +
                             std::to_string(static_cast<int>(error)) + ")");
  }
  impl_->scene = scene;
}

EmbreeClosest::~EmbreeClosest() {
  if (impl_ && impl_->scene) rtcReleaseScene(impl_->scene);
}

double EmbreeClosest::vertexRoundingError() const { return impl_->vertex_error; }

PeerHit EmbreeClosest::closest(const Vec3& p) const {
  QueryState state;
  state.mesh = impl_->mesh;
  state.robust = impl_->robust.data();
  state.p = p;
  RTCPointQuery query;
  query.x = static_cast<float>(p.x());
  query.y = static_cast<float>(p.y());
  query.z = static_cast<float>(p.z());
  query.time = 0.f;
  query.radius = std::numeric_limits<float>::infinity();
  const Vec3 pf(query.x, query.y, query.z);
  state.slack = impl_->vertex_error + (pf - p).norm() * (1.0 + 1e-12);
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(impl_->scene, &query, &context,
                impl_->kernel == EmbreeKernel::kEricson
                    ? closestTriangleCallback<EmbreeKernel::kEricson>
                    : closestTriangleCallback<EmbreeKernel::kMeshsweeper>,
                &state);

  PeerHit hit;
  hit.triangles_tested = state.tested;
  hit.triangle = state.best_triangle;
  if (state.best_triangle != kInvalidIndex) {
    const Triangle& tri = impl_->mesh->triangles[state.best_triangle];
    const auto& pos = impl_->mesh->positions;
    const TriangleClosest c = closestPointOnTriangle(p, pos[tri[0]], pos[tri[1]], pos[tri[2]]);
    hit.point = c.point;
    hit.distance = std::sqrt(c.squared_distance);
  } else {
    hit.distance = std::numeric_limits<double>::infinity();
  }
  return hit;
}

}  // namespace meshsweeper::bench
