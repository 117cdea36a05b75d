// Broadphase of the distance service (see broadphase.h for the choice of a flat loop).
#include "collision/broadphase.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <numeric>

#if defined(__AVX__)
#include <immintrin.h>
#endif

namespace meshsweeper {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// distance^2 with the rounding slack; finite even for distance = +inf, so empty boxes (whose
// squared distance is +inf) never pass.
double squaredLimit(double distance) {
  const double d2 = distance * distance * (1 + 1e-12);
  return std::min(d2, std::numeric_limits<double>::max());
}

// The squared distance from (px, py, pz) to a box given by its corners, as every test here
// computes it (the AVX loop included): the tree's node and leaf tests must agree with the flat
// loop's to the bit.
inline double squaredGap(double lx, double ly, double lz, double ux, double uy, double uz, double px, double py,
                         double pz) {
  const double gx = std::max(std::max(lx - px, px - ux), 0.0);
  const double gy = std::max(std::max(ly - py, py - uy), 0.0);
  const double gz = std::max(std::max(lz - pz, pz - uz), 0.0);
  return (gx * gx + gy * gy) + gz * gz;
}

}  // namespace

bool boxWithin(const Box3& box, const Vec3& p, double distance) {
  if (box.empty()) return false;
  return squaredBoxDistance(box, p) <= squaredLimit(distance);
}

constexpr uint32_t kNoPosition = std::numeric_limits<uint32_t>::max();

void Broadphase::resize(size_t slots) {
  for (size_t slot = slots; slot < dense_of_.size(); ++slot) set(slot, Box3{});
  dense_of_.resize(slots, kNoPosition);
}

void Broadphase::pad() {
  const size_t positions = slot_of_.size(), padded = (positions + 3) / 4 * 4;
  for (int axis = 0; axis < 3; ++axis) {
    lower_[axis].resize(padded, kInf);
    upper_[axis].resize(padded, -kInf);
  }
}

// O(1): a slot switched off leaves an empty box at its position (a hole, never reported), one
// switched on is appended; prepare() closes the holes and restores slot order.
void Broadphase::set(size_t slot, const Box3& box) {
  assert(slot < dense_of_.size());
  tree_ready_ = false;
  uint32_t at = dense_of_[slot];
  if (box.empty()) {
    if (at == kNoPosition) return;
    for (int axis = 0; axis < 3; ++axis) {
      lower_[axis][at] = kInf;
      upper_[axis][at] = -kInf;
    }
    dense_of_[slot] = kNoPosition;
    ++holes_;
    return;
  }
  if (at == kNoPosition) {
    at = static_cast<uint32_t>(slot_of_.size());
    if (!slot_of_.empty() && slot_of_.back() > slot) unordered_ = true;
    slot_of_.push_back(static_cast<uint32_t>(slot));
    dense_of_[slot] = at;
    pad();
  }
  for (int axis = 0; axis < 3; ++axis) {
    lower_[axis][at] = box.lower[axis];
    upper_[axis][at] = box.upper[axis];
  }
}

void Broadphase::compact() {
  if (holes_ == 0 && !unordered_) return;
  std::vector<uint32_t> live;  // the slots still switched on (a hole's slot may be again, elsewhere)
  for (size_t k = 0; k < slot_of_.size(); ++k) {
    const uint32_t slot = slot_of_[k];
    if (slot < dense_of_.size() && dense_of_[slot] == k) live.push_back(slot);
  }
  std::sort(live.begin(), live.end());
  std::vector<double> lower[3], upper[3];
  for (int axis = 0; axis < 3; ++axis) {
    lower[axis].reserve(live.size() + 3);
    upper[axis].reserve(live.size() + 3);
    for (uint32_t slot : live) {
      lower[axis].push_back(lower_[axis][dense_of_[slot]]);
      upper[axis].push_back(upper_[axis][dense_of_[slot]]);
    }
    lower_[axis].swap(lower[axis]);
    upper_[axis].swap(upper[axis]);
  }
  for (size_t k = 0; k < live.size(); ++k) dense_of_[live[k]] = static_cast<uint32_t>(k);
  slot_of_.swap(live);
  holes_ = 0;
  unordered_ = false;
  pad();
}

