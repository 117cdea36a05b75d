// Building the Meshsweeper hierarchy (Guéziec, "Meshsweeper", section 4.1; DESIGN.md section 1).
//
//   contract (rounds):
//     repeat until the base mesh is small or nothing can be contracted:
//       for every live vertex v: candidate v -> u, u its nearest legal neighbour (cost r_v + |u - v|),
//         or, when no edge contraction is legal, its nearest vertex in Morton order (no shared edge)
//       sort the candidates by cost; apply each whose vertices are still free this round,
//         (v must not have been a target this round, u must not have been contracted; legality
//         is checked on the current mesh when applying)
//       applying v -> u: r_u <- max(r_u, r_v + |u - v|); triangles of v's star become (u, a, b);
//         a triangle holding u and v is deleted and adopted by a survivor holding its edge (u, a)
//   cover tree: every original face is a leaf; a deleted triangle's node becomes a child of the
//     triangle that adopts it (a new node with that triangle's current corners, unless the adopter
//     already opened one since its corners last changed). Survivors are the roots; a median-split
//     tree over the roots makes one top.
//   collapse: each cover-tree node with more than 8 faces becomes an 8-wide node whose slots are
//     its children, the largest expanded into theirs while they fit; children of at most 8 faces
//     become leaf slots, packed first-fit into blocks of 8 faces (laid out depth-first).
//   bounds: per slot, the float box of its subtree's vertices (rounded outward) and
//     eps = max over its subtree's vertices of their distance to the slot's triangle.
#include "core/hierarchy.h"
#include "core/morton.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <cstring>
#include <numeric>

namespace meshsweeper {
namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

constexpr uint32_t kNone = kInvalidIndex;
constexpr uint32_t kLeafFaces = 8;
constexpr uint32_t kSpatialFaces = 512;  // subtrees this small are split spatially into leaf blocks

struct Box {
  Vec3 lower = Vec3::Constant(std::numeric_limits<double>::infinity());
  Vec3 upper = Vec3::Constant(-std::numeric_limits<double>::infinity());
  void add(const Vec3& p) { lower = lower.cwiseMin(p); upper = upper.cwiseMax(p); }
  void add(const Box& b) { lower = lower.cwiseMin(b.lower); upper = upper.cwiseMax(b.upper); }
  double area() const {
    const Vec3 e = (upper - lower).cwiseMax(0.0);
    return e.x() * e.y() + e.y() * e.z() + e.z() * e.x();
  }
  Vec3 center() const { return 0.5 * (lower + upper); }
};

// The cover tree produced by contraction: raw nodes [0, faces) are the original faces, later ones
// are triangles created by contractions (or synthetic nodes over the roots).
struct CoverTree {
  std::vector<int32_t> parent;     // [raw node] -1 for a root
  std::vector<Triangle> corners;   // [raw node] the node's triangle (original vertex indices)
  std::vector<int32_t> roots;
};

// Phase 1: contraction rounds over a corner-list representation of the current mesh.
class Contractor {
 public:
  Contractor(const Mesh& mesh, uint32_t base_triangles)
      : mesh_(mesh), base_triangles_(std::max<uint32_t>(base_triangles, 1)) {}

  void run(CoverTree& tree, std::vector<VertexIndex>& contracted_into, HierarchyStats& stats);

 private:
  struct Candidate {
    double cost;
    VertexIndex v, u;
  };
  struct Deletion {
    uint32_t slot;
    uint32_t adopter;
  };

