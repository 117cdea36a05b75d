// Broadphase of the distance service (see broadphase.h for the choice of a flat loop).
#include "collision/broadphase.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>

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

}  // namespace

bool boxWithin(const Box3& box, const Vec3& p, double distance) {
  if (box.empty()) return false;
  double d2 = 0;
  for (int axis = 0; axis < 3; ++axis) {
    const double gap = std::max({box.lower[axis] - p[axis], p[axis] - box.upper[axis], 0.0});
    d2 += gap * gap;
  }
  return d2 <= squaredLimit(distance);
}

constexpr uint32_t kNoPosition = std::numeric_limits<uint32_t>::max();

void Broadphase::resize(size_t slots) {
  for (size_t slot = slots; slot < dense_of_.size(); ++slot) set(slot, Box3{});
  dense_of_.resize(slots, kNoPosition);
}

void Broadphase::pad() {
  const size_t live = slot_of_.size(), padded = (live + 3) / 4 * 4;
  for (int axis = 0; axis < 3; ++axis) {
    lower_[axis].resize(padded);
    upper_[axis].resize(padded);
    for (size_t k = live; k < padded; ++k) {
      lower_[axis][k] = kInf;
      upper_[axis][k] = -kInf;
    }
  }
}

void Broadphase::set(size_t slot, const Box3& box) {
  assert(slot < dense_of_.size());
  uint32_t at = dense_of_[slot];
  if (box.empty()) {
    if (at == kNoPosition) return;
    // Out of the loop: the later slots move down one position.
    for (int axis = 0; axis < 3; ++axis) {
      lower_[axis].erase(lower_[axis].begin() + at);
      upper_[axis].erase(upper_[axis].begin() + at);
    }
    slot_of_.erase(slot_of_.begin() + at);
    for (size_t k = at; k < slot_of_.size(); ++k) dense_of_[slot_of_[k]] = static_cast<uint32_t>(k);
    dense_of_[slot] = kNoPosition;
    pad();
    return;
  }
  if (at == kNoPosition) {
    // Into the loop at its slot's place: the later slots move up one position.
    at = static_cast<uint32_t>(std::lower_bound(slot_of_.begin(), slot_of_.end(), static_cast<uint32_t>(slot)) -
                               slot_of_.begin());
    for (int axis = 0; axis < 3; ++axis) {
      lower_[axis].resize(slot_of_.size());
      upper_[axis].resize(slot_of_.size());
      lower_[axis].insert(lower_[axis].begin() + at, 0.0);
      upper_[axis].insert(upper_[axis].begin() + at, 0.0);
    }
    slot_of_.insert(slot_of_.begin() + at, static_cast<uint32_t>(slot));
    for (size_t k = at; k < slot_of_.size(); ++k) dense_of_[slot_of_[k]] = static_cast<uint32_t>(k);
    pad();
  }
  for (int axis = 0; axis < 3; ++axis) {
    lower_[axis][at] = box.lower[axis];
    upper_[axis][at] = box.upper[axis];
  }
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

size_t Broadphase::candidates(const Vec3& p, double distance, uint32_t* out) const {
  const double limit = squaredLimit(distance);
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
  for (size_t s = 0; s < live; ++s) {
    const double gx = std::max(std::max(lx[s] - px, px - ux[s]), 0.0);
    const double gy = std::max(std::max(ly[s] - py, py - uy[s]), 0.0);
    const double gz = std::max(std::max(lz[s] - pz, pz - uz[s]), 0.0);
    out[n] = slot_of[s];
    n += (gx * gx + gy * gy + gz * gz <= limit) ? 1 : 0;
  }
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
