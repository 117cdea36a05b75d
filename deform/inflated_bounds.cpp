// Displacement-inflated bounds (paper section 5.3; DESIGN.md section 3).
//
// Why inflation is valid: if every vertex x moved at most delta_x from the anchor, a slot's
// subtree vertices lie in its anchor box grown by D_sub = max delta over the subtree; and, as
// for key frames, moving a triangle's corners by at most D_T moves each of its points by at most
// D_T, so dist(x', T') <= dist(x, T) + delta_x + D_T <= eps + D_sub + D_T.
#include "deform/inflated_bounds.h"

#include <algorithm>
#include <cstdio>
#include <iterator>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace meshsweeper {

namespace {

// The largest |coordinate| of any used box (scaled units).
double boxExtent(const std::vector<Node8>& nodes) {
  double extent = 0;
  for (const Node8& n : nodes)
    for (int axis = 0; axis < 3; ++axis)
      for (int k = 0; k < 8; ++k) {
        if (n.child[k] == kEmptyChild) continue;
        extent = std::max({extent, std::abs(static_cast<double>(n.lower[axis][k])),
                           std::abs(static_cast<double>(n.upper[axis][k]))});
      }
  return extent;
}

}  // namespace

DeformingBody::DeformingBody(std::shared_ptr<const Hierarchy> hierarchy)
    : hierarchy_(std::move(hierarchy)) {
  const Hierarchy& h = *hierarchy_;
  anchor_nodes_ = h.nodes();
  anchor_extent_ = boxExtent(anchor_nodes_);
  extent_bound_ = anchor_extent_;
  inflated_nodes_ = anchor_nodes_;
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

void DeformingBody::setInlineFaces(bool on) {
  if (on == inlineFaces()) return;
  if (on) {
    leaf_blocks_.resize(hierarchy_->leafCount());  // at least one leaf: never null
    geometry_.leaf_blocks = leaf_blocks_.data();
    refreshInlineFaces();
  } else {
    geometry_.leaf_blocks = nullptr;
    leaf_blocks_.clear();
    leaf_blocks_.shrink_to_fit();
    nodes_ = inflated_nodes_;  // the tight boxes held only for the current positions
  }
}

// Inline faces at the current positions, and boxes refitted to them (the inflated boxes are
// valid for any positions within the bounds; these are tighter, so fewer leaves are opened).
// The current positions lie within the inflated boxes, so extent_bound_ bounds their extent.
void DeformingBody::refreshInlineFaces() {
  if (!inlineFaces()) return;
  refreshLeafBlocks(*hierarchy_, positions_.data(), extent_bound_, leaf_blocks_, nodes_);
}

// Positions whose bounding-box diagonal (`diagonal`) exceeds the supported mesh size (core/mesh.h) would
// overflow the exact distance: refused like a mesh of that size.
void DeformingBody::checkExtent(double diagonal, const char* what) const {
  if (!(diagonal > kMaxMeshSize)) return;
  char span[32];
  std::snprintf(span, sizeof span, "%.3g", diagonal);
  throw std::invalid_argument(std::string("DeformingBody: the ") + what + " span " + span +
                              " (bounding-box diagonal), beyond the supported mesh size 1e50");
}

void DeformingBody::checkSize(size_t count, const char* what) const {
  if (count != positions_.size())
    throw std::invalid_argument(std::string("DeformingBody: ") + what + " has " + std::to_string(count) +
                                " entries, the mesh has " + std::to_string(positions_.size()) + " vertices");
}

void DeformingBody::anchor(const std::vector<Vec3>& positions) {
  checkSize(positions.size(), "anchor positions");
  for (size_t v = 0; v < positions.size(); ++v)
    if (!inCoordinateRange(positions[v]))
      throw std::invalid_argument("DeformingBody: anchor position " + std::to_string(v) +
                                  " is not finite or beyond 1e150 in magnitude");
  checkExtent(positionsDiagonal(positions), "positions");
  anchor_positions_ = positions;
  positions_ = positions;
  anchor_nodes_ = hierarchy_->nodes();
  refitBounds(*hierarchy_, anchor_positions_.data(), anchor_nodes_, radii_);
  if (!radii_)  // no radius phase: every radius unbounded (valid, it prunes nothing)
    for (Node8& n : anchor_nodes_) std::fill(std::begin(n.eps), std::end(n.eps), std::numeric_limits<float>::infinity());
  anchor_extent_ = boxExtent(anchor_nodes_);
  extent_bound_ = anchor_extent_;
  inflated_nodes_ = anchor_nodes_;
  nodes_ = anchor_nodes_;
  refreshInlineFaces();
  std::fill(delta_.begin(), delta_.end(), 0.0);
  geometry_.version = nextGeometryVersion();
  geometry_.lineage = geometry_.version;  // positions replaced: coherent state starts over
}

void DeformingBody::reanchor(const std::vector<Vec3>& positions) {
  checkSize(positions.size(), "anchor positions");
  double moved2 = 0;
  for (size_t v = 0; v < positions.size(); ++v) moved2 = std::max(moved2, (positions[v] - positions_[v]).squaredNorm());
  const uint64_t lineage = geometry_.lineage;
  const double drift = geometry_.drift;
  anchor(positions);  // checks the positions; throws with the body unchanged
  geometry_.lineage = lineage;
  geometry_.drift = grownDrift(drift, std::sqrt(moved2));
}

void DeformingBody::inflate(double delta) { inflate(std::vector<double>(positions_.size(), delta)); }

void DeformingBody::inflate(const std::vector<double>& delta) {
  checkSize(delta.size(), "the displacement bounds");
  // One pass: the bounds' validity (nothing changes if one is bad) and whether the current
  // positions stay within the new bounds.
  bool bad = false, outside = false;
  constexpr double kMax = std::numeric_limits<double>::max();
  for (size_t v = 0; v < delta.size(); ++v) {  // branch-free: the compiler vectorises it
    bad |= !(delta[v] >= 0 && delta[v] <= kMax);
    // Squared, with a relative 1e-12 that the bounds' own slack covers (eps carries 1e-9,
    // boxes a float rounding up).
    outside |= (positions_[v] - anchor_positions_[v]).squaredNorm() > delta[v] * delta[v] * (1 + 1e-12);
  }
  for (size_t v = 0; bad && v < delta.size(); ++v)
    if (!(delta[v] >= 0 && delta[v] <= kMax))
      throw std::invalid_argument("DeformingBody: displacement bound " + std::to_string(v) +
                                  " must be finite and >= 0");
  const Hierarchy& h = *hierarchy_;
  const double scale = h.boxScale();
  // How far each slot's subtree and corners may move (one bottom-up pass).
  if (leaf_vertices_.offsets.empty()) leaf_vertices_ = leafVertices(h);
  slotDisplacements(h, delta, subtree_, corners_, &leaf_vertices_);
  float largest_grow = 0;
  for (size_t node = 0; node < anchor_nodes_.size(); ++node) {
    const Node8& a = anchor_nodes_[node];
    Node8& out = inflated_nodes_[node];
    out = a;
    for (int k = 0; k < 8; ++k) {
      if (a.child[k] == kEmptyChild) continue;
      const double worst = subtree_[8 * node + k];
      out.eps[k] = floatAtLeast((a.eps[k] + worst + corners_[8 * node + k]) * (1 + 1e-9));
      const float grow = floatAtLeast(worst * scale);
      largest_grow = std::max(largest_grow, grow);
      for (int axis = 0; axis < 3; ++axis) {
        out.lower[axis][k] = a.lower[axis][k] - grow;
        out.upper[axis][k] = a.upper[axis][k] + grow;
      }
    }
  }
  // Boxes reaching beyond the anchor's extent need a wider query-rounding margin (a bound on
  // the new extent: the anchor's plus the largest growth).
  const float margin = boxMargin(anchor_extent_ + largest_grow) - boxMargin(1.0);
  if (margin > 0) {
    for (Node8& n : inflated_nodes_)
      for (int axis = 0; axis < 3; ++axis)
        for (int k = 0; k < 8; ++k) {
          n.lower[axis][k] -= margin;
          n.upper[axis][k] += margin;
        }
  }
  delta_ = delta;
  extent_bound_ = anchor_extent_ + largest_grow;
  nodes_ = inflated_nodes_;
  // Current positions outside the new bounds fall back to the anchor positions.
  if (outside) {
    positions_ = anchor_positions_;
    geometry_.lineage = nextGeometryVersion();  // positions replaced: coherent state starts over
  }
  refreshInlineFaces();
  geometry_.version = nextGeometryVersion();
}

DisplacementCheck DeformingBody::setPositions(const std::vector<Vec3>& positions) {
  checkSize(positions.size(), "positions");
  DisplacementCheck check;
  // A branch-free pass (the compiler vectorises it): positions not finite or beyond
  // kMaxCoordinate, vertices that may be past their bound (a superset: squared, with a relative
  // 1e-12 to spare), and how far the farthest vertex moves (the lineage's drift grows by that).
  // NaN fails every comparison, so it is caught by `finite`.
  // The same pass takes the positions' box, for the extent check.
  bool finite = true, suspect = false;
  double moved2 = 0;
  Vec3 lower = Vec3::Constant(std::numeric_limits<double>::infinity()), upper = -lower;
  for (size_t v = 0; v < positions.size(); ++v) {
    const Vec3 d = positions[v] - anchor_positions_[v];
    const double d2 = d.squaredNorm();
    finite &= inCoordinateRange(positions[v]);
    suspect |= d2 > delta_[v] * delta_[v] * (1 - 1e-12);
    moved2 = std::max(moved2, (positions[v] - positions_[v]).squaredNorm());
    lower = lower.cwiseMin(positions[v]);
    upper = upper.cwiseMax(positions[v]);
  }
  if (!finite || suspect) {
    for (size_t v = 0; v < positions.size(); ++v) {
      if (!inCoordinateRange(positions[v]))
        throw std::invalid_argument("DeformingBody: position " + std::to_string(v) +
                                    " is not finite or beyond 1e150 in magnitude");
      const double excess = (positions[v] - anchor_positions_[v]).norm() - delta_[v];
      if (excess > 0 && excess > check.excess) {
        check.accepted = false;
        check.excess = excess;
        check.worst_vertex = static_cast<VertexIndex>(v);
      }
    }
  }
  if (!check.accepted) return check;
  checkExtent((upper - lower).norm(), "positions");
  positions_ = positions;
  refreshInlineFaces();
  geometry_.version = nextGeometryVersion();
  geometry_.drift = grownDrift(geometry_.drift, std::sqrt(moved2));
  return check;
}

}  // namespace meshsweeper