  bool holds(uint32_t slot, VertexIndex x) const {
    const VertexIndex* t = &tri_[3 * slot];
    return t[0] == x || t[1] == x || t[2] == x;
  }
  // The corner of `slot` that is neither v nor u; u when there is none (degenerate triangle).
  VertexIndex thirdVertex(uint32_t slot, VertexIndex v, VertexIndex u) const {
    for (int k = 0; k < 3; ++k) {
      const VertexIndex x = tri_[3 * slot + k];
      if (x != v && x != u) return x;
    }
    return u;
  }
  // Calls f(corner) for each live corner of v, unlinking corners of deleted triangles.
  template <class F>
  void forEachCorner(VertexIndex v, F&& f) {
    uint32_t prev = kNone;
    for (uint32_t c = head_[v]; c != kNone;) {
      const uint32_t following = next_[c];
      if (!alive_[c / 3]) {
        if (prev == kNone) head_[v] = following; else next_[prev] = following;
      } else {
        f(c);
        prev = c;
      }
      c = following;
    }
  }
  bool findDeletions(VertexIndex v, VertexIndex u, std::vector<Deletion>& deletions);
  uint32_t findSurvivor(VertexIndex v, VertexIndex u, VertexIndex a);
  void apply(VertexIndex v, VertexIndex u, const std::vector<Deletion>& deletions);
  void adopt(uint32_t adopter, uint32_t deleted);
  int32_t newNode(uint32_t slot) {
    tree_->parent.push_back(-1);
    tree_->corners.push_back({tri_[3 * slot], tri_[3 * slot + 1], tri_[3 * slot + 2]});
    return static_cast<int32_t>(tree_->parent.size() - 1);
  }

