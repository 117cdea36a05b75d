// Certified Hausdorff distance between meshes (Guéziec, "Meshsweeper", section 6 and Fig. 9;
// DESIGN.md section 4).
//
// One direction, h(A, B) (a "cell" is a triangle of A or a piece of one after splits):
//   vertex pass: query every vertex of A on B, in Morton order, in fixed chunks of 64 (one
//     query stream per thread, each query warm-started from the previous one's closest face);
//     LB <- the largest vertex distance
//   every triangle of A is a cell (bounded in the Morton order of its first corner); UB(cell) <-
//     the corner bound if that makes it final, else the cover bound (with up to kExtraQueries
//     extra queries), else the bisector bound (below)
//   max-heap of cells on UB
//   repeat (round):
//     threshold <- LB + tol   (symmetric: the larger LB of the two directions + tol)
//     pop up to `batch` cells with UB > threshold (the highest first)
//     their edge midpoints: one sample per edge, shared with every cell that has that edge
//       (hash map keyed by the edge's two sample ids); query the new ones (Morton order,
//       parallel chunks; each warm-started from the closest face of its edge's nearer end)
//     LB <- max(LB, new sample distances)
//     each popped cell -> 4 children (corners and edge midpoints), or 2 for a thin one (the
//       halves of its longest edge, its width a margin: kThinFraction); bound each child;
//       push it if its UB > threshold, else it is final ("dropped")
//   until the highest UB <= threshold
//   upper = max(LB, highest UB left, highest UB dropped) <= LB + tol
//
// Both directions: refine, each round, the direction whose highest UB is larger; cells of
// either direction are dropped once their UB is within tol of the larger LB, so the direction
// that cannot change H stops being refined as soon as that is proven (paper section 6).
//
// Determinism: a sample's answer depends only on its point and on the earlier samples of its
// chunk (warm start; ties between equidistant faces), chunks and batches are fixed by the data
// (not by the thread count), and every reduction (LB, heap pushes, sums) runs sequentially in
// sample/cell order. So 1 and N threads give bit-identical results.
//
// ---- The bisector bound (paper Fig. 9) ----
// Corners v0, v1, v2 of a cell t, with points c0, c1, c2 of B (their closest points). For any
// x, d(x, B) <= f(x) = min_i |x - c_i|. The region R_i = {x in t : |x - c_i| <= |x - c_j| for
// all j} is t cut by half-planes h_ij(x) = |x - c_i|^2 - |x - c_j|^2 <= 0, and h_ij is affine
// in x: h_ij(x) = (c_j - c_i) . (2x - c_i - c_j). So R_i is a convex polygon, f = |x - c_i| is
// convex on it and peaks at one of its vertices: a corner of t, a crossing of a bisector plane
// h_ij = 0 with an edge of t, or the point of t's plane where h_01 = h_02 = 0 (equidistant from
// all three; only when it lies inside t). max over t of f is the largest f over these
// candidates (identical c_i are merged; with two distinct points there is one bisector and no
// triple point; on a degenerate t, a segment, the crossings on its edges suffice).
// Rounding: a candidate computed at x' instead of x* (|x' - x*| <= delta, from a first-order
// error bound of its construction) gives f(x*) <= f(x') + delta, since f is 1-Lipschitz; each
// candidate is also capped by a bound valid for every point of t (or of its edge):
// max over t of |x - c_i| = max_k |v_k - c_i| by convexity. An ill-conditioned triple point
// (planes nearly parallel to t) thus costs the cap, never a wrong bound. It is skipped when
// the circumradius of c0 c1 c2 exceeds the cap (then f > cap there, so it is not in t).
//
// ---- The cover bound ----
// d(x, T) for one triangle T of B is convex in x, so over any triangle P it peaks at P's
// corners: max over P of d(x, B) <= min over T of max over P's corners y of d(y, T). The
// candidates T are the faces of the hierarchy's leaf blocks (8 spatially grouped faces of B,
// tested 8 at a time) that hold the cell's corners' closest triangles: at most 24 faces, not
// only the 3 closest ones, so a cell much larger than B's triangles (the coarse-to-fine
// direction) can still be covered. The cell is covered as a whole, or its four midpoint pieces
// each, recursively up to kCoverLevels levels (64 pieces), splitting only the pieces that no
// single candidate covers; no point of B is queried for this, the pieces' corners are only
// measured against the candidates. Only whether the bound is <= `enough` (the cell is then
// final) matters for cells that would be split anyway, so a piece takes the first candidate
// that brings it below, and the bound is the largest over the pieces. When some piece has no
// such candidate the cell gets the bisector bound (capped by min_i max_k |v_k - c_i|), which
// orders the heap. A ball around each leaf block skips blocks too far from a point.
// On the armadillo, bunny and mannequin pairs (1e-4) this made 3.5-5x fewer cells split than
// the bisector bound with the face bound of the 3 closest triangles over the cell and its four
// midpoint pieces (which the cover bound contains: the same pieces, more candidates).
// Extra queries: when some piece has no covering candidate, the centroid of the first such
// piece is queried exactly (warm-started from the nearest corner's closest face) and the leaf
// block of its closest face joins the candidates; the cover is retried, up to kExtraQueries
// times per cell (a retry re-measures no piece corner: CoverGrid keeps them). The queried
// point is a point of the cell, so its exact distance is a sample for LB too (per chunk of
// cells the farthest one, merged in chunk order: deterministic); it is not a cell corner, so
// it does not enter mean/RMS. One query replaces the split it avoids
// (two or three midpoint queries and four child bounds): on the armadillo pair (1e-4) the
// coarse-to-fine direction split 96 cells instead of 5010 (1 extra query: 1449, 2: 369), on the
// bunny pair 4224 instead of 25694. Fewer final cells also make the mean/RMS estimates coarser
// (armadillo, coarse to fine: mean 0.119 instead of 0.097).
// The pieces' corners are midpoints computed in double: the pieces cover the cell up to gaps of
// the order of the rounding of a coordinate, which the margin below covers (f is 1-Lipschitz).
//
// ---- The corner bound ----
// d(x, B) is 1-Lipschitz, so d(x, B) <= d_k + |x - v_k| for each corner; see cornerBound(). It
// reads no face of B and is only used when it makes the cell final.
//
// Each bound gets a margin of 1e-12 times the largest coordinate magnitude of A and B, which
// covers the rounding of the distances themselves.
#include "core/hausdorff.h"
#include "core/morton.h"

#include "core/sweep_query.h"
#include "core/threads.h"

#include <Eigen/Geometry>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace meshsweeper {
namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kEps = std::numeric_limits<double>::epsilon();
// Margin added to every upper bound, relative to the largest coordinate magnitude.
constexpr double kMarginRelative = 1e-12;
// Samples per query chunk (fixed: the work decomposition must not depend on thread count).
constexpr size_t kQueryChunk = 64;
// Triangles ahead whose corners' samples are prefetched while bounding.
constexpr size_t kPrefetchAhead = 4;
// Cells per bounding chunk.
constexpr size_t kCellChunk = 64;
// Cells popped per refinement round: max(kMinBatch, heap size / kBatchDivisor), at most
// kMaxBatch. Larger batches parallelise better but may split cells that a sample of an earlier
// cell of the same round would have made final.
constexpr size_t kMinBatch = 64;
constexpr size_t kBatchDivisor = 16;
constexpr size_t kMaxBatch = 8192;
// A cell 2^-kMaxDepth the size of its triangle is not split further.
constexpr uint8_t kMaxDepth = 48;
// A cell whose third corner lies within this fraction of the tolerance of its longest edge
// (degenerate: collinear or repeated corners, or nearly so) is split as that segment, in two,
// its thickness carried as a margin. Split in four like the others, its children would overlap
// (three of them cover half the segment each: a triangle with a repeated corner ran into
// gigabytes at a relative tolerance of 1e-10; found by review).
constexpr double kThinFraction = 1e-3;

// ---- Samples and cells -----------------------------------------------------------------

struct Sample {
  Vec3 position = Vec3::Zero();  // a point of A
  Vec3 closest = Vec3::Zero();   // its closest point on B
  double distance = kNaN;        // exact distance to B (NaN: not queried, unused vertex)
  TriangleIndex closest_triangle = kInvalidIndex;  // [triangle of B]
  TriangleIndex source = kInvalidIndex;            // [triangle of A] one that contains it
};

struct Cell {
  uint32_t corner[3];    // [sample]
  TriangleIndex source;  // [triangle of A] the original triangle it is a piece of
  double upper;          // certified bound of d(x, B) over the cell
  uint8_t depth;         // 0 for an original triangle
  bool split;            // replaced by its children
  float thickness;       // every point of the piece of A is within thickness * scale of the
                         // cell (a segment standing for a thin piece, thinCell; relative to
                         // the coordinates' scale, so that it fits a float); 0 for a triangle
};

