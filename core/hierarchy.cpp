// Invariant checks of the hierarchy (DESIGN.md section 1), used by the tests.
#include "core/hierarchy.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <sstream>

namespace meshsweeper {
namespace {

std::string describe(const char* what, size_t node, int slot) {
  std::ostringstream out;
  out << what << " (node " << node << ", slot " << slot << ")";
  return out.str();
}

}  // namespace

uint64_t nextGeometryVersion() {
  static std::atomic<uint64_t> counter{0};
  return ++counter;
}

void packSlotBoxes(Node8& n, const SlotBoxes& boxes, double magnitude) {
  bool used[8];
  int used_count = 0;
  double centres[3][8];
  for (int k = 0; k < 8; ++k) {
    used[k] = boxes.lower[0][k] <= boxes.upper[0][k];  // else empty (NaN: never a box)
    if (!used[k]) continue;
    bool finite = true;
    for (int axis = 0; axis < 3; ++axis) {
      centres[axis][used_count] = 0.5 * boxes.lower[axis][k] + 0.5 * boxes.upper[axis][k];
      finite = finite && std::isfinite(centres[axis][used_count]);
      magnitude = std::max({magnitude, std::abs(boxes.lower[axis][k]), std::abs(boxes.upper[axis][k])});
    }
    // An unbounded box (interpolated from a key frame past the float range) is no centre: the
    // origin stays finite, and such a node's slots become infinite (the slack below).
    used_count += finite;
  }
  // Any origin is valid. The median of the used slots' centres (per axis) sits among most of
  // them: a node that holds a far-away part in one slot keeps the others' offsets small.
  for (int axis = 0; axis < 3; ++axis) {
    double* c = centres[axis];
    std::nth_element(c, c + used_count / 2, c + used_count);
    n.origin[axis] = used_count > 0 ? c[used_count / 2] : 0.0;
  }
  // The boxes' own rounding, and the caller's: relative 2^-53 of the coordinates involved, 16
  // times over.
  const double slack = magnitude * 0x1p-49;
  // Offsets from the origin (double: relative error 2^-53, which floatBelow/Above's relative
  // 2^-23 covers). A query point q is rounded to float as fl(q - origin), off by at most
  // 2^-24 |q - origin| <= 2^-24 (gap to slot k's box + slot k's largest offset) per axis: the
  // gap's share is relative (the queries' box slack), the offset's is slot k's margin below,
  // 8 times over.
  constexpr float inf = std::numeric_limits<float>::infinity();
  for (int k = 0; k < 8; ++k) {
    double offset_lo[3], offset_hi[3], largest = 0;
    for (int axis = 0; axis < 3; ++axis) {
      offset_lo[axis] = boxes.lower[axis][k] - n.origin[axis];
      offset_hi[axis] = boxes.upper[axis][k] - n.origin[axis];
      largest = std::max({largest, std::abs(offset_lo[axis]), std::abs(offset_hi[axis])});
    }
    const double margin = largest * 0x1p-21 + slack;
    for (int axis = 0; axis < 3; ++axis) {
      n.lower[axis][k] = used[k] ? floatBelow(offset_lo[axis] - margin) : inf;
      n.upper[axis][k] = used[k] ? floatAbove(offset_hi[axis] + margin) : -inf;
    }
  }
}

void slotBox(const Node8& n, int k, double lower[3], double upper[3]) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  const bool used = n.lower[0][k] <= n.upper[0][k];
  for (int axis = 0; axis < 3; ++axis) {
    if (!used) {
      lower[axis] = inf;
      upper[axis] = -inf;
      continue;
    }
    // origin + offset, off by at most half an ulp in double: one ulp outward keeps the box
    // holding what the stored one holds.
    const double o = n.origin[axis];
    lower[axis] = std::nextafter(o + static_cast<double>(n.lower[axis][k]), -inf);
    upper[axis] = std::nextafter(o + static_cast<double>(n.upper[axis][k]), inf);
  }
}

