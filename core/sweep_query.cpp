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
// Coherent exact query (set certificate, DESIGN.md section 2): at an anchor q0 with distance
//   D0, gather every face within D0 + 2R (at most max_candidates, the nearest; then the reach L
//   is the distance of the first face left out; if the search pruned nothing nearer than some
//   L' > D0 + 2R, L = L'). Every other face f has d(q0, f) >= L, so for a later point p,
//   d(p, f) >= L - |p - q0|. If the best candidate is at M with M + |p - q0| < L, no other
//   face can be closer: M is exact. Else rebuild at p, the depth-first query starting from the
//   distance to the previous closest face. The first eight candidates are tested first, the
//   others only if their least distance at q0, minus |p - q0|, is below M.
//   With a cap c (closest within c): D0 is min(D0, c), and min(M, c) + |p - q0| < L proves
//   the answer, "none within c" when M > c. On a deforming geometry of the same lineage, faces
//   moved by at most the growth of its drift since q0: it adds to |p - q0| in every bound.
//   A compact state (CoherentState) gathers its set at q0 = p + lead_steps * (mean velocity)
//   when that lead is within 2R: a steady point first moves toward q0, then away, so the set
//   lasts about twice as long; p itself must be certified by the new set (else it is gathered
//   at p), so the answer is exact either way.
// Dynamic front (paper section 5.1): the front persists; moving by delta lowers every bound by
//   delta. Entries store bound + drift-at-computation, so the current bound is key - drift and
//   the heap order never changes; a stale entry reaching the top is recomputed and pushed back.
//
// Float boxes are conservative: stored relative to their node's origin, rounded outward and
// widened by a margin that covers the rounding of the query point relative to that origin
// (packSlotBoxes); the pruning threshold gets a relative slack for the float arithmetic and the
// query point's own rounding in double. Points farther than ~1e15 mesh radii from the mesh skip
// box pruning.
#include "core/sweep_query.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <stdexcept>

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

// Squared distances, in the hierarchy's scaled float units, from q (relative to the node's
// origin: nodePoint) to the node's eight boxes.
inline void boxDistancesFrom(const Node8& n, const float q[3], float out[8]) {
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

// Order keys for the children: box distance plus a weighted squared distance to the box centre.
inline void centerDistances(const Node8& n, const float q[3], const float box[8], float out[8]) {
  constexpr float kCenterWeight = 0.25f;
  for (int k = 0; k < 8; ++k) {
    float acc = 0;
    for (int axis = 0; axis < 3; ++axis) {
      const float c = 0.5f * (n.lower[axis][k] + n.upper[axis][k]) - q[axis];
      acc += c * c;
    }
    out[k] = box[k] + kCenterWeight * acc;
  }
}

// Starts loading a node (384 bytes) or leaf block (576 bytes) into cache.
inline void prefetchChild(const TreeGeometry& g, ChildRef ref) {
  const char* base;
  int lines;
  if (isLeafRef(ref)) {
    if (!g.leaf_blocks) return;
    base = reinterpret_cast<const char*>(&g.leaf_blocks[leafIndex(ref)]);
    lines = sizeof(TriangleBlock8) / 64;
  } else {
    base = reinterpret_cast<const char*>(&g.nodes[ref]);
    lines = (sizeof(Node8) + 63) / 64;
  }
  for (int i = 0; i < lines; ++i) __builtin_prefetch(base + 64 * i);
}

}  // namespace

// A query point in scaled double coordinates, and the bound `err` on their rounding (relative
// 2^-52 of the largest, scaled units): a box bound from the computed point may fall short of
// the true point's by that much.
struct ScaledPoint {
  double q[3];
  double err;
  bool far;  // too far for float boxes: every box bound is taken as 0
};