// Whether a cell is split as a segment (kThinFraction), along which edge (its corners edge,
// edge + 1), and the children's thickness then (rounded up).
struct ThinSplit {
  bool thin = false;
  int edge = 0;
  float thickness = 0;  // relative, as Cell::thickness
  double area = 0;      // the cell's (its segments have none)
};

// Mean and RMS integrals: area, integral of the distance and of its square.
struct MeanSums {
  double area = 0, sum = 0, sum2 = 0;
};

// A table's bytes (its capacity), and at most while it grows to `needed` elements (libstdc++'s
// growth; other libraries grow by less), old and new buffers both held while the elements move:
// push_back doubles a full capacity, as often as it takes (only the last old buffer is still
// held); resize and assign take max(2 size, needed) at once.
template <class T>
uint64_t capacityBytes(const std::vector<T>& v) {
  return v.capacity() * sizeof(T);
}
template <class T>
uint64_t pushedBytes(const std::vector<T>& v, size_t needed) {
  size_t capacity = v.capacity(), previous = capacity;
  while (capacity < needed) {
    previous = capacity;
    capacity = std::max<size_t>(1, 2 * capacity);
  }
  return (capacity == v.capacity() ? capacity : previous + capacity) * sizeof(T);
}
template <class T>
uint64_t resizedBytes(const std::vector<T>& v, size_t needed) {
  if (needed <= v.capacity()) return capacityBytes(v);
  return (v.capacity() + std::max(2 * v.size(), needed)) * sizeof(T);
}

// Edge (two sample ids) -> midpoint sample id; open addressing, linear probing.
class EdgeMap {
 public:
  // Returns the value stored for (a, b) or inserts `fresh` and returns it.
  uint32_t findOrInsert(uint32_t a, uint32_t b, uint32_t fresh, bool& inserted) {
    if (a > b) std::swap(a, b);
    const uint64_t key = (static_cast<uint64_t>(a) << 32 | b) + 1;  // 0 marks an empty slot
    if (2 * (size_ + 1) > keys_.size()) grow();
    size_t i = slot(key);
    while (keys_[i] != 0) {
      if (keys_[i] == key) {
        inserted = false;
        return values_[i];
      }
      i = (i + 1) & (keys_.size() - 1);
    }
    keys_[i] = key;
    values_[i] = fresh;
    ++size_;
    inserted = true;
    return fresh;
  }

  // Its bytes now, and at most while `inserts` more go in: it may grow more than once, and holds
  // the last old table and the new one while it moves the entries.
  uint64_t bytes() const { return keys_.capacity() * sizeof(uint64_t) + values_.capacity() * sizeof(uint32_t); }
  uint64_t bytesAfter(size_t inserts) const {
    size_t slots = keys_.size(), previous = slots;
    while (2 * (size_ + inserts) > slots) {
      previous = slots;
      slots = std::max<size_t>(1024, 2 * slots);
    }
    const uint64_t per_slot = sizeof(uint64_t) + sizeof(uint32_t);
    return slots == keys_.size() ? bytes() : std::max(bytes(), (previous + slots) * per_slot);
  }

 private:
  std::vector<uint64_t> keys_;
  std::vector<uint32_t> values_;
  size_t size_ = 0;
  int shift_ = 64;

  size_t slot(uint64_t key) const {
    return static_cast<size_t>((key * 0x9E3779B97F4A7C15ull) >> shift_);
  }
  void grow() {
    std::vector<uint64_t> keys = std::move(keys_);
    std::vector<uint32_t> values = std::move(values_);
    const size_t capacity = std::max<size_t>(1024, 2 * keys.size());
    keys_.assign(capacity, 0);
    values_.assign(capacity, 0);
    shift_ = 64 - static_cast<int>(std::log2(static_cast<double>(capacity)));
    for (size_t j = 0; j < keys.size(); ++j) {
      if (keys[j] == 0) continue;
      size_t i = slot(keys[j]);
      while (keys_[i] != 0) i = (i + 1) & (capacity - 1);
      keys_[i] = keys[j];
      values_[i] = values[j];
    }
  }
};

// ---- Bounds over one cell --------------------------------------------------------------

struct CellBound {
  double upper;
  bool face_won;
};

// f(x) = min over the distinct points c of |x - c|.
inline double nearestOf(const Vec3& x, const Vec3* c, int n) {
  double best2 = (x - c[0]).squaredNorm();
  for (int i = 1; i < n; ++i) best2 = std::min(best2, (x - c[i]).squaredNorm());
  return std::sqrt(best2);
}

// The bisector bound without margin: max over t = (v0, v1, v2) of min_i |x - c_i|.
// `scale` is the largest coordinate magnitude (for the rounding error bounds).
double bisectorBound(const Vec3 v[3], const Vec3 c_in[3], double scale) {
  Vec3 c[3];
  int n = 0;
  for (int i = 0; i < 3; ++i) {
    bool seen = false;
    for (int j = 0; j < n; ++j) seen = seen || c[j] == c_in[i];
    if (!seen) c[n++] = c_in[i];
  }
  double best = 0;
  for (int k = 0; k < 3; ++k) best = std::max(best, nearestOf(v[k], c, n));
  if (n == 1) return best;

  // cap_i = max over t of |x - c_i|; cap = min_i cap_i bounds f everywhere on t.
  double cap_i[3];
  double cap = kInf;
  for (int i = 0; i < n; ++i) {
    double m = 0;
    for (int k = 0; k < 3; ++k) m = std::max(m, (v[k] - c[i]).squaredNorm());
    cap_i[i] = std::sqrt(m);
    cap = std::min(cap, cap_i[i]);
  }
  if (best >= cap) return best;  // f <= cap everywhere and a corner reaches it

  // Bisector planes crossing the edges.
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      const Vec3 delta = c[j] - c[i];
      const Vec3 sum = c[i] + c[j];
      const double err_h =
          64 * kEps * std::sqrt(delta.squaredNorm()) * scale;  // error of an h value
      double h[3];
      for (int k = 0; k < 3; ++k) h[k] = delta.dot(2 * v[k] - sum);
      for (int k = 0; k < 3; ++k) {
        const int l = (k + 1) % 3;
        if (!((h[k] < 0 && h[l] > 0) || (h[k] > 0 && h[l] < 0))) continue;
        const double s = std::clamp(h[k] / (h[k] - h[l]), 0.0, 1.0);
        const Vec3 edge = v[l] - v[k];
        const Vec3 x = v[k] + s * edge;
        const double delta_x = 3 * err_h / std::abs(h[k] - h[l]) * edge.norm();
        const double value = nearestOf(x, c, n) + delta_x;
        if (value <= best) continue;
        const double edge_cap2 =
            std::min(std::max((v[k] - c[i]).squaredNorm(), (v[l] - c[i]).squaredNorm()),
                     std::max((v[k] - c[j]).squaredNorm(), (v[l] - c[j]).squaredNorm()));
        best = std::max(best, std::min(value, std::sqrt(edge_cap2)));
      }
    }
  }
  if (n < 3 || best >= cap) return std::min(best, cap);

  // The triple point, only if it may lie in t: its distance to the c_i is at least the
  // circumradius of c0 c1 c2, and f <= cap on t.
  const Vec3 a = c[1] - c[0], b = c[2] - c[0];
  const double na = a.norm(), nb = b.norm(), nab = (b - a).norm();
  const double cross = a.cross(b).norm();
  const double radius_low = na * nb * nab / (2 * (cross + 16 * kEps * na * nb)) * (1 - 1e-12);
  if (!(radius_low <= cap)) return best;

  const Vec3 e1 = v[1] - v[0], e2 = v[2] - v[0];
  const Vec3 sum1 = c[0] + c[1], sum2 = c[0] + c[2];
  // h_01 = 0 and h_02 = 0 at v0 + u e1 + w e2:  G (u, w) = r.
  const double g1x = 2 * a.dot(e1), g1y = 2 * a.dot(e2);
  const double g2x = 2 * b.dot(e1), g2y = 2 * b.dot(e2);
  const double r1 = -a.dot(2 * v[0] - sum1), r2 = -b.dot(2 * v[0] - sum2);
  const double det = g1x * g2y - g1y * g2x;
  const double ne = std::max(e1.norm(), e2.norm());
  const double nab2 = std::sqrt(na * na + nb * nb);
  const double err_g = 64 * kEps * nab2 * ne;  // norm of the error of G
  const double err_r = 64 * kEps * nab2 * scale;
  const double g_norm = std::sqrt(g1x * g1x + g1y * g1y + g2x * g2x + g2y * g2y);
  const double inv_norm = g_norm / std::abs(det);  // >= |G^-1|
  double value = cap;
  if (det != 0 && std::isfinite(inv_norm) && inv_norm * err_g <= 0.5) {
    const double u = (r1 * g2y - r2 * g1y) / det;
    const double w = (g1x * r2 - g2x * r1) / det;
    // First-order perturbation bound, doubled for the second-order terms.
    const double err_uw = 2 * 2 * inv_norm * (err_g * std::sqrt(u * u + w * w) + err_r);
    const double delta_x = err_uw * (e1.norm() + e2.norm());
    Vec3 x = v[0] + u * e1 + w * e2;
    if (u < 0 || w < 0 || u + w > 1) {
      // Outside t as computed: the projection onto t is within delta_x of the true point if
      // the true point is in t (projection onto a convex set does not expand distances).
      const TriangleClosest p = closestPointOnTriangle(x, v[0], v[1], v[2]);
      if (std::sqrt(p.squared_distance) > delta_x) return best;  // not in t
      x = p.point;
    }
    if (!std::isfinite(delta_x)) return std::max(best, cap);
    value = std::min(nearestOf(x, c, n) + delta_x, cap);
  }
  return std::max(best, value);
}

