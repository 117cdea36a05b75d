#pragma once
// Broadphase of the distance service: which bodies a query point can reach.
//
// A body is a candidate of point p for the query distance d when the Euclidean distance from p
// to the body's world box is at most d (the box inflated by d, rounded corners); the box holds
// every point of the body's surface, so no body with a triangle within d is ever left out.
//
// Layout: a flat structure-of-arrays loop over all body boxes (lower/upper x, y, z in six
// contiguous double arrays, padded to a multiple of 4 with empty boxes), four boxes per AVX
// instruction, a bit mask compacted into the candidate list. Measured with
// `bench_service --broadphase` (bench/README.md): 4-17 ns per point for 1-16 bodies, against
// 8-30 ns for a uniform grid over the bodies and 9-55 ns for the scalar reference; at 64 bodies
// both are ~30-37 ns. Every step queries each point against its candidates at ~0.3-1 us per
// pair, so the broadphase is 1-2% of a step. The flat loop has no build cost (bodies move every
// step), no cell-size parameter, and its cost does not depend on where points fall; a grid or
// a tree over the bodies pays off only beyond ~64 bodies. Only the slots with a box are in the
// loop: a world that once held many bodies and now holds few costs what the few cost. set() is
// O(1): a slot switched off leaves a hole, one switched on is appended, and prepare() restores
// the slot order once for all of them. Beyond kTreeBodies live bodies, prepare() builds a
// binary tree over the boxes (median splits, leaves of up to 8, rebuilt when a box changed),
// which candidates() descends with the same per-box test, so the answers are the same:
// measured equal to the flat loop at 256 bodies, 2.7x faster at 1024 and 8x at 4096
// (bench/README.md).
// BroadphaseReference answers the same question box by box (array of structures, scalar) for
// the tests.
#include "core/types.h"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace meshsweeper {

// An axis-aligned box; lower > upper on some axis means empty (reaches no point).
struct Box3 {
  Vec3 lower = Vec3::Constant(1);
  Vec3 upper = Vec3::Constant(-1);
  bool empty() const { return (lower.array() > upper.array()).any(); }
};

class Broadphase {
 public:
  // Sets the number of slots (bodies, by slot index); new slots are empty.
  void resize(size_t slots);
  size_t size() const { return dense_of_.size(); }
  // Slots with a box (non-empty).
  size_t liveCount() const { return slot_of_.size() - holes_; }
  // Sets slot `slot`'s world box (an empty box to switch the slot off). Precondition:
  // slot < size(); box coordinates are not NaN.
  void set(size_t slot, const Box3& box);
  Box3 box(size_t slot) const;

  // Writes to out[0..n) the slots whose box is within distance `distance` of p, by increasing
  // slot, and returns n. distance may be +infinity (every non-empty slot). out must hold
  // liveCount() entries. Preconditions: p finite; distance >= 0. Safe to call from several
  // threads at once (between calls of set() and prepare()).
  size_t candidates(const Vec3& p, double distance, uint32_t* out) const;
  // The least distance from p to the farthest point of a box (+infinity when no slot holds
  // one): every box holds its body's surface, so each body has a point within that distance of
  // p, and the closest body of p is within it. Through the tree when it is ready (a descent,
  // nearest nodes first), else a loop over every box. Precondition: p finite.
  double nearestFar(const Vec3& p) const;
  // Builds the tree over the boxes when more than kTreeBodies slots hold one and a box changed
  // since; else nothing. Call it after the boxes of a step are set, before candidates() (which
  // loops over every box while no tree is ready).
  void prepare();
  static constexpr size_t kTreeBodies = 256;

 private:
  void pad();
  void compact();
  size_t flatCandidates(const Vec3& p, double limit, uint32_t* out) const;
  size_t candidatesInTree(const Vec3& p, double limit, uint32_t* out) const;
  struct TreeNode {
    double lower[3], upper[3];  // the union of the boxes below
    uint32_t first, count;      // leaf: positions order_[first, first + count); inner: count 0
    uint32_t left, right;       // inner: children
  };
  uint32_t buildTree(uint32_t first, uint32_t count);
  std::vector<TreeNode> tree_;
  std::vector<uint32_t> order_;  // positions, grouped by leaf
  bool tree_ready_ = false;
  std::vector<uint32_t> dense_of_;  // [slot] position in the arrays below, or UINT32_MAX (empty)
  std::vector<uint32_t> slot_of_;   // [position] slot, increasing after prepare()
  size_t holes_ = 0;                // positions of slots switched off since (empty boxes)
  bool unordered_ = false;          // a slot was appended out of order since
  // [axis][position] padded to a multiple of 4 with empty boxes (lower = +inf, upper = -inf).
  std::vector<double> lower_[3], upper_[3];
};

// The reference: the same answer, one box at a time.
class BroadphaseReference {
 public:
  std::vector<Box3> boxes;  // [slot]
  size_t candidates(const Vec3& p, double distance, uint32_t* out) const;
};

// The squared distance from p to a non-empty box, computed in double.
inline double squaredBoxDistance(const Box3& box, const Vec3& p) {
  double d2 = 0;
  for (int axis = 0; axis < 3; ++axis) {
    const double gap = std::max({box.lower[axis] - p[axis], p[axis] - box.upper[axis], 0.0});
    d2 += gap * gap;
  }
  return d2;
}

// The comparison both use: true when the squared distance from p to the box (computed in double)
// is at most distance^2, with a relative slack of 1e-12 that covers the rounding of the box
// distance, so a body at exactly `distance` is never dropped. Empty boxes: false.
bool boxWithin(const Box3& box, const Vec3& p, double distance);

}  // namespace meshsweeper