  const Mesh& mesh_;
  uint32_t base_triangles_;
  CoverTree* tree_ = nullptr;
  std::vector<VertexIndex> tri_;    // [3 * slot + k] current corners of each triangle slot
  std::vector<uint8_t> alive_;      // [slot]
  std::vector<uint32_t> head_;      // [vertex] first corner of the vertex's corner list
  std::vector<uint32_t> next_;      // [corner] next corner of the same vertex
  std::vector<double> radius_;      // [vertex] contraction radius r
  std::vector<int32_t> holder_;     // [slot] cover-tree node carrying the slot's faces
  std::vector<uint8_t> open_;       // [slot] holder_ was created since the corners last changed
  std::vector<VertexIndex> neighbours_;                 // sorted by index
  std::vector<std::pair<double, VertexIndex>> ranked_;  // (squared distance, neighbour)
  std::vector<Deletion> deletions_;
  size_t live_triangles_ = 0;
};

// Lists the triangles v -> u deletes (those holding both) with their adopters. Returns false
// when some deleted triangle (v, u, a) would leave edge (u, a) in no surviving triangle.
bool Contractor::findDeletions(VertexIndex v, VertexIndex u, std::vector<Deletion>& deletions) {
  deletions.clear();
  forEachCorner(v, [&](uint32_t c) {
    const uint32_t slot = c / 3;
    if (!holds(slot, u)) return;
    for (const Deletion& d : deletions) if (d.slot == slot) return;
    deletions.push_back({slot, kNone});
  });
  for (Deletion& d : deletions) {
    d.adopter = findSurvivor(v, u, thirdVertex(d.slot, v, u));
    if (d.adopter == kNone) return false;
  }
  return true;
}

// A triangle that survives v -> u and holds a (after the contraction: holds u and a).
uint32_t Contractor::findSurvivor(VertexIndex v, VertexIndex u, VertexIndex a) {
  uint32_t found = kNone;
  auto check = [&](VertexIndex other) {
    return [&, other](uint32_t c) {
      const uint32_t slot = c / 3;
      if (found == kNone && !holds(slot, other) && holds(slot, a)) found = slot;
    };
  };
  forEachCorner(u, check(v));
  if (found == kNone) forEachCorner(v, check(u));
  return found;
}

void Contractor::adopt(uint32_t adopter, uint32_t deleted) {
  const int32_t child = holder_[deleted];
  if (open_[adopter]) {
    tree_->parent[child] = holder_[adopter];
    return;
  }
  const int32_t node = newNode(adopter);
  tree_->parent[holder_[adopter]] = node;
  tree_->parent[child] = node;
  holder_[adopter] = node;
  open_[adopter] = 1;
}

void Contractor::apply(VertexIndex v, VertexIndex u, const std::vector<Deletion>& deletions) {
  for (const Deletion& d : deletions) {
    alive_[d.slot] = 0;
    --live_triangles_;
  }
  uint32_t tail = kNone;
  forEachCorner(v, [&](uint32_t c) {
    tri_[c] = u;
    open_[c / 3] = 0;
    tail = c;
  });
  if (tail != kNone) {
    next_[tail] = head_[u];
    head_[u] = head_[v];
  }
  head_[v] = kNone;
  for (const Deletion& d : deletions) adopt(d.adopter, d.slot);
  radius_[u] = std::max(radius_[u], radius_[v] + (mesh_.positions[u] - mesh_.positions[v]).norm());
}

void Contractor::run(CoverTree& tree, std::vector<VertexIndex>& contracted_into,
                     HierarchyStats& stats) {
  tree_ = &tree;
  const size_t n = mesh_.positions.size();
  const size_t m = mesh_.triangles.size();
  tri_.resize(3 * m);
  alive_.assign(m, 1);
  head_.assign(n, kNone);
  next_.assign(3 * m, kNone);
  radius_.assign(n, 0.0);
  holder_.resize(m);
  open_.assign(m, 0);
  tree.parent.assign(m, -1);
  tree.corners.assign(mesh_.triangles.begin(), mesh_.triangles.end());
  contracted_into.assign(n, kNone);
  live_triangles_ = m;
  for (size_t t = m; t-- > 0;) {
    holder_[t] = static_cast<int32_t>(t);
    for (int k = 0; k < 3; ++k) {
      const uint32_t c = static_cast<uint32_t>(3 * t + k);
      tri_[c] = mesh_.triangles[t][k];
      next_[c] = head_[tri_[c]];
      head_[tri_[c]] = c;
    }
  }

  // Vertices used by some triangle, in Morton order (for contractions across gaps).
  Box bounds;
  std::vector<VertexIndex> active;
  for (size_t v = 0; v < n; ++v) {
    if (head_[v] != kNone) {
      active.push_back(static_cast<VertexIndex>(v));
      bounds.add(mesh_.positions[v]);
    }
  }
  {
    const Vec3 extent = (bounds.upper - bounds.lower).cwiseMax(1e-300);
    std::vector<uint64_t> code(n, 0);
    for (VertexIndex v : active) {
      code[v] = mortonCode(mesh_.positions[v], bounds.lower, extent);
    }
    std::sort(active.begin(), active.end(), [&](VertexIndex a, VertexIndex b) {
      return code[a] != code[b] ? code[a] < code[b] : a < b;
    });
  }

  std::vector<Candidate> candidates;
  std::vector<uint64_t> order;
  std::vector<uint8_t> locked(n, 0);  // [vertex] contracted or grown this round: not a source
  const uint32_t kMaxRounds = 10000;
  while (live_triangles_ > base_triangles_ && stats.rounds < kMaxRounds) {
    ++stats.rounds;
    // Drop vertices that no live triangle uses any more (keeps Morton order).
    size_t kept = 0;
    for (VertexIndex v : active) {
      bool used = false;
      forEachCorner(v, [&](uint32_t) { used = true; });
      if (used) active[kept++] = v;
    }
    active.resize(kept);
    if (active.size() < 2) break;

    candidates.clear();
    for (size_t i = 0; i < active.size(); ++i) {
      const VertexIndex v = active[i];
      const Vec3& pv = mesh_.positions[v];
      neighbours_.clear();
      forEachCorner(v, [&](uint32_t c) {
        for (int k = 0; k < 3; ++k) {
          const VertexIndex x = tri_[3 * (c / 3) + k];
          if (x != v) neighbours_.push_back(x);
        }
      });
      std::sort(neighbours_.begin(), neighbours_.end());
      neighbours_.erase(std::unique(neighbours_.begin(), neighbours_.end()), neighbours_.end());
      ranked_.clear();
      for (VertexIndex u : neighbours_) ranked_.emplace_back((mesh_.positions[u] - pv).squaredNorm(), u);
      std::sort(ranked_.begin(), ranked_.end());
      VertexIndex target = kNone;
      for (size_t j = 0; j < ranked_.size() && j < 2; ++j) {
        if (findDeletions(v, ranked_[j].second, deletions_)) {
          target = ranked_[j].second;
          break;
        }
      }
      if (target == kNone) {
        // No legal edge contraction: the nearest Morton-order vertex not sharing a triangle.
        double best = std::numeric_limits<double>::infinity();
        for (size_t j = (i >= 2 ? i - 2 : 0); j <= i + 2 && j < active.size(); ++j) {
          const VertexIndex w = active[j];
          if (w == v || std::binary_search(neighbours_.begin(), neighbours_.end(), w)) continue;
          const double d = (mesh_.positions[w] - pv).squaredNorm();
          if (d < best) { best = d; target = w; }
        }
      }
      if (target != kNone)
        candidates.push_back({radius_[v] + (mesh_.positions[target] - pv).norm(), v, target});
    }
    // Cheapest first: costs are >= 0, so their float bits order like the costs (ties by index).
    order.resize(candidates.size());
    for (size_t i = 0; i < candidates.size(); ++i) {
      const float cost = static_cast<float>(candidates[i].cost);
      uint32_t bits;
      std::memcpy(&bits, &cost, sizeof(bits));
      order[i] = static_cast<uint64_t>(bits) << 32 | i;
    }
    std::sort(order.begin(), order.end());

    uint32_t applied = 0;
    for (uint64_t key : order) {
      const Candidate& cand = candidates[static_cast<uint32_t>(key)];
      if (live_triangles_ <= base_triangles_) break;
      if (locked[cand.v] || contracted_into[cand.u] != kNone || contracted_into[cand.v] != kNone)
        continue;
      if (!findDeletions(cand.v, cand.u, deletions_)) continue;
      locked[cand.v] = 1;
      locked[cand.u] = 1;
      contracted_into[cand.v] = cand.u;
      apply(cand.v, cand.u, deletions_);
      ++applied;
    }
    stats.contractions += applied;
    for (VertexIndex v : active) locked[v] = 0;
    if (applied == 0) break;
    // Contracted vertices leave the active list at the next filtering (their lists are empty).
  }
  for (size_t t = 0; t < m; ++t) {
    if (alive_[t]) tree.roots.push_back(holder_[t]);
  }
  stats.base_triangles = static_cast<uint32_t>(live_triangles_);
}

}  // namespace