// The corner bound without margin: d(x, B) <= d(v_k, B) + |x - v_k| (d is 1-Lipschitz), so
// over t = (v0, v1, v2) d(x, B) <= min(min_k (d_k + max_j |v_j - v_k|), max_k d_k + R), R the
// circumradius of t: every x of t is within R of some corner (with O the circumcentre in t's
// plane and u = (x - O)/|x - O|, some corner has (v_k - x).u >= 0 since x is in their hull, and
// then R^2 = |v_k - O|^2 >= |v_k - x|^2 + |x - O|^2 >= |v_k - x|^2). No point of B is read.
// Rounding: the cross product's error is below 8 eps |e1| |e2| (a smaller |cross| only raises
// R); the rest is a few relative eps, which the caller's (1 + 1e-13) factor covers.
inline double cornerBound(const Vec3 v[3], double d0, double d1, double d2) {
  const Vec3 e0 = v[2] - v[1], e1 = v[0] - v[2], e2 = v[1] - v[0];
  const double l0 = e0.norm(), l1 = e1.norm(), l2 = e2.norm();
  // Largest distance from each corner to the others.
  double bound = std::min({d0 + std::max(l1, l2), d1 + std::max(l2, l0), d2 + std::max(l0, l1)});
  const double cross = e1.cross(e2).norm() - 8 * kEps * l1 * l2;
  if (cross > 0) bound = std::min(bound, std::max({d0, d1, d2}) + l0 * l1 * l2 / (2 * cross));
  return bound;
}

// A ball around each leaf block of B (box centre, farthest corner): a point farther than
// radius + target from it is farther than target from all eight faces.
struct BlockBall {
  Vec3 centre;
  double radius;
};

std::vector<BlockBall> blockBalls(const Hierarchy& b) {
  const std::vector<TriangleBlock8>& blocks = b.leafBlocks();
  std::vector<BlockBall> balls(blocks.size());
  for (size_t leaf = 0; leaf < blocks.size(); ++leaf) {
    const TriangleBlock8& block = blocks[leaf];
    Vec3 lower = Vec3::Constant(kInf), upper = Vec3::Constant(-kInf);
    for (int k = 0; k < 3; ++k) {
      for (int lane = 0; lane < 8; ++lane) {
        const Vec3 x(block.v[k][0][lane], block.v[k][1][lane], block.v[k][2][lane]);
        lower = lower.cwiseMin(x);
        upper = upper.cwiseMax(x);
      }
    }
    const Vec3 centre = 0.5 * (lower + upper);
    double r2 = 0;
    for (int k = 0; k < 3; ++k) {
      for (int lane = 0; lane < 8; ++lane) {
        const Vec3 x(block.v[k][0][lane], block.v[k][1][lane], block.v[k][2][lane]);
        r2 = std::max(r2, (x - centre).squaredNorm());
      }
    }
    balls[leaf] = {centre, std::sqrt(r2) * (1 + 1e-12)};
  }
  return balls;
}

// What the cover bound reads of B: its leaf blocks, which block holds each face, their balls.
struct CoverContext {
  const TriangleBlock8* blocks;    // [leaf] the hierarchy's leaf blocks (original faces)
  const uint32_t* face_leaf;       // [triangle of B] the leaf block that holds it
  const BlockBall* balls;          // [leaf]
};

// Levels of midpoint pieces the cover bound may split a cell into (4^3 = 64 pieces at most).
// Measured on the bunny pair: 2 levels split 30% more cells, 4 levels gain nothing.
constexpr int kCoverLevels = 3;
// Extra exact queries per cell: when no candidate covers a piece, the closest face of its
// centroid brings its leaf block in as one more candidate.
constexpr int kExtraQueries = 3;
constexpr int kMaxCandidateBlocks = 3 + kExtraQueries;  // one per corner, one per extra query

// A corner of a piece with its squared distances to the candidate blocks, computed on demand.
// Left uninitialised: CoverGrid sets position and known when it makes the point.
struct CoverPoint {
  Vec3 position;
  uint32_t known;                        // bit u: block u measured
  uint8_t within[kMaxCandidateBlocks];   // [block] lanes within target (bit per lane)
  alignas(64) double squared[kMaxCandidateBlocks][8];  // [block][lane]
};

// The corners of a cell's pieces: a barycentric grid of step 2^-kCoverLevels, (i, j) standing
// for v0 + i/side (v1 - v0) + j/side (v2 - v0). Each point is computed once per cell, as the
// midpoint of the edge of the coarser piece it splits (the same value from both pieces that
// share the edge), and measured once per candidate block, so that a retry with one more
// candidate measures only that one.
struct CoverGrid {
  static constexpr int kSide = 1 << kCoverLevels;
  static constexpr int kPoints = (kSide + 1) * (kSide + 2) / 2;
  struct Index {
    int i, j;
  };
  CoverPoint points[kPoints];
  bool made[kPoints] = {};

  static int slot(Index g) { return g.i * (kSide + 1) - g.i * (g.i - 1) / 2 + g.j; }
  CoverPoint& corner(Index g, const Vec3& position) {
    const int k = slot(g);
    made[k] = true;
    points[k].position = position;
    points[k].known = 0;
    return points[k];
  }
  // The midpoint of the edge (a, b).
  CoverPoint& midpoint(Index a, Index b, Index& m) {
    m = {(a.i + b.i) / 2, (a.j + b.j) / 2};
    const int k = slot(m);
    if (!made[k]) {
      made[k] = true;
      points[k].position = 0.5 * (points[slot(a)].position + points[slot(b)].position);
      points[k].known = 0;
    }
    return points[k];
  }
};

// Covers pieces of one cell with single faces of the candidate blocks (see the file comment).
class Cover {
 public:
  using Index = CoverGrid::Index;
  Cover(const CoverContext& context, const uint32_t* leaves, int blocks, double target,
        CoverGrid& grid)
      : context_(context), leaves_(leaves), blocks_(blocks), target_(target),
        target2_(target * target), grid_(grid) {}

  // Largest over the pieces of (a, b, c) of the squared bound of its covering face, or +inf
  // when some piece `levels` splits deep has no candidate face within target of its corners.
  // `hint`: the block that covered the previous piece, tried first.
  double piece(Index ga, Index gb, Index gc, int levels, int& hint) const {
    CoverPoint& a = grid_.points[CoverGrid::slot(ga)];
    CoverPoint& b = grid_.points[CoverGrid::slot(gb)];
    CoverPoint& c = grid_.points[CoverGrid::slot(gc)];
    for (int i = 0; i < blocks_; ++i) {
      const int u = i == 0 ? hint : (i <= hint ? i - 1 : i);
      const double m = coverWith(a, b, c, u);
      if (m <= target2_) {
        hint = u;
        return m;
      }
    }
    if (levels <= 0) {
      if (!failed_) {
        failed_ = true;
        fail_point_ = (a.position + b.position + c.position) / 3;
      }
      return kInf;
    }
    Index mid[3];
    grid_.midpoint(ga, gb, mid[0]);
    grid_.midpoint(gb, gc, mid[1]);
    grid_.midpoint(gc, ga, mid[2]);
    const Index pieces[4][3] = {
        {ga, mid[0], mid[2]}, {mid[0], gb, mid[1]}, {mid[2], mid[1], gc}, {mid[0], mid[1], mid[2]}};
    double worst = 0;
    for (auto& p : pieces) {
      const double m = piece(p[0], p[1], p[2], levels - 1, hint);
      if (!(m <= target2_)) return kInf;
      worst = std::max(worst, m);
    }
    return worst;
  }

  // Whether some piece had no covering candidate, and the centroid of the first such piece.
  bool failed() const { return failed_; }
  const Vec3& failPoint() const { return fail_point_; }

