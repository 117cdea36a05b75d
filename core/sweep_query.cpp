// Queries over the Meshsweeper hierarchy (Guéziec, "Meshsweeper", sections 3.2, 4.3, 4.4;
// DESIGN.md section 2).
//
// Fresh exact query (depth-first):
//   stack <- {root}; best <- infinity
//   while stack: pop (entry, bound); skip if bound > best
//     leaf block: exact squared distances of its 8 faces at once; best <- min
//     node: float box bounds of its 8 children at once; push those below best, farthest first
//   the closest point on the best face, recomputed with the scalar exact routine
//
// Priority process (anytime, k closest): the front is a heap keyed by a lower bound,
//   max(box distance, d(p, slot triangle) - eps); the slot triangle's corners are surface
//   points, so their distances (and exact face distances) give the upper bound. Pop the front:
//   a face entry is exact; a node pushes its children; a leaf block pushes its faces.
//   Anytime: stop when upper - lower <= tolerance. k closest: stop after k faces.
// Within d: depth-first like the fresh query with the fixed radius d (every node whose bound
//   is within d must be opened whatever the order, so no heap is needed).
//
// Float boxes are conservative: stored rounded outward and widened by a margin that covers the
// rounding of the query point (hierarchy_build.cpp); the pruning threshold gets a relative slack
// for the float arithmetic. Points farther than ~1e15 mesh radii from the mesh skip box pruning.
#include "core/sweep_query.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>

#if defined(__AVX__)
#include <immintrin.h>
#endif

namespace meshsweeper {
namespace {

constexpr float kFloatInf = std::numeric_limits<float>::infinity();
constexpr double kInf = std::numeric_limits<double>::infinity();
// Relative slack on float box bounds (float rounding of a few operations is ~1e-7).
constexpr double kBoxSlack = 1e-5;
constexpr double kFarLimit = 1e15;

// Squared distances, in the hierarchy's scaled float units, from q to the node's eight boxes.
inline void boxDistances(const Node8& n, const float q[3], float out[8]) {
#if defined(__AVX__)
  __m256 acc = _mm256_setzero_ps();
  const __m256 zero = _mm256_setzero_ps();
  for (int axis = 0; axis < 3; ++axis) {
    const __m256 qa = _mm256_set1_ps(q[axis]);
    const __m256 below = _mm256_sub_ps(_mm256_load_ps(n.lower[axis]), qa);
    const __m256 above = _mm256_sub_ps(qa, _mm256_load_ps(n.upper[axis]));
    const __m256 gap = _mm256_max_ps(_mm256_max_ps(below, above), zero);
    acc = _mm256_add_ps(acc, _mm256_mul_ps(gap, gap));
  }
  _mm256_storeu_ps(out, acc);
#else
  for (int k = 0; k < 8; ++k) {
    float acc = 0;
    for (int axis = 0; axis < 3; ++axis) {
      const float gap = std::max(std::max(n.lower[axis][k] - q[axis], q[axis] - n.upper[axis][k]), 0.0f);
      acc += gap * gap;
    }
    out[k] = acc;
  }
#endif
}

struct ScaledPoint {
  float q[3];
  bool far;  // too far for float boxes: every box bound is taken as 0
};

ScaledPoint scalePoint(const Hierarchy& h, const Vec3& p) {
  ScaledPoint s{};
  const Vec3 local = (p - h.center()) * h.boxScale();
  s.far = !(local.cwiseAbs().maxCoeff() < kFarLimit);
  for (int axis = 0; axis < 3; ++axis) s.q[axis] = s.far ? 0.0f : static_cast<float>(local[axis]);
  return s;
}

// Float threshold in scaled units above which a box bound proves a squared distance > best2.
inline float pruneThreshold(double best2, double scale2) {
  const double t = best2 * scale2 * (1 + kBoxSlack);
  return t < 3e38 ? static_cast<float>(t) : kFloatInf;
}

// A lower bound, in mesh units, on the distance to anything inside a box with float bound d2.
inline double boxLowerBound(float d2, double inv_scale) {
  return std::sqrt(static_cast<double>(d2) * (1 - kBoxSlack)) * inv_scale;
}

TriangleHit makeHit(const Mesh& mesh, TriangleIndex f, const Vec3& p) {
  const Triangle& t = mesh.triangles[f];
  const TriangleClosest c =
      closestPointOnTriangle(p, mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]);
  TriangleHit hit;
  hit.distance = std::sqrt(c.squared_distance);
  hit.triangle = f;
  hit.point = c.point;
  hit.barycentric = c.barycentric;
  hit.feature = c.feature;
  return hit;
}

void fillFromHit(ClosestPoint& out, const TriangleHit& hit) {
  out.distance = out.lower = out.upper = hit.distance;
  out.point = hit.point;
  out.triangle = hit.triangle;
  out.barycentric = hit.barycentric;
  out.feature = hit.feature;
}

bool hitBefore(const TriangleHit& a, const TriangleHit& b) {
  return a.distance != b.distance ? a.distance < b.distance : a.triangle < b.triangle;
}

}  // namespace