Box3 Broadphase::box(size_t slot) const {
  Box3 b;
  const uint32_t at = dense_of_[slot];
  for (int axis = 0; axis < 3; ++axis) {
    b.lower[axis] = at == kNoPosition ? kInf : lower_[axis][at];
    b.upper[axis] = at == kNoPosition ? -kInf : upper_[axis][at];
  }
  return b;
}

uint32_t Broadphase::buildTree(uint32_t first, uint32_t count) {
  TreeNode node{};
  double centre_lower[3], centre_upper[3];
  for (int axis = 0; axis < 3; ++axis) {
    node.lower[axis] = centre_lower[axis] = kInf;
    node.upper[axis] = centre_upper[axis] = -kInf;
  }
  auto centre = [this](int axis, uint32_t k) { return 0.5 * lower_[axis][k] + 0.5 * upper_[axis][k]; };
  for (uint32_t i = first; i < first + count; ++i) {
    const uint32_t k = order_[i];
    for (int axis = 0; axis < 3; ++axis) {
      node.lower[axis] = std::min(node.lower[axis], lower_[axis][k]);
      node.upper[axis] = std::max(node.upper[axis], upper_[axis][k]);
      centre_lower[axis] = std::min(centre_lower[axis], centre(axis, k));
      centre_upper[axis] = std::max(centre_upper[axis], centre(axis, k));
    }
  }
  const uint32_t index = static_cast<uint32_t>(tree_.size());
  tree_.push_back(node);
  constexpr uint32_t kLeafBoxes = 8;
  if (count <= kLeafBoxes) {
    tree_[index].first = first;
    tree_[index].count = count;
    return index;
  }
  // Median split along the widest spread of the box centres.
  int axis = 0;
  for (int a = 1; a < 3; ++a)
    if (centre_upper[a] - centre_lower[a] > centre_upper[axis] - centre_lower[axis]) axis = a;
  const uint32_t half = count / 2;
  std::nth_element(order_.begin() + first, order_.begin() + first + half, order_.begin() + first + count,
                   [&](uint32_t a, uint32_t b) {
                     return centre(axis, a) < centre(axis, b) || (centre(axis, a) == centre(axis, b) && a < b);
                   });
  const uint32_t left = buildTree(first, half);
  const uint32_t right = buildTree(first + half, count - half);
  tree_[index].left = left;
  tree_[index].right = right;
  return index;
}

void Broadphase::prepare() {
  compact();
  if (tree_ready_ || slot_of_.size() <= kTreeBodies) return;
  order_.resize(slot_of_.size());
  std::iota(order_.begin(), order_.end(), 0u);
  tree_.clear();
  buildTree(0, static_cast<uint32_t>(order_.size()));
  tree_ready_ = true;
}

// The tree's nodes bound their boxes by the min and max of their coordinates, so a node's
// computed squared distance is at most any of its boxes' (rounding is monotone): a node is
// skipped only when none of its boxes would pass the flat loop's test.
size_t Broadphase::candidatesInTree(const Vec3& p, double limit, uint32_t* out) const {
  const double px = p.x(), py = p.y(), pz = p.z();
  size_t n = 0;
  uint32_t stack[64];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const TreeNode& node = tree_[stack[--top]];
    if (!(squaredGap(node.lower[0], node.lower[1], node.lower[2], node.upper[0], node.upper[1], node.upper[2], px,
                     py, pz) <= limit))
      continue;
    if (node.count > 0) {
      for (uint32_t i = node.first; i < node.first + node.count; ++i) {
        const uint32_t k = order_[i];
        if (squaredGap(lower_[0][k], lower_[1][k], lower_[2][k], upper_[0][k], upper_[1][k], upper_[2][k], px, py,
                       pz) <= limit)
          out[n++] = slot_of_[k];
      }
      continue;
    }
    stack[top++] = node.right;
    stack[top++] = node.left;
  }
  std::sort(out, out + n);  // by increasing slot, as the flat loop gives them
  return n;
}