 private:
  const CoverContext& context_;
  const uint32_t* leaves_;  // [block] candidate leaf blocks
  int blocks_;
  double target_, target2_;
  CoverGrid& grid_;
  mutable bool failed_ = false;
  mutable Vec3 fail_point_ = Vec3::Zero();

  // Lanes of block u within target of the point (measured once per point and block).
  unsigned within(CoverPoint& q, int u) const {
    if (q.known >> u & 1) return q.within[u];
    q.known |= 1u << u;
    const uint32_t leaf = leaves_[u];
    const BlockBall& ball = context_.balls[leaf];
    const double reach = ball.radius + target_;
    unsigned mask = 0;
    if ((q.position - ball.centre).squaredNorm() <= reach * reach) {
      squaredDistancesToBlock(q.position, context_.blocks[leaf], q.squared[u]);
      for (int lane = 0; lane < 8; ++lane)
        mask |= static_cast<unsigned>(q.squared[u][lane] <= target2_) << lane;
    }
    q.within[u] = static_cast<uint8_t>(mask);
    return mask;
  }

  // min over the faces of block u within target of all three corners of the largest of their
  // squared distances; +inf when there is none. Corners already measured are checked first.
  double coverWith(CoverPoint& a, CoverPoint& b, CoverPoint& c, int u) const {
    CoverPoint* corners[3] = {&a, &b, &c};
    unsigned mask = 0xff;
    for (int k = 0; k < 3 && mask; ++k)
      if (corners[k]->known >> u & 1) mask &= corners[k]->within[u];
    for (int k = 0; k < 3 && mask; ++k)
      if (!(corners[k]->known >> u & 1)) mask &= within(*corners[k], u);
    double best = kInf;
    for (; mask; mask &= mask - 1) {
      const int lane = __builtin_ctz(mask);
      best = std::min(best, std::max({a.squared[u][lane], b.squared[u][lane], c.squared[u][lane]}));
    }
    return best;
  }
};

// An upper bound of d(x, B) over the cell (s0, s1, s2). Only whether it is <= `enough` (the
// cell is then final) matters for cells that will be split anyway: the cover bound is the
// first covering found; when it fails, the bisector bound (which may still be <= enough).
// `query`: exact queries of points of the cell (CellQuery); `source`: the cell's triangle of A.
template <class Query>
CellBound boundCell(const Sample& s0, const Sample& s1, const Sample& s2,
                    const CoverContext& context, double scale, double margin, double enough,
                    TriangleIndex source, Query& query) {
  const Sample* s[3] = {&s0, &s1, &s2};
  // One closest triangle for all corners: the face bound is exact at the corners.
  if (s0.closest_triangle == s1.closest_triangle && s0.closest_triangle == s2.closest_triangle)
    return {std::max({s0.distance, s1.distance, s2.distance}) * (1 + 1e-13) + margin, true};
  const Vec3 v[3] = {s0.position, s1.position, s2.position};
  // Squared distances below target2 give a bound <= enough once the margins are added.
  const double target = (enough - margin) / (1 + 1e-13);
  if (target > 0) {
    const double corner = cornerBound(v, s0.distance, s1.distance, s2.distance);
    if (corner <= target) return {corner * (1 + 1e-13) + margin, false};
    uint32_t leaves[kMaxCandidateBlocks];
    int blocks = 0;
    for (int k = 0; k < 3; ++k) {
      const uint32_t leaf = context.face_leaf[s[k]->closest_triangle];
      bool seen = false;
      for (int u = 0; u < blocks; ++u) seen = seen || leaves[u] == leaf;
      if (!seen) leaves[blocks++] = leaf;
    }
    CoverGrid grid;
    const CoverGrid::Index corners[3] = {{0, 0}, {CoverGrid::kSide, 0}, {0, CoverGrid::kSide}};
    for (int k = 0; k < 3; ++k) grid.corner(corners[k], v[k]);
    for (int extra = 0;; ++extra) {
      // A retry keeps the points' measurements (the candidates only grow; same target).
      const Cover cover(context, leaves, blocks, target, grid);
      int hint = blocks - 1;  // a retry: the new candidate first
      if (extra == 0) hint = 0;
      const double squared = cover.piece(corners[0], corners[1], corners[2], kCoverLevels, hint);
      if (squared <= target * target) return {std::sqrt(squared) * (1 + 1e-13) + margin, true};
      if (extra == kExtraQueries || !cover.failed()) break;
      // Nearest corner's closest face as the query's warm start.
      const Vec3& x = cover.failPoint();
      int near = 0;
      for (int k = 1; k < 3; ++k)
        if ((v[k] - x).squaredNorm() < (v[near] - x).squaredNorm()) near = k;
      const TriangleIndex f = query(x, s[near]->closest_triangle, source);
      const uint32_t leaf = context.face_leaf[f];
      bool seen = false;
      for (int u = 0; u < blocks; ++u) seen = seen || leaves[u] == leaf;
      if (seen) break;
      leaves[blocks++] = leaf;
    }
  }
  // Not covered: the bisector bound, capped by min_i max_k |v_k - c_i| (valid on all of t).
  const Vec3 c[3] = {s0.closest, s1.closest, s2.closest};
  double cap2 = kInf;
  for (int i = 0; i < 3; ++i) {
    double m = 0;
    for (int k = 0; k < 3; ++k) m = std::max(m, (v[k] - c[i]).squaredNorm());
    cap2 = std::min(cap2, m);
  }
  return {std::min(bisectorBound(v, c, scale), std::sqrt(cap2)) + margin, false};
}

// ---- Parallel helpers ------------------------------------------------------------------

// Runs body(begin, end) over [0, n) in fixed chunks of `chunk`, in parallel.
template <class Body>
void forChunks(size_t n, size_t chunk, bool parallel, const Body& body) {
  const size_t chunks = (n + chunk - 1) / chunk;
  if (!parallel || chunks <= 1) {
    for (size_t c = 0; c < chunks; ++c) body(c * chunk, std::min(n, (c + 1) * chunk));
    return;
  }
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, chunks, 1),
      [&](const tbb::blocked_range<size_t>& r) {
        for (size_t c = r.begin(); c != r.end(); ++c) body(c * chunk, std::min(n, (c + 1) * chunk));
      },
      tbb::simple_partitioner());
}

double largestCoordinate(const Mesh& mesh) {
  double m = 0;
  for (const Triangle& t : mesh.triangles)
    for (VertexIndex v : t) m = std::max(m, mesh.positions[v].cwiseAbs().maxCoeff());
  return m;
}

// ---- One direction ---------------------------------------------------------------------

class Direction {
 public:
  Direction(const Mesh& from, std::shared_ptr<const Hierarchy> to, double scale, bool parallel)
      : from_(from),
        to_(std::move(to)),
        scale_(scale),
        margin_(kMarginRelative * scale),
        parallel_(parallel),
        streams_(to_),
        balls_(blockBalls(*to_)),
        face_leaf_(to_->mesh().triangles.size(), 0) {
    const std::vector<TriangleIndex>& lanes = to_->leafTriangles();
    for (size_t i = 0; i < lanes.size(); ++i)
      if (lanes[i] != kInvalidIndex) face_leaf_[lanes[i]] = static_cast<uint32_t>(i / 8);
    cover_ = CoverContext{to_->leafBlocks().data(), face_leaf_.data(), balls_.data()};
  }

  // Queries every used vertex of A (Morton order, fixed chunks); LB <- the largest distance.
  void sampleVertices() {
    const Mesh& a = from_;
    const size_t nv = a.positions.size();
    samples_.assign(nv, Sample{});
    std::vector<uint8_t> used(nv, 0);
    for (TriangleIndex f = 0; f < a.triangles.size(); ++f) {
      for (VertexIndex v : a.triangles[f]) {
        if (!used[v]) {
          used[v] = 1;
          samples_[v].source = f;
        }
      }
    }
    Vec3 upper;
    meshBounds(a, box_lower_, upper);
    box_extent_ = (upper - box_lower_).cwiseMax(1e-300);
    std::vector<std::pair<uint64_t, VertexIndex>> order;
    order.reserve(nv);
    for (VertexIndex v = 0; v < nv; ++v) {
      if (!used[v]) continue;
      samples_[v].position = a.positions[v];
      order.emplace_back(mortonCode(a.positions[v]), v);
    }
    std::sort(order.begin(), order.end());
    std::vector<uint32_t> ids(order.size());
    for (size_t i = 0; i < order.size(); ++i) ids[i] = order[i].second;
    // Triangles in the Morton order of their first corner (a counting sort): bounding them in
    // that order reads nearby samples and leaf blocks of B one after the other.
    std::vector<uint32_t> rank(nv, 0), start(order.size() + 1, 0);
    for (size_t i = 0; i < order.size(); ++i) rank[order[i].second] = static_cast<uint32_t>(i);
    for (const Triangle& t : a.triangles) ++start[rank[t[0]] + 1];
    for (size_t i = 0; i < order.size(); ++i) start[i + 1] += start[i];
    triangle_order_.resize(a.triangles.size());
    for (TriangleIndex f = 0; f < a.triangles.size(); ++f)
      triangle_order_[start[rank[a.triangles[f][0]]]++] = f;
    querySamples(ids);
    for (VertexIndex v = 0; v < nv; ++v) {
      if (used[v] && samples_[v].distance > lb_) {
        lb_ = samples_[v].distance;
        lb_sample_ = v;
      }
    }
  }