SlotBoxes slotBoxes(const Node8& n) {
  SlotBoxes out;
  for (int k = 0; k < 8; ++k) {
    double lo[3], hi[3];
    slotBox(n, k, lo, hi);
    for (int axis = 0; axis < 3; ++axis) {
      out.lower[axis][k] = lo[axis];
      out.upper[axis][k] = hi[axis];
    }
  }
  return out;
}

namespace {

// Rewrites every used slot's box, children first (a child node always has a larger index than
// its parent): a leaf slot's from leaf_box(leaf, lo, hi) (scaled double coordinates, holding
// the leaf's faces), an inner slot's as the union of its child node's slots (kept in double,
// before packing); each node packed with packSlotBoxes.
template <class LeafBox>
void refitSlotBoxes(std::vector<Node8>& nodes, LeafBox&& leaf_box) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  std::vector<std::array<double, 6>> unions(nodes.size());  // [node] lower, upper
  for (size_t node = nodes.size(); node-- > 0;) {
    Node8& n = nodes[node];
    SlotBoxes boxes;
    std::array<double, 6>& all = unions[node];
    all = {inf, inf, inf, -inf, -inf, -inf};
    for (int k = 0; k < 8; ++k) {
      const ChildRef c = n.child[k];
      double lo[3] = {inf, inf, inf}, hi[3] = {-inf, -inf, -inf};
      if (isLeafRef(c)) {
        leaf_box(leafIndex(c), lo, hi);
      } else if (c != kEmptyChild) {
        std::copy_n(unions[c].begin(), 3, lo);
        std::copy_n(unions[c].begin() + 3, 3, hi);
      }
      for (int axis = 0; axis < 3; ++axis) {
        boxes.lower[axis][k] = lo[axis];
        boxes.upper[axis][k] = hi[axis];
        all[axis] = std::min(all[axis], lo[axis]);
        all[3 + axis] = std::max(all[3 + axis], hi[axis]);
      }
    }
    packSlotBoxes(n, boxes);
  }
}

}  // namespace

