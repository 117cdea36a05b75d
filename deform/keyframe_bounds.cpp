// Key-frame bounds (paper section 5.3; DESIGN.md section 3).
//
// Why the interpolated bounds are valid. Positions between frames 0 and 1 are
// x(s) = (1 - s) x0 + s x1, s in [0, 1].
// - Boxes: for every axis, min_i x_i(s) >= (1 - s) min_i x0_i + s min_i x1_i (the minimum of a
//   sum is at least the sum of the minima), and likewise for the maximum. So the linear
//   interpolation of a slot's two frame boxes contains the slot's subtree vertices at s. It is
//   computed in double and packed again (packSlotBoxes), whose slack covers its rounding.
// - Radii: let T(s) be the slot's triangle at s and x(s) one of its subtree vertices. Moving
//   every corner of a triangle by at most D moves each of its points (a convex combination of
//   the corners) by at most D, so dist(y, T(s)) <= dist(y, T(0)) + s * D_T, where D_T is the
//   largest corner displacement |x1 - x0| of the triangle. With |x(s) - x(0)| <= s * D_x:
//     dist(x(s), T(s)) <= dist(x(0), T(0)) + s * (D_x + D_T) <= eps0 + s * Delta,
//   Delta = D_T + (largest displacement among the slot's subtree vertices). From frame 1 in the
//   same way: <= eps1 + (1 - s) * Delta. Both hold, so their minimum is a valid radius.
#include "deform/keyframe_bounds.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace meshsweeper {

KeyframeBody::KeyframeBody(std::shared_ptr<const Hierarchy> hierarchy,
                           std::vector<std::vector<Vec3>> frames)
    : hierarchy_(std::move(hierarchy)), frames_(std::move(frames)) {
  if (!hierarchy_) throw std::invalid_argument("KeyframeBody: null hierarchy");
  const Hierarchy& h = *hierarchy_;
  const size_t n = h.mesh().positions.size();
  if (frames_.empty()) throw std::invalid_argument("KeyframeBody: no key frame given");
  for (size_t f = 0; f < frames_.size(); ++f) {
    if (frames_[f].size() != n)
      throw std::invalid_argument("KeyframeBody: frame " + std::to_string(f) + " has " +
                                  std::to_string(frames_[f].size()) + " positions, the mesh has " +
                                  std::to_string(n));
    for (size_t v = 0; v < n; ++v)
      if (!inCoordinateRange(frames_[f][v]))
        throw std::invalid_argument("KeyframeBody: frame " + std::to_string(f) + " vertex " +
                                    std::to_string(v) + " is not finite or beyond 1e150 in magnitude");
    if (!withinMeshSize(h.mesh(), frames_[f]))
      throw std::invalid_argument("KeyframeBody: frame " + std::to_string(f) +
                                  " spans more than the supported mesh size 1e50 (bounding-box diagonal)");
  }
  for (const auto& frame : frames_) {
    frame_nodes_.push_back(h.nodes());
    refitBounds(h, frame.data(), frame_nodes_.back(), true);
    std::vector<SlotBoxes>& boxes = frame_boxes_.emplace_back();
    boxes.reserve(frame_nodes_.back().size());
    for (const Node8& n : frame_nodes_.back()) boxes.push_back(slotBoxes(n));
  }

  // Delta per slot and frame pair: corner displacement + subtree displacement (bottom-up).
  const auto& nodes = h.nodes();
  for (size_t f = 0; f + 1 < frames_.size(); ++f) {
    std::vector<double> moved(n);
    for (size_t v = 0; v < n; ++v) moved[v] = (frames_[f + 1][v] - frames_[f][v]).norm();
    std::vector<double> subtree, corners;
    slotDisplacements(h, moved, subtree, corners);
    std::vector<float>& delta = delta_.emplace_back(8 * nodes.size(), 0.0f);
    for (size_t i = 0; i < delta.size(); ++i)
      delta[i] = floatAtLeast((subtree[i] + corners[i]) * (1 + 1e-9));  // +inf past the float range
  }
  nodes_ = h.nodes();
  positions_ = frames_[0];
  const std::vector<TriangleIndex>& vertex_face = h.vertexFace();
  unused_vertices_ = std::find(vertex_face.begin(), vertex_face.end(), kInvalidIndex) != vertex_face.end();
  // The rounding of an interpolated position, (1 - s) a + s b in world coordinates: a few ulps
  // of the largest coordinate a face uses, in every frame. It moves a vertex and a triangle's
  // corners, so the radii carry it twice over (found by an audit: key frames at 1e12 left eps
  // below a computed vertex's distance).
  double largest = 0;
  for (const auto& frame : frames_)
    for (size_t v = 0; v < n; ++v)
      if (vertex_face[v] != kInvalidIndex) largest = std::max(largest, frame[v].cwiseAbs().maxCoeff());
  interpolation_rounding_ = 16 * 0x1p-53 * largest;
  geometry_.hierarchy = hierarchy_.get();
  geometry_.nodes = nodes_.data();
  geometry_.leaf_blocks = nullptr;  // faces are gathered from the interpolated positions
  geometry_.positions = positions_.data();
  geometry_.center = h.center();
  geometry_.box_scale = h.boxScale();
  geometry_.version = nextGeometryVersion();
  geometry_.lineage = geometry_.version;
  setTime(0);
}