// Phases 2 and 3: the 8-wide query tree and its bounds.
class HierarchyBuilder {
 public:
  HierarchyBuilder(const Mesh& mesh, Hierarchy& h) : mesh_(mesh), h_(h) {}
  void run(const BuildOptions& options);

 private:
  void buildChildLists();
  void boundRawNodes();
  int32_t buildTop(std::vector<int32_t>::iterator first, std::vector<int32_t>::iterator last);
  void collapse();
  void collectFaces(int32_t raw, std::vector<TriangleIndex>& faces) const;
  void spatialNode(std::vector<TriangleIndex>& faces, int32_t node);
  template <class Emit>
  void splitFaces(std::vector<TriangleIndex>::iterator first, std::vector<TriangleIndex>::iterator last,
                  size_t group, Emit&& emit) const;
  uint32_t addLeafBlock(const std::vector<TriangleIndex>& faces);
  void setSlot(Node8& node, int k, ChildRef child, const Triangle& corners, const Box& box) const;
  void computeRadii();

  const Mesh& mesh_;
  Hierarchy& h_;
  CoverTree tree_;
  std::vector<Box> raw_box_;          // [raw node] box of the subtree's vertices
  std::vector<uint32_t> raw_faces_;   // [raw node] original faces in the subtree
  std::vector<uint32_t> child_begin_; // [raw node + 1] CSR into child_list_
  std::vector<int32_t> child_list_;
  Node8 empty_;                       // a node with eight empty slots
  std::vector<Vec3> centroid_;        // [face] sum of its corners (3x the centroid)
};

void HierarchyBuilder::buildChildLists() {
  const size_t raw = tree_.parent.size();
  child_begin_.assign(raw + 1, 0);
  for (size_t id = 0; id < raw; ++id)
    if (tree_.parent[id] >= 0) ++child_begin_[tree_.parent[id] + 1];
  for (size_t id = 0; id < raw; ++id) child_begin_[id + 1] += child_begin_[id];
  child_list_.resize(child_begin_[raw]);
  std::vector<uint32_t> fill(child_begin_.begin(), child_begin_.end() - 1);
  for (size_t id = 0; id < raw; ++id)
    if (tree_.parent[id] >= 0) child_list_[fill[tree_.parent[id]]++] = static_cast<int32_t>(id);
}