void refitBounds(const Hierarchy& h, const Vec3* positions, std::vector<Node8>& nodes, bool radii, bool boxes) {
  const Mesh& mesh = h.mesh();
  const Triangle* corners = h.leafCorners().data();
  const double scale = h.boxScale();
  const float inf = std::numeric_limits<float>::infinity();
  // Leaf slots from their faces' vertices (refitSlotBoxes does the inner slots); unused lanes
  // copy lane 0's corners, so all eight count.
  if (boxes) {
    refitSlotBoxes(nodes, [&](int32_t leaf, double lo[3], double hi[3]) {
      Vec3 low = Vec3::Constant(std::numeric_limits<double>::infinity()), high = -low;
      for (uint32_t lane = 0; lane < 8; ++lane) {
        for (VertexIndex v : corners[8 * static_cast<size_t>(leaf) + lane]) {
          low = low.cwiseMin(positions[v]);
          high = high.cwiseMax(positions[v]);
        }
      }
      const Vec3 scaled_low = (low - h.center()) * scale, scaled_high = (high - h.center()) * scale;
      for (int axis = 0; axis < 3; ++axis) {
        lo[axis] = scaled_low[axis];
        hi[axis] = scaled_high[axis];
      }
    });
  }
  if (!radii) return;
  // eps of a slot = the largest distance from its subtree's vertices to its triangle T, found
  // by branch and bound over the subtree's slots, farthest bound first: a slot whose box lies
  // within `worst` of T cannot raise the maximum and is skipped, so the result is the same
  // maximum as over every vertex. Each vertex is shared by about six faces: within one slot it
  // is evaluated once (a per-task stamp array marks the vertices already seen).
  const size_t vertex_count = mesh.positions.size();
  struct Scratch {
    std::vector<uint32_t> seen;  // [vertex] the clock value of the last slot that saw it
    uint32_t clock = 0;
    std::vector<std::pair<double, ChildRef>> pending;  // (bound, child) still to visit
  };
  tbb::enumerable_thread_specific<Scratch> per_thread;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, nodes.size(), 16), [&](const tbb::blocked_range<size_t>& range) {
    Scratch& scratch = per_thread.local();
    if (scratch.seen.size() != vertex_count) scratch.seen.assign(vertex_count, 0);
    std::vector<uint32_t>& stamp = scratch.seen;
    uint32_t& clock = scratch.clock;
    auto& pending = scratch.pending;
    for (size_t node = range.begin(); node < range.end(); ++node) {
      Node8& n = nodes[node];
      for (int k = 0; k < 8; ++k) {
        const ChildRef child = n.child[k];
        if (child == kEmptyChild) continue;
        const Vec3& a = positions[n.corner[0][k]];
        const Vec3& b = positions[n.corner[1][k]];
        const Vec3& c = positions[n.corner[2][k]];
        ++clock;
        double worst = 0;  // squared
        auto evaluateLeaf = [&](int32_t leaf) {
          for (uint32_t lane = 0; lane < h.leafLanes(leaf); ++lane) {
            for (VertexIndex v : corners[8 * static_cast<size_t>(leaf) + lane]) {
              if (stamp[v] == clock) continue;
              stamp[v] = clock;
              worst = std::max(worst, squaredDistanceToTriangle(positions[v], a, b, c));
            }
          }
        };
        if (isLeafRef(child)) {
          evaluateLeaf(leafIndex(child));
        } else {
          pending.clear();
          pending.emplace_back(std::numeric_limits<double>::infinity(), child);
          while (!pending.empty()) {
            const auto [bound, ref] = pending.back();
            pending.pop_back();
            if (!(bound > worst)) continue;
            if (isLeafRef(ref)) {
              evaluateLeaf(leafIndex(ref));
              continue;
            }
            // Bound each slot by a ball around its box: sqrt(d(centre, T)) + half diagonal
            // (the box, converted back from scaled coordinates, holds its vertices; the
            // rounding of the centre is added, and the 1e-6 slack covers the rest of this
            // bound's). Visit the farthest first (pushed last).
            const Node8& m = nodes[ref];
            const size_t first = pending.size();
            for (int j = 0; j < 8; ++j) {
              if (m.child[j] == kEmptyChild) continue;
              double slot_lo[3], slot_hi[3];
              slotBox(m, j, slot_lo, slot_hi);
              Vec3 lo, hi;
              for (int axis = 0; axis < 3; ++axis) {
                lo[axis] = slot_lo[axis] / scale;
                hi[axis] = slot_hi[axis] / scale;
              }
              const Vec3 centre = h.center() + 0.5 * (lo + hi);
              // Plus the rounding of the centre's coordinates (relative 2^-52 of their size).
              const double reach = std::sqrt(squaredDistanceToTriangle(centre, a, b, c)) + 0.5 * (hi - lo).norm() +
                                   centre.cwiseAbs().maxCoeff() * 0x1p-48;
              // An unbounded box (past the float range of the scaled units) gives no reach (NaN,
              // from its centre): its subtree is visited (found by an audit).
              const double squared_reach = reach * reach * (1 + 1e-6);
              if (!(squared_reach <= worst))
                pending.emplace_back(std::isnan(squared_reach) ? std::numeric_limits<double>::infinity() : squared_reach, m.child[j]);
            }
            std::sort(pending.begin() + static_cast<std::ptrdiff_t>(first), pending.end(),
                      [](const auto& x, const auto& y) { return x.first < y.first; });
          }
        }
        // Rounded up, with a relative margin for the rounding of the distance computation.
        const float eps = static_cast<float>(std::sqrt(worst) * (1 + 1e-9));
        n.eps[k] = std::nextafter(eps, inf);
      }
    }
  });
}

LeafVertices leafVertices(const Hierarchy& h) {
  const auto& lanes = h.leafTriangles();
  const Mesh& mesh = h.mesh();
  const size_t leaves = lanes.size() / 8;
  LeafVertices out;
  out.offsets.reserve(leaves + 1);
  out.offsets.push_back(0);
  for (size_t leaf = 0; leaf < leaves; ++leaf) {
    const size_t first = out.vertices.size();
    for (uint32_t lane = 0; lane < h.leafLanes(static_cast<int32_t>(leaf)); ++lane)
      for (VertexIndex v : mesh.triangles[lanes[8 * leaf + lane]])
        if (std::find(out.vertices.begin() + first, out.vertices.end(), v) == out.vertices.end())
          out.vertices.push_back(v);
    out.offsets.push_back(static_cast<uint32_t>(out.vertices.size()));
  }
  return out;
}