QueryStream::QueryStream(std::shared_ptr<const Hierarchy> hierarchy)
    : hierarchy_(std::move(hierarchy)) {
  assert(hierarchy_);
  stack_.reserve(64);
  heap_.reserve(64);
}

ClosestPoint QueryStream::closest(const Vec3& p) {
  const Hierarchy& h = *hierarchy_;
  counters_ = {};
  const ScaledPoint sp = scalePoint(h, p);
  const double scale2 = h.boxScale() * h.boxScale();
  const auto& nodes = h.nodes();
  const auto& blocks = h.leafBlocks();
  const auto& lanes = h.leafTriangles();

  double best2 = kInf;
  TriangleIndex best_face = kInvalidIndex;
  float threshold = kFloatInf;
  stack_.clear();
  stack_.push_back({0, 0.0f});
  float dist[8];
  double exact[8];
  while (!stack_.empty()) {
    const StackEntry entry = stack_.back();
    stack_.pop_back();
    if (entry.bound > threshold) continue;
    if (isLeafRef(entry.ref)) {
      const int32_t leaf = leafIndex(entry.ref);
      squaredDistancesToBlock(p, blocks[leaf], exact);
      const uint32_t used = h.leafLanes(leaf);
      ++counters_.leaves_tested;
      counters_.triangles_tested += used;
      for (uint32_t lane = 0; lane < used; ++lane) {
        if (exact[lane] < best2) {
          best2 = exact[lane];
          best_face = lanes[8 * leaf + lane];
        }
      }
      threshold = pruneThreshold(best2, scale2);
      continue;
    }
    const Node8& node = nodes[entry.ref];
    ++counters_.nodes_visited;
    if (sp.far) std::fill(dist, dist + 8, 0.0f); else boxDistances(node, sp.q, dist);
    // Children below the threshold, pushed farthest first so the closest is popped next.
    StackEntry open[8];
    int count = 0;
    for (int k = 0; k < 8; ++k) {
      if (node.child[k] == kEmptyChild || dist[k] > threshold) continue;
      int i = count++;
      while (i > 0 && open[i - 1].bound < dist[k]) { open[i] = open[i - 1]; --i; }
      open[i] = {node.child[k], dist[k]};
    }
    stack_.insert(stack_.end(), open, open + count);
  }

  ClosestPoint out;
  out.counters = counters_;
  if (best_face == kInvalidIndex) {  // only for a non-finite query point
    out.distance = out.lower = out.upper = std::numeric_limits<double>::quiet_NaN();
    return out;
  }
  fillFromHit(out, makeHit(h.mesh(), best_face, p));
  return out;
}