  // Bounds every triangle of A; those above max(LB, other_lower) + tol go to the heap.
  void boundTriangles(double other_lower, double tol) {
    const Mesh& a = from_;
    const double threshold = std::max(lb_, other_lower) + tol;
    const size_t nt = a.triangles.size();
    cells_.resize(nt);
    forCellChunks(nt, kCellChunk * 16, [&](size_t begin, size_t end, CellQuery& query) {
      uint64_t wins = 0;
      for (size_t i = begin; i < end; ++i) {
        if (i + kPrefetchAhead < end) {
          for (VertexIndex v : a.triangles[triangle_order_[i + kPrefetchAhead]])
            __builtin_prefetch(&samples_[v]);
        }
        const TriangleIndex f = triangle_order_[i];
        const Triangle& t = a.triangles[f];
        Cell& cell = cells_[f];
        cell = Cell{{t[0], t[1], t[2]}, static_cast<TriangleIndex>(f), 0, 0, false, 0.0f};
        const CellBound bound = boundCell(samples_[t[0]], samples_[t[1]], samples_[t[2]],
                                          cover_, scale_, margin_, threshold, cell.source, query);
        cell.upper = bound.upper;
        wins += bound.face_won;
      }
      face_wins_ += wins;
    });
    counters_.cells = nt;
    heap_.clear();
    for (uint32_t f = 0; f < nt; ++f) pushOrDrop(f, threshold);
  }

  // The refinement's tables (HausdorffOptions::max_bytes): their bytes now, and at most during
  // the next refine(). A round of b cells adds up to 4 b cells, 3 b midpoint samples and one
  // sample per chunk of kCellChunk cells (a cover bound's best point), 3 b edges, and 4 b heap
  // entries after popping b; its scratch tables hold b or 3 b entries, or a chunk's.
  uint64_t bytes() const {
    return capacityBytes(cells_) + capacityBytes(samples_) + capacityBytes(heap_) + edges_.bytes() +
           capacityBytes(batch_) + capacityBytes(mids_) + capacityBytes(new_ids_) + capacityBytes(child_first_) +
           capacityBytes(thin_) + capacityBytes(order_) + capacityBytes(chunk_best_) + capacityBytes(chunk_queries_);
  }
  size_t nextBatch() const {
    return std::min(heap_.size(), std::clamp(heap_.size() / kBatchDivisor, kMinBatch, kMaxBatch));
  }
  static size_t newSamples(size_t batch) { return 3 * batch + (batch + kCellChunk - 1) / kCellChunk; }
  // Whether the next refine() could number cells or samples past 32 bits (their ids): about
  // 300 GB of tables, reached only without a max_bytes.
  bool idsFull() const {
    const size_t batch = nextBatch();
    constexpr size_t kIds = std::numeric_limits<uint32_t>::max();
    return cells_.size() + 4 * batch >= kIds || samples_.size() + newSamples(batch) >= kIds;
  }
  uint64_t bytesAfterRound() const {
    const size_t b = nextBatch(), chunks = (b + kCellChunk - 1) / kCellChunk;
    const uint64_t peaks =
        resizedBytes(cells_, cells_.size() + 4 * b) + pushedBytes(samples_, samples_.size() + newSamples(b)) +
        pushedBytes(heap_, heap_.size() + 3 * b) + edges_.bytesAfter(3 * b) + pushedBytes(batch_, b) +
        resizedBytes(mids_, 3 * b) + resizedBytes(new_ids_, 3 * b) + resizedBytes(child_first_, b + 1) +
        resizedBytes(thin_, b) + resizedBytes(order_, 3 * b) + resizedBytes(chunk_best_, chunks) +
        resizedBytes(chunk_queries_, chunks);
    return std::max(bytes(), peaks);
  }

  double lower() const { return lb_; }
  double topUpper() const { return heap_.empty() ? -kInf : heap_.front().upper; }
  double upper() const { return std::max({lb_, topUpper(), dropped_upper_}); }
  uint64_t samples() const { return counters_.samples; }
  bool converged() const { return converged_; }

  // One round: splits up to a batch of the highest cells above the threshold
  // max(LB, other_lower) + tol (other_lower: the other direction's LB, or -inf).
  void refine(double other_lower, double tol) {
    double threshold = std::max(lb_, other_lower) + tol;
    const size_t batch_size = std::clamp(heap_.size() / kBatchDivisor, kMinBatch, kMaxBatch);
    batch_.clear();
    while (batch_.size() < batch_size && !heap_.empty()) {
      const uint32_t top = heap_.front().cell;
      if (cells_[top].upper <= threshold) break;
      std::pop_heap(heap_.begin(), heap_.end(), heapBefore);
      heap_.pop_back();
      const Cell& cell = cells_[top];
      if (cell.depth >= kMaxDepth) {  // below rounding size: keep its bound as is
        dropped_upper_ = std::max(dropped_upper_, cell.upper);
        converged_ = false;
        continue;
      }
      batch_.push_back(top);
    }
    ++counters_.rounds;
    if (batch_.empty()) return;

    // Thin cells (thinCell): their longest edge, and how far the third corner is from it.
    thin_.resize(batch_.size());
    child_first_.resize(batch_.size() + 1);
    child_first_[0] = 0;
    for (size_t i = 0; i < batch_.size(); ++i) {
      const Cell& cell = cells_[batch_[i]];
      thin_[i] = thinCell(cell, tol);
      child_first_[i + 1] = child_first_[i] + (thin_[i].thin ? 2 : 4);
      // A thin cell with area keeps it for mean and RMS, taken over it now: its segments have none.
      if (thin_[i].thin && thin_[i].area > 0) addToMean(cell, thin_[i].area, thin_sums_);
    }

    // Midpoint samples, shared through the edge map (a thin cell's longest edge only).
    const uint32_t first_new = static_cast<uint32_t>(samples_.size());
    mids_.resize(3 * batch_.size());
    for (size_t i = 0; i < batch_.size(); ++i) {
      const Cell cell = cells_[batch_[i]];
      for (int k = 0; k < 3; ++k) {
        const uint32_t s = cell.corner[k], t = cell.corner[(k + 1) % 3];
        if (s == t || (thin_[i].thin && k != thin_[i].edge)) {
          mids_[3 * i + k] = s;
          continue;
        }
        bool inserted = false;
        const uint32_t id =
            edges_.findOrInsert(s, t, static_cast<uint32_t>(samples_.size()), inserted);
        mids_[3 * i + k] = id;
        if (!inserted) continue;
        Sample m;
        m.position = 0.5 * (samples_[s].position + samples_[t].position);
        m.source = cell.source;
        // Warm start of its query (replaced by the answer): the nearer end's closest face.
        m.closest_triangle = samples_[s].distance <= samples_[t].distance
                                 ? samples_[s].closest_triangle
                                 : samples_[t].closest_triangle;
        samples_.push_back(m);
      }
    }
    // Queried in Morton order (nearby queries touch the same nodes), a fixed order.
    order_.resize(samples_.size() - first_new);
    for (uint32_t id = first_new; id < samples_.size(); ++id)
      order_[id - first_new] = {mortonCode(samples_[id].position), id};
    std::sort(order_.begin(), order_.end());
    new_ids_.resize(order_.size());
    for (size_t i = 0; i < order_.size(); ++i) new_ids_[i] = order_[i].second;
    querySamples(new_ids_);
    for (uint32_t id = first_new; id < samples_.size(); ++id) {
      if (samples_[id].distance > lb_) {
        lb_ = samples_[id].distance;
        lb_sample_ = id;
      }
    }
    threshold = std::max(lb_, other_lower) + tol;  // LB may have risen

    // Children: (s0 m01 m20) (m01 s1 m12) (m20 m12 s2) (m01 m12 m20); a thin cell's, the two
    // halves of its longest edge (a b), (a m m) (m b b), as thick as it plus its third corner's
    // distance.
    const uint32_t first_child = static_cast<uint32_t>(cells_.size());
    cells_.resize(cells_.size() + child_first_[batch_.size()]);
    forCellChunks(batch_.size(), kCellChunk, [&](size_t begin, size_t end, CellQuery& query) {
      uint64_t wins = 0;
      for (size_t i = begin; i < end; ++i) {
        Cell& parent = cells_[batch_[i]];
        parent.split = true;
        const uint32_t s0 = parent.corner[0], s1 = parent.corner[1], s2 = parent.corner[2];
        const uint32_t m01 = mids_[3 * i], m12 = mids_[3 * i + 1], m20 = mids_[3 * i + 2];
        uint32_t corners[4][3] = {{s0, m01, m20}, {m01, s1, m12}, {m20, m12, s2}, {m01, m12, m20}};
        int count = 4;
        float thickness = parent.thickness;  // relative (Cell::thickness)
        if (thin_[i].thin) {
          const int e = thin_[i].edge;
          const uint32_t a = parent.corner[e], b = parent.corner[(e + 1) % 3], m = mids_[3 * i + e];
          corners[0][0] = a, corners[0][1] = m, corners[0][2] = m;
          corners[1][0] = m, corners[1][1] = b, corners[1][2] = b;
          count = 2;
          thickness = thin_[i].thickness;
        }
        for (int k = 0; k < count; ++k) {
          Cell& child = cells_[first_child + child_first_[i] + k];
          child = Cell{{corners[k][0], corners[k][1], corners[k][2]},
                       parent.source,
                       0,
                       static_cast<uint8_t>(parent.depth + 1),
                       false,
                       thickness};
          const CellBound bound =
              boundCell(samples_[corners[k][0]], samples_[corners[k][1]], samples_[corners[k][2]],
                        cover_, scale_, margin_ + absoluteThickness(thickness), threshold, parent.source, query);
          child.upper = bound.upper;
          wins += bound.face_won;
        }
      }
      face_wins_ += wins;
    });
    counters_.triangles_refined += batch_.size();
    counters_.cells += child_first_[batch_.size()];
    for (uint32_t c = first_child; c < cells_.size(); ++c) pushOrDrop(c, threshold);
  }