void slotDisplacements(const Hierarchy& h, const std::vector<double>& w, std::vector<double>& subtree,
                       std::vector<double>& corners, const LeafVertices* leaf_vertices) {
  const auto& nodes = h.nodes();
  const auto& lanes = h.leafTriangles();
  const Mesh& mesh = h.mesh();
  subtree.assign(8 * nodes.size(), 0.0);
  corners.assign(8 * nodes.size(), 0.0);
  for (size_t node = nodes.size(); node-- > 0;) {  // children have larger indices
    for (int k = 0; k < 8; ++k) {
      const ChildRef c = nodes[node].child[k];
      if (c == kEmptyChild) continue;
      double worst = 0;
      if (isLeafRef(c) && leaf_vertices) {
        const int32_t leaf = leafIndex(c);
        for (uint32_t i = leaf_vertices->offsets[leaf]; i < leaf_vertices->offsets[leaf + 1]; ++i)
          worst = std::max(worst, w[leaf_vertices->vertices[i]]);
      } else if (isLeafRef(c)) {
        for (uint32_t lane = 0; lane < h.leafLanes(leafIndex(c)); ++lane)
          for (VertexIndex v : mesh.triangles[lanes[8 * leafIndex(c) + lane]]) worst = std::max(worst, w[v]);
      } else {
        for (int j = 0; j < 8; ++j) worst = std::max(worst, subtree[8 * c + j]);
      }
      subtree[8 * node + k] = worst;
      double corner = 0;
      for (int i = 0; i < 3; ++i) corner = std::max(corner, w[nodes[node].corner[i][k]]);
      corners[8 * node + k] = corner;
    }
  }
}

TreeGeometry Hierarchy::restGeometry() const {
  TreeGeometry g;
  g.hierarchy = this;
  g.nodes = nodes_.data();
  g.leaf_blocks = leaf_blocks_.data();
  g.positions = mesh_.positions.data();
  g.center = center_;
  g.box_scale = box_scale_;
  g.version = rest_version_;
  g.lineage = rest_version_;
  return g;
}

void refreshLeafBlocks(const Hierarchy& h, const Vec3* positions, std::vector<TriangleBlock8>& blocks,
                       std::vector<Node8>& nodes) {
  const Triangle* corners = h.leafCorners().data();
  const double scale = h.boxScale();
  const Vec3& center = h.center();
  blocks.resize(h.leafCount());
  // Each block is assembled on the stack and its box taken there (not read back afterwards:
  // a large body's blocks do not stay in the caches).
  std::vector<std::array<double, 6>> leaf_boxes(h.leafCount());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, blocks.size(), 256), [&](const tbb::blocked_range<size_t>& range) {
    for (size_t leaf = range.begin(); leaf < range.end(); ++leaf) {
      TriangleBlock8 b;
      gatherLeafBlock(corners + 8 * leaf, positions, b);
      // Unused lanes copy a used one, so all 8 lanes of each corner count.
      for (int axis = 0; axis < 3; ++axis) {
        double low = b.v[0][axis][0], high = low;
        for (int corner = 0; corner < 3; ++corner)
          for (int lane = 0; lane < 8; ++lane) {
            low = std::min(low, b.v[corner][axis][lane]);
            high = std::max(high, b.v[corner][axis][lane]);
          }
        leaf_boxes[leaf][axis] = (low - center[axis]) * scale;
        leaf_boxes[leaf][3 + axis] = (high - center[axis]) * scale;
      }
      blocks[leaf] = b;
    }
  });
  refitSlotBoxes(nodes, [&](int32_t leaf, double lo[3], double hi[3]) {
    std::copy_n(leaf_boxes[leaf].begin(), 3, lo);
    std::copy_n(leaf_boxes[leaf].begin() + 3, 3, hi);
  });
}