// Boxes and face counts of every cover-tree node, children before parents (post-order from
// the roots: an adopter's open node can be older than the nodes it adopts later).
void HierarchyBuilder::boundRawNodes() {
  const int32_t m = static_cast<int32_t>(mesh_.triangles.size());
  const size_t raw = tree_.parent.size();
  buildChildLists();
  raw_box_.assign(raw, Box());
  raw_faces_.assign(raw, 0);
  std::vector<std::pair<int32_t, bool>> stack;
  for (int32_t root : tree_.roots) {
    stack.emplace_back(root, false);
    while (!stack.empty()) {
      auto [x, expanded] = stack.back();
      stack.pop_back();
      if (!expanded) {
        stack.emplace_back(x, true);
        for (uint32_t i = child_begin_[x]; i < child_begin_[x + 1]; ++i) stack.emplace_back(child_list_[i], false);
        continue;
      }
      if (x < m) {
        for (VertexIndex v : mesh_.triangles[x]) raw_box_[x].add(mesh_.positions[v]);
        raw_faces_[x] = 1;
      }
      for (uint32_t i = child_begin_[x]; i < child_begin_[x + 1]; ++i) {
        raw_box_[x].add(raw_box_[child_list_[i]]);
        raw_faces_[x] += raw_faces_[child_list_[i]];
      }
    }
  }
}

// A median-split binary tree over the roots; synthetic nodes take the triangle of their
// larger child (any triangle is valid: its radius is computed from its subtree).
int32_t HierarchyBuilder::buildTop(std::vector<int32_t>::iterator first,
                                   std::vector<int32_t>::iterator last) {
  if (last - first == 1) return *first;
  Box centers;
  for (auto it = first; it != last; ++it) centers.add(raw_box_[*it].center());
  int axis = 0;
  const Vec3 extent = centers.upper - centers.lower;
  if (extent.y() > extent[axis]) axis = 1;
  if (extent.z() > extent[axis]) axis = 2;
  auto middle = first + (last - first) / 2;
  std::nth_element(first, middle, last, [&](int32_t a, int32_t b) {
    return raw_box_[a].center()[axis] < raw_box_[b].center()[axis];
  });
  const int32_t left = buildTop(first, middle);
  const int32_t right = buildTop(middle, last);
  const int32_t node = static_cast<int32_t>(tree_.parent.size());
  tree_.parent.push_back(-1);
  tree_.corners.push_back(tree_.corners[raw_faces_[left] >= raw_faces_[right] ? left : right]);
  tree_.parent[left] = node;
  tree_.parent[right] = node;
  Box box = raw_box_[left];
  box.add(raw_box_[right]);
  raw_box_.push_back(box);
  raw_faces_.push_back(raw_faces_[left] + raw_faces_[right]);
  return node;
}

void HierarchyBuilder::collectFaces(int32_t raw, std::vector<TriangleIndex>& faces) const {
  const int32_t m = static_cast<int32_t>(mesh_.triangles.size());
  std::vector<int32_t> stack{raw};
  while (!stack.empty()) {
    const int32_t x = stack.back();
    stack.pop_back();
    if (x < m) faces.push_back(static_cast<TriangleIndex>(x));
    for (uint32_t i = child_begin_[x]; i < child_begin_[x + 1]; ++i) stack.push_back(child_list_[i]);
  }
}

// Fills `node` with the faces of a small subtree re-grouped by median splits: groups of at
// most 8 faces become leaf blocks, larger groups child nodes (depth-first, like collapse()).
// Any grouping of whole faces is a valid cover; contraction groups are spatially looser.
void HierarchyBuilder::spatialNode(std::vector<TriangleIndex>& faces, int32_t node) {
  size_t group = kLeafFaces;
  while (group * 8 < faces.size()) group *= 8;
  std::vector<std::vector<TriangleIndex>> groups;
  splitFaces(faces.begin(), faces.end(), group, [&](auto first, auto last) { groups.emplace_back(first, last); });
  int k = 0;
  std::vector<std::pair<int32_t, size_t>> children;  // (node, group)
  for (size_t i = 0; i < groups.size(); ++i) {
    Box box;
    for (TriangleIndex f : groups[i])
      for (VertexIndex v : mesh_.triangles[f]) box.add(mesh_.positions[v]);
    const Triangle& corners = mesh_.triangles[groups[i].front()];
    if (groups[i].size() <= kLeafFaces) {
      const uint32_t leaf = addLeafBlock(groups[i]);
      setSlot(h_.nodes_[node], k++, leafRef(static_cast<int32_t>(leaf)), corners, box);
      continue;
    }
    const int32_t child = static_cast<int32_t>(h_.nodes_.size());
    h_.nodes_.push_back(empty_);
    h_.parent_.push_back(node);
    h_.leaf_begin_.push_back(0);
    setSlot(h_.nodes_[node], k++, child, corners, box);
    children.emplace_back(child, i);
  }
  for (auto& [child, i] : children) {
    h_.leaf_begin_[child] = static_cast<uint32_t>(h_.leaf_blocks_.size());
    spatialNode(groups[i], child);
  }
}