namespace {

ScaledPoint scalePoint(const TreeGeometry& g, const Vec3& p) {
  ScaledPoint s{};
  const Vec3 local = (p - g.center) * g.box_scale;
  const double largest = local.cwiseAbs().maxCoeff();
  s.far = !(largest < kFarLimit);
  for (int axis = 0; axis < 3; ++axis) s.q[axis] = s.far ? 0.0 : local[axis];
  s.err = s.far ? 0.0 : largest * 0x1p-50;
  return s;
}

// The query point relative to a node's origin, rounded to float (off by at most 2^-24 of
// |q - origin| per axis, which the node's margin and the box slack cover: packSlotBoxes).
inline void nodePoint(const Node8& n, const ScaledPoint& sp, float qn[3]) {
  for (int axis = 0; axis < 3; ++axis) qn[axis] = static_cast<float>(sp.q[axis] - n.origin[axis]);
}

// boxDistancesFrom at sp (0 for every box when sp is far); qn receives sp relative to the node.
inline void boxDistances(const Node8& n, const ScaledPoint& sp, float out[8], float qn[3]) {
  if (sp.far) {
    std::fill(out, out + 8, 0.0f);
    std::fill(qn, qn + 3, 0.0f);
    return;
  }
  nodePoint(n, sp, qn);
  boxDistancesFrom(n, qn, out);
}

// Float threshold in scaled units above which a box bound proves a squared distance > best2:
// (sqrt(best2) scale + err)^2, with a relative slack for the float arithmetic of a box bound
// (well below it).
inline float pruneThreshold(double best2, double scale2, const ScaledPoint& sp) {
  const double r = std::sqrt(best2 * scale2) + sp.err;
  const double t = r * r * (1 + kBoxSlack);
  return t < 3e38 ? static_cast<float>(t) : kFloatInf;
}

// A lower bound, in mesh units, on the distance to anything inside a box with float bound d2.
inline double boxLowerBound(float d2, double inv_scale, const ScaledPoint& sp) {
  return std::max(0.0, std::sqrt(static_cast<double>(d2) * (1 - kBoxSlack)) - sp.err) * inv_scale;
}

// Whether a face at squared distance d2 (index f) comes before the best so far (squared
// distance best2, index best): by distance, the square root hitOn() reports (two squared
// distances an ulp apart can have one root), ties to the lowest index, as kClosest() and the
// brute force order them. Only near-ties take the roots.
inline bool closerFace(double d2, TriangleIndex f, double best2, TriangleIndex best) {
  if (d2 < best2 * (1 - 1e-15)) return true;
  if (!(d2 <= best2 * (1 + 1e-15))) return false;
  const double a = std::sqrt(d2), b = std::sqrt(best2);
  return a < b || (a == b && f < best);
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

// A surface point at distance `upper`: an exact face point, or a vertex (on the surface).
ClosestPoint upperAnswer(const Hierarchy& h, const Vec3* positions, const TriangleHit* face_hit,
                         VertexIndex vertex, double upper, double lower) {
  ClosestPoint out;
  if (face_hit) {
    fillFromHit(out, *face_hit);
  } else if (vertex != kInvalidIndex) {
    const TriangleIndex f = h.vertexFace()[vertex];
    const Triangle& t = h.mesh().triangles[f];
    const int k = t[0] == vertex ? 0 : t[1] == vertex ? 1 : 2;
    out.distance = upper;
    out.point = positions[vertex];
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

// Lower bound from one slot: the larger of its box bound and d(p, slot triangle) - eps, less
// the rounding of both distances (the one computed here and the build's, which eps carries):
// relative 1e-12, and absolute kSlotRounding times the coordinates involved. A point on the
// surface is computed up to about 20 eps of its coordinates away from it: with a relative
// margin only, a slot holding a face at distance 0 (or one an ulp of the coordinates away)
// could bound it from above, and the priority queries took a farther face first (found by an
// audit: kClosestCoherent on meshes of duplicate and degenerate faces).
constexpr double kSlotRounding = 256 * std::numeric_limits<double>::epsilon();
double slotBound(const Node8& node, int k, const Vec3* positions, const Vec3& p, float box_d2,
                 double inv_scale, const ScaledPoint& sp) {
  const Vec3& a = positions[node.corner[0][k]];
  const Vec3& b = positions[node.corner[1][k]];
  const Vec3& c = positions[node.corner[2][k]];
  const double to_triangle = std::sqrt(squaredDistanceToTriangle(p, a, b, c));
  const double coordinates = p.cwiseAbs().cwiseMax(a.cwiseAbs()).cwiseMax(b.cwiseAbs()).cwiseMax(c.cwiseAbs()).maxCoeff();
  return std::max(boxLowerBound(box_d2, inv_scale, sp),
                  to_triangle * (1 - 1e-12) - kSlotRounding * coordinates - node.eps[k]);
}

// The answer to a point that cannot be queried (beyond kMaxQueryCoordinate, or NaN): NaN, no
// triangle.
ClosestPoint unanswerable() {
  ClosestPoint out;
  out.distance = out.lower = out.upper = std::numeric_limits<double>::quiet_NaN();
  return out;
}

}  // namespace

QueryStream::QueryStream(std::shared_ptr<const Hierarchy> hierarchy, CoherenceOptions options)
    : hierarchy_(std::move(hierarchy)), options_(options) {
  if (!hierarchy_) throw std::invalid_argument("QueryStream: null hierarchy");
  rest_ = hierarchy_->restGeometry();
  stack_.reserve(64);
  heap_.reserve(64);
}

void QueryStream::trimScratch(size_t entries) {
  auto trim = [entries](auto& buffer) {
    if (buffer.capacity() > entries) std::remove_reference_t<decltype(buffer)>().swap(buffer);
  };
  trim(stack_);
  trim(heap_);
  trim(gathered_);
  trim(within_keys_);
  trim(within_hits_);
}

size_t QueryStream::stateBytes() const {
  return sizeof(*this) + stack_.capacity() * sizeof(StackEntry) + heap_.capacity() * sizeof(FrontEntry) +
         set_faces_.capacity() * sizeof(TriangleIndex) + set_blocks_.capacity() * sizeof(TriangleBlock8) +
         gathered_.capacity() * sizeof(gathered_[0]) + within_keys_.capacity() * sizeof(within_keys_[0]) +
         within_hits_.capacity() * sizeof(TriangleHit) +
         front_.capacity() * sizeof(DriftEntry) +
         popped_.capacity() * sizeof(DriftEntry);
}

void QueryStream::frontTriangles(std::vector<FrontTriangle>& out) const {
  out.clear();
  const TreeGeometry& g = geometry();
  for (const DriftEntry& e : front_) {
    FrontTriangle t;
    if (e.lane < 8) {
      t.corners = hierarchy_->mesh().triangles[e.ref];
      t.face = true;
    } else if (e.parent >= 0) {
      const Node8& node = g.nodes[e.parent];
      t.corners = {node.corner[0][e.slot], node.corner[1][e.slot], node.corner[2][e.slot]};
      t.eps = node.eps[e.slot];
    } else {
      continue;  // the root, before the first refinement
    }
    out.push_back(t);
  }
}

void QueryStream::setGeometry(const TreeGeometry* geometry) {
  // Another hierarchy's nodes and leaves would be read with this one's layout (found by
  // review: out-of-range reads, or triangles of the other mesh).
  if (geometry != nullptr && geometry->hierarchy != hierarchy_.get())
    throw std::invalid_argument(
        "QueryStream::setGeometry: the geometry belongs to another hierarchy than the stream's (build the "
        "stream on the body's hierarchy)");
  geometry_ = geometry;
  reset();
}

void QueryStream::reset() {
  coherence_ = {};
  has_set_ = false;
  has_last_ = false;
  has_front_ = false;
  last_face_ = kInvalidIndex;
  mean_step_ = 0;
  closest_wait_ = closest_backoff_ = set_steps_ = 0;
  set_unmeasured_ = false;
  body_state_ = CoherentState{};
  front_.clear();
}

// Exact squared distances from p to a leaf block's faces (out[lane]); counts the test and
// returns the used lanes.
uint32_t QueryStream::testLeaf(int32_t leaf, const Vec3& p, double out[8]) {
  squaredDistancesToBlock(p, leafBlock(leaf), out);
  return hierarchy_->leafLanes(leaf);
}

// A leaf's faces as a block, counted as tested: the inline block, or (moving geometry without
// inline faces) the lanes' corners gathered from the positions.
const TriangleBlock8& QueryStream::leafBlock(int32_t leaf) {
  const TreeGeometry& g = geometry();
  ++counters_.leaves_tested;
  counters_.triangles_tested += hierarchy_->leafLanes(leaf);
  if (g.leaf_blocks) return g.leaf_blocks[leaf];
  gatherLeafBlock(&hierarchy_->leafCorners()[8 * static_cast<size_t>(leaf)], g.positions, gather_);
  return gather_;
}

double QueryStream::squaredDistanceToFace(TriangleIndex face, const Vec3& p) const {
  const Vec3* x = geometry().positions;
  const Triangle& t = hierarchy_->mesh().triangles[face];
  return squaredDistanceToTriangle(p, x[t[0]], x[t[1]], x[t[2]]);
}

namespace {
TriangleHit hitFrom(TriangleIndex face, const TriangleClosest& c) {
  TriangleHit hit;
  hit.distance = std::sqrt(c.squared_distance);
  hit.triangle = face;
  hit.point = c.point;
  hit.barycentric = c.barycentric;
  hit.feature = c.feature;
  return hit;
}
}  // namespace

TriangleHit QueryStream::hitOn(TriangleIndex face, const Vec3& p) const {
  const Vec3* x = geometry().positions;
  const Triangle& t = hierarchy_->mesh().triangles[face];
  return hitFrom(face, closestPointOnTriangle(p, x[t[0]], x[t[1]], x[t[2]]));
}


// Depth-first search from the root with best squared distance start2 (best_face holds its face).
// With reach > 0, the faces within sqrt(best) + reach (as best shrinks) are gathered into
// gathered_ (at most about twice capacity + 1: past that only the nearest capacity + 1 are kept
// and the search narrows to the farthest of them), and pruned_lower_ bounds from below the
// distance of every face not gathered. Returns the best squared distance; best_face is its face.
double QueryStream::depthFirst(const Vec3& p, double start2, double reach, TriangleIndex& best_face,
                               uint32_t capacity) {
  const Hierarchy& h = *hierarchy_;
  const TreeGeometry& g = geometry();
  const ScaledPoint sp = scalePoint(g, p);
  const double scale2 = g.box_scale * g.box_scale;
  const TriangleIndex* lanes = h.leafTriangles().data();

  double best2 = start2;
  auto limit2 = [&] {
    if (reach <= 0) return best2;
    const double r = std::sqrt(best2) + reach;
    return r * r;
  };
  double gather2 = limit2();
  float threshold = pruneThreshold(gather2, scale2, sp);
  double threshold2 = gather2;  // the squared distance threshold was taken from
  // With reach > 0: the smallest box bound pruned and squared distance not gathered.
  float pruned_box = kFloatInf;
  double pruned_face2 = kInf;
  double kept_limit2 = kInf;  // with reach > 0: nothing farther is needed in gathered_
  stack_.clear();
  stack_.push_back({0, 0.0f});
  float dist[8];
  double exact[8];
  while (!stack_.empty()) {
    const StackEntry entry = stack_.back();
    stack_.pop_back();
    if (entry.bound > threshold) {
      pruned_box = std::min(pruned_box, entry.bound);
      continue;
    }
    if (isLeafRef(entry.ref)) {
      const int32_t leaf = leafIndex(entry.ref);
      const uint32_t used = testLeaf(leaf, p, exact);
      for (uint32_t lane = 0; lane < used; ++lane) {
        // Ties go to the lowest face index, as in testSet: the answer does not depend on the
        // order of the search, the warm start or a cached set (closerFace).
        const TriangleIndex f = lanes[8 * leaf + lane];
        if (closerFace(exact[lane], f, best2, best_face)) {
          best2 = exact[lane];
          best_face = f;
        }
      }
      if (reach > 0) {
        gather2 = std::min(limit2(), kept_limit2);
        for (uint32_t lane = 0; lane < used; ++lane) {
          if (!(exact[lane] <= gather2)) {
            pruned_face2 = std::min(pruned_face2, exact[lane]);
            continue;
          }
          gathered_.emplace_back(exact[lane], lanes[8 * leaf + lane]);
          // Twice too many: keep the nearest capacity + 1 (a partial selection). The farthest
          // kept is as far as the set can reach, so nothing beyond it needs opening.
          if (gathered_.size() >= 2 * (static_cast<size_t>(capacity) + 1)) {
            std::nth_element(gathered_.begin(), gathered_.begin() + capacity, gathered_.end());
            kept_limit2 = gathered_[capacity].first;  // the dropped ones are at least as far
            pruned_face2 = std::min(pruned_face2, kept_limit2);
            gathered_.resize(capacity + 1);
            gather2 = std::min(gather2, kept_limit2);
          }
        }
      } else {
        gather2 = best2;
      }
      if (gather2 != threshold2) {
        threshold2 = gather2;
        threshold = pruneThreshold(gather2, scale2, sp);
      }
      continue;
    }
    const Node8& node = g.nodes[entry.ref];
    ++counters_.nodes_visited;
    float qn[3];
    boxDistances(node, sp, dist, qn);
    // Children below the threshold, pushed farthest first so the closest is popped next. The
    // order key adds the distance to the box centre, which ranks boxes that hold the point.
    float order[8];
    centerDistances(node, qn, dist, order);
    StackEntry open[8];
    float open_key[8];
    int count = 0;
    for (int k = 0; k < 8; ++k) {
      if (node.child[k] == kEmptyChild) continue;
      if (dist[k] > threshold) {
        pruned_box = std::min(pruned_box, dist[k]);
        continue;
      }
      int i = count++;
      while (i > 0 && open_key[i - 1] < order[k]) { open[i] = open[i - 1]; open_key[i] = open_key[i - 1]; --i; }
      open[i] = {node.child[k], dist[k]};
      open_key[i] = order[k];
    }
    stack_.insert(stack_.end(), open, open + count);
    // The closest child is popped next: start loading it.
    if (count > 0) prefetchChild(g, open[count - 1].ref);
    if (count > 1) prefetchChild(g, open[count - 2].ref);
  }
  if (reach > 0) {
    pruned_lower_ = std::sqrt(pruned_face2);
    if (pruned_box < kFloatInf && !sp.far) pruned_lower_ = std::min(pruned_lower_, boxLowerBound(pruned_box, 1.0 / g.box_scale, sp));
  }
  return best2;
}

namespace {

// Sorts entries [0, n) (n <= kMaxRanked) by squared distance (ties: the order found), keeping the
// first `keep`; returns the squared distance of the first entry not kept (+inf if none). Ranks by
// counting (branch-free, vectorised): cheaper than std::sort on these short, unordered lists.
constexpr size_t kMaxRanked = 2 * (kCoherentSetSize + 1);
double sortNearest(std::pair<double, TriangleIndex>* entries, size_t n, size_t keep) {
  assert(n <= kMaxRanked && keep <= kCoherentSetSize);
  alignas(64) double d[(kMaxRanked + 7) / 8 * 8];
  for (size_t i = 0; i < n; ++i) d[i] = entries[i].first;
  for (size_t i = n; i % 8 != 0; ++i) d[i] = kInf;  // padding: never before a finite distance
  std::pair<double, TriangleIndex> sorted[kCoherentSetSize];
  double first_out = kInf;
  for (size_t i = 0; i < n; ++i) {
    const double di = d[i];
    uint32_t rank = 0;
#if defined(__AVX512F__)
    const __m512d v = _mm512_set1_pd(di);
    for (size_t j = 0; j < n; j += 8) {
      const __m512d dj = _mm512_load_pd(d + j);
      // Equal distances rank by position: lanes j + lane < i only.
      const size_t before = i > j ? std::min<size_t>(i - j, 8) : 0;
      const __mmask8 earlier = static_cast<__mmask8>((1u << before) - 1);
      const __mmask8 ahead = _mm512_cmp_pd_mask(dj, v, _CMP_LT_OQ) |
                             (_mm512_cmp_pd_mask(dj, v, _CMP_EQ_OQ) & earlier);
      rank += static_cast<uint32_t>(__builtin_popcount(ahead));
    }
#else
    for (size_t j = 0; j < n; ++j) rank += (d[j] < di) | ((d[j] == di) & (j < i));
#endif
    if (rank < keep) sorted[rank] = entries[i];
    else if (rank == keep) first_out = di;
  }
  std::copy(sorted, sorted + std::min(n, keep), entries);
  return first_out;
}

}  // namespace

// The rebuild of a set certificate: a depth-first search from start2 (best_face its face) that
// leaves in gathered_ the faces within best + reach of p, at most `capacity` of them (the
// nearest): by increasing distance if `sorted` (capacity <= kCoherentSetSize), else in no
// particular order. Returns the set's reach: every face not kept is at least that far from p.
double QueryStream::gatherCandidates(const Vec3& p, double start2, double reach, uint32_t capacity,
                                     TriangleIndex& best_face, bool sorted) {
  gathered_.clear();
  const double best2 = depthFirst(p, start2, reach, best_face, capacity);
  const double limit = std::sqrt(best2) + reach;
  // Everything never gathered is strictly farther than `limit`, and at least pruned_lower_
  // (the smallest bound depthFirst pruned); so is what the filter drops.
  double outside = pruned_lower_;
  size_t kept = 0;
  for (const auto& entry : gathered_) {
    const double d = std::sqrt(entry.first);
    if (d <= limit) gathered_[kept++] = entry;
    else outside = std::min(outside, d);
  }
  gathered_.resize(kept);
  // If too many were gathered, keep the nearest (ranked, or a partial selection): the reach
  // drops to the first left out.
  double first_out2 = kInf;
  if (sorted) {
    first_out2 = sortNearest(gathered_.data(), kept, capacity);
  } else if (kept > capacity) {
    std::nth_element(gathered_.begin(), gathered_.begin() + capacity, gathered_.end());
    first_out2 = gathered_[capacity].first;
  }
  if (kept > capacity) {
    gathered_.resize(capacity);
    return std::sqrt(first_out2);
  }
  return std::max(std::nextafter(limit, kInf), outside);
}

// The first eight faces of gathered_ (squared distance, face), in the order the depth-first
// search found them (nearest leaves first), are block 0. block_lower[b] (b < blocks) receives a
// lower bound on the distance of every face in blocks b.. (rounded down): 0 for block 0, the
// least distance past the first eight for the others; a query can skip the later blocks once
// that is farther than its best. (Selecting the nearest eight first, by std::nth_element, cost
// more than it saved: measured 10-15% slower on the coherent paths.)
void QueryStream::orderIntoBlocks(float* block_lower, size_t blocks) {
  float rest = kFloatInf;
  if (gathered_.size() > 8) {
    double rest2 = kInf;
    for (size_t i = 8; i < gathered_.size(); ++i) rest2 = std::min(rest2, gathered_[i].first);
    rest = std::nextafter(static_cast<float>(std::sqrt(rest2)), 0.0f);
  }
  for (size_t b = 0; b < blocks; ++b) block_lower[b] = b == 0 ? 0.0f : rest;
}

ClosestPoint QueryStream::closest(const Vec3& p) {
  counters_ = {};
  if (!inCoordinateRange(p, kMaxQueryCoordinate)) return unanswerable();
  TriangleIndex face = kInvalidIndex;
  depthFirst(p, kInf, 0, face);
  ClosestPoint out;
  fillFromHit(out, hitOn(face, p));  // a point in range always finds a face
  out.counters = counters_;
  return out;
}

namespace {

// closestCoherent's back-off (both versions): a set that fails within kPayingSteps tests (the
// point or the faces near it move by about its margin each step) cost a gather and saved
// little, so the next kClosestWait queries search from the warm start without one, twice as
// many each time the next set fails too (up to kMaxWait), back to kClosestWait once a set
// pays. On bench_service's sheets a set that certified fewer than 2 steps cost more than plain
// searches, and these waits measured best.
constexpr uint8_t kPayingSteps = 2, kClosestWait = 6, kMaxWait = 24;

// The point's distance from a set's anchor, plus the rounding that distances computed at
// coordinates of their magnitude carry (16 eps of the larger coordinate): the set's distances
// from the anchor, |p - anchor| and p's own distances to the faces each carry a few eps of the
// coordinates, which the relative margins (1e-9 of the distances) do not cover on a mesh far
// from the origin. Without it, at 1e7 times a mesh's size from the origin, a set's test
// skipped a block holding the lowest-index face of an exact tie, and a certificate held for a
// face outside the set at the answer's distance (found by an audit: closestCoherent returned
// the other face of a tie at distance 0, withinCoherent left out a face at d).
double movedFromAnchor(const Vec3& p, const Vec3& anchor) {
  constexpr double kCoordinateRounding = 16 * std::numeric_limits<double>::epsilon();
  return (p - anchor).norm() +
         kCoordinateRounding * std::max(p.cwiseAbs().maxCoeff(), anchor.cwiseAbs().maxCoeff());
}

}  // namespace

ClosestPoint QueryStream::closestCoherent(const Vec3& p) {
  const TreeGeometry& g = geometry();
  if (geometry_ != nullptr && inCoordinateRange(p, kMaxQueryCoordinate)) {  // a body's geometry
    ++coherence_.steps;
    bool certified = false;
    const ClosestPoint c = closestCoherent(p, body_state_, &certified);
    if (certified) {
      ++coherence_.certified;
    } else if (body_state_.has_set) {
      ++coherence_.rebuilds;
      coherence_.candidates += body_state_.count;
    } else {
      ++coherence_.searched;
    }
    return c;
  }
  if (!inCoordinateRange(p, kMaxQueryCoordinate)) {
    counters_ = {};
    ++coherence_.steps;
    has_last_ = false;
    has_set_ = false;
    return unanswerable();
  }
  counters_ = {};
  ++coherence_.steps;
  if (has_last_) {
    const double step = (p - last_point_).norm();
    mean_step_ = coherence_.steps > 2 ? 0.9 * mean_step_ + 0.1 * step : step;
  }
  TriangleIndex face = kInvalidIndex;
  bool certified = false;
  const bool tested = has_set_ && set_version_ == g.version;
  if (tested) {
    const double moved = movedFromAnchor(p, anchor_);
    if (moved < set_reach_) {
      double best2 = kInf;
      double exact[8];
      const size_t count = set_faces_.size();
      size_t tested = 0;
      for (size_t b = 0; b < set_blocks_.size(); ++b) {
        // Block 0 first: stop once the rest cannot be closer than the best.
        if (b == 1 && set_block_lower_[b] - moved > std::sqrt(best2) * (1 + 1e-9)) break;
        squaredDistancesToBlock(p, set_blocks_[b], exact);
        tested += std::min<size_t>(8, count - 8 * b);
        const size_t lanes = std::min<size_t>(8, count - 8 * b);
        for (size_t lane = 0; lane < lanes; ++lane) {
          const TriangleIndex f = set_faces_[8 * b + lane];
          if (closerFace(exact[lane], f, best2, face)) { best2 = exact[lane]; face = f; }
        }
      }
      counters_.triangles_tested = static_cast<uint32_t>(tested);
      // Certificate: every face outside the set is at least set_reach_ - moved away.
      certified = std::sqrt(best2) + moved < set_reach_ * (1 - 1e-9);
    }
  }
  if (certified && set_steps_ < 255) ++set_steps_;
  if (certified && set_steps_ >= kPayingSteps) closest_backoff_ = 0;
  // A point that jumps or turns back fails its sets at once (found by an audit: a set gathered
  // for every query, 4.6 times a plain search, where the CoherentState version backed off).
  if (!certified && tested && set_steps_ < kPayingSteps && !set_unmeasured_) {
    closest_wait_ = std::max(kClosestWait, closest_backoff_);
    closest_backoff_ = static_cast<uint8_t>(std::min<int>(2 * closest_wait_, kMaxWait));
  }
  const bool warm = has_last_ && last_face_ != kInvalidIndex && set_version_ == g.version;
  if (certified) {
    ++coherence_.certified;
  } else if (closest_wait_ > 0 && warm) {
    ++coherence_.searched;
    --closest_wait_;
    has_set_ = false;
    double start2 = squaredDistanceToFace(last_face_, p);
    face = last_face_;
    depthFirst(p, start2, 0, face);
  } else {
    ++coherence_.rebuilds;
    closest_wait_ = 0;
    set_steps_ = 0;
    set_unmeasured_ = !(mean_step_ > 0);
    // A stationary point still gets a certificate: a reach of at least 1e-6 of the mesh size.
    const double reach = 2 * std::max(options_.reach_steps * mean_step_, 1e-6 / g.box_scale);
    double start2 = kInf;
    face = kInvalidIndex;
    if (warm) {
      start2 = squaredDistanceToFace(last_face_, p);
      face = last_face_;
    }
    const double set_reach = gatherCandidates(p, start2, reach, options_.max_candidates, face);
    set_faces_.clear();
    for (const auto& entry : gathered_) set_faces_.push_back(entry.second);
    set_blocks_.resize((set_faces_.size() + 7) / 8);
    set_block_lower_.resize(set_blocks_.size());
    orderIntoBlocks(set_block_lower_.data(), set_blocks_.size());
    for (size_t b = 0; b < set_blocks_.size(); ++b)
      gatherTriangleBlock(hierarchy_->mesh().triangles.data(), g.positions, set_faces_.data() + 8 * b,
                          static_cast<uint32_t>(std::min<size_t>(8, set_faces_.size() - 8 * b)), set_blocks_[b]);
    coherence_.candidates += set_faces_.size();
    anchor_ = p;
    set_reach_ = set_faces_.empty() ? 0 : set_reach;
    has_set_ = !set_faces_.empty();
    set_version_ = g.version;
  }
  ClosestPoint out;
  if (face == kInvalidIndex) {
    out.distance = out.lower = out.upper = std::numeric_limits<double>::quiet_NaN();
    has_last_ = false;
    has_set_ = false;
  } else {
    fillFromHit(out, hitOn(face, p));
    has_last_ = true;
    last_point_ = p;
    last_face_ = face;
  }
  out.counters = counters_;
  return out;
}

namespace {

// The geometry's drift by region when the state's set has a region of its current epoch, else
// null (no regions, none attached, or an earlier epoch).
const RegionDrift* regionOf(const CoherentState& state, const TreeGeometry& g) {
  return g.regions && state.region_epoch != 0 && state.region_epoch == g.regions->epoch ? g.regions : nullptr;
}

}  // namespace

// The set of a compact state from gathered_ (sorted by distance from anchor), with its reach,
// at the geometry's current drift.
void QueryStream::storeSet(const Vec3& anchor, double set_reach, CoherentState& state) const {
  for (uint32_t b = 0; b < kCoherentSetSize / 8; ++b)
    state.block_lower[b] = 8 * b < gathered_.size() ? std::nextafter(static_cast<float>(std::sqrt(gathered_[8 * b].first)), 0.0f) : kFloatInf;
  state.count = static_cast<uint32_t>(gathered_.size());
  for (uint32_t i = 0; i < state.count; ++i) state.faces[i] = gathered_[i].second;
  state.anchor = anchor;
  state.reach = set_reach;
  const TreeGeometry& g = geometry();
  state.drift_at = g.drift;
  state.has_set = set_reach > 0;  // infinite: every face is in the set
  // Drift by region (movedSinceSet): the region of the set's nearest face, at `best` from the
  // anchor; an empty set (no face within its reach) keeps its last region of this epoch, else
  // takes the region whose box is nearest (a scan), at its box's distance.
  const RegionDrift* regions = g.regions;
  const bool had_region = regionOf(state, g) != nullptr;
  state.region_epoch = 0;
  if (regions && regions->epoch != 0 && state.has_set && set_reach < kInf) {
    uint32_t region = 0;
    float best = 0;
    if (!gathered_.empty()) {
      region = regions->face_region[gathered_[0].second];
      best = floatAtLeast(std::sqrt(gathered_[0].first));
    } else if (had_region) {
      region = state.region;
      best = floatAtLeast(regionDistance(*regions, region, anchor));
    } else {
      double distance = 0;
      region = nearestRegion(*regions, anchor, distance);
      best = floatAtLeast(distance);
    }
    state.region_epoch = regions->epoch;
    state.region = static_cast<uint16_t>(region);
    state.region_best = best;
    state.region_at[0] = regions->drift[2 * region];
    state.region_at[1] = regions->drift[2 * region + 1];
  }
}

// Tests a compact state's set at p, `moved` from its anchor (drift included): best2 and face
// receive the best candidate (face kInvalidIndex when certified and none is within `within`).
// Returns whether the set's certificate proves that answer.
bool QueryStream::testSet(const CoherentState& state, const Vec3& p, double moved, double within, double& best2,
                          TriangleIndex& face) {
  if (!(moved < state.reach)) return false;
  const TreeGeometry& g = geometry();
  const Mesh& mesh = hierarchy_->mesh();
  // Blocks in order, while they could be closer than the best so far (or within the cap).
  double exact[8];
  for (uint32_t first = 0; first < state.count; first += 8) {
    if (state.block_lower[first / 8] - moved > std::min(std::sqrt(best2), within) * (1 + 1e-9)) break;
    const uint32_t lanes = std::min<uint32_t>(8, state.count - first);
    gatherTriangleBlock(mesh.triangles.data(), g.positions, state.faces + first, lanes, gather_);
    squaredDistancesToBlock(p, gather_, exact);
    counters_.triangles_tested += lanes;
    for (uint32_t lane = 0; lane < lanes; ++lane) {
      const TriangleIndex f = state.faces[first + lane];
      if (closerFace(exact[lane], f, best2, face)) {
        best2 = exact[lane];
        face = f;
      }
    }
  }
  // Every face outside the set is at least reach - moved away: nothing there is closer than
  // the best candidate, or within the cap when no candidate is.
  const bool certified = std::min(std::sqrt(best2), within) + moved < state.reach * (1 - 1e-9);
  if (certified && !(best2 <= within * within)) face = kInvalidIndex;
  return certified;
}

namespace {

// A cold state with the same tuning.
void restartState(CoherentState& state) {
  const float reach_steps = state.reach_steps, lead_steps = state.lead_steps;
  state = CoherentState{};
  state.reach_steps = reach_steps;
  state.lead_steps = lead_steps;
}

// The drift the state's motion follows: its region's first-level drift while its set has one
// in the geometry's epoch (`local`), else the lineage's.
double followedDrift(const CoherentState& state, const TreeGeometry& g, bool& local) {
  const RegionDrift* regions = regionOf(state, g);
  local = regions != nullptr;
  return local ? regions->drift[2 * state.region] : g.drift;
}

// The running means of the point's motion relative to the geometry (its step plus the growth
// of the drift it follows), from which a set's reach and lead are taken.
void trackMotion(CoherentState& state, const Vec3& p, const TreeGeometry& g) {
  const Vec3 point_step = p - state.last_point;
  bool local = false;
  const double drift = followedDrift(state, g, local);
  // A switch between the two drifts (a new epoch) counts the point's step only, once.
  const double step = point_step.norm() + (local == state.last_local ? drift - state.last_drift : 0.0);
  // A step counts for at most a thousand rest sizes (a jump, not a motion to follow), and
  // stays in float: one jump of 1e39 (query points go to 1e153) left the means at +inf for
  // good, every later query gathering afresh (found by an audit).
  const double limit = std::min(1e37, 2e3 / g.box_scale);
  const Eigen::Vector3f velocity = point_step.cwiseMax(-limit).cwiseMin(limit).cast<float>();
  const float step_f = static_cast<float>(std::min(step, limit));
  if (state.mean_step > 0) {
    state.mean_step = 0.9f * state.mean_step + 0.1f * step_f;
    state.mean_velocity = 0.9f * state.mean_velocity + 0.1f * velocity;
  } else {
    state.mean_step = step_f;
    state.mean_velocity = velocity;
  }
}

// How far the faces may have come toward p since the state's set was gathered: the point's
// distance from the anchor (movedFromAnchor) plus the growth of the lineage's drift. With drift by region
// (storeSet attached one; `best` bounds the anchor's distance to a point q of the region's
// box), a face was at least its gathered distance (reach, for one outside the set) from the
// anchor, and:
//  - one within the first width of the region moved by at most that level's drift growth;
//  - one beyond it lies, for the whole epoch, in a region box more than width[0] from q: at
//    least width[0] - best from the anchor whatever it did (the reach plus slack0), and it
//    moved by at most the second level's drift growth;
//  - one beyond the second width, the same with width[1] and the lineage's drift.
// The result bounds how far any of them may have come within its gathered distance or the
// reach, which is all the set's test and certificate need (testSet: a face that came closer
// than that by its box alone is still beyond the reach less this motion).
double movedSinceSet(const CoherentState& state, const Vec3& p, const TreeGeometry& g) {
  const double step = movedFromAnchor(p, state.anchor);
  const double lineage = g.drift - state.drift_at;
  const RegionDrift* regions = regionOf(state, g);
  if (!regions) return step + lineage;
  const double* drift = regions->drift + 2 * state.region;
  const double near = drift[0] - state.region_at[0];
  const double middle = drift[1] - state.region_at[1];
  const double best = static_cast<double>(state.region_best);
  // A drift that reached infinity (motions past 1e154 a step) makes a difference NaN, which
  // std::min and std::max would drop: no certificate then.
  if (!(std::isfinite(near) && std::isfinite(middle) && std::isfinite(lineage))) return kInf;
  const double slack0 = regions->width[0] - best - state.reach;
  const double slack1 = regions->width[1] - best - state.reach;
  return step + std::max({near, std::min(middle, -slack0), std::min(lineage, -slack1)});
}

// Where a rebuilt set is gathered: its margin 2R, R = reach_steps mean steps (at least 1e-6 of
// the mesh size: a stationary point still gets a certificate), and lead_steps mean steps ahead
// when that lies within the margin (on a steady path the set lasts about twice as long; on a
// path that turns back the mean velocity, and the lead, shrink). p must still be certified by
// a set gathered ahead, else it is gathered at p.
struct SetPlan {
  double reach;
  Vec3 lead;
  bool ahead;  // gather at p + lead first
};
SetPlan planSet(const CoherentState& state, const TreeGeometry& g, bool same_lineage) {
  SetPlan plan;
  plan.reach = 2.0 * std::max(static_cast<double>(state.reach_steps) * state.mean_step, 1e-6 / g.box_scale);
  plan.lead = static_cast<double>(state.lead_steps) * state.mean_velocity.cast<double>();
  const double ahead = same_lineage ? plan.lead.norm() : 0.0;
  plan.ahead = ahead > 0 && ahead < plan.reach;
  return plan;
}

}  // namespace

ClosestPoint QueryStream::closestCoherent(const Vec3& p, CoherentState& state, bool* certified_out,
                                          double max_distance) {
  const TreeGeometry& g = geometry();
  const Mesh& mesh = hierarchy_->mesh();
  counters_ = {};
  if (!inCoordinateRange(p, kMaxQueryCoordinate)) {
    if (certified_out) *certified_out = false;
    restartState(state);
    return unanswerable();
  }
  // Within a lineage faces move by at most the change of the geometry's drift: the previous
  // face warm-starts the search and the set's certificate shrinks by that much.
  const bool same_lineage = state.lineage != 0 && state.lineage == g.lineage;
  const double cap = max_distance >= 0 ? max_distance : 0;  // NaN: 0
  // Faces within the cap plus the rounding of a computed distance (relative 1e-12, absolute
  // 1e-15 of the mesh's size) count as within it.
  const double within = cap < kInf ? cap * (1 + 1e-12) + 1e-15 / g.box_scale : kInf;
  const double within2 = within * within;
  if (same_lineage) trackMotion(state, p, g);
  TriangleIndex face = kInvalidIndex;
  bool certified = false;
  double best2 = kInf;
  // The back-off (kPayingSteps, kClosestWait, kMaxWait above) after a set that fails early.
  // A set gathered before the point's motion was measured (a cold state's first, with the
  // least margin) tells nothing about that motion when it fails: no wait then.
  const bool tested = same_lineage && state.has_set;
  if (tested) certified = testSet(state, p, movedSinceSet(state, p, g), within, best2, face);
  if (certified && state.set_steps < 255) ++state.set_steps;
  if (certified && state.set_steps >= kPayingSteps) state.closest_backoff = 0;
  if (!certified && tested && state.set_steps < kPayingSteps && !state.set_unmeasured) {
    state.closest_wait = std::max(kClosestWait, state.closest_backoff);
    state.closest_backoff = static_cast<uint8_t>(std::min<int>(2 * state.closest_wait, kMaxWait));
  }
  if (!certified) {
    // Start from the best face of the set just tested (no distance to recompute), else the
    // previous face's distance; or the cap if smaller.
    double start2 = within2;
    const TriangleIndex set_face = face;
    face = kInvalidIndex;
    if (set_face != kInvalidIndex) {
      if (best2 < start2) {
        start2 = best2;
        face = set_face;
      }
    } else if (same_lineage && state.last_face < mesh.triangles.size()) {
      const double last2 = squaredDistanceToFace(state.last_face, p);
      if (last2 < start2) {
        start2 = last2;
        face = state.last_face;
      }
    }
    state.has_set = false;
    if (state.closest_wait > 0 && same_lineage) {
      --state.closest_wait;
      depthFirst(p, start2, 0, face);
    } else if (state.reach_steps > 0) {
      state.closest_wait = 0;
      state.set_steps = 0;
      state.set_unmeasured = !(state.mean_step > 0);
      const SetPlan plan = planSet(state, g, same_lineage);
      const double reach = plan.reach;
      bool answered = false;
      if (plan.ahead) {
        const Vec3 anchor = p + plan.lead;
        double anchor2 = within2;
        TriangleIndex anchor_face = kInvalidIndex;
        if (face != kInvalidIndex) {
          const double d2 = squaredDistanceToFace(face, anchor);
          if (d2 < anchor2) {
            anchor2 = d2;
            anchor_face = face;
          }
        }
        storeSet(anchor, gatherCandidates(anchor, anchor2, reach, kCoherentSetSize, anchor_face, true), state);
        double set2 = kInf;
        TriangleIndex set_best = kInvalidIndex;
        answered = state.has_set && testSet(state, p, movedFromAnchor(p, anchor), within, set2, set_best);
        if (answered) face = set_best;
      }
      if (!answered) storeSet(p, gatherCandidates(p, start2, reach, kCoherentSetSize, face, true), state);
    } else {
      depthFirst(p, start2, 0, face);
    }
  }
  if (certified_out) *certified_out = certified;
  ClosestPoint out;
  if (face == kInvalidIndex) {  // nothing within the cap: farther than cap
    out.distance = out.upper = kInf;
    out.lower = cap;
  } else {
    fillFromHit(out, hitOn(face, p));
    state.last_face = face;
  }
  if (!same_lineage && face == kInvalidIndex) state.last_face = kInvalidIndex;
  state.lineage = g.lineage;
  state.last_point = p;
  state.last_drift = followedDrift(state, g, state.last_local);
  out.counters = counters_;
  return out;
}

// Tests a compact state's set for within(p, d), `moved` from its anchor (drift included):
// when its certificate holds (every face outside the set is farther than d), out receives the
// faces within d, as within() gives them, and it returns true.
bool QueryStream::testSetWithin(const CoherentState& state, const Vec3& p, double moved, double d,
                                std::vector<TriangleHit>& out) {
  out.clear();
  // within() keeps a face whose computed distance is <= d; a face outside the set is at least
  // reach - moved away (up to the rounding of both, which the relative margins cover).
  const double d_up = d * (1 + 1e-9);
  if (!(d_up + moved < state.reach * (1 - 1e-9))) return false;
  const TreeGeometry& g = geometry();
  const Mesh& mesh = hierarchy_->mesh();
  const double d2 = d * d * (1 + 1e-9);
  within_keys_.clear();
  within_hits_.clear();
  for (uint32_t first = 0; first < state.count; first += 8) {
    if (state.block_lower[first / 8] - moved > d_up) break;  // sorted: the rest are farther
    const uint32_t lanes = std::min<uint32_t>(8, state.count - first);
    gatherTriangleBlock(mesh.triangles.data(), g.positions, state.faces + first, lanes, gather_);
    keepWithin(p, gather_, state.faces + first, lanes, d2);
    counters_.triangles_tested += lanes;
  }
  finishWithin(d, out);
  return true;
}

void QueryStream::withinCoherent(const Vec3& p, double d, CoherentState& state, std::vector<TriangleHit>& out,
                                 bool* certified_out) {
  const TreeGeometry& g = geometry();
  out.clear();
  counters_ = {};
  if (certified_out) *certified_out = false;
  if (!(d >= 0)) return;  // NaN or negative: no face, as within()
  if (!inCoordinateRange(p, kMaxQueryCoordinate)) {
    restartState(state);
    return;
  }
  const bool same_lineage = state.lineage != 0 && state.lineage == g.lineage;
  if (same_lineage) trackMotion(state, p, g);
  bool certified = false;
  if (same_lineage && state.has_set) certified = testSetWithin(state, p, movedSinceSet(state, p, g), d, out);
  if (certified && state.set_steps < 255) ++state.set_steps;
  bool answered = certified;
  // A set that did not certify this step is dropped (it may belong to another lineage, which
  // the state is about to take): only a set gathered now may answer later steps.
  if (!answered) state.has_set = false;
  if (!answered && state.reach_steps > 0 && d < kInf) {
    if (state.within_wait > 0) {
      --state.within_wait;
    } else {
      // Gathered within d + 2R (planSet), ahead of p first.
      state.set_steps = 0;
      state.set_unmeasured = !(state.mean_step > 0);
      const SetPlan plan = planSet(state, g, same_lineage);
      const double radius = d * (1 + 1e-9) + plan.reach;
      TriangleIndex ignored = kInvalidIndex;
      if (plan.ahead) {
        const Vec3 anchor = p + plan.lead;
        storeSet(anchor, gatherCandidates(anchor, 0.0, radius, kCoherentSetSize, ignored, true), state);
        answered = state.has_set && testSetWithin(state, p, movedFromAnchor(p, anchor), d, out);
      }
      if (!answered) {
        ignored = kInvalidIndex;
        storeSet(p, gatherCandidates(p, 0.0, radius, kCoherentSetSize, ignored, true), state);
        answered = state.has_set && testSetWithin(state, p, 0.0, d, out);
      }
      if (!answered) {  // more than a set's worth of faces within d: wait before trying again
        state.has_set = false;
        state.within_wait = 8;
      }
    }
  }
  if (!answered) {
    const QueryCounters gathering = counters_;
    within(p, d, out);
    counters_.nodes_visited += gathering.nodes_visited;
    counters_.leaves_tested += gathering.leaves_tested;
    counters_.triangles_tested += gathering.triangles_tested;
  }
  if (certified_out) *certified_out = certified;
  if (!out.empty()) state.last_face = out.front().triangle;
  else if (!same_lineage) state.last_face = kInvalidIndex;
  state.lineage = g.lineage;
  state.last_point = p;
  state.last_drift = followedDrift(state, g, state.last_local);
}

ClosestPoint QueryStream::closestWithin(const Vec3& p, double tolerance) {
  const Hierarchy& h = *hierarchy_;
  const TreeGeometry& g = geometry();
  counters_ = {};
  if (!inCoordinateRange(p, kMaxQueryCoordinate)) return unanswerable();
  // An exact answer is the depth-first query's: the same answer, without the heap (about three
  // times faster).
  if (!(tolerance > 0)) return closest(p);
  const ScaledPoint sp = scalePoint(g, p);
  const double inv_scale = 1.0 / g.box_scale;
  const TriangleIndex* lanes = h.leafTriangles().data();

  // The upper bound and the surface point that realises it: a face (exact) or a vertex.
  double upper = kInf;
  TriangleIndex upper_face = kInvalidIndex;
  VertexIndex upper_vertex = kInvalidIndex;
  auto before = [](const FrontEntry& a, const FrontEntry& b) { return a.key > b.key; };
  heap_.clear();
  heap_.push_back({0.0, 0, 8});
  double lower = 0;
  float dist[8];
  double exact[8];
  while (true) {
    if (heap_.empty()) { lower = upper; break; }
    lower = std::min(heap_.front().key, upper);
    if (upper < kInf && upper - lower <= tolerance) break;  // an infinite tolerance still needs a point
    std::pop_heap(heap_.begin(), heap_.end(), before);
    const FrontEntry entry = heap_.back();
    heap_.pop_back();
    if (isLeafRef(entry.ref)) {
      const int32_t leaf = leafIndex(entry.ref);
      const uint32_t used = testLeaf(leaf, p, exact);
      for (uint32_t lane = 0; lane < used; ++lane) {
        const double d = std::sqrt(exact[lane]);
        if (d < upper) { upper = d; upper_face = lanes[8 * leaf + lane]; upper_vertex = kInvalidIndex; }
      }
      continue;
    }
    const Node8& node = g.nodes[entry.ref];
    ++counters_.nodes_visited;
    float qn[3];
    boxDistances(node, sp, dist, qn);
    for (int k = 0; k < 8; ++k) {
      if (node.child[k] == kEmptyChild) continue;
      for (int corner = 0; corner < 3; ++corner) {
        const VertexIndex v = node.corner[corner][k];
        const double d = (g.positions[v] - p).norm();
        if (d < upper) { upper = d; upper_vertex = v; upper_face = kInvalidIndex; }
      }
      const double key = slotBound(node, k, g.positions, p, dist[k], inv_scale, sp);
      if (key < upper) {
        heap_.push_back({key, node.child[k], 8});
        std::push_heap(heap_.begin(), heap_.end(), before);
      }
    }
    counters_.heap_max = std::max<uint32_t>(counters_.heap_max, static_cast<uint32_t>(heap_.size()));
  }
  TriangleHit hit;
  if (upper_face != kInvalidIndex) hit = hitOn(upper_face, p);
  ClosestPoint out = upperAnswer(h, g.positions, upper_face != kInvalidIndex ? &hit : nullptr,
                                 upper_vertex, upper, lower);
  out.counters = counters_;
  return out;
}

// An exact answer of the priority process, given as closest() gives it: among the faces at the
// same distance the lowest index (the process stops at whichever it meets first). A depth-first
// search warm-started at the answer's face opens only what could tie with it.
void QueryStream::canonicalExact(const Vec3& p, ClosestPoint& out) {
  if (out.triangle == kInvalidIndex) return;
  TriangleIndex face = out.triangle;
  depthFirst(p, squaredDistanceToFace(face, p), 0, face);
  fillFromHit(out, hitOn(face, p));  // also when the face is the same: a vertex answer's
                                     // distance can differ from the face's by an ulp
}

void QueryStream::kClosest(const Vec3& p, size_t k, std::vector<TriangleHit>& out) {
  const Hierarchy& h = *hierarchy_;
  const TreeGeometry& g = geometry();
  out.clear();
  counters_ = {};
  if (k == 0 || !inCoordinateRange(p, kMaxQueryCoordinate)) return;
  const ScaledPoint sp = scalePoint(g, p);
  const double inv_scale = 1.0 / g.box_scale;
  const TriangleIndex* lanes = h.leafTriangles().data();

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
      out.push_back(hitOn(static_cast<TriangleIndex>(entry.ref), p));
      continue;
    }
    if (isLeafRef(entry.ref)) {
      const int32_t leaf = leafIndex(entry.ref);
      const uint32_t used = h.leafLanes(leaf);
      ++counters_.leaves_tested;
      counters_.triangles_tested += used;
      for (uint32_t lane = 0; lane < used; ++lane) {
        const TriangleIndex f = lanes[8 * leaf + lane];
        push({hitOn(f, p).distance, static_cast<ChildRef>(f), lane});
      }
    } else {
      const Node8& node = g.nodes[entry.ref];
      ++counters_.nodes_visited;
      float qn[3];
      boxDistances(node, sp, dist, qn);
      for (int s = 0; s < 8; ++s) {
        if (node.child[s] == kEmptyChild) continue;
        push({boxLowerBound(dist[s], inv_scale, sp), node.child[s], 8});
      }
    }
    counters_.heap_max = std::max<uint32_t>(counters_.heap_max, static_cast<uint32_t>(heap_.size()));
  }
}

void QueryStream::within(const Vec3& p, double d, std::vector<TriangleHit>& out) {
  const Hierarchy& h = *hierarchy_;
  const TreeGeometry& g = geometry();
  out.clear();
  counters_ = {};
  if (!(d >= 0) || !inCoordinateRange(p, kMaxQueryCoordinate)) return;
  const ScaledPoint sp = scalePoint(g, p);
  const float threshold = pruneThreshold(d * d, g.box_scale * g.box_scale, sp);
  const TriangleIndex* lanes = h.leafTriangles().data();
  within_keys_.clear();
  within_hits_.clear();
  stack_.clear();
  stack_.push_back({0, 0.0f});
  float dist[8];
  while (!stack_.empty()) {
    const StackEntry entry = stack_.back();
    stack_.pop_back();
    if (isLeafRef(entry.ref)) {
      const int32_t leaf = leafIndex(entry.ref);
      keepWithin(p, leafBlock(leaf), lanes + 8 * static_cast<size_t>(leaf), h.leafLanes(leaf), d * d * (1 + 1e-9));
      continue;
    }
    const Node8& node = g.nodes[entry.ref];
    ++counters_.nodes_visited;
    float qn[3];
    boxDistances(node, sp, dist, qn);
    for (int k = 0; k < 8; ++k) {
      if (node.child[k] != kEmptyChild && dist[k] <= threshold) stack_.push_back({node.child[k], dist[k]});
    }
  }
  finishWithin(d, out);
}

void QueryStream::keepWithin(const Vec3& p, const TriangleBlock8& block, const TriangleIndex* faces, uint32_t lanes,
                             double d2) {
  double exact[8];
  closestPointsInBlock(p, block, exact, within_details_);
  for (uint32_t lane = 0; lane < lanes; ++lane) {
    if (!(exact[lane] <= d2)) continue;
    // The hit's distance is its key's: the kernel's squared distance, bit for bit.
    within_hits_.push_back(hitFrom(faces[lane], blockLaneClosest(p, block, within_details_, static_cast<int>(lane))));
    within_keys_.push_back({within_hits_.back().distance, faces[lane], static_cast<uint32_t>(within_hits_.size() - 1)});
  }
}

// The hits found (within_keys_, within_hits_) whose distance is <= d, in within()'s order. The
// keys are sorted (small entries, not the hits); each hit is the one hitOn() gives, from the
// block kernel that computed its key's distance (the same bits: the hits come out in order,
// checked, sorted if not).
void QueryStream::finishWithin(double d, std::vector<TriangleHit>& out) {
  std::sort(within_keys_.begin(), within_keys_.end());
  out.clear();
  for (const WithinKey& key : within_keys_) {
    const TriangleHit& hit = within_hits_[key.hit];
    if (hit.distance <= d) out.push_back(hit);
  }
  if (!std::is_sorted(out.begin(), out.end(), hitBefore)) std::sort(out.begin(), out.end(), hitBefore);
}

// ---- The dynamic front (paper section 5.1) ----

namespace {
// Heap order of the dynamic front: smaller key first; bounds before faces at equal keys; faces
// by triangle index (same tie rules as kClosest).
template <class Entry>
bool driftAfter(const Entry& a, const Entry& b) {
  if (a.key != b.key) return a.key > b.key;
  const bool a_face = a.lane < 8, b_face = b.lane < 8;
  if (a_face != b_face) return a_face;
  return a_face && a.ref > b.ref;
}
}  // namespace

void QueryStream::frontPush(const DriftEntry& e) {
  front_.push_back(e);
  std::push_heap(front_.begin(), front_.end(), driftAfter<DriftEntry>);
}

QueryStream::DriftEntry QueryStream::frontPop() {
  std::pop_heap(front_.begin(), front_.end(), driftAfter<DriftEntry>);
  const DriftEntry e = front_.back();
  front_.pop_back();
  return e;
}

void QueryStream::frontStart(const Vec3& p) {
  front_.clear();
  drift_ = 0;
  front_point_ = p;
  has_front_ = true;
  front_version_ = geometry().version;
  ++coherence_.front_resets;
  frontPush({0.0, 0.0, 0, -1, 0, 8});
}

double QueryStream::entryBound(const DriftEntry& e, const Vec3& p, const ScaledPoint& sp) const {
  const TreeGeometry& g = geometry();
  if (e.lane < 8) return hitOn(static_cast<TriangleIndex>(e.ref), p).distance;
  if (e.parent < 0) return 0;
  const Node8& node = g.nodes[e.parent];
  float box_d2 = 0;
  if (!sp.far) {
    float q[3];
    nodePoint(node, sp, q);
    for (int axis = 0; axis < 3; ++axis) {
      const float gap = std::max(std::max(node.lower[axis][e.slot] - q[axis], q[axis] - node.upper[axis][e.slot]), 0.0f);
      box_d2 += gap * gap;
    }
  }
  return slotBound(node, e.slot, g.positions, p, box_d2, 1.0 / g.box_scale, sp);
}

// Refines the front at p. Anytime (k == 0): until upper - lower <= tolerance. k closest: until
// k fresh faces reach the top (they are written to *out and pushed back).
void QueryStream::frontRefine(const Vec3& p, const ScaledPoint& sp, double& upper,
                              TriangleIndex& upper_face, VertexIndex& upper_vertex,
                              bool stop_at_tolerance, double tolerance, size_t k,
                              std::vector<TriangleHit>* out) {
  const Hierarchy& h = *hierarchy_;
  const TreeGeometry& g = geometry();
  const double inv_scale = 1.0 / g.box_scale;
  const TriangleIndex* lanes = h.leafTriangles().data();
  popped_.clear();
  float dist[8];
  double lower = 0;
  front_tie_ = true;  // unless a face at the top proves otherwise
  double kth_key = 0;  // k closest: the key of the last face taken
  // Keys carry the drift's rounding (relative 1e-12 of the keys and the drift) and the bounds'
  // own, at the coordinates' size (kSlotRounding of the point's, and of the distance, whose
  // faces the near bounds come from): an entry within both of a face's key may hold a face as
  // close (found by the degenerate-faces test in the sanitizer build, whose rounding differs:
  // at coordinates of 1e4 a face at distance 0 was missed behind one 9e-13 away).
  const double rounding = kSlotRounding * p.cwiseAbs().maxCoeff();
  auto near = [&](double key) { return key + 1e-12 * (std::abs(key) + std::abs(drift_)) + rounding + kSlotRounding * std::abs(key - drift_); };
  while (!front_.empty()) {
    lower = std::min(front_.front().key - drift_, upper);
    if (stop_at_tolerance && upper < kInf && upper - lower <= tolerance) break;
    // Keys carry the drift's rounding: distances a few ulps apart can merge or swap. Past k
    // faces, whatever is within that rounding of the k-th key is taken too (the caller keeps
    // the k closest by exact distance).
    if (!stop_at_tolerance && out->size() >= k &&
        front_.front().key > near(kth_key))
      break;
    DriftEntry e = frontPop();
    if (e.drift_at < drift_) {  // stale: recompute at p and put back
      const double bound = entryBound(e, p, sp);
      ++coherence_.recomputed;
      if (e.lane < 8 && bound < upper) { upper = bound; upper_face = static_cast<TriangleIndex>(e.ref); upper_vertex = kInvalidIndex; }
      e.key = bound + drift_;
      e.drift_at = drift_;
      frontPush(e);
      continue;
    }
    if (e.lane < 8) {  // a fresh face at the top: the closest remaining face
      if (stop_at_tolerance) {
        // Exact: the answer is this face's distance, which key - drift_ can miss by an ulp;
        // an infinite lower bound lets upperAnswer take that distance for both bounds. Another
        // face can tie with it only if the next entry's bound reaches its distance (keys carry
        // the drift's rounding: a relative margin covers it).
        upper = e.key - drift_;
        lower = kInf;
        front_tie_ = !front_.empty() && front_.front().key <= near(e.key);
        upper_face = static_cast<TriangleIndex>(e.ref);
        upper_vertex = kInvalidIndex;
        frontPush(e);
        break;
      }
      out->push_back(hitOn(static_cast<TriangleIndex>(e.ref), p));
      popped_.push_back(e);
      kth_key = e.key;
      continue;
    }
    if (isLeafRef(e.ref)) {
      const int32_t leaf = leafIndex(e.ref);
      const uint32_t used = h.leafLanes(leaf);
      ++counters_.leaves_tested;
      counters_.triangles_tested += used;
      for (uint32_t lane = 0; lane < used; ++lane) {
        const TriangleIndex f = lanes[8 * leaf + lane];
        const double d = hitOn(f, p).distance;
        if (d < upper) { upper = d; upper_face = f; upper_vertex = kInvalidIndex; }
        frontPush({d + drift_, drift_, static_cast<ChildRef>(f), -1, 0, static_cast<uint8_t>(lane)});
      }
      continue;
    }
    const Node8& node = g.nodes[e.ref];
    ++counters_.nodes_visited;
    float qn[3];
    boxDistances(node, sp, dist, qn);
    for (int s = 0; s < 8; ++s) {
      if (node.child[s] == kEmptyChild) continue;
      for (int corner = 0; corner < 3; ++corner) {
        const VertexIndex v = node.corner[corner][s];
        const double d = (g.positions[v] - p).norm();
        if (d < upper) { upper = d; upper_vertex = v; upper_face = kInvalidIndex; }
      }
      const double bound = slotBound(node, s, g.positions, p, dist[s], inv_scale, sp);
      frontPush({bound + drift_, drift_, node.child[s], e.ref, static_cast<uint8_t>(s), 8});
    }
    counters_.heap_max = std::max<uint32_t>(counters_.heap_max, static_cast<uint32_t>(front_.size()));
  }
  for (const DriftEntry& e : popped_) frontPush(e);
  front_distance_ = upper;
  lower_ = lower;
}

// Moves the front to p: every bound drops by the distance moved (the drift offset), or the
// front restarts from the root (the reset policy: new geometry, a front over budget, or a jump
// longer than jump_factor times the last distance).
void QueryStream::frontMove(const Vec3& p) {
  const double moved = (p - front_point_).norm();
  if (!has_front_ || front_version_ != geometry().version || front_.size() > options_.front_budget ||
      moved > options_.jump_factor * front_distance_) {
    frontStart(p);
  } else {
    drift_ += moved;
    front_point_ = p;
    // Keys are bound + drift when computed, rounded at the drift's magnitude: once the drift is
    // large against what the front still resolves (its least bound now, or a thousandth of the
    // mesh's size), start over, e.g. a point back from far away along the way it went.
    const double least = front_.empty() ? 0.0 : front_.front().key - drift_;
    if (drift_ > 1e3 * std::max(least, 1e-3 / geometry().box_scale)) frontStart(p);
  }
}

ClosestPoint QueryStream::closestWithinCoherent(const Vec3& p, double tolerance) {
  const Hierarchy& h = *hierarchy_;
  const TreeGeometry& g = geometry();
  counters_ = {};
  ++coherence_.steps;
  if (!inCoordinateRange(p, kMaxQueryCoordinate)) {
    has_front_ = false;  // the front restarts at the next point
    return unanswerable();
  }
  const ScaledPoint sp = scalePoint(g, p);
  frontMove(p);
  double upper = kInf;
  TriangleIndex upper_face = kInvalidIndex;
  VertexIndex upper_vertex = kInvalidIndex;
  frontRefine(p, sp, upper, upper_face, upper_vertex, true, tolerance, 0, nullptr);
  TriangleHit hit;
  if (upper_face != kInvalidIndex) hit = hitOn(upper_face, p);
  ClosestPoint out = upperAnswer(h, g.positions, upper_face != kInvalidIndex ? &hit : nullptr,
                                 upper_vertex, upper, lower_);
  if (!(tolerance > 0) && front_tie_) canonicalExact(p, out);  // NaN is 0, as in closestWithin
  out.counters = counters_;
  return out;
}

void QueryStream::kClosestCoherent(const Vec3& p, size_t k, std::vector<TriangleHit>& out) {
  const TreeGeometry& g = geometry();
  out.clear();
  counters_ = {};
  ++coherence_.steps;
  if (!inCoordinateRange(p, kMaxQueryCoordinate)) {
    has_front_ = false;  // the front restarts at the next point
    return;
  }
  if (k == 0) return;
  const ScaledPoint sp = scalePoint(g, p);
  frontMove(p);
  double upper = kInf;
  TriangleIndex upper_face = kInvalidIndex;
  VertexIndex upper_vertex = kInvalidIndex;
  frontRefine(p, sp, upper, upper_face, upper_vertex, false, 0, k, &out);
  // Front keys carry the drift offset, which can merge distances one ulp apart: order the
  // answer by the exact distances (ties by triangle index), as kClosest does, and keep k.
  std::sort(out.begin(), out.end(), hitBefore);
  if (out.size() > k) out.resize(k);
}

}  // namespace meshsweeper