std::string validate(const Hierarchy& h) {
  const Mesh& mesh = h.mesh();
  const auto& nodes = h.nodes();
  const auto& blocks = h.leafBlocks();
  const auto& lanes = h.leafTriangles();
  const size_t m = mesh.triangles.size();
  if (nodes.empty()) return "no root node";
  if (lanes.size() != 8 * blocks.size()) return "leaf triangle table has the wrong size";
  if (h.leafCorners().size() != 8 * blocks.size()) return "leaf corner table has the wrong size";

  // Every original face in exactly one used leaf lane, with its coordinates inline.
  std::vector<uint32_t> seen(m, 0);
  for (uint32_t leaf = 0; leaf < blocks.size(); ++leaf) {
    const uint32_t used = h.leafLanes(leaf);
    if (used < 1 || used > 8) return "leaf " + std::to_string(leaf) + " has no used lane";
    for (uint32_t lane = 0; lane < 8; ++lane) {
      const TriangleIndex f = lanes[8 * leaf + lane];
      if ((lane < used) != (f != kInvalidIndex))
        return "leaf " + std::to_string(leaf) + " lane " + std::to_string(lane) + " misplaced";
      const TriangleIndex corner_face = lane < used ? f : lanes[8 * leaf];
      if (corner_face < m && h.leafCorners()[8 * leaf + lane] != mesh.triangles[corner_face])
        return "leaf " + std::to_string(leaf) + " lane " + std::to_string(lane) + " holds the wrong corners";
      if (f == kInvalidIndex) continue;
      if (f >= m) return "leaf " + std::to_string(leaf) + " names a face out of range";
      ++seen[f];
      for (int k = 0; k < 3; ++k)
        for (int axis = 0; axis < 3; ++axis)
          if (blocks[leaf].v[k][axis][lane] != mesh.positions[mesh.triangles[f][k]][axis])
            return "leaf " + std::to_string(leaf) + " holds wrong coordinates for face " +
                   std::to_string(f);
    }
  }
  for (size_t f = 0; f < m; ++f)
    if (seen[f] != 1)
      return "face " + std::to_string(f) + " appears in " + std::to_string(seen[f]) + " leaf lanes";

  // Tree structure: every node but the root referenced once, by its recorded parent; every
  // leaf block referenced once; subtree leaf ranges contiguous.
  std::vector<uint32_t> node_refs(nodes.size(), 0), leaf_refs(blocks.size(), 0);
  for (size_t node = 0; node < nodes.size(); ++node) {
    for (int k = 0; k < 8; ++k) {
      const ChildRef c = nodes[node].child[k];
      if (c == kEmptyChild) continue;
      if (isLeafRef(c)) {
        if (static_cast<size_t>(leafIndex(c)) >= blocks.size()) return describe("leaf out of range", node, k);
        ++leaf_refs[leafIndex(c)];
        continue;
      }
      if (static_cast<size_t>(c) >= nodes.size() || c == 0) return describe("child out of range", node, k);
      ++node_refs[c];
      if (h.parentNode(c) != static_cast<int32_t>(node)) return describe("parent link broken", node, k);
      if (h.leafBegin(c) < h.leafBegin(static_cast<int32_t>(node)) ||
          h.leafEnd(c) > h.leafEnd(static_cast<int32_t>(node)))
        return describe("child leaf range outside its parent's", node, k);
    }
  }
  for (size_t node = 1; node < nodes.size(); ++node)
    if (node_refs[node] != 1) return "node " + std::to_string(node) + " is not referenced once";
  for (size_t leaf = 0; leaf < blocks.size(); ++leaf)
    if (leaf_refs[leaf] != 1) return "leaf " + std::to_string(leaf) + " is not referenced once";
  if (h.leafBegin(0) != 0 || h.leafEnd(0) != blocks.size()) return "root does not span all leaves";

  return validateGeometry(h, h.restGeometry());
}