  // Fills `out` (bounds, where, mean/RMS, per-vertex distances, counters).
  void finish(OneSidedHausdorff& out) {
    out.lower = std::max(lb_, 0.0);
    out.upper = std::max(upper(), out.lower);
    if (lb_sample_ != kInvalidIndex) {
      const Sample& s = samples_[lb_sample_];
      out.at = s.position;
      out.at_triangle = s.source;
      out.closest = s.closest;
      out.closest_triangle = s.closest_triangle;
    }
    // Mean and RMS: the distance taken as linear over each final cell between its corners'
    // exact distances, integrated exactly (int L = A (d0+d1+d2)/3,
    // int L^2 = A (d0^2+d1^2+d2^2 + d0 d1 + d1 d2 + d2 d0) / 6).
    MeanSums sums = thin_sums_;
    for (const Cell& cell : cells_) {
      if (cell.split) continue;
      const Sample& s0 = samples_[cell.corner[0]];
      const Sample& s1 = samples_[cell.corner[1]];
      const Sample& s2 = samples_[cell.corner[2]];
      addToMean(cell, 0.5 * (s1.position - s0.position).cross(s2.position - s0.position).norm(), sums);
    }
    const double area = sums.area;
    double sum = sums.sum, sum2 = sums.sum2;
    const size_t nv = from_.positions.size();
    out.vertex_distance.assign(nv, kNaN);
    for (VertexIndex v = 0; v < nv; ++v) out.vertex_distance[v] = samples_[v].distance;
    if (area > 0) {
      out.mean = sum / area;
      out.rms = std::sqrt(sum2 / area);
    } else {
      double n = 0;
      sum = sum2 = 0;
      for (double d : out.vertex_distance) {
        if (std::isnan(d)) continue;
        n += 1;
        sum += d;
        sum2 += d * d;
      }
      out.mean = sum / n;
      out.rms = std::sqrt(sum2 / n);
    }
    out.area = area;
    out.counters = counters_;
    out.counters.triangles_tested = triangles_tested_;
    out.counters.face_bound_wins = face_wins_;
  }

 private:
  const Mesh& from_;
  std::shared_ptr<const Hierarchy> to_;
  double scale_, margin_;
  bool parallel_;
  tbb::enumerable_thread_specific<QueryStream> streams_;
  std::vector<BlockBall> balls_;     // [leaf block of B]
  std::vector<uint32_t> face_leaf_;  // [triangle of B] its leaf block
  CoverContext cover_{};

  std::vector<Sample> samples_;  // [sample] vertices of A first (sample id = vertex index)
  std::vector<Cell> cells_;      // [cell] triangles of A first (cell id = triangle index)
  struct HeapEntry {
    double upper;
    uint32_t cell;
  };
  std::vector<HeapEntry> heap_;  // cells above the threshold, max-heap on upper
  EdgeMap edges_;
  double lb_ = -kInf;
  uint32_t lb_sample_ = kInvalidIndex;
  double dropped_upper_ = -kInf;  // highest bound of a final cell
  bool converged_ = true;
  HausdorffCounters counters_;
  std::atomic<uint64_t> triangles_tested_{0};
  std::atomic<uint64_t> face_wins_{0};
  std::vector<TriangleIndex> triangle_order_;  // [i] triangles of A in the order they are bounded
  std::vector<Sample> chunk_best_;  // [chunk] per-chunk scratch of forCellChunks
  std::vector<uint64_t> chunk_queries_;
  uint64_t rest_lineage_ = to_->restGeometry().lineage;
  std::vector<uint32_t> batch_, mids_, new_ids_, child_first_;  // per-round scratch
  std::vector<ThinSplit> thin_;                                 // per-round scratch: [batch cell]
  MeanSums thin_sums_;  // of the thin cells split as segments (their area and distances)
  std::vector<std::pair<uint64_t, uint32_t>> order_;
  Vec3 box_lower_ = Vec3::Zero(), box_extent_ = Vec3::Ones();  // A's bounds, for Morton codes

  uint64_t mortonCode(const Vec3& x) const { return meshsweeper::mortonCode(x, box_lower_, box_extent_); }

  // Higher bound first; among equal bounds the lower cell id (deterministic).
  static bool heapBefore(const HeapEntry& x, const HeapEntry& y) {
    return x.upper != y.upper ? x.upper < y.upper : x.cell > y.cell;
  }

  // Whether a cell is split as a segment (ThinSplit).
  ThinSplit thinCell(const Cell& cell, double tol) const {
    const Vec3 v[3] = {samples_[cell.corner[0]].position, samples_[cell.corner[1]].position,
                       samples_[cell.corner[2]].position};
    ThinSplit out;
    double longest = -1;
    for (int k = 0; k < 3; ++k) {
      const double l = (v[(k + 1) % 3] - v[k]).squaredNorm();
      if (l > longest) {
        longest = l;
        out.edge = k;
      }
    }
    if (!(longest > 0)) return out;  // a point: split in four (it is final long before)
    const Vec3 &a = v[out.edge], &b = v[(out.edge + 1) % 3], &c = v[(out.edge + 2) % 3];
    const Vec3 ab = b - a, ac = c - a;
    // The third corner's distance to the edge (its foot lies on the edge: ab is the longest),
    // rounded up: relative 1e-12, and eps of the coordinates for the differences. A repeated
    // corner (a segment cell's, or a degenerate triangle's) is on the edge exactly.
    const double t = std::clamp(ac.dot(ab) / ab.squaredNorm(), 0.0, 1.0);
    const double coordinates = std::max({a.cwiseAbs().maxCoeff(), b.cwiseAbs().maxCoeff(), c.cwiseAbs().maxCoeff()});
    const double width = c == a || c == b
                             ? 0.0
                             : (ac - t * ab).norm() * (1 + 1e-12) + 8 * std::numeric_limits<double>::epsilon() * coordinates;
    const double thickness = absoluteThickness(cell.thickness) + width;
    if (!(width <= kThinFraction * tol)) return out;
    out.thin = true;
    out.thickness = std::nextafter(static_cast<float>(thickness / scale_), std::numeric_limits<float>::infinity());
    out.area = 0.5 * ab.cross(ac).norm();
    return out;
  }
  // A cell's thickness in mesh units, rounded up.
  double absoluteThickness(float relative) const {
    return relative > 0 ? static_cast<double>(relative) * scale_ * (1 + 1e-15) : 0.0;
  }

  // Adds a final cell (or a thin one split as segments) to `sums`.
  void addToMean(const Cell& cell, double cell_area, MeanSums& sums) const {
    const double d0 = samples_[cell.corner[0]].distance, d1 = samples_[cell.corner[1]].distance,
                 d2 = samples_[cell.corner[2]].distance;
    sums.area += cell_area;
    sums.sum += cell_area * (d0 + d1 + d2) / 3;
    sums.sum2 += cell_area * (d0 * d0 + d1 * d1 + d2 * d2 + d0 * d1 + d1 * d2 + d2 * d0) / 6;
  }