double Broadphase::nearestFar(const Vec3& p) const {
  const double px = p.x(), py = p.y(), pz = p.z();
  // Squared distance to the farthest corner of box k (+inf for a hole or padding).
  auto far2 = [&](uint32_t k) {
    const double fx = std::max(std::abs(px - lower_[0][k]), std::abs(px - upper_[0][k]));
    const double fy = std::max(std::abs(py - lower_[1][k]), std::abs(py - upper_[1][k]));
    const double fz = std::max(std::abs(pz - lower_[2][k]), std::abs(pz - upper_[2][k]));
    return lower_[0][k] <= upper_[0][k] ? (fx * fx + fy * fy) + fz * fz : kInf;
  };
  double best2 = kInf;
  if (!tree_ready_) {
    for (uint32_t k = 0; k < slot_of_.size(); ++k) best2 = std::min(best2, far2(k));
    return std::sqrt(best2);
  }
  auto gap2 = [&](const TreeNode& n) {
    return squaredGap(n.lower[0], n.lower[1], n.lower[2], n.upper[0], n.upper[1], n.upper[2], px, py, pz);
  };
  // A node's boxes are no nearer than the node's box: one whose gap is past the best is skipped.
  uint32_t stack[64];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const TreeNode& node = tree_[stack[--top]];
    if (!(gap2(node) < best2)) continue;
    if (node.count > 0) {
      for (uint32_t i = node.first; i < node.first + node.count; ++i) best2 = std::min(best2, far2(order_[i]));
      continue;
    }
    const bool left_first = gap2(tree_[node.left]) <= gap2(tree_[node.right]);
    stack[top++] = left_first ? node.right : node.left;  // the nearer child is popped first
    stack[top++] = left_first ? node.left : node.right;
  }
  return std::sqrt(best2);
}

size_t Broadphase::candidates(const Vec3& p, double distance, uint32_t* out) const {
  const double limit = squaredLimit(distance);
  if (tree_ready_) return candidatesInTree(p, limit, out);
  const size_t n = flatCandidates(p, limit, out);
  if (unordered_) std::sort(out, out + n);  // slots switched on since prepare() were appended
  return n;
}

size_t Broadphase::flatCandidates(const Vec3& p, double limit, uint32_t* out) const {
  const double px = p.x(), py = p.y(), pz = p.z();
  const double* lx = lower_[0].data();
  const double* ly = lower_[1].data();
  const double* lz = lower_[2].data();
  const double* ux = upper_[0].data();
  const double* uy = upper_[1].data();
  const double* uz = upper_[2].data();
  const uint32_t* slot_of = slot_of_.data();
  const size_t live = slot_of_.size();
  size_t n = 0;
#if defined(__AVX__)
  // Four boxes at a time; padding positions are empty (+inf gaps) and never pass.
  const __m256d qx = _mm256_set1_pd(px), qy = _mm256_set1_pd(py), qz = _mm256_set1_pd(pz);
  const __m256d zero = _mm256_setzero_pd(), bound = _mm256_set1_pd(limit);
  for (size_t s = 0; s < live; s += 4) {
    const __m256d gx = _mm256_max_pd(_mm256_max_pd(_mm256_sub_pd(_mm256_loadu_pd(lx + s), qx),
                                                   _mm256_sub_pd(qx, _mm256_loadu_pd(ux + s))), zero);
    const __m256d gy = _mm256_max_pd(_mm256_max_pd(_mm256_sub_pd(_mm256_loadu_pd(ly + s), qy),
                                                   _mm256_sub_pd(qy, _mm256_loadu_pd(uy + s))), zero);
    const __m256d gz = _mm256_max_pd(_mm256_max_pd(_mm256_sub_pd(_mm256_loadu_pd(lz + s), qz),
                                                   _mm256_sub_pd(qz, _mm256_loadu_pd(uz + s))), zero);
    const __m256d d2 = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(gx, gx), _mm256_mul_pd(gy, gy)), _mm256_mul_pd(gz, gz));
    unsigned mask = static_cast<unsigned>(_mm256_movemask_pd(_mm256_cmp_pd(d2, bound, _CMP_LE_OQ)));
    while (mask) {
      out[n++] = slot_of[s + static_cast<size_t>(__builtin_ctz(mask))];
      mask &= mask - 1;
    }
  }
#else
  // Written only when it passes: with holes, positions outnumber the live slots out holds.
  for (size_t s = 0; s < live; ++s)
    if (squaredGap(lx[s], ly[s], lz[s], ux[s], uy[s], uz[s], px, py, pz) <= limit) out[n++] = slot_of[s];
#endif
  return n;
}

size_t BroadphaseReference::candidates(const Vec3& p, double distance, uint32_t* out) const {
  size_t n = 0;
  for (size_t s = 0; s < boxes.size(); ++s)
    if (boxWithin(boxes[s], p, distance)) out[n++] = static_cast<uint32_t>(s);
  return n;
}

}  // namespace meshsweeper