// Splits faces at the median of their centroids along the widest axis into groups of at most
// `group` faces, the left part a multiple of `group` so that groups are full; emits them in order.
template <class Emit>
void HierarchyBuilder::splitFaces(std::vector<TriangleIndex>::iterator first,
                                  std::vector<TriangleIndex>::iterator last, size_t group, Emit&& emit) const {
  const size_t count = static_cast<size_t>(last - first);
  if (count <= group) {
    emit(first, last);
    return;
  }
  auto centroid = [&](TriangleIndex f) -> const Vec3& { return centroid_[f]; };
  Box bounds;
  for (auto it = first; it != last; ++it) bounds.add(centroid(*it));
  int axis = 0;
  const Vec3 extent = bounds.upper - bounds.lower;
  if (extent.y() > extent[axis]) axis = 1;
  if (extent.z() > extent[axis]) axis = 2;
  const size_t blocks = (count + group - 1) / group;
  auto middle = first + static_cast<std::ptrdiff_t>(group * ((blocks + 1) / 2));
  std::nth_element(first, middle, last, [&](TriangleIndex a, TriangleIndex b) {
    const double ca = centroid(a)[axis], cb = centroid(b)[axis];
    return ca != cb ? ca < cb : a < b;
  });
  splitFaces(first, middle, group, emit);
  splitFaces(middle, last, group, emit);
}

uint32_t HierarchyBuilder::addLeafBlock(const std::vector<TriangleIndex>& faces) {
  const uint32_t leaf = static_cast<uint32_t>(h_.leaf_blocks_.size());
  TriangleBlock8& block = h_.leaf_blocks_.emplace_back();
  for (uint32_t lane = 0; lane < 8; ++lane) {
    const bool used = lane < faces.size();
    const TriangleIndex f = faces[used ? lane : 0];
    for (int k = 0; k < 3; ++k) {
      const Vec3& x = mesh_.positions[mesh_.triangles[f][k]];
      for (int axis = 0; axis < 3; ++axis) block.v[k][axis][lane] = x[axis];
    }
    h_.leaf_triangles_.push_back(used ? f : kInvalidIndex);
  }
  h_.leaf_lanes_.push_back(static_cast<uint8_t>(faces.size()));
  return leaf;
}

void HierarchyBuilder::setSlot(Node8& node, int k, ChildRef child, const Triangle& corners,
                               const Box& box) const {
  // Scaled float coordinates, rounded outward, widened by a margin that covers the rounding
  // of a query point to float (DESIGN.md section 1: conservative float boxes).
  const float margin = boxMargin(1.0);
  const float inf = std::numeric_limits<float>::infinity();
  for (int axis = 0; axis < 3; ++axis) {
    const float lo = static_cast<float>((box.lower[axis] - h_.center_[axis]) * h_.box_scale_);
    const float hi = static_cast<float>((box.upper[axis] - h_.center_[axis]) * h_.box_scale_);
    node.lower[axis][k] = std::nextafter(lo, -inf) - margin;
    node.upper[axis][k] = std::nextafter(hi, inf) + margin;
  }
  node.child[k] = child;
  for (int c = 0; c < 3; ++c) node.corner[c][k] = corners[c];
  node.eps[k] = 0;
}