  void pushOrDrop(uint32_t c, double threshold) {
    if (cells_[c].upper > threshold) {
      heap_.push_back({cells_[c].upper, c});
      std::push_heap(heap_.begin(), heap_.end(), heapBefore);
    } else {
      dropped_upper_ = std::max(dropped_upper_, cells_[c].upper);
    }
  }

  // The one place a sample meets B: an exact query warm-started from the previous sample's
  // closest face, or for a midpoint from its edge's nearer end's closest face (set in
  // CoherentState::last_face; QueryStream::closestCoherent's search radius starts at the
  // distance to that face; ~7% fewer triangles tested on the bunny pair than the previous
  // sample's face, which after the Morton sort of a sparse batch is often far). The state is
  // per chunk, so answers (ties included) depend on the chunk, never on the thread. The coherent query's set certificate is switched off (reach_steps = 0): it
  // gathers every face within d + 2R, thousands when, as here, the point is far from B relative
  // to B's triangles, and measured 20-70x slower; the warm start alone tests ~25% fewer
  // triangles than a fresh closest().
  void querySample(QueryStream& stream, CoherentState& state, Sample& s) {
    const ClosestPoint c = stream.closestCoherent(s.position, state);
    s.distance = c.distance;
    s.closest = c.point;
    s.closest_triangle = c.triangle;
  }

  // Exact queries of points of A for the cover bound of one chunk of cells (a fresh
  // warm-started state each: the answer depends only on the point and the warm face). Keeps
  // the farthest point queried (the first among equals), a sample for the lower bound.
  struct CellQuery {
    Direction& d;
    Sample best;
    uint64_t count = 0;
    explicit CellQuery(Direction& direction) : d(direction) {}
    TriangleIndex operator()(const Vec3& x, TriangleIndex warm, TriangleIndex source) {
      QueryStream& stream = d.streams_.local();
      CoherentState state;
      state.reach_steps = 0;
      state.last_face = warm;
      state.lineage = d.rest_lineage_;
      const ClosestPoint c = stream.closestCoherent(x, state);
      d.triangles_tested_ += stream.counters().triangles_tested;
      ++count;
      if (!(c.distance <= best.distance)) {
        best.position = x;
        best.closest = c.point;
        best.distance = c.distance;
        best.closest_triangle = c.triangle;
        best.source = source;
      }
      return c.triangle;
    }
  };

  // Runs body(begin, end, query) over [0, n) in chunks of `chunk`; then, in chunk order, the
  // points its queries measured join the samples when they raise LB.
  template <class Body>
  void forCellChunks(size_t n, size_t chunk, const Body& body) {
    const size_t chunks = (n + chunk - 1) / chunk;
    chunk_best_.assign(chunks, Sample{});
    chunk_queries_.assign(chunks, 0);
    forChunks(n, chunk, parallel_, [&](size_t begin, size_t end) {
      CellQuery query(*this);
      body(begin, end, query);
      chunk_best_[begin / chunk] = query.best;
      chunk_queries_[begin / chunk] = query.count;
    });
    for (size_t c = 0; c < chunks; ++c) {
      counters_.samples += chunk_queries_[c];
      counters_.queries += chunk_queries_[c];
      if (chunk_best_[c].distance > lb_) {
        lb_ = chunk_best_[c].distance;
        lb_sample_ = static_cast<uint32_t>(samples_.size());
        samples_.push_back(chunk_best_[c]);
      }
    }
  }

  void querySamples(const std::vector<uint32_t>& ids) {
    forChunks(ids.size(), kQueryChunk, parallel_, [&](size_t begin, size_t end) {
      QueryStream& stream = streams_.local();
      uint64_t tested = 0;
      CoherentState state;  // cold at each chunk start
      state.reach_steps = 0;
      for (size_t i = begin; i < end; ++i) {
        Sample& s = samples_[ids[i]];
        if (s.closest_triangle != kInvalidIndex) state.last_face = s.closest_triangle;
        querySample(stream, state, s);
        tested += stream.counters().triangles_tested;
      }
      triangles_tested_ += tested;
    });
    counters_.samples += ids.size();
    counters_.queries += ids.size();
  }
};

void addCounters(HausdorffCounters& sum, const HausdorffCounters& c) {
  sum.samples += c.samples;
  sum.queries += c.queries;
  sum.triangles_tested += c.triangles_tested;
  sum.triangles_refined += c.triangles_refined;
  sum.cells += c.cells;
  sum.face_bound_wins += c.face_bound_wins;
  sum.rounds += c.rounds;
}

double effectiveTolerance(const HausdorffOptions& options, const Mesh& a) {
  if (!(options.tolerance >= 0) || !std::isfinite(options.tolerance))
    throw std::invalid_argument("hausdorff: tolerance must be finite and >= 0");
  if (!(options.max_seconds >= 0) || !std::isfinite(options.max_seconds))
    throw std::invalid_argument("hausdorff: max_seconds must be finite and >= 0 (0: no limit)");
  if (options.tolerance > 0) return options.tolerance;
  if (!(options.relative_tolerance > 0) || !std::isfinite(options.relative_tolerance))
    throw std::invalid_argument("hausdorff: relative tolerance must be finite and > 0");
  const double tolerance = options.relative_tolerance * meshDiagonal(a);
  if (!(tolerance > 0))
    throw std::invalid_argument("hausdorff: " + (a.name.empty() ? std::string("mesh A") : a.name) +
                                " has zero extent; give an absolute tolerance");
  // Found by an audit: --relative 1e308 made an infinite tolerance, printed as inf%.
  if (!std::isfinite(tolerance))
    throw std::invalid_argument("hausdorff: the relative tolerance times A's diagonal is beyond the largest double");
  return tolerance;
}

void checkOrThrow(const Mesh& mesh) {
  const std::string problem = checkMesh(mesh);
  if (!problem.empty()) throw MeshError(problem);
}

// The driver for both entry points; `a_hierarchy` null means one-sided.
HausdorffResult run(const Mesh& a, const std::shared_ptr<const Hierarchy>& a_hierarchy,
                    const std::shared_ptr<const Hierarchy>& b_hierarchy,
                    const HausdorffOptions& options, Clock::time_point start,
                    double build_seconds) {
  const Mesh& b = b_hierarchy->mesh();
  const bool symmetric = a_hierarchy != nullptr;
  const double scale = std::max(largestCoordinate(a), largestCoordinate(b));
  HausdorffResult result;
  result.requested_tolerance = effectiveTolerance(options, a);
  result.tolerance = std::max(result.requested_tolerance, 4 * kMarginRelative * scale);
  result.build_seconds = build_seconds;
  const double tol = result.tolerance;
  const bool parallel = options.threads != 1;

  tbb::task_arena arena(arenaConcurrency(options.threads));
  result.threads = static_cast<unsigned>(arena.max_concurrency());
  arena.execute([&] {
    Direction ab(a, b_hierarchy, scale, parallel);
    std::unique_ptr<Direction> ba;
    if (symmetric) ba = std::make_unique<Direction>(b, a_hierarchy, scale, parallel);
    auto tableBytes = [&] { return ab.bytes() + (ba ? ba->bytes() : 0); };  // HausdorffOptions::max_bytes
    auto report = [&] {
      if (!options.progress) return;
      HausdorffProgress p;
      p.lower = std::max({ab.lower(), ba ? ba->lower() : -kInf, 0.0});
      p.upper = std::max(ab.upper(), ba ? ba->upper() : -kInf);
      p.tolerance = tol;
      p.samples = ab.samples() + (ba ? ba->samples() : 0);
      p.seconds = secondsSince(start);
      options.progress(p);
    };
    // A direction's cells are final once within tol of the larger LB of both directions
    // (tighten_both: of its own LB).
    const bool joint = ba && !options.tighten_both;
    ab.sampleVertices();
    if (ba) ba->sampleVertices();
    ab.boundTriangles(joint ? ba->lower() : -kInf, tol);
    if (ba) ba->boundTriangles(joint ? ab.lower() : -kInf, tol);
    report();
    while (true) {
      const double floor_ab = joint ? ba->lower() : -kInf;
      const double floor_ba = joint ? ab.lower() : -kInf;
      const double excess_ab = ab.topUpper() - (std::max(ab.lower(), floor_ab) + tol);
      const double excess_ba =
          ba ? ba->topUpper() - (std::max(ba->lower(), floor_ba) + tol) : -kInf;
      if (!(excess_ab > 0) && !(excess_ba > 0)) break;
      if (options.max_seconds > 0 && secondsSince(start) > options.max_seconds) {
        result.timed_out = true;  // not within the tolerance yet
        break;
      }
      // Refine the direction with the larger bound (tighten_both: the larger excess).
      const bool pick_ba =
          ba && excess_ba > 0 &&
          (!(excess_ab > 0) ||
           (options.tighten_both ? excess_ba > excess_ab : ba->topUpper() > ab.topUpper()));
      const Direction& picked = pick_ba ? *ba : ab;
      if (picked.idsFull() ||
          (options.max_bytes > 0 && tableBytes() + (picked.bytesAfterRound() - picked.bytes()) > options.max_bytes)) {
        result.memory_limited = true;  // not within the tolerance yet
        break;
      }
      if (pick_ba)
        ba->refine(floor_ba, tol);
      else
        ab.refine(floor_ab, tol);
      report();
    }
    result.table_bytes = tableBytes();
    ab.finish(result.a_to_b);
    addCounters(result.counters, result.a_to_b.counters);
    result.converged = ab.converged();
    if (ba) {
      ba->finish(result.b_to_a);
      addCounters(result.counters, result.b_to_a.counters);
      result.converged = result.converged && ba->converged();
      result.lower = std::max(result.a_to_b.lower, result.b_to_a.lower);
      result.upper = std::max(result.a_to_b.upper, result.b_to_a.upper);
    } else {
      result.b_to_a.lower = result.b_to_a.upper = kNaN;
      result.b_to_a.mean = result.b_to_a.rms = kNaN;
      result.lower = result.a_to_b.lower;
      result.upper = result.a_to_b.upper;
    }
  });
  result.converged = result.converged && !result.timed_out && !result.memory_limited && result.upper - result.lower <= tol;
  result.seconds = secondsSince(start);
  return result;
}

