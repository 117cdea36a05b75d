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

// Whether a vertex displaced by sqrt(d2) from its anchor is within its bound `delta`: squared,
// with a relative 1e-12 that the bounds' own slack covers (eps carries a relative 1e-9; each
// packed box a margin of 2^-21 of its largest offset, at least the displacement it was grown
// by, of which a query point's rounding takes 2^-24). setPositions() and inflate() decide
// alike (an audit saw positions that inflate() kept refused by setPositions(), and positions
// computed at exactly their bound refused by rounding).
bool withinBound(double d2, double delta) { return d2 <= delta * delta * (1 + 1e-12); }

}  // namespace

DeformingBody::DeformingBody(std::shared_ptr<const Hierarchy> hierarchy)
    : hierarchy_(std::move(hierarchy)) {
  if (!hierarchy_) throw std::invalid_argument("DeformingBody: null hierarchy");
  const Hierarchy& h = *hierarchy_;
  anchor_nodes_ = h.nodes();
  inflated_nodes_ = anchor_nodes_;
  nodes_ = anchor_nodes_;
  anchor_positions_ = h.mesh().positions;
  positions_ = anchor_positions_;
  delta_.assign(positions_.size(), 0.0);
  const std::vector<TriangleIndex>& vertex_face = h.vertexFace();
  unused_vertices_ = std::find(vertex_face.begin(), vertex_face.end(), kInvalidIndex) != vertex_face.end();
  geometry_.hierarchy = hierarchy_.get();
  geometry_.nodes = nodes_.data();
  geometry_.leaf_blocks = nullptr;  // faces are gathered from the current positions
  geometry_.positions = positions_.data();
  geometry_.center = h.center();
  geometry_.box_scale = h.boxScale();
  geometry_.version = nextGeometryVersion();
  geometry_.lineage = geometry_.version;
  setRegionalDrift(true);
}

void DeformingBody::setRegionalDrift(bool on) {
  if (on == regionalDrift()) return;
  if (on) {
    setupRegions();
    newRegionEpoch();
    return;
  }
  geometry_.regions = nullptr;
  regions_ = RegionTables{};
}

// The regions: the cells of a grid over the mesh's own positions that hold a face's centroid
// (cells of 1/16 of the box's diagonal, wider until at most 256 are used), with each face's
// region and each region's distinct vertices. Compact regions keep the neighbourhoods small;
// answers do not depend on them (the boxes of each epoch hold whatever positions come).
void DeformingBody::setupRegions() {
  const Mesh& mesh = hierarchy_->mesh();
  constexpr size_t kMaxRegions = 256;
  const size_t faces = mesh.triangles.size();
  Vec3 lower, upper;
  meshBounds(mesh, lower, upper);
  const double diagonal = (upper - lower).norm();
  std::vector<Vec3> centroids(faces);
  for (size_t f = 0; f < faces; ++f) {
    const Triangle& t = mesh.triangles[f];
    centroids[f] = (mesh.positions[t[0]] + mesh.positions[t[1]] + mesh.positions[t[2]]) / 3.0;
  }
  std::vector<uint64_t> cell(faces, 0), used;
  if (diagonal > 0 && std::isfinite(diagonal)) {
    // Each try widens the cells by at least 1.25, by the root of the excess when larger (the
    // cells a surface occupies fall as the square of their size): a few tries, even for a
    // mesh of millions of faces.
    for (double side = diagonal / 16;; side *= std::max(1.25, std::sqrt(static_cast<double>(used.size()) / kMaxRegions))) {
      for (size_t f = 0; f < faces; ++f) {
        uint64_t key = 0;
        for (int axis = 0; axis < 3; ++axis) {
          const double at = std::floor((centroids[f][axis] - lower[axis]) / side);
          key = key * 4096 + static_cast<uint64_t>(std::clamp(at, 0.0, 4095.0));
        }
        cell[f] = key;
      }
      used = cell;
      std::sort(used.begin(), used.end());
      used.erase(std::unique(used.begin(), used.end()), used.end());
      if (used.size() <= kMaxRegions) break;
    }
  } else {
    used.assign(1, 0);  // no extent: one region
  }
  const uint32_t count = static_cast<uint32_t>(used.size());
  regions_.face_region.resize(faces);
  std::vector<std::vector<VertexIndex>> vertices(count);
  for (size_t f = 0; f < faces; ++f) {
    const uint16_t region = static_cast<uint16_t>(std::lower_bound(used.begin(), used.end(), cell[f]) - used.begin());
    regions_.face_region[f] = region;
    const Triangle& t = mesh.triangles[f];
    vertices[region].insert(vertices[region].end(), t.begin(), t.end());
  }
  regions_.vertex_offsets.assign(static_cast<size_t>(count) + 1, 0);
  regions_.vertices.clear();
  for (uint32_t region = 0; region < count; ++region) {
    std::vector<VertexIndex>& list = vertices[region];
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
    regions_.vertices.insert(regions_.vertices.end(), list.begin(), list.end());
    regions_.vertex_offsets[region + 1] = static_cast<uint32_t>(regions_.vertices.size());
  }
  regions_.drift.assign(2 * static_cast<size_t>(count), 0.0);
  regions_.motion2.assign(count, 0.0);
  regions_.vertex_motion2.assign(mesh.positions.size(), 0.0);
  regions_.view.face_region = regions_.face_region.data();
  regions_.view.count = count;
  regions_.view.drift = regions_.drift.data();
  geometry_.regions = &regions_.view;
}