void HierarchyBuilder::collapse() {
  centroid_.resize(mesh_.triangles.size());
  for (size_t f = 0; f < mesh_.triangles.size(); ++f) {
    const Triangle& t = mesh_.triangles[f];
    centroid_[f] = mesh_.positions[t[0]] + mesh_.positions[t[1]] + mesh_.positions[t[2]];
  }
  buildChildLists();

  const int32_t top = tree_.roots.front();
  Node8& empty = empty_;
  for (int axis = 0; axis < 3; ++axis) {
    for (int k = 0; k < 8; ++k) {
      empty.lower[axis][k] = std::numeric_limits<float>::infinity();
      empty.upper[axis][k] = -std::numeric_limits<float>::infinity();
    }
  }
  for (int k = 0; k < 8; ++k) {
    empty.child[k] = kEmptyChild;
    empty.eps[k] = 0;
    for (int c = 0; c < 3; ++c) empty.corner[c][k] = 0;
  }
  h_.nodes_.assign(1, empty);
  h_.parent_.assign(1, -1);
  h_.leaf_begin_.assign(1, 0);

  std::vector<TriangleIndex> faces;
  if (raw_faces_[top] <= kLeafFaces) {
    collectFaces(top, faces);
    setSlot(h_.nodes_[0], 0, leafRef(static_cast<int32_t>(addLeafBlock(faces))),
            tree_.corners[top], raw_box_[top]);
    return;
  }
  struct Bin {
    uint32_t faces = 0;
    std::vector<int32_t> members;
  };
  std::vector<std::pair<int32_t, int32_t>> stack{{top, 0}};  // (raw node, 8-wide node)
  std::vector<int32_t> slots, inner, trial, blocked;
  std::vector<Bin> bins;
  while (!stack.empty()) {
    const auto [x, node] = stack.back();
    stack.pop_back();
    h_.leaf_begin_[node] = static_cast<uint32_t>(h_.leaf_blocks_.size());
    if (raw_faces_[x] <= kSpatialFaces) {
      faces.clear();
      collectFaces(x, faces);
      spatialNode(faces, node);
      continue;
    }
    slots.assign(child_list_.begin() + child_begin_[x], child_list_.begin() + child_begin_[x + 1]);
    // Small children (at most 8 faces) become leaf blocks, packed first-fit by decreasing size;
    // the rest are inner slots. Expand the largest inner slot into its children as long as the
    // packed slots still fit in eight (wide nodes, shallow trees).
    auto pack = [&](std::vector<int32_t>& list) {
      inner.clear();
      bins.clear();
      std::sort(list.begin(), list.end(), [&](int32_t a, int32_t b) {
        return raw_faces_[a] != raw_faces_[b] ? raw_faces_[a] > raw_faces_[b] : a < b;
      });
      for (int32_t c : list) {
        if (raw_faces_[c] > kLeafFaces) { inner.push_back(c); continue; }
        Bin* fit = nullptr;
        for (Bin& bin : bins) if (bin.faces + raw_faces_[c] <= kLeafFaces) { fit = &bin; break; }
        if (!fit) fit = &bins.emplace_back();
        fit->faces += raw_faces_[c];
        fit->members.push_back(c);
      }
      return inner.size() + bins.size();
    };
    pack(slots);
    blocked.clear();
    while (true) {
      int32_t best = -1;
      double best_area = -1;
      for (int32_t c : inner) {
        if (std::find(blocked.begin(), blocked.end(), c) != blocked.end()) continue;
        if (raw_box_[c].area() > best_area) { best_area = raw_box_[c].area(); best = c; }
      }
      if (best < 0) break;
      trial = slots;
      trial.erase(std::find(trial.begin(), trial.end(), best));
      trial.insert(trial.end(), child_list_.begin() + child_begin_[best], child_list_.begin() + child_begin_[best + 1]);
      if (pack(trial) <= 8) {
        slots.swap(trial);
      } else {
        blocked.push_back(best);
      }
      pack(slots);
    }
    int k = 0;
    for (const Bin& bin : bins) {
      faces.clear();
      Box box;
      for (int32_t c : bin.members) {
        collectFaces(c, faces);
        box.add(raw_box_[c]);
      }
      const uint32_t leaf = addLeafBlock(faces);
      setSlot(h_.nodes_[node], k++, leafRef(static_cast<int32_t>(leaf)),
              tree_.corners[bin.members.front()], box);
    }
    for (int32_t c : inner) {
      const int32_t child = static_cast<int32_t>(h_.nodes_.size());
      h_.nodes_.push_back(empty);
      h_.parent_.push_back(node);
      h_.leaf_begin_.push_back(0);
      setSlot(h_.nodes_[node], k++, child, tree_.corners[c], raw_box_[c]);
      stack.emplace_back(c, child);
    }
  }
}

