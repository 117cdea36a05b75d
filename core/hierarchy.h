#pragma once
// The Meshsweeper hierarchy: fixed, shareable tables built once per mesh (DESIGN.md section 1).
//
// Simplification by vertex contractions (v -> u, u keeps its position) gives a cover tree of
// triangle nodes: every original face is a leaf, every triangle a contraction creates is a node
// responsible for the original faces of its subtree. The query tree stored here is that cover
// tree collapsed to 8-wide nodes. Each child slot of a node carries two bounds of its subtree:
//  - a box of the subtree's original vertices (float, rounded outward): fresh exact queries;
//  - the node's own triangle (three original vertices, which lie on the surface) and its radius
//    eps = max over the subtree's original vertices of their distance to that triangle: the
//    paper's triangle swept by a sphere, used for [d - eps, d + eps] intervals.
// Leaves are blocks of up to 8 original faces stored inline (double, SoA) in tree order;
// small leaf slots of one node are packed together so blocks are well filled.
//
// Immutable after build; share it as std::shared_ptr<const Hierarchy> between threads.
#include "core/mesh.h"
#include "core/triangle_distance.h"

#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace meshsweeper {

// A child reference in a node: >= 0 an inner node index, < 0 a leaf block ~index (leafRef()).
using ChildRef = int32_t;
inline constexpr ChildRef kEmptyChild = INT32_MIN;  // unused slot; its box is empty
inline bool isLeafRef(ChildRef c) { return c < 0 && c != kEmptyChild; }
inline int32_t leafIndex(ChildRef c) { return ~c; }
inline ChildRef leafRef(int32_t leaf) { return ~leaf; }

// Eight children of one node, structure of arrays (384 bytes with padding; 32-byte aligned for
// AVX loads).
// The boxes are stored in float relative to the node's own origin (scaled units, see
// Hierarchy::boxScale()): a query point is rounded to float relative to that origin, so the
// rounding, and the margin that covers it, scale with the node's size and not with the mesh's
// extent (a small part far from the others keeps tight boxes). Write them with
// packSlotBoxes(), read them back with slotBox().
struct alignas(32) Node8 {
  float lower[3][8];            // [axis][slot] subtree box - origin, rounded down
  float upper[3][8];            // [axis][slot] subtree box - origin, rounded up (empty slot: +inf, -inf)
  ChildRef child[8];            // [slot]
  float eps[8];                 // [slot] swept-sphere radius of the slot's triangle, rounded up
  VertexIndex corner[3][8];     // [corner][slot] the slot's triangle (original vertex indices)
  double origin[3];             // [axis] the boxes' origin (scaled units)
};

// A node's slot boxes in scaled double coordinates, before packing (empty slot: lower +inf,
// upper -inf).
struct SlotBoxes {
  double lower[3][8];
  double upper[3][8];
};
inline SlotBoxes emptySlotBoxes() {
  SlotBoxes out;
  for (int axis = 0; axis < 3; ++axis)
    for (int k = 0; k < 8; ++k) {
      out.lower[axis][k] = std::numeric_limits<double>::infinity();
      out.upper[axis][k] = -std::numeric_limits<double>::infinity();
    }
  return out;
}

// Stores `boxes` in n relative to a new origin (the median of their centres), rounded outward
// and widened by a margin that covers (a) the rounding of a query point to float relative to
// that origin, up to a relative error the queries' box slack covers, and (b) the rounding of
// the boxes' double coordinates: relative 2^-53 of the largest of them, or of `magnitude` when
// the caller computed them from larger ones (scaled units).
void packSlotBoxes(Node8& n, const SlotBoxes& boxes, double magnitude = 0);
// Slot k's box in scaled double coordinates, rounded outward (it holds what the stored box
// holds); an empty slot gives lower +inf, upper -inf.
void slotBox(const Node8& n, int k, double lower[3], double upper[3]);
// All of a node's slot boxes (slotBox for each slot).
SlotBoxes slotBoxes(const Node8& n);

// Drift by region: the faces are split into regions (nearby faces) whose boxes hold their faces
// for the whole epoch. Region r's running drift at level k, drift[2 * r + k], grows at each change
// by how far the farthest vertex of any region whose box lies within width[k] of r's box moved.
// Between two changes of one epoch, a face within width[k] of a face of region r moved at most
// the difference of that drift value (rounded up, as grownDrift); a face farther away, at most
// the difference of the lineage's drift. A new epoch (new regions' boxes) restarts the values.
struct RegionDrift {
  uint64_t epoch = 0;                     // a nextGeometryVersion() value; 0: none
  const uint16_t* face_region = nullptr;  // [face] its region
  uint32_t count = 0;                     // regions
  double width[2] = {0, 0};               // neighbourhood widths, width[0] <= width[1]
  const double* drift = nullptr;          // [2 * region + level]
  const double* box = nullptr;            // [axis * count + region] lower, [(3 + axis) * count
                                          // + region] upper: the regions' boxes this epoch
};

// The region whose box (RegionDrift::box) is nearest to p, and that distance (rounded up).
uint32_t nearestRegion(const RegionDrift& regions, const Vec3& p, double& distance);
// The distance from p to a region's box (rounded up).
double regionDistance(const RegionDrift& regions, uint32_t region, const Vec3& p);

