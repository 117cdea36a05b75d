// Displacement-inflated bounds (paper section 5.3; DESIGN.md section 3).
//
// Why inflation is valid: if every vertex x moved at most delta_x from the anchor, a slot's
// subtree vertices lie in its anchor box grown by D_sub = max delta over the subtree; and, as
// for key frames, moving a triangle's corners by at most D_T moves each of its points by at most
// D_T, so dist(x', T') <= dist(x, T) + delta_x + D_T <= eps + D_sub + D_T.
#include "deform/inflated_bounds.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace meshsweeper {

DeformingBody::DeformingBody(std::shared_ptr<const Hierarchy> hierarchy)
    : hierarchy_(std::move(hierarchy)) {
  const Hierarchy& h = *hierarchy_;
  anchor_nodes_ = h.nodes();
  nodes_ = anchor_nodes_;
  anchor_positions_ = h.mesh().positions;
  positions_ = anchor_positions_;
  delta_.assign(positions_.size(), 0.0);
  geometry_.nodes = nodes_.data();
  geometry_.leaf_blocks = nullptr;  // faces are gathered from the current positions
  geometry_.positions = positions_.data();
  geometry_.center = h.center();
  geometry_.box_scale = h.boxScale();
  geometry_.version = nextGeometryVersion();
  geometry_.lineage = geometry_.version;
}

void DeformingBody::checkSize(size_t count, const char* what) const {
  if (count != positions_.size())
    throw std::invalid_argument(std::string("DeformingBody: ") + what + " has " + std::to_string(count) +
                                " entries, the mesh has " + std::to_string(positions_.size()) + " vertices");
}

void DeformingBody::anchor(const std::vector<Vec3>& positions) {
  checkSize(positions.size(), "anchor positions");
  for (size_t v = 0; v < positions.size(); ++v)
    if (!positions[v].allFinite())
      throw std::invalid_argument("DeformingBody: anchor position " + std::to_string(v) + " is not finite");
  anchor_positions_ = positions;
  positions_ = positions;
  anchor_nodes_ = hierarchy_->nodes();
  refitBounds(*hierarchy_, anchor_positions_.data(), anchor_nodes_, true);
  nodes_ = anchor_nodes_;
  std::fill(delta_.begin(), delta_.end(), 0.0);
  geometry_.version = nextGeometryVersion();
  geometry_.lineage = geometry_.version;  // positions replaced: coherent state starts over
}

void DeformingBody::inflate(double delta) { inflate(std::vector<double>(positions_.size(), delta)); }

void DeformingBody::inflate(const std::vector<double>& delta) {
  checkSize(delta.size(), "the displacement bounds");
  for (size_t v = 0; v < delta.size(); ++v)
    if (!(delta[v] >= 0) || !std::isfinite(delta[v]))
      throw std::invalid_argument("DeformingBody: displacement bound " + std::to_string(v) +
                                  " must be finite and >= 0");
  const Hierarchy& h = *hierarchy_;
  const float inf = std::numeric_limits<float>::infinity();
  const double scale = h.boxScale();
  // How far each slot's subtree and corners may move (one bottom-up pass).
  std::vector<double> subtree, corners;
  slotDisplacements(h, delta, subtree, corners);
  double extent = 0;
  for (size_t node = 0; node < anchor_nodes_.size(); ++node) {
    const Node8& a = anchor_nodes_[node];
    Node8& out = nodes_[node];
    out = a;
    for (int k = 0; k < 8; ++k) {
      if (a.child[k] == kEmptyChild) continue;
      const double worst = subtree[8 * node + k];
      out.eps[k] = std::nextafter(static_cast<float>((a.eps[k] + worst + corners[8 * node + k]) * (1 + 1e-9)), inf);
      const float grow = std::nextafter(static_cast<float>(worst * scale), inf);
      for (int axis = 0; axis < 3; ++axis) {
        out.lower[axis][k] = a.lower[axis][k] - grow;
        out.upper[axis][k] = a.upper[axis][k] + grow;
        extent = std::max({extent, std::abs(static_cast<double>(out.lower[axis][k])),
                           std::abs(static_cast<double>(out.upper[axis][k]))});
      }
    }
  }
  // Boxes reaching beyond the anchor's extent need a wider query-rounding margin.
  const float margin = boxMargin(extent) - boxMargin(1.0);
  if (margin > 0) {
    for (Node8& n : nodes_)
      for (int axis = 0; axis < 3; ++axis)
        for (int k = 0; k < 8; ++k) {
          n.lower[axis][k] -= margin;
          n.upper[axis][k] += margin;
        }
  }
  delta_ = delta;
  // Current positions outside the new bounds fall back to the anchor positions.
  for (size_t v = 0; v < positions_.size(); ++v) {
    if ((positions_[v] - anchor_positions_[v]).norm() > delta_[v]) {
      positions_ = anchor_positions_;
      geometry_.lineage = nextGeometryVersion();  // positions replaced: coherent state starts over
      break;
    }
  }
  geometry_.version = nextGeometryVersion();
}

DisplacementCheck DeformingBody::setPositions(const std::vector<Vec3>& positions) {
  checkSize(positions.size(), "positions");
  DisplacementCheck check;
  double moved2 = 0;  // how far the farthest vertex moves: the lineage's drift grows by that
  for (size_t v = 0; v < positions.size(); ++v) {
    if (!positions[v].allFinite())
      throw std::invalid_argument("DeformingBody: position " + std::to_string(v) + " is not finite");
    const double excess = (positions[v] - anchor_positions_[v]).norm() - delta_[v];
    if (excess > 0 && excess > check.excess) {
      check.accepted = false;
      check.excess = excess;
      check.worst_vertex = static_cast<VertexIndex>(v);
    }
    moved2 = std::max(moved2, (positions[v] - positions_[v]).squaredNorm());
  }
  if (!check.accepted) return check;
  positions_ = positions;
  geometry_.version = nextGeometryVersion();
  geometry_.drift += std::sqrt(moved2) * (1 + 1e-12);
  return check;
}

}  // namespace meshsweeper