ClosestPoint QueryStream::closestWithin(const Vec3& p, double tolerance) {
  const Hierarchy& h = *hierarchy_;
  const Mesh& mesh = h.mesh();
  counters_ = {};
  const ScaledPoint sp = scalePoint(h, p);
  const double inv_scale = 1.0 / h.boxScale();
  const auto& nodes = h.nodes();
  const auto& blocks = h.leafBlocks();
  const auto& lanes = h.leafTriangles();

  // The upper bound and the surface point that realises it: a face (exact) or a vertex.
  double upper = kInf;
  TriangleIndex upper_face = kInvalidIndex;
  VertexIndex upper_vertex = kInvalidIndex;
  auto offerVertex = [&](VertexIndex v) {
    const double d = (mesh.positions[v] - p).norm();
    if (d < upper) { upper = d; upper_vertex = v; upper_face = kInvalidIndex; }
  };

  auto before = [](const FrontEntry& a, const FrontEntry& b) { return a.key > b.key; };
  heap_.clear();
  heap_.push_back({0.0, 0, 8});
  double lower = 0;
  float dist[8];
  double exact[8];
  while (true) {
    if (heap_.empty()) { lower = upper; break; }
    lower = std::min(heap_.front().key, upper);
    if (upper - lower <= tolerance) break;
    std::pop_heap(heap_.begin(), heap_.end(), before);
    const FrontEntry entry = heap_.back();
    heap_.pop_back();
    if (isLeafRef(entry.ref)) {
      const int32_t leaf = leafIndex(entry.ref);
      squaredDistancesToBlock(p, blocks[leaf], exact);
      const uint32_t used = h.leafLanes(leaf);
      ++counters_.leaves_tested;
      counters_.triangles_tested += used;
      for (uint32_t lane = 0; lane < used; ++lane) {
        const double d = std::sqrt(exact[lane]);
        if (d < upper) { upper = d; upper_face = lanes[8 * leaf + lane]; upper_vertex = kInvalidIndex; }
      }
      continue;
    }
    const Node8& node = nodes[entry.ref];
    ++counters_.nodes_visited;
    if (sp.far) std::fill(dist, dist + 8, 0.0f); else boxDistances(node, sp.q, dist);
    for (int k = 0; k < 8; ++k) {
      if (node.child[k] == kEmptyChild) continue;
      const Vec3& a = mesh.positions[node.corner[0][k]];
      const Vec3& b = mesh.positions[node.corner[1][k]];
      const Vec3& c = mesh.positions[node.corner[2][k]];
      for (int corner = 0; corner < 3; ++corner) offerVertex(node.corner[corner][k]);
      const double to_triangle = std::sqrt(squaredDistanceToTriangle(p, a, b, c));
      const double key = std::max(boxLowerBound(dist[k], inv_scale),
                                  to_triangle * (1 - 1e-12) - node.eps[k]);
      if (key < upper) {
        heap_.push_back({key, node.child[k], 8});
        std::push_heap(heap_.begin(), heap_.end(), before);
      }
    }
    counters_.heap_max = std::max<uint32_t>(counters_.heap_max, static_cast<uint32_t>(heap_.size()));
  }

  ClosestPoint out;
  out.counters = counters_;
  if (upper_face != kInvalidIndex) {
    fillFromHit(out, makeHit(mesh, upper_face, p));
  } else if (upper_vertex != kInvalidIndex) {
    const TriangleIndex f = h.vertexFace()[upper_vertex];
    const Triangle& t = mesh.triangles[f];
    const int k = t[0] == upper_vertex ? 0 : t[1] == upper_vertex ? 1 : 2;
    out.distance = upper;
    out.point = mesh.positions[upper_vertex];
    out.triangle = f;
    out.barycentric = Vec3::Zero();
    out.barycentric[k] = 1;
    out.feature = static_cast<Feature>(k);
  } else {
    out.distance = std::numeric_limits<double>::quiet_NaN();
    out.lower = out.upper = out.distance;
    return out;
  }
  out.upper = out.distance;
  out.lower = std::min(lower, out.distance);
  return out;
}