// The geometry a query reads, over a Hierarchy's fixed topology (children, leaf lanes). The
// Hierarchy provides its rest geometry; deform/ bodies provide per-frame geometry (moved
// positions, refreshed or inflated bounds) with the same node and leaf layout.
class Hierarchy;
struct TreeGeometry {
  const Node8* nodes = nullptr;                // [node] boxes, eps, children, slot triangles
  const TriangleBlock8* leaf_blocks = nullptr;  // [leaf] inline faces; null: gather from positions
  const Vec3* positions = nullptr;             // [vertex]
  Vec3 center = Vec3::Zero();                  // boxes hold (x - center) * box_scale in float
  double box_scale = 1;
  uint64_t version = 0;                        // unique in the process: a new value from
                                               // nextGeometryVersion() whenever it changes
  // Geometries of one lineage share the hierarchy (a body deforming step by step): between
  // two of them every vertex moved by at most the difference of their drift values (a running
  // sum of per-change bounds), so coherent state can follow the faces. A new lineage (a
  // nextGeometryVersion() value) whenever that bound is not kept.
  uint64_t lineage = 0;
  double drift = 0;
  // Optional (deforming bodies, DeformingBody): drift by region, for motion that is local.
  const RegionDrift* regions = nullptr;
  // The hierarchy whose layout it has (QueryStream::setGeometry checks it).
  const Hierarchy* hierarchy = nullptr;
};


// A lineage's drift after a change that moved no vertex farther than `motion`: rounded up, so
// that the difference of two drift values never falls short of the motion between them, even
// when the motion is below the drift's rounding (a long-lived lineage).
inline double grownDrift(double drift, double motion) {
  if (!(motion > 0)) return drift;
  return std::nextafter(drift + motion * (1 + 1e-12), std::numeric_limits<double>::infinity());
}

// A process-wide unique, never-zero geometry version (thread-safe). Every geometry, and every
// change of one, takes a new value, so coherent state never mistakes one geometry for another.
uint64_t nextGeometryVersion();

struct BuildOptions {
  // Stop contracting when this many triangles remain (the base mesh; its triangles are roots).
  uint32_t base_triangles = 16;
};

// What the build did and what it costs; filled by build().
struct HierarchyStats {
  double contract_seconds = 0;  // simplification rounds
  double tree_seconds = 0;      // cover tree -> 8-wide node tree, leaf blocks
  double bounds_seconds = 0;    // boxes and radii
  double total_seconds = 0;
  uint32_t rounds = 0;          // contraction rounds
  uint32_t contractions = 0;
  uint32_t base_triangles = 0;  // triangles left in the base mesh (roots of the cover tree)
  uint32_t depth = 0;           // levels of 8-wide nodes
  // Triangles the contraction checks visited to find the adopters of deleted triangles: a
  // small multiple of the triangles times the rounds (a vertex of high degree once made it
  // quadratic).
  uint64_t adopter_visits = 0;
  size_t fixed_bytes = 0;       // memory of the fixed tables (nodes, leaves, mesh copy)
};

class Hierarchy {
 public:
  // Builds the hierarchy of a mesh. Throws MeshError if checkMesh() fails (empty mesh,
  // non-finite coordinates, out-of-range indices). The mesh is copied.
  static std::shared_ptr<const Hierarchy> build(const Mesh& mesh, const BuildOptions& options = {});

  const Mesh& mesh() const { return mesh_; }
  // The rest geometry: the mesh as given, boxes and radii as built.
  TreeGeometry restGeometry() const;
  const HierarchyStats& stats() const { return stats_; }

  // The query tree. nodes()[0] is the root node; a mesh of at most 8 faces has a root with one
  // leaf child.
  const std::vector<Node8>& nodes() const { return nodes_; }
  // [leaf] up to eight original faces inline (double, SoA); unused lanes copy lane 0.
  const std::vector<TriangleBlock8>& leafBlocks() const { return leaf_blocks_; }
  // [8 * leaf + lane] original face index of a leaf lane, kInvalidIndex when unused.
  const std::vector<TriangleIndex>& leafTriangles() const { return leaf_triangles_; }
  // [8 * leaf + lane] the corners (original vertex indices) of that lane's face, in leaf order,
  // so that refreshing moved faces reads one table front to back; unused lanes copy lane 0.
  const std::vector<Triangle>& leafCorners() const { return leaf_corners_; }
  uint32_t leafCount() const { return static_cast<uint32_t>(leaf_blocks_.size()); }
  // Used lanes of a leaf block (1..8); used lanes come first.
  uint32_t leafLanes(int32_t leaf) const { return leaf_lanes_[leaf]; }
  const std::vector<uint8_t>& leafLaneCounts() const { return leaf_lanes_; }