// Leaf ranges of every node, then every slot's bounds: the box of its subtree's vertices and eps,
// the largest distance from them to the slot's triangle.
void HierarchyBuilder::computeRadii() {
  const size_t count = h_.nodes_.size();
  h_.leaf_end_.assign(count, 0);
  for (size_t node = count; node-- > 0;) {  // children have larger indices than their parent
    uint32_t end = h_.leaf_begin_[node];
    const Node8& n = h_.nodes_[node];
    for (int k = 0; k < 8; ++k) {
      if (isLeafRef(n.child[k])) end = std::max(end, static_cast<uint32_t>(leafIndex(n.child[k])) + 1);
      else if (n.child[k] >= 0) end = std::max(end, h_.leaf_end_[n.child[k]]);
    }
    h_.leaf_end_[node] = end;
  }
  refitBounds(h_, mesh_.positions.data(), h_.nodes_, true, false);  // boxes are set already
}

void HierarchyBuilder::run(const BuildOptions& options) {
  const auto start = Clock::now();
  HierarchyStats& stats = h_.stats_;
  Contractor(mesh_, options.base_triangles)
      .run(tree_, h_.contracted_into_, stats);
  stats.contract_seconds = secondsSince(start);

  const auto tree_start = Clock::now();
  boundRawNodes();
  Box bounds;
  for (int32_t r : tree_.roots) bounds.add(raw_box_[r]);
  h_.center_ = bounds.center();
  const double half = 0.5 * (bounds.upper - bounds.lower).maxCoeff();
  h_.box_scale_ = half > 0 ? std::ldexp(1.0, -std::ilogb(half) - 1) : 1.0;
  // A node that adopted more than 8 children gets a median-split tree over them.
  for (size_t x = 0, raw = tree_.parent.size(); x < raw; ++x) {
    if (child_begin_[x + 1] - child_begin_[x] <= 8) continue;
    std::vector<int32_t> group(child_list_.begin() + child_begin_[x], child_list_.begin() + child_begin_[x + 1]);
    tree_.parent[buildTop(group.begin(), group.end())] = static_cast<int32_t>(x);
  }
  if (tree_.roots.size() > 1) {
    std::vector<int32_t> roots = tree_.roots;
    const int32_t top = buildTop(roots.begin(), roots.end());
    tree_.roots.assign(1, top);
  }
  collapse();
  stats.tree_seconds = secondsSince(tree_start);

  const auto bounds_start = Clock::now();
  computeRadii();
  h_.vertex_face_.assign(mesh_.positions.size(), kInvalidIndex);
  for (size_t f = mesh_.triangles.size(); f-- > 0;)
    for (VertexIndex v : mesh_.triangles[f]) h_.vertex_face_[v] = static_cast<TriangleIndex>(f);
  std::vector<uint32_t> depth(h_.nodes_.size(), 1);
  for (size_t node = 1; node < h_.nodes_.size(); ++node) {
    depth[node] = depth[h_.parent_[node]] + 1;
    stats.depth = std::max(stats.depth, depth[node]);
  }
  stats.depth = std::max<uint32_t>(stats.depth, 1);
  stats.bounds_seconds = secondsSince(bounds_start);
  stats.total_seconds = secondsSince(start);
  stats.fixed_bytes = h_.nodes_.size() * (sizeof(Node8) + 3 * sizeof(uint32_t)) +
                      h_.leaf_blocks_.size() * (sizeof(TriangleBlock8) + 8 * sizeof(TriangleIndex) + 1) +
                      mesh_.positions.size() * (sizeof(Vec3) + 2 * sizeof(uint32_t)) +
                      mesh_.triangles.size() * sizeof(Triangle);
}

std::shared_ptr<const Hierarchy> Hierarchy::build(const Mesh& mesh, const BuildOptions& options) {
  const std::string problem = checkMesh(mesh);
  if (!problem.empty()) throw MeshError(problem);
  auto h = std::make_shared<Hierarchy>();
  h->mesh_ = mesh;
  HierarchyBuilder(h->mesh_, *h).run(options);
  return h;
}

}  // namespace meshsweeper