void QueryStream::kClosest(const Vec3& p, size_t k, std::vector<TriangleHit>& out) {
  const Hierarchy& h = *hierarchy_;
  const Mesh& mesh = h.mesh();
  out.clear();
  counters_ = {};
  if (k == 0) return;
  const ScaledPoint sp = scalePoint(h, p);
  const double inv_scale = 1.0 / h.boxScale();
  const auto& nodes = h.nodes();
  const auto& lanes = h.leafTriangles();

  // Front order: smaller key first; at equal keys, bounds (lane 8) before exact faces, so a
  // subtree that may hold an equally distant face is opened first; faces by triangle index.
  auto before = [](const FrontEntry& a, const FrontEntry& b) {
    if (a.key != b.key) return a.key > b.key;
    const bool a_face = a.lane < 8, b_face = b.lane < 8;
    if (a_face != b_face) return a_face;
    return a_face && a.ref > b.ref;  // for faces, ref holds the triangle index
  };
  auto push = [&](const FrontEntry& e) {
    heap_.push_back(e);
    std::push_heap(heap_.begin(), heap_.end(), before);
  };
  heap_.clear();
  push({0.0, 0, 8});
  float dist[8];
  while (!heap_.empty() && out.size() < k) {
    std::pop_heap(heap_.begin(), heap_.end(), before);
    const FrontEntry entry = heap_.back();
    heap_.pop_back();
    if (entry.lane < 8) {
      out.push_back(makeHit(mesh, static_cast<TriangleIndex>(entry.ref), p));
      continue;
    }
    if (isLeafRef(entry.ref)) {
      const int32_t leaf = leafIndex(entry.ref);
      const uint32_t used = h.leafLanes(leaf);
      ++counters_.leaves_tested;
      counters_.triangles_tested += used;
      for (uint32_t lane = 0; lane < used; ++lane) {
        const TriangleIndex f = lanes[8 * leaf + lane];
        const Triangle& t = mesh.triangles[f];
        const double d = std::sqrt(closestPointOnTriangle(p, mesh.positions[t[0]], mesh.positions[t[1]],
                                                          mesh.positions[t[2]]).squared_distance);
        push({d, static_cast<ChildRef>(f), lane});
      }
    } else {
      const Node8& node = nodes[entry.ref];
      ++counters_.nodes_visited;
      if (sp.far) std::fill(dist, dist + 8, 0.0f); else boxDistances(node, sp.q, dist);
      for (int s = 0; s < 8; ++s) {
        if (node.child[s] == kEmptyChild) continue;
        push({boxLowerBound(dist[s], inv_scale), node.child[s], 8});
      }
    }
    counters_.heap_max = std::max<uint32_t>(counters_.heap_max, static_cast<uint32_t>(heap_.size()));
  }
}

void QueryStream::within(const Vec3& p, double d, std::vector<TriangleHit>& out) {
  const Hierarchy& h = *hierarchy_;
  const Mesh& mesh = h.mesh();
  out.clear();
  counters_ = {};
  if (!(d >= 0)) return;
  const ScaledPoint sp = scalePoint(h, p);
  const float threshold = pruneThreshold(d * d, h.boxScale() * h.boxScale());
  const auto& nodes = h.nodes();
  const auto& blocks = h.leafBlocks();
  const auto& lanes = h.leafTriangles();
  stack_.clear();
  stack_.push_back({0, 0.0f});
  float dist[8];
  double exact[8];
  while (!stack_.empty()) {
    const StackEntry entry = stack_.back();
    stack_.pop_back();
    if (isLeafRef(entry.ref)) {
      const int32_t leaf = leafIndex(entry.ref);
      squaredDistancesToBlock(p, blocks[leaf], exact);
      const uint32_t used = h.leafLanes(leaf);
      ++counters_.leaves_tested;
      counters_.triangles_tested += used;
      for (uint32_t lane = 0; lane < used; ++lane) {
        if (!(exact[lane] <= d * d * (1 + 1e-9))) continue;
        const TriangleHit hit = makeHit(mesh, lanes[8 * leaf + lane], p);
        if (hit.distance <= d) out.push_back(hit);
      }
      continue;
    }
    const Node8& node = nodes[entry.ref];
    ++counters_.nodes_visited;
    if (sp.far) std::fill(dist, dist + 8, 0.0f); else boxDistances(node, sp.q, dist);
    for (int k = 0; k < 8; ++k) {
      if (node.child[k] != kEmptyChild && dist[k] <= threshold) stack_.push_back({node.child[k], dist[k]});
    }
  }
  std::sort(out.begin(), out.end(), hitBefore);
}

}  // namespace meshsweeper