// A new epoch of drift by region, for the current anchor positions and displacement bounds:
// each region's box holds its vertices at any accepted positions (anchor box grown by the
// region's largest bound, and a rounding margin); the neighbourhoods at 1/16 and 1/4 of the
// diagonal of all of them list the regions whose boxes come that close (with a relative 1e-9 to
// spare, so a computed gap never leaves out a region within the width). Running drifts start
// at zero under a new epoch value: states gathered before stop reading them.
void DeformingBody::newRegionEpoch() {
  if (!regionalDrift()) return;
  const uint32_t count = regions_.view.count;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  std::vector<Vec3> lower(count, Vec3::Constant(kInf)), upper(count, Vec3::Constant(-kInf));
  Vec3 all_lower = Vec3::Constant(kInf), all_upper = Vec3::Constant(-kInf);
  for (uint32_t region = 0; region < count; ++region) {
    double grow = 0;
    for (uint32_t i = regions_.vertex_offsets[region]; i < regions_.vertex_offsets[region + 1]; ++i) {
      const VertexIndex v = regions_.vertices[i];
      lower[region] = lower[region].cwiseMin(anchor_positions_[v]);
      upper[region] = upper[region].cwiseMax(anchor_positions_[v]);
      grow = std::max(grow, delta_[v]);
    }
    const double extent = std::max(lower[region].cwiseAbs().maxCoeff(), upper[region].cwiseAbs().maxCoeff());
    const double margin = grow * (1 + 1e-9) + 1e-12 * (extent + grow);
    lower[region].array() -= margin;
    upper[region].array() += margin;
    all_lower = all_lower.cwiseMin(lower[region]);
    all_upper = all_upper.cwiseMax(upper[region]);
  }
  regions_.box.resize(6 * static_cast<size_t>(count));
  for (uint32_t region = 0; region < count; ++region)
    for (int axis = 0; axis < 3; ++axis) {
      regions_.box[axis * count + region] = lower[region][axis];
      regions_.box[(3 + axis) * count + region] = upper[region][axis];
    }
  regions_.view.box = regions_.box.data();
  const double diagonal = (all_upper - all_lower).norm();
  regions_.view.width[0] = diagonal / 16;
  regions_.view.width[1] = diagonal / 4;
  for (int level = 0; level < 2; ++level) {
    const double reach = regions_.view.width[level] * (1 + 1e-9);
    std::vector<uint32_t>& offsets = regions_.neighbour_offsets[level];
    std::vector<uint16_t>& list = regions_.neighbours[level];
    offsets.assign(static_cast<size_t>(count) + 1, 0);
    list.clear();
    for (uint32_t region = 0; region < count; ++region) {
      for (uint32_t other = 0; other < count; ++other) {
        const Vec3 gap = (lower[other] - upper[region]).cwiseMax(lower[region] - upper[other]).cwiseMax(0.0);
        if (!(gap.norm() > reach)) list.push_back(static_cast<uint16_t>(other));
      }
      offsets[region + 1] = static_cast<uint32_t>(list.size());
    }
  }
  std::fill(regions_.drift.begin(), regions_.drift.end(), 0.0);
  regions_.uniform_skips = 0;
  regions_.view.epoch = nextGeometryVersion();
}

