#pragma once
// A freely deforming body with displacement-inflated bounds (paper section 5.3, second method;
// DESIGN.md section 3). The caller states how far each vertex may move from the anchor
// positions (where the bounds are exact); one bottom-up pass inflates every slot's box and
// radius accordingly. New positions are then accepted each step without touching the bounds,
// as long as every vertex stays within its bound; a step that breaks a bound is refused and
// reported, so the caller can inflate again or re-anchor. Never a silently wrong answer.
#include "core/hierarchy.h"

#include <memory>
#include <vector>

namespace meshsweeper {

// The outcome of DeformingBody::setPositions.
struct DisplacementCheck {
  bool accepted = true;                   // all vertices within their bounds
  VertexIndex worst_vertex = kInvalidIndex;  // the vertex farthest past its bound (if refused)
  double excess = 0;                      // how far past its bound it is
};

class DeformingBody {
 public:
  // Starts at the hierarchy's rest positions with exact bounds and zero displacement bounds.
  explicit DeformingBody(std::shared_ptr<const Hierarchy> hierarchy);
  // Not copyable or movable: geometry() points into the body's own tables (hold bodies by
  // pointer, as the distance service does).
  DeformingBody(const DeformingBody&) = delete;
  DeformingBody& operator=(const DeformingBody&) = delete;

  // Recomputes exact bounds at `positions` (as many as the mesh has, finite; else throws
  // std::invalid_argument) and makes them the anchor and the current positions; displacement
  // bounds reset to zero. Costs the build's radius phase.
  void anchor(const std::vector<Vec3>& positions);
  // The same for positions that continue the current ones (a step that broke a displacement
  // bound): the geometry's lineage is kept and its drift grows by how far the farthest vertex
  // moved, so coherent query state survives (TreeGeometry::lineage). anchor() starts a new
  // lineage (the positions may have jumped anywhere).
  void reanchor(const std::vector<Vec3>& positions);

  // Every vertex v may move up to delta[v] (>= 0, finite) from the anchor positions: inflates all
  // bounds in one bottom-up pass. If any current position lies outside the new bounds, every
  // position is reset to the anchor positions (and coherent state starts over): returns
  // whether that happened. Throws std::invalid_argument on a wrong size or a bad value.
  bool inflate(const std::vector<double>& delta);
  // Same bound for every vertex.
  bool inflate(double delta);

  // Accepts new positions if every vertex is within its bound of the anchor; otherwise keeps the
  // previous positions and reports the worst offender. Throws std::invalid_argument on a wrong
  // size or non-finite positions. "Within" allows a relative 1e-12 of the squared bound, which
  // the bounds' slack covers: positions computed at exactly their bound are not refused for
  // their rounding, and setPositions() and inflate() decide alike. A vertex of bound delta may
  // so lie up to delta * kBoundReach from its anchor.
  DisplacementCheck setPositions(const std::vector<Vec3>& positions);
  static constexpr double kBoundReach = 1 + 1e-12;  // > sqrt(1 + 1e-12), rounding included

  // Radii: whether anchor() computes every slot's swept-sphere radius (eps, the hierarchy
  // build's radius phase: most of an anchor's cost, 6 ms on a 52k-face body). Off, anchor()
  // sets them unbounded: box queries (closest, within, the coherent ones) are unchanged, and
  // the priority queries (closestWithin, kClosest, the dynamic front) stay exact without the
  // radii's pruning. For a body only box queries read, as the distance service's. On by
  // default; takes effect at the next anchor().
  void setRadii(bool on) { radii_ = on; }
  bool radii() const { return radii_; }

  // Inline faces: keep a copy of every leaf block's faces at the current positions, as the
  // rigid hierarchy has (Hierarchy::leafBlocks()), so a query tests a leaf without gathering
  // its corners, and refit the boxes to them (tighter than the inflated ones: fewer leaves
  // opened; the radii stay inflated). Costs a pass over the faces in each setPositions and
  // 72 bytes a face; pays off for a body that many points query each step (the service turns
  // it on by that measure). Off by default; turning it on fills the blocks at once.
  void setInlineFaces(bool on);
  bool inlineFaces() const { return geometry_.leaf_blocks != nullptr; }