// Hausdorff distances do not change when both meshes move by the same translation. About the
// centre of their joint box, the coordinates (and with them the rounding margin and the least
// tolerance, 4e-12 of the largest coordinate) measure the meshes' own extent, not how far they
// lie from the origin: the bundled elephant moved by 1e9 had its tolerance raised from 1.4e-4
// to 4e-3 in place (found by an audit). The meshes are moved only where that shrinks the
// coordinates at least fourfold, so meshes placed about the origin are computed as given.
// Each translated coordinate's rounding error is measured exactly (Knuth's two-sum; it is 0
// where a coordinate and the centre are within a factor of two, Sterbenz); a vertex moved off
// its exact translate by e moves every point of its faces by at most e, so both one-sided
// distances change by at most the largest e of A plus that of B, by which the bounds widen.
struct Centred {
  Mesh a, b;                  // the translated copies (when moved)
  Vec3 shift = Vec3::Zero();  // a point of the copies plus shift is the original point
  double error = 0;           // bound on how far the copies' faces lie from the exact translates
  bool moved = false;
};

// The copy of `mesh` with its used vertices moved by -shift (the others, which no distance
// reads, stay as they are: moved, one could leave the coordinate range checkMesh allows; found
// by review); returns a bound on how far a moved vertex lies from its exact translate: sqrt(3)
// times its largest coordinate error (not the root of the squares, which could underflow).
double translated(const Mesh& mesh, const Vec3& shift, Mesh& out) {
  out.name = mesh.name;
  out.triangles = mesh.triangles;
  out.positions = mesh.positions;
  std::vector<uint8_t> moved(mesh.positions.size(), 0);
  double worst = 0;
  for (const Triangle& t : mesh.triangles)
    for (VertexIndex v : t) {
      if (moved[v]) continue;
      moved[v] = 1;
      for (int axis = 0; axis < 3; ++axis) {
        const double x = mesh.positions[v][axis], y = -shift[axis];
        const double sum = x + y, back = sum - x;
        const double e = (x - (sum - back)) + (y - back);  // x + y = sum + e exactly
        out.positions[v][axis] = sum;
        worst = std::max(worst, std::abs(e));
      }
    }
  return worst > 0 ? worst * 1.7320508075688774 * (1 + 4 * kEps) : 0.0;
}

Centred centred(const Mesh& a, const Mesh* b) {
  Centred c;
  Vec3 lower, upper;  // the joint box of the used vertices
  meshBounds(a, lower, upper);
  if (b) {
    Vec3 b_lower, b_upper;
    meshBounds(*b, b_lower, b_upper);
    lower = lower.cwiseMin(b_lower);
    upper = upper.cwiseMax(b_upper);
  }
  const Vec3 centre = 0.5 * lower + 0.5 * upper;
  const double now = lower.cwiseAbs().cwiseMax(upper.cwiseAbs()).maxCoeff();
  const double then = (upper - lower).maxCoeff() / 2;
  if (!(4 * then < now)) return c;
  c.moved = true;
  c.shift = centre;
  c.error = translated(a, centre, c.a);
  if (b) c.error += translated(*b, centre, c.b);
  return c;
}

// The tolerance to ask of the centred computation, whose bounds then widen by 2 * error (and
// round: a few ulps less).
HausdorffOptions centredOptions(const HausdorffOptions& options, double tolerance, const Centred& c) {
  HausdorffOptions inner = options;
  const double less = (tolerance - 2 * c.error) * (1 - 8 * kEps);
  inner.tolerance = c.error > 0 && less > 0 ? less : tolerance;
  return inner;
}

// Back to the original coordinates: witnesses shifted, bounds widened by the copies' error;
// the tolerance is the one asked for unless the centred run raised its own.
void uncentre(HausdorffResult& r, const Centred& c, bool symmetric, double requested) {
  const bool raised = r.tolerance > r.requested_tolerance;
  r.requested_tolerance = requested;
  for (OneSidedHausdorff* h : {&r.a_to_b, &r.b_to_a}) {
    if (h == &r.b_to_a && !symmetric) continue;
    h->at += c.shift;
    h->closest += c.shift;
    if (c.error > 0) {
      h->lower = std::max(0.0, h->lower - c.error);
      h->upper += c.error;
    }
  }
  if (c.error > 0) {
    r.lower = std::max(0.0, r.lower - c.error);
    r.upper += c.error;
    r.tolerance += 2 * c.error;
  }
  if (!raised) r.tolerance = requested;
  r.converged = r.converged && r.upper - r.lower <= r.tolerance;
}

}  // namespace

HausdorffResult hausdorff(const std::shared_ptr<const Hierarchy>& a,
                          const std::shared_ptr<const Hierarchy>& b,
                          const HausdorffOptions& options) {
  if (!a || !b) throw std::invalid_argument("hausdorff: a hierarchy is null");
  return run(a->mesh(), a, b, options, Clock::now(), 0);
}

HausdorffResult hausdorff(const Mesh& a, const Mesh& b, const HausdorffOptions& options) {
  const auto start = Clock::now();
  checkOrThrow(a);
  checkOrThrow(b);
  const double tolerance = effectiveTolerance(options, a);  // fail before building
  const Centred c = centred(a, &b);
  const Mesh& ca = c.moved ? c.a : a;
  const Mesh& cb = c.moved ? c.b : b;
  std::shared_ptr<const Hierarchy> ha, hb;
  tbb::task_arena arena(arenaConcurrency(options.threads));
  arena.execute([&] {
    tbb::parallel_invoke([&] { ha = Hierarchy::build(ca); }, [&] { hb = Hierarchy::build(cb); });
  });
  if (!c.moved) return run(ha->mesh(), ha, hb, options, start, secondsSince(start));
  HausdorffResult r = run(ha->mesh(), ha, hb, centredOptions(options, tolerance, c), start, secondsSince(start));
  uncentre(r, c, true, tolerance);
  return r;
}

HausdorffResult hausdorffOneSided(const Mesh& a, const std::shared_ptr<const Hierarchy>& b,
                                  const HausdorffOptions& options) {
  if (!b) throw std::invalid_argument("hausdorffOneSided: B's hierarchy is null");
  checkOrThrow(a);
  return run(a, nullptr, b, options, Clock::now(), 0);
}

HausdorffResult hausdorffOneSided(const Mesh& a, const Mesh& b, const HausdorffOptions& options) {
  const auto start = Clock::now();
  checkOrThrow(a);
  checkOrThrow(b);
  const double tolerance = effectiveTolerance(options, a);
  const Centred c = centred(a, &b);
  // Built before the call: its arguments' order is unspecified (build_seconds read the clock
  // first; found by review).
  const std::shared_ptr<const Hierarchy> hb = Hierarchy::build(c.moved ? c.b : b);
  const double build_seconds = secondsSince(start);
  if (!c.moved) return run(a, nullptr, hb, options, start, build_seconds);
  HausdorffResult r = run(c.a, nullptr, hb, centredOptions(options, tolerance, c), start, build_seconds);
  uncentre(r, c, false, tolerance);
  return r;
}

}  // namespace meshsweeper