// Each region's running drifts grow by how far the farthest vertex of its neighbourhoods moved
// in this change (`by_region`: from the vertex motions setPositions kept), or by the
// largest motion of all (`largest`, an upper bound of every region's). A change where nine
// regions in ten saw their first neighbourhood move by half the largest or more (a wave over
// the whole body) gains nothing from regions: the next kUniformSkips changes skip the
// per-region pass and take the largest, then a change measures again.
void DeformingBody::growRegionDrift(bool by_region, double largest) {
  if (!regionalDrift()) return;
  const uint32_t count = regions_.view.count;
  if (!by_region) {
    for (double& drift : regions_.drift) drift = grownDrift(drift, largest);
    --regions_.uniform_skips;
    return;
  }
  const double* motion2 = regions_.vertex_motion2.data();
  for (uint32_t region = 0; region < count; ++region) {
    double moved2 = 0;
    for (uint32_t i = regions_.vertex_offsets[region]; i < regions_.vertex_offsets[region + 1]; ++i)
      moved2 = std::max(moved2, motion2[regions_.vertices[i]]);
    regions_.motion2[region] = moved2;
  }
  // A neighbourhood of most regions takes the largest motion of all (an upper bound of its
  // own); a scan stops once it meets it.
  const double largest2 = *std::max_element(regions_.motion2.begin(), regions_.motion2.end());
  uint32_t uniform = 0;  // regions whose first neighbourhood moved by half the largest or more
  for (int level = 0; level < 2; ++level) {
    const std::vector<uint32_t>& offsets = regions_.neighbour_offsets[level];
    const std::vector<uint16_t>& list = regions_.neighbours[level];
    for (uint32_t region = 0; region < count; ++region) {
      double moved2 = largest2;
      if (2 * (offsets[region + 1] - offsets[region]) <= count) {
        moved2 = 0;
        for (uint32_t i = offsets[region]; i < offsets[region + 1] && moved2 < largest2; ++i)
          moved2 = std::max(moved2, regions_.motion2[list[i]]);
      }
      if (level == 0) uniform += moved2 >= 0.25 * largest2;
      double& drift = regions_.drift[2 * static_cast<size_t>(region) + level];
      drift = grownDrift(drift, std::sqrt(moved2));
    }
  }
  constexpr int kUniformSkips = 7;
  if (10 * uniform >= 9 * count) regions_.uniform_skips = kUniformSkips;
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
void DeformingBody::refreshInlineFaces() {
  if (!inlineFaces()) return;
  refreshLeafBlocks(*hierarchy_, positions_.data(), leaf_blocks_, nodes_);
}

// Positions whose bounding-box diagonal exceeds the supported mesh size (core/mesh.h) over the
// vertices the faces use would overflow the exact distance: refused like a mesh of that size.
// `diagonal` is that of all the positions (computed by the caller's pass); only when it is too
// large are the used vertices measured (a vertex no face uses may lie anywhere, as in a mesh).
void DeformingBody::checkExtent(const std::vector<Vec3>& positions, double diagonal, const char* what) const {
  if (!(diagonal > kMaxMeshSize)) return;
  diagonal = usedPositionsDiagonal(hierarchy_->mesh(), positions);
  if (!(diagonal > kMaxMeshSize)) return;
  char span[32];
  std::snprintf(span, sizeof span, "%.3g", diagonal);
  throw std::invalid_argument(std::string("DeformingBody: the ") + what + " span " + span +
                              " (bounding-box diagonal), beyond the supported mesh size 1e50");
}

void DeformingBody::checkSize(size_t count, const char* what) const {
  if (count != positions_.size())
    throw std::invalid_argument(std::string("DeformingBody: ") + what + " hold " + std::to_string(count) +
                                " entries, the mesh has " + std::to_string(positions_.size()) + " vertices");
}

void DeformingBody::anchor(const std::vector<Vec3>& positions) {
  checkSize(positions.size(), "anchor positions");
  for (size_t v = 0; v < positions.size(); ++v)
    if (!inCoordinateRange(positions[v]))
      throw std::invalid_argument("DeformingBody: anchor position " + std::to_string(v) +
                                  " is not finite or beyond 1e150 in magnitude");
  checkExtent(positions, positionsDiagonal(positions), "positions");
  anchor_positions_ = positions;
  positions_ = positions;
  anchor_nodes_ = hierarchy_->nodes();
  refitBounds(*hierarchy_, anchor_positions_.data(), anchor_nodes_, radii_);
  if (!radii_)  // no radius phase: every radius unbounded (valid, it prunes nothing)
    for (Node8& n : anchor_nodes_) std::fill(std::begin(n.eps), std::end(n.eps), std::numeric_limits<float>::infinity());
  inflated_nodes_ = anchor_nodes_;
  nodes_ = anchor_nodes_;
  refreshInlineFaces();
  std::fill(delta_.begin(), delta_.end(), 0.0);
  newRegionEpoch();
  geometry_.version = nextGeometryVersion();
  geometry_.lineage = geometry_.version;  // positions replaced: coherent state starts over
}

void DeformingBody::reanchor(const std::vector<Vec3>& positions) {
  checkSize(positions.size(), "anchor positions");
  const TriangleIndex* used = unused_vertices_ ? hierarchy_->vertexFace().data() : nullptr;
  double moved2 = 0;
  for (size_t v = 0; v < positions.size(); ++v)
    if (!used || used[v] != kInvalidIndex) moved2 = std::max(moved2, (positions[v] - positions_[v]).squaredNorm());
  const uint64_t lineage = geometry_.lineage;
  const double drift = geometry_.drift;
  anchor(positions);  // checks the positions; throws with the body unchanged
  geometry_.lineage = lineage;
  geometry_.drift = grownDrift(drift, std::sqrt(moved2));
}

bool DeformingBody::inflate(double delta) { return inflate(std::vector<double>(positions_.size(), delta)); }

bool DeformingBody::inflate(const std::vector<double>& delta) {
  checkSize(delta.size(), "the displacement bounds");
  // One pass: the bounds' validity (nothing changes if one is bad) and whether the current
  // positions stay within the new bounds.
  bool bad = false, outside = false;
  constexpr double kMax = std::numeric_limits<double>::max();
  for (size_t v = 0; v < delta.size(); ++v) {  // branch-free: the compiler vectorises it
    bad |= !(delta[v] >= 0 && delta[v] <= kMax);
    outside |= !withinBound((positions_[v] - anchor_positions_[v]).squaredNorm(), delta[v]);
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
  for (size_t node = 0; node < anchor_nodes_.size(); ++node) {
    const Node8& a = anchor_nodes_[node];
    Node8& out = inflated_nodes_[node];
    out = a;
    // Each box grown by its subtree's displacement, in scaled double coordinates, then packed
    // again (its margin follows the grown offsets; its slack, relative to the grown
    // coordinates, covers this arithmetic: one of each slot's two grown bounds is at least
    // `grow` in magnitude).
    SlotBoxes boxes = slotBoxes(a);
    for (int k = 0; k < 8; ++k) {
      if (a.child[k] == kEmptyChild) continue;
      const double worst = subtree_[8 * node + k];
      out.eps[k] = floatAtLeast((a.eps[k] + worst + corners_[8 * node + k]) * (1 + 1e-9));
      const double grow = worst * scale;
      for (int axis = 0; axis < 3; ++axis) {
        boxes.lower[axis][k] -= grow;
        boxes.upper[axis][k] += grow;
      }
    }
    packSlotBoxes(out, boxes);
  }
  delta_ = delta;
  nodes_ = inflated_nodes_;
  // Current positions outside the new bounds fall back to the anchor positions.
  if (outside) {
    positions_ = anchor_positions_;
    geometry_.lineage = nextGeometryVersion();  // positions replaced: coherent state starts over
  }
  refreshInlineFaces();
  newRegionEpoch();  // the regions' boxes grew
  geometry_.version = nextGeometryVersion();
  return outside;
}

DisplacementCheck DeformingBody::setPositions(const std::vector<Vec3>& positions) {
  checkSize(positions.size(), "positions");
  DisplacementCheck check;
  // A branch-free pass (the compiler vectorises it): positions not finite or beyond
  // kMaxCoordinate, vertices past their bound (withinBound), and how far the farthest vertex
  // moves (the lineage's drift grows by that).
  // NaN fails every comparison, so it is caught by `finite`.
  // The same pass takes the positions' box, for the extent check.
  // With drift by region it also keeps each vertex's squared motion (in double: a float
  // overflowed past motions of 1.8e19, and an infinite drift made a NaN of the certificate).
  bool finite = true, suspect = false;
  double moved2 = 0;
  Vec3 lower = Vec3::Constant(std::numeric_limits<double>::infinity()), upper = -lower;
  // (Skipped while the motion is uniform: growRegionDrift then grows every region by the largest.)
  const bool by_region = regionalDrift() && regions_.uniform_skips == 0;
  double* motion2 = by_region ? regions_.vertex_motion2.data() : nullptr;
  // A vertex no face uses moves nothing a query reads: its motion is no drift (found by an
  // audit: one such vertex jumping by 1e100 kept every certificate from holding).
  const TriangleIndex* used = unused_vertices_ ? hierarchy_->vertexFace().data() : nullptr;
  for (size_t v = 0; v < positions.size(); ++v) {
    const Vec3 d = positions[v] - anchor_positions_[v];
    const double d2 = d.squaredNorm();
    finite &= inCoordinateRange(positions[v]);
    suspect |= !withinBound(d2, delta_[v]);
    const double step2 = used && used[v] == kInvalidIndex ? 0.0 : (positions[v] - positions_[v]).squaredNorm();
    moved2 = std::max(moved2, step2);
    if (motion2) motion2[v] = step2;
    lower = lower.cwiseMin(positions[v]);
    upper = upper.cwiseMax(positions[v]);
  }
  if (!finite || suspect) {
    for (size_t v = 0; v < positions.size(); ++v) {
      if (!inCoordinateRange(positions[v]))
        throw std::invalid_argument("DeformingBody: position " + std::to_string(v) +
                                    " is not finite or beyond 1e150 in magnitude");
      const double d2 = (positions[v] - anchor_positions_[v]).squaredNorm();
      if (withinBound(d2, delta_[v])) continue;
      const double excess = std::sqrt(d2) - delta_[v];
      if (check.accepted || excess > check.excess) {
        check.accepted = false;
        check.excess = excess;
        check.worst_vertex = static_cast<VertexIndex>(v);
      }
    }
  }
  if (!check.accepted) return check;
  checkExtent(positions, stableLength(upper - lower), "positions");  // as positionsDiagonal()
  if (moved2 > 0) growRegionDrift(by_region, std::sqrt(moved2));
  positions_ = positions;
  refreshInlineFaces();
  geometry_.version = nextGeometryVersion();
  geometry_.drift = grownDrift(geometry_.drift, std::sqrt(moved2));
  return check;
}

}  // namespace meshsweeper