  // Node boxes are stored in float as (x - center()) * boxScale() - (the node's origin),
  // boxScale() a power of two that maps the mesh into [-1, 1]; they are rounded outward and
  // widened by a margin (packSlotBoxes()) so that float rounding of a query point never makes
  // a box bound exceed the true distance.
  const Vec3& center() const { return center_; }
  double boxScale() const { return box_scale_; }
  // [vertex] some face that uses the vertex (kInvalidIndex for unused vertices).
  const std::vector<TriangleIndex>& vertexFace() const { return vertex_face_; }

  // Contraction record: [vertex] the vertex it was contracted into (kInvalidIndex for base
  // vertices and vertices no triangle uses). The contraction radii (r_u <- max(r_u, r_v + |u-v|))
  // order the contractions during the build; queries use the tighter per-node eps instead.
  const std::vector<VertexIndex>& contractedInto() const { return contracted_into_; }

  // For an inner node: the range of leaf blocks of its subtree ([first, last) in leafBlocks()).
  // Leaves are laid out depth-first, so every subtree is a contiguous range.
  uint32_t leafBegin(int32_t node) const { return leaf_begin_[node]; }
  uint32_t leafEnd(int32_t node) const { return leaf_end_[node]; }
  // [node] parent node index (-1 for the root) and the slot it occupies there.
  int32_t parentNode(int32_t node) const { return parent_[node]; }

 private:
  friend class HierarchyBuilder;
  Mesh mesh_;
  HierarchyStats stats_;
  std::vector<Node8> nodes_;
  std::vector<TriangleBlock8> leaf_blocks_;
  std::vector<TriangleIndex> leaf_triangles_;
  std::vector<Triangle> leaf_corners_;
  std::vector<uint8_t> leaf_lanes_;
  std::vector<TriangleIndex> vertex_face_;
  Vec3 center_ = Vec3::Zero();
  double box_scale_ = 1;
  std::vector<uint32_t> leaf_begin_, leaf_end_;  // [node]
  std::vector<int32_t> parent_;                  // [node]
  std::vector<VertexIndex> contracted_into_;     // [vertex]
  uint64_t rest_version_ = nextGeometryVersion();
};

// Recomputes slot bounds over the hierarchy's topology for other vertex positions (a moved or
// deformed copy of the mesh): `nodes` must be a copy of h.nodes(); every slot's box (scaled
// with h.center() and h.boxScale(), rounded outward with a margin) unless `boxes` is false, and
// if `radii` its eps (max distance of its subtree's vertices to its triangle, at these
// positions) are rewritten.
// positions: [vertex], as many as the mesh has. Boxes: one bottom-up pass; radii: exact, the
// cost of the build's radius phase (a branch and bound that skips subtrees whose box lies within
// the radius found so far: with `boxes` false, the boxes in `nodes` must already hold the
// subtrees' vertices at these positions).
void refitBounds(const Hierarchy& h, const Vec3* positions, std::vector<Node8>& nodes, bool radii,
                 bool boxes = true);

// The distinct vertices of each leaf block's faces, CSR: leaf l's are
// vertices[offsets[l] .. offsets[l + 1]). For slotDisplacements when it runs often.
struct LeafVertices {
  std::vector<uint32_t> offsets;
  std::vector<VertexIndex> vertices;
};
LeafVertices leafVertices(const Hierarchy& h);

// Moving geometry with inline faces: fills `blocks` (resized to h.leafCount()) with each leaf
// block's faces at `positions` (one per mesh vertex), laid out as Hierarchy::leafBlocks(), and
// rewrites every slot's box in `nodes` (a copy over h's layout) as the box of its subtree's
// faces there (packSlotBoxes()). eps and the rest of each node are kept. The leaves in
// parallel (TBB, in the caller's task arena), then one bottom-up pass.
void refreshLeafBlocks(const Hierarchy& h, const Vec3* positions, std::vector<TriangleBlock8>& blocks,
                       std::vector<Node8>& nodes);

// How far each slot's bounds can be pushed when every vertex v moves at most w[v] (w >= 0,
// one per mesh vertex; DESIGN.md section 3), per slot [8 * node + slot]: `subtree` = the largest
// w among the slot's subtree vertices (its box grows by that), `corners` = the largest w among
// its triangle's corners (its radius grows by subtree + corners). Empty slots get 0. One
// bottom-up pass; `leaf_vertices` (optional, from leafVertices(h)) makes it read each leaf's
// vertices once.
void slotDisplacements(const Hierarchy& h, const std::vector<double>& w, std::vector<double>& subtree,
                       std::vector<double>& corners, const LeafVertices* leaf_vertices = nullptr);

// Checks that the bounds of `geometry` (over h's layout) hold for its positions: every slot's
// box contains its subtree's vertices and every eps bounds their distance to the slot's
// triangle; inline leaf blocks (if any) hold the faces at the positions. Returns an empty string
// when valid, else the first violation.
std::string validateGeometry(const Hierarchy& h, const TreeGeometry& geometry);

// Checks the hierarchy's invariants: every original face appears in exactly one leaf lane;
// every slot's box contains its subtree's vertices; every slot's eps bounds the distance from
// its subtree's vertices to its triangle; parent links and leaf ranges are consistent.
// Returns an empty string when valid, else a description of the first violation.
std::string validate(const Hierarchy& hierarchy);

}  // namespace meshsweeper