std::string validateGeometry(const Hierarchy& h, const TreeGeometry& g) {
  const Mesh& mesh = h.mesh();
  const auto& lanes = h.leafTriangles();
  const Node8* nodes = g.nodes;
  const Vec3* positions = g.positions;
  // Bounds: every slot's box holds its subtree's vertices, and eps bounds their distance to
  // the slot's triangle.
  for (size_t node = 0; node < h.nodes().size(); ++node) {
    const Node8& n = nodes[node];
    for (int k = 0; k < 8; ++k) {
      const ChildRef c = n.child[k];
      if (c == kEmptyChild) continue;
      uint32_t first = 0, last = 0;
      if (isLeafRef(c)) { first = leafIndex(c); last = first + 1; }
      else { first = h.leafBegin(c); last = h.leafEnd(c); }
      for (int corner = 0; corner < 3; ++corner)
        if (n.corner[corner][k] >= mesh.positions.size()) return describe("corner out of range", node, k);
      const Vec3& a = positions[n.corner[0][k]];
      const Vec3& b = positions[n.corner[1][k]];
      const Vec3& cc = positions[n.corner[2][k]];
      for (uint32_t leaf = first; leaf < last; ++leaf) {
        for (uint32_t lane = 0; lane < h.leafLanes(leaf); ++lane) {
          for (VertexIndex v : mesh.triangles[lanes[8 * leaf + lane]]) {
            const Vec3& x = positions[v];
            // Relative to the node's origin in long double: exact for any offset the float
            // boxes can tell apart.
            const Vec3 scaled = (x - g.center) * g.box_scale;
            for (int axis = 0; axis < 3; ++axis) {
              const long double offset = static_cast<long double>(scaled[axis]) - n.origin[axis];
              if (!(n.lower[axis][k] <= offset && offset <= n.upper[axis][k]))
                return describe("box misses a subtree vertex", node, k);
            }
            const double d = std::sqrt(squaredDistanceToTriangle(x, a, b, cc));
            if (!(d <= n.eps[k])) return describe("eps below a subtree vertex's distance", node, k);
          }
        }
      }
    }
  }
  // Inline faces, when the geometry has them: each used lane holds its face at the positions.
  if (g.leaf_blocks) {
    for (uint32_t leaf = 0; leaf < h.leafCount(); ++leaf)
      for (uint32_t lane = 0; lane < 8; ++lane) {
        const TriangleIndex f = lanes[8 * leaf + (lane < h.leafLanes(leaf) ? lane : 0)];
        for (int k = 0; k < 3; ++k)
          for (int axis = 0; axis < 3; ++axis)
            if (!(g.leaf_blocks[leaf].v[k][axis][lane] == positions[mesh.triangles[f][k]][axis]))
              return "leaf " + std::to_string(leaf) + " lane " + std::to_string(lane) +
                     " holds stale coordinates for face " + std::to_string(f);
      }
  }
  return {};
}

namespace {

double regionDistance2(const RegionDrift& regions, uint32_t region, const Vec3& p) {
  const uint32_t count = regions.count;
  const double* box = regions.box;
  double d2 = 0;
  for (int axis = 0; axis < 3; ++axis) {
    const double below = box[axis * count + region] - p[axis];
    const double above = p[axis] - box[(3 + axis) * count + region];
    const double gap = std::max({below, above, 0.0});
    d2 += gap * gap;
  }
  return d2;
}

double roundedUpRoot(double d2) {
  return std::nextafter(std::sqrt(d2) * (1 + 1e-12), std::numeric_limits<double>::infinity());
}

}  // namespace

uint32_t nearestRegion(const RegionDrift& regions, const Vec3& p, double& distance) {
  double best2 = std::numeric_limits<double>::infinity();
  uint32_t best = 0;
  for (uint32_t r = 0; r < regions.count; ++r) {
    const double d2 = regionDistance2(regions, r, p);
    if (d2 < best2) {
      best2 = d2;
      best = r;
    }
  }
  distance = roundedUpRoot(best2);
  return best;
}

double regionDistance(const RegionDrift& regions, uint32_t region, const Vec3& p) {
  return roundedUpRoot(regionDistance2(regions, region, p));
}

}  // namespace meshsweeper