  // Drift by region (TreeGeometry::regions): the faces are split into up to 256 regions of
  // nearby faces (grid cells over the mesh's own positions), and each setPositions also tracks how far the vertices
  // of each region's neighbourhood moved (within 1/16 and 1/4 of the anchor box's diagonal).
  // A coherent state near a part that stays still then keeps its certificate while another
  // part moves fast (a character's waving arm under a cloth resting on its torso), where the
  // lineage's drift alone would count the arm's motion everywhere. Costs a pass over the
  // regions' vertices in each setPositions that moves them (skipped for the 7 changes after
  // one that moved nine regions in ten by half the largest motion or more: a wave, where every
  // region then takes the largest), and an O(regions^2) pass in each anchor() and inflate().
  // On by default; off: the lineage's drift only.
  void setRegionalDrift(bool on);
  bool regionalDrift() const { return geometry_.regions != nullptr; }

  // What queries read (QueryStream::setGeometry); valid until the body is destroyed.
  const TreeGeometry& geometry() const { return geometry_; }
  const std::vector<Vec3>& positions() const { return positions_; }
  const std::vector<Vec3>& anchorPositions() const { return anchor_positions_; }
  const std::shared_ptr<const Hierarchy>& hierarchy() const { return hierarchy_; }

 private:
  void checkSize(size_t count, const char* what) const;
  void checkExtent(const std::vector<Vec3>& positions, double diagonal, const char* what) const;
  std::shared_ptr<const Hierarchy> hierarchy_;
  std::vector<Node8> anchor_nodes_;     // exact bounds at the anchor positions
  std::vector<Node8> inflated_nodes_;   // inflated bounds: hold for any positions within delta_
  std::vector<Node8> nodes_;            // what queries read: inflated_nodes_, or with inline
                                        // faces the same with boxes refitted to positions_
  std::vector<Vec3> anchor_positions_;  // [vertex]
  std::vector<Vec3> positions_;         // [vertex] current
  std::vector<double> delta_;           // [vertex] displacement bounds
  std::vector<double> subtree_, corners_;  // inflate()'s per-slot displacements (reused)
  LeafVertices leaf_vertices_;             // built by the first inflate()
  std::vector<TriangleBlock8> leaf_blocks_;  // [leaf] faces at positions_ (setInlineFaces)
  bool radii_ = true;                        // anchor() computes eps (setRadii)
  bool unused_vertices_ = false;             // some vertex no face uses (its motion is no drift)
  void refreshInlineFaces();
  // Drift by region (setRegionalDrift).
  void setupRegions();
  void newRegionEpoch();
  void growRegionDrift(bool by_region, double largest);
  // Drift by region's tables; empty while it is off (setRegionalDrift(false) resets them).
  struct RegionTables {
    std::vector<uint16_t> face_region;            // [face]
    std::vector<uint32_t> vertex_offsets;         // CSR: region r's distinct vertices
    std::vector<VertexIndex> vertices;
    std::vector<uint32_t> neighbour_offsets[2];   // CSR per level: the regions within width[k]
    std::vector<uint16_t> neighbours[2];
    std::vector<double> drift;                    // [2 * region + level]
    std::vector<double> motion2;                  // [region] scratch: squared motion of a change
    std::vector<double> box;                      // RegionDrift::box
    std::vector<double> vertex_motion2;           // [vertex] squared motion of the last change
    int uniform_skips = 0;                        // changes left that skip the per-region pass
    RegionDrift view;                             // what geometry_.regions points to
  };
  RegionTables regions_;
  TreeGeometry geometry_;
};

}  // namespace meshsweeper