namespace {
double clampedTime(double t, size_t frames) { return std::clamp(t, 0.0, static_cast<double>(frames - 1)); }
}  // namespace

void KeyframeBody::interpolatedBounds(double t, std::vector<Node8>& out_nodes) const {
  // As setTime (found by an audit: NaN was read as time 0 here).
  if (!std::isfinite(t))
    throw std::invalid_argument("KeyframeBody::interpolatedBounds: the time " + std::to_string(t) + " is not finite");
  const size_t last = frames_.size() - 1;
  t = clampedTime(t, frames_.size());
  const size_t f = std::min(static_cast<size_t>(t), last == 0 ? 0 : last - 1);
  const double s = last == 0 ? 0.0 : t - static_cast<double>(f);
  if (out_nodes.size() != nodes_.size()) out_nodes = nodes_;  // children and slots; bounds below
  const std::vector<Node8>& a = frame_nodes_[f];
  const std::vector<Node8>& b = frame_nodes_[last == 0 ? 0 : f + 1];
  const std::vector<SlotBoxes>& box_a = frame_boxes_[f];
  const std::vector<SlotBoxes>& box_b = frame_boxes_[last == 0 ? 0 : f + 1];
  const double wr = 1 - s;
  const double world_magnitude = hierarchy_->center().cwiseAbs().maxCoeff() * hierarchy_->boxScale();
  for (size_t node = 0; node < out_nodes.size(); ++node) {
    Node8& out = out_nodes[node];
    const Node8& na = a[node];
    const Node8& nb = b[node];
    // In scaled double coordinates, packed again: its slack covers this arithmetic (relative
    // 2^-53 of the frames' coordinates, `magnitude`).
    // The positions are interpolated in world coordinates: their rounding is relative to the
    // mesh's distance from the world origin too (found by an audit: key frames at 1e10 left
    // the computed positions an ulp outside the boxes), so the centre's scaled magnitude counts.
    SlotBoxes boxes = emptySlotBoxes();  // empty slots stay empty (0 * inf is NaN)
    double magnitude = world_magnitude;
    for (int k = 0; k < 8; ++k) {
      if (na.child[k] == kEmptyChild) continue;
      for (int axis = 0; axis < 3; ++axis) {
        const double lo_a = box_a[node].lower[axis][k], lo_b = box_b[node].lower[axis][k];
        const double hi_a = box_a[node].upper[axis][k], hi_b = box_b[node].upper[axis][k];
        // A frame's bound past the float range reads back infinite: a weight of 0 leaves it
        // out (0 * inf is NaN, which would read as an empty slot; found by an audit).
        boxes.lower[axis][k] = s == 0 ? lo_a : wr == 0 ? lo_b : wr * lo_a + s * lo_b;
        boxes.upper[axis][k] = s == 0 ? hi_a : wr == 0 ? hi_b : wr * hi_a + s * hi_b;
        magnitude = std::max({magnitude, std::abs(lo_a), std::abs(lo_b), std::abs(hi_a), std::abs(hi_b)});
      }
    }
    packSlotBoxes(out, boxes, magnitude);
    if (last == 0) {
      std::copy(na.eps, na.eps + 8, out.eps);
      continue;
    }
    const float* delta = &delta_[f][8 * node];
    for (int k = 0; k < 8; ++k) {
      const double from_a = s == 0 ? na.eps[k] : na.eps[k] + s * delta[k];  // delta may be inf
      const double from_b = wr == 0 ? nb.eps[k] : nb.eps[k] + wr * delta[k];
      out.eps[k] = floatAtLeast(std::min(from_a, from_b) + interpolation_rounding_);
    }
  }
}

void KeyframeBody::setTime(double t) {
  // As the distance service's setTime (found by review: NaN silently read as frame 0).
  if (!std::isfinite(t)) throw std::invalid_argument("KeyframeBody::setTime: the time " + std::to_string(t) + " is not finite");
  interpolatedBounds(t, nodes_);  // in place: same size, so geometry_.nodes stays valid
  time_ = clampedTime(t, frames_.size());
  geometry_.version = nextGeometryVersion();
  const size_t last = frames_.size() - 1;
  const size_t f = std::min(static_cast<size_t>(time_), last == 0 ? 0 : last - 1);
  const double s = last == 0 ? 0.0 : time_ - static_cast<double>(f);
  const std::vector<Vec3>& a = frames_[f];
  const std::vector<Vec3>& b = frames_[last == 0 ? 0 : f + 1];
  // How far the farthest vertex moved: the lineage's drift grows by that. A vertex no face uses
  // does not count (found by an audit: one still at 1e100 moved 1e84 by rounding each time).
  const TriangleIndex* used = unused_vertices_ ? hierarchy_->vertexFace().data() : nullptr;
  double moved2 = 0;
  for (size_t v = 0; v < positions_.size(); ++v) {
    const Vec3 x = (1 - s) * a[v] + s * b[v];
    if (!used || used[v] != kInvalidIndex) moved2 = std::max(moved2, (x - positions_[v]).squaredNorm());
    positions_[v] = x;
  }
  geometry_.drift = grownDrift(geometry_.drift, std::sqrt(moved2));
}

}  // namespace meshsweeper
