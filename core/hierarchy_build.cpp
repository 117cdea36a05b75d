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
//
// What keeps it fast (none of it changes the hierarchy built, bit for bit): vertices renumbered
// in Morton order and triangle slots sorted by their first corner (memory locality); per round,
// the stars of the round's start as CSR arrays for the proposals (no list walks, no neighbour
// sorting); stable radix sorts; subtree boxes and face counts accumulated during the contraction
// instead of a pass over the cover tree; eps found by branch and bound over the subtree's boxes.
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
constexpr double kInfinity = std::numeric_limits<double>::infinity();
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
// A node's subtree is final when it gets its parent (a deleted triangle adopts nothing, and
// an adopter's old node is never reopened), so boxes and face counts are accumulated while the
// contraction runs.
struct CoverTree {
  std::vector<int32_t> parent;     // [raw node] -1 for a root
  std::vector<Triangle> corners;   // [raw node] the node's triangle (original vertex indices)
  std::vector<Box> box;            // [raw node] box of the subtree's vertices
  std::vector<uint32_t> faces;     // [raw node] original faces in the subtree
  std::vector<int32_t> roots;
};

// Sorts (keys[i], values[i]) by the low `bits` bits of the keys: a stable LSD radix sort, 11
// bits per pass, so equal keys keep their order.
void radixSort(std::vector<uint64_t>& keys, std::vector<uint32_t>& values, int bits) {
  const size_t count = keys.size();
  std::vector<uint64_t> key_temp(count);
  std::vector<uint32_t> value_temp(count);
  for (int shift = 0; shift < bits; shift += 11) {
    uint32_t histogram[2048] = {};
    for (size_t i = 0; i < count; ++i) ++histogram[(keys[i] >> shift) & 2047];
    uint32_t sum = 0;
    for (uint32_t& h : histogram) {
      const uint32_t c = h;
      h = sum;
      sum += c;
    }
    for (size_t i = 0; i < count; ++i) {
      const uint32_t slot = histogram[(keys[i] >> shift) & 2047]++;
      key_temp[slot] = keys[i];
      value_temp[slot] = values[i];
    }
    keys.swap(key_temp);
    values.swap(value_temp);
  }
}

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
    VertexIndex third;  // the corner that is neither v nor u (u for a degenerate triangle)
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
  // Calls f(corner) for each live corner of v, unlinking corners of deleted triangles on the
  // way, until f returns false.
  template <class F>
  void forEachCorner(VertexIndex v, F&& f) {
    uint32_t prev = kNone;
    for (uint32_t c = head_[v]; c != kNone;) {
      const uint32_t following = next_[c];
      if (!alive_[c / 3]) {
        if (prev == kNone) head_[v] = following; else next_[prev] = following;
      } else {
        if (!f(c)) return;
        prev = c;
      }
      c = following;
    }
  }
  // star <- the live corners of v, in list order.
  void gatherStar(VertexIndex v, std::vector<uint32_t>& star) {
    star.clear();
    forEachCorner(v, [&](uint32_t c) {
      star.push_back(c);
      return true;
    });
  }
  template <class ForEachV, class ForEachIn, class StarSize>
  bool findDeletions(VertexIndex v, VertexIndex u, ForEachV&& for_each_v, ForEachIn&& for_each_in,
                     StarSize&& star_size, std::vector<Deletion>& deletions);
  // v -> u on the current mesh, with v's star from gatherStar().
  bool findDeletions(VertexIndex v, VertexIndex u, const std::vector<uint32_t>& v_star,
                     std::vector<Deletion>& deletions) {
    return findDeletions(
        v, u,
        [&](auto&& f) {
          for (uint32_t c : v_star)
            if (!f(c / 3)) return;
        },
        [&](VertexIndex x, auto&& f) { forEachCorner(x, [&](uint32_t c) { return f(c / 3); }); },
        [&](VertexIndex x) { return live_corners_[x]; }, deletions);
  }
  // Whether v -> u is legal on the mesh of the round's start (stars from buildStars()).
  bool legalAtRoundStart(VertexIndex v, VertexIndex u) {
    auto for_each_in = [this](VertexIndex x, auto&& f) {
      for (uint32_t i = star_begin_[x]; i < star_begin_[x + 1]; ++i)
        if (!f(star_slot_[i])) return;
    };
    return findDeletions(
        v, u, [&](auto&& f) { for_each_in(v, f); }, for_each_in,
        [this](VertexIndex x) { return star_begin_[x + 1] - star_begin_[x]; }, deletions_);
  }
  void buildStars();
  void apply(VertexIndex v, VertexIndex u, const std::vector<uint32_t>& v_star,
             const std::vector<Deletion>& deletions);
  void release(uint32_t slot);
  void adopt(uint32_t adopter, uint32_t deleted);
  int32_t newNode(uint32_t slot) {
    tree_->parent.push_back(-1);
    tree_->corners.push_back(
        {original_[tri_[3 * slot]], original_[tri_[3 * slot + 1]], original_[tri_[3 * slot + 2]]});
    tree_->box.emplace_back();
    tree_->faces.push_back(0);
    return static_cast<int32_t>(tree_->parent.size() - 1);
  }

  // A neighbour by squared distance, ties broken by original index.
  struct Near {
    double squared_distance = kInfinity;
    VertexIndex vertex = kNone;
  };
  bool closer(const Near& a, const Near& b) const {
    if (a.squared_distance != b.squared_distance) return a.squared_distance < b.squared_distance;
    return b.vertex == kNone || (a.vertex != kNone && original_[a.vertex] < original_[b.vertex]);
  }

  const Mesh& mesh_;
  uint32_t base_triangles_;
  CoverTree* tree_ = nullptr;
  // Vertices are renumbered (local ids, Morton order); every array below uses local ids.
  std::vector<VertexIndex> original_;  // [vertex] original index
  std::vector<Vec3> pos_;              // [vertex] position
  std::vector<VertexIndex> into_;      // [vertex] the vertex it was contracted into
  std::vector<VertexIndex> tri_;    // [3 * slot + k] current corners of each triangle slot
  std::vector<uint8_t> alive_;      // [slot]
  std::vector<uint32_t> head_;      // [vertex] first corner of the vertex's corner list
  std::vector<uint32_t> next_;      // [corner] next corner of the same vertex
  std::vector<uint32_t> live_corners_;  // [vertex] corners of live triangles at the vertex
  std::vector<double> radius_;      // [vertex] contraction radius r
  std::vector<int32_t> holder_;     // [slot] cover-tree node carrying the slot's faces
  std::vector<uint8_t> open_;       // [slot] holder_ was created since the corners last changed
  std::vector<Box> slot_box_;       // [slot] box of holder_'s subtree
  std::vector<uint32_t> slot_faces_;  // [slot] original faces in holder_'s subtree
  std::vector<uint32_t> star_;             // live corners of the vertex at hand
  std::vector<uint32_t> live_slots_;       // slots alive at the round's start, increasing
  std::vector<uint32_t> star_begin_;       // [vertex + 1] CSR into star_slot_
  std::vector<uint32_t> star_slot_;        // live triangles per vertex at the round's start
  std::vector<Deletion> deletions_;
  std::vector<uint8_t> listed_;       // [slot] in deletions_ (findDeletions; cleared after)
  std::vector<uint32_t> third_group_; // [vertex] a deletion with that third corner (findDeletions)
  size_t live_triangles_ = 0;
  uint64_t adopter_visits_ = 0;  // HierarchyStats::adopter_visits
};

// Lists the triangles v -> u deletes (those holding both) with their adopters: for a deleted
// (v, u, a), a triangle that holds u and a but not v (found in u's star, or in a's when the
// third corners' stars are smaller together: the first in list order), else the first in v's
// star that does not hold u and holds a (it becomes (u, a, .)). Returns false when some
// deleted triangle leaves edge (u, a) in no surviving triangle. for_each_v(f) calls f(slot) for
// the live triangles of v, for_each_in(x, f) those of any vertex x, in list order, until f
// returns false; star_size(x) counts them.
// Linear in v's star plus the smaller of u's star and the third corners' (many triangles on one
// edge, copies of one triangle, or a vertex of high degree as u made it quadratic): deletions
// are listed with a per-slot mark, and those with the same third corner share their adopter,
// found through a per-vertex group index.
template <class ForEachV, class ForEachIn, class StarSize>
bool Contractor::findDeletions(VertexIndex v, VertexIndex u, ForEachV&& for_each_v, ForEachIn&& for_each_in,
                               StarSize&& star_size, std::vector<Deletion>& deletions) {
  deletions.clear();
  for_each_v([&](uint32_t slot) {
    if (holds(slot, u) && !listed_[slot]) {
      listed_[slot] = 1;
      deletions.push_back({slot, kNone, thirdVertex(slot, v, u)});
    }
    return true;
  });
  if (deletions.empty()) return true;
  // One group per distinct third corner: the group's first deletion carries the adopter.
  size_t missing = 0;
  const size_t u_star = star_size(u);
  size_t thirds_star = 0;
  for (size_t i = 0; i < deletions.size(); ++i) {
    listed_[deletions[i].slot] = 0;
    uint32_t& group = third_group_[deletions[i].third];
    if (group == kNone) {
      group = static_cast<uint32_t>(i);
      ++missing;
      if (thirds_star < u_star) thirds_star += star_size(deletions[i].third);
    }
  }
  // A surviving triangle on edge (u, a) lies in both stars: walk the smaller side.
  auto adoptFrom = [&](uint32_t slot, VertexIndex other) {
    ++adopter_visits_;
    if (holds(slot, other)) return missing > 0;
    for (int k = 0; k < 3; ++k) {
      const uint32_t group = third_group_[tri_[3 * slot + k]];
      if (group != kNone && deletions[group].adopter == kNone) {
        deletions[group].adopter = slot;
        --missing;
      }
    }
    return missing > 0;
  };
  if (thirds_star < u_star) {
    for (size_t i = 0; i < deletions.size(); ++i) {
      const VertexIndex a = deletions[i].third;
      if (third_group_[a] != i) continue;
      for_each_in(a, [&](uint32_t slot) {
        ++adopter_visits_;
        if (holds(slot, v) || !holds(slot, u)) return true;
        deletions[i].adopter = slot;
        --missing;
        return false;
      });
    }
  } else {
    for_each_in(u, [&](uint32_t slot) { return adoptFrom(slot, v); });
  }
  if (missing > 0) for_each_v([&](uint32_t slot) { return adoptFrom(slot, u); });
  for (Deletion& d : deletions) {
    const uint32_t group = third_group_[d.third];
    if (group != kNone) d.adopter = deletions[group].adopter;
  }
  for (const Deletion& d : deletions) third_group_[d.third] = kNone;
  return missing == 0;
}

// The box and face count of a slot's holder live in slot_box_ / slot_faces_ (next to the
// slot's other data) while it is the holder; they are copied into the tree when it stops being
// one. Faces (the initial holders) already have theirs.
void Contractor::release(uint32_t slot) {
  const int32_t node = holder_[slot];
  if (static_cast<size_t>(node) < mesh_.triangles.size()) return;
  tree_->box[node] = slot_box_[slot];
  tree_->faces[node] = slot_faces_[slot];
}

void Contractor::adopt(uint32_t adopter, uint32_t deleted) {
  const int32_t child = holder_[deleted];
  release(deleted);
  if (!open_[adopter]) {
    const int32_t node = newNode(adopter);
    release(adopter);
    tree_->parent[holder_[adopter]] = node;
    holder_[adopter] = node;
    open_[adopter] = 1;
  }
  tree_->parent[child] = holder_[adopter];
  slot_box_[adopter].add(slot_box_[deleted]);
  slot_faces_[adopter] += slot_faces_[deleted];
}

void Contractor::apply(VertexIndex v, VertexIndex u, const std::vector<uint32_t>& v_star,
                       const std::vector<Deletion>& deletions) {
  for (const Deletion& d : deletions) {
    alive_[d.slot] = 0;
    --live_triangles_;
    for (int k = 0; k < 3; ++k) --live_corners_[tri_[3 * d.slot + k]];
  }
  live_corners_[u] += live_corners_[v];
  live_corners_[v] = 0;
  // v's surviving corners become u's, spliced in front of u's list.
  uint32_t first = kNone, tail = kNone;
  for (uint32_t c : v_star) {
    if (!alive_[c / 3]) continue;
    tri_[c] = u;
    open_[c / 3] = 0;
    if (tail == kNone) first = c; else next_[tail] = c;
    tail = c;
  }
  if (tail != kNone) {
    next_[tail] = head_[u];
    head_[u] = first;
  }
  head_[v] = kNone;
  for (const Deletion& d : deletions) adopt(d.adopter, d.slot);
  radius_[u] = std::max(radius_[u], radius_[v] + (pos_[u] - pos_[v]).norm());
}

// The stars of the round's start as CSR arrays (the proposals read them; contractions applied
// later in the round walk the corner lists).
void Contractor::buildStars() {
  size_t kept = 0;
  for (uint32_t slot : live_slots_)
    if (alive_[slot]) live_slots_[kept++] = slot;
  live_slots_.resize(kept);
  star_begin_.assign(head_.size() + 2, 0);
  for (uint32_t slot : live_slots_)
    for (int k = 0; k < 3; ++k) ++star_begin_[tri_[3 * slot + k] + 2];
  for (size_t v = 2; v < star_begin_.size(); ++v) star_begin_[v] += star_begin_[v - 1];
  star_slot_.resize(3 * live_slots_.size());
  for (uint32_t slot : live_slots_)
    for (uint32_t c = 3 * slot; c < 3 * slot + 3; ++c) star_slot_[star_begin_[tri_[c] + 1]++] = slot;
  star_begin_.pop_back();  // star_begin_[v] .. star_begin_[v + 1] now spans v's triangles
}

void Contractor::run(CoverTree& tree, std::vector<VertexIndex>& contracted_into,
                     HierarchyStats& stats) {
  tree_ = &tree;
  const size_t m = mesh_.triangles.size();

  // Vertices used by some triangle, renumbered in Morton order (the order of contractions across
  // gaps): local ids keep neighbours close in memory. Ties between equal distances are still
  // broken by original index, so the result does not depend on the renumbering.
  {
    std::vector<uint8_t> used(mesh_.positions.size(), 0);
    for (const Triangle& t : mesh_.triangles)
      for (VertexIndex v : t) used[v] = 1;
    Box bounds;
    original_.clear();
    for (size_t v = 0; v < used.size(); ++v) {
      if (!used[v]) continue;
      original_.push_back(static_cast<VertexIndex>(v));
      bounds.add(mesh_.positions[v]);
    }
    const Vec3 extent = (bounds.upper - bounds.lower).cwiseMax(1e-300);
    std::vector<uint64_t> code(original_.size());
    for (size_t i = 0; i < original_.size(); ++i)
      code[i] = mortonCode(mesh_.positions[original_[i]], bounds.lower, extent);
    radixSort(code, original_, 63);  // ties by original index
  }
  const size_t n = original_.size();
  std::vector<VertexIndex> local(mesh_.positions.size(), kNone);  // [original vertex]
  pos_.resize(n);
  for (size_t i = 0; i < n; ++i) {
    local[original_[i]] = static_cast<VertexIndex>(i);
    pos_[i] = mesh_.positions[original_[i]];
  }

  // Triangle slots renumbered by their first corner in Morton order (counting sort), for the
  // same reason. Corner lists are still built in original face order, so every walk of a list
  // visits triangles in the same order whatever the numbering.
  std::vector<uint32_t> slot_of(m);  // [original face] slot
  {
    std::vector<uint32_t> start(n + 1, 0);
    auto key = [&](size_t t) {
      const Triangle& f = mesh_.triangles[t];
      return std::min({local[f[0]], local[f[1]], local[f[2]]});
    };
    for (size_t t = 0; t < m; ++t) ++start[key(t) + 1];
    for (size_t i = 1; i <= n; ++i) start[i] += start[i - 1];
    for (size_t t = 0; t < m; ++t) slot_of[t] = start[key(t)]++;
  }

  tri_.resize(3 * m);
  alive_.assign(m, 1);
  head_.assign(n, kNone);
  next_.assign(3 * m, kNone);
  live_corners_.assign(n, 0);
  radius_.assign(n, 0.0);
  holder_.resize(m);
  open_.assign(m, 0);
  listed_.assign(m, 0);
  third_group_.assign(n, kNone);
  into_.assign(n, kNone);
  // Each node a contraction creates replaces a deleted triangle's: at most m of them.
  tree.parent.reserve(2 * m);
  tree.corners.reserve(2 * m);
  tree.box.reserve(2 * m);
  tree.faces.reserve(2 * m);
  tree.parent.assign(m, -1);
  tree.corners.assign(mesh_.triangles.begin(), mesh_.triangles.end());
  tree.box.resize(m);
  tree.faces.assign(m, 1);
  slot_box_.resize(m);
  slot_faces_.assign(m, 1);
  for (size_t t = 0; t < m; ++t) {
    for (VertexIndex v : mesh_.triangles[t]) tree.box[t].add(mesh_.positions[v]);
    slot_box_[slot_of[t]] = tree.box[t];
  }
  live_triangles_ = m;
  live_slots_.resize(m);
  std::iota(live_slots_.begin(), live_slots_.end(), 0u);
  for (size_t t = m; t-- > 0;) {
    const uint32_t slot = slot_of[t];
    holder_[slot] = static_cast<int32_t>(t);
    for (int k = 0; k < 3; ++k) {
      const uint32_t c = 3 * slot + k;
      tri_[c] = local[mesh_.triangles[t][k]];
      next_[c] = head_[tri_[c]];
      head_[tri_[c]] = c;
      ++live_corners_[tri_[c]];
    }
  }
  std::vector<VertexIndex> active(n);  // live vertices, in Morton order
  std::iota(active.begin(), active.end(), 0u);

  std::vector<Candidate> candidates;
  std::vector<uint64_t> keys;
  std::vector<uint32_t> order;
  std::vector<uint8_t> locked(n, 0);  // [vertex] contracted or grown this round: not a source
  const uint32_t kMaxRounds = 10000;
  while (live_triangles_ > base_triangles_ && stats.rounds < kMaxRounds) {
    ++stats.rounds;
    // Drop vertices that no live triangle uses any more (keeps Morton order).
    size_t kept = 0;
    for (VertexIndex v : active)
      if (live_corners_[v] > 0) active[kept++] = v;
    active.resize(kept);
    if (active.size() < 2) break;
    buildStars();

    candidates.clear();
    for (size_t i = 0; i < active.size(); ++i) {
      const VertexIndex v = active[i];
      const Vec3& pv = pos_[v];
      // The two nearest distinct neighbours of v by (squared distance, original index).
      const uint32_t* star = &star_slot_[star_begin_[v]];
      const size_t star_count = star_begin_[v + 1] - star_begin_[v];
      Near nearest[2];
      for (size_t j = 0; j < star_count; ++j) {
        const VertexIndex* t = &tri_[3 * star[j]];
        for (int k = 0; k < 3; ++k) {
          const VertexIndex x = t[k];
          if (x == v || x == nearest[0].vertex || x == nearest[1].vertex) continue;
          const Near key{(pos_[x] - pv).squaredNorm(), x};
          if (closer(key, nearest[0])) { nearest[1] = nearest[0]; nearest[0] = key; }
          else if (closer(key, nearest[1])) nearest[1] = key;
        }
      }
      VertexIndex target = kNone;
      for (const Near& near : nearest) {
        const VertexIndex x = near.vertex;
        if (x != kNone && legalAtRoundStart(v, x)) {
          target = x;
          break;
        }
      }
      if (target == kNone) {
        // No legal edge contraction: the nearest Morton-order vertex not sharing a triangle.
        double best = kInfinity;
        for (size_t j = (i >= 2 ? i - 2 : 0); j <= i + 2 && j < active.size(); ++j) {
          const VertexIndex w = active[j];
          bool shares = w == v;
          for (size_t k = 0; k < star_count && !shares; ++k) shares = holds(star[k], w);
          if (shares) continue;
          const double d = (pos_[w] - pv).squaredNorm();
          if (d < best) { best = d; target = w; }
        }
      }
      if (target != kNone)
        candidates.push_back({radius_[v] + (pos_[target] - pv).norm(), v, target});
    }
    // Cheapest first: costs are >= 0, so their float bits order like the costs; the radix sort
    // is stable, so ties stay in candidate order.
    keys.resize(candidates.size());
    order.resize(candidates.size());
    for (size_t i = 0; i < candidates.size(); ++i) {
      const float cost = static_cast<float>(candidates[i].cost);
      uint32_t bits;
      std::memcpy(&bits, &cost, sizeof(bits));
      keys[i] = bits;
      order[i] = static_cast<uint32_t>(i);
    }
    radixSort(keys, order, 32);

    uint32_t applied = 0;
    for (uint32_t index : order) {
      const Candidate& cand = candidates[index];
      if (live_triangles_ <= base_triangles_) break;
      if (locked[cand.v] || into_[cand.u] != kNone || into_[cand.v] != kNone) continue;
      gatherStar(cand.v, star_);
      if (!findDeletions(cand.v, cand.u, star_, deletions_)) continue;
      locked[cand.v] = 1;
      locked[cand.u] = 1;
      into_[cand.v] = cand.u;
      apply(cand.v, cand.u, star_, deletions_);
      ++applied;
    }
    stats.contractions += applied;
    for (VertexIndex v : active) locked[v] = 0;
    if (applied == 0) break;
    // A round that contracts almost nothing (each vertex takes one contraction a round, so a
    // vertex thousands of triangles hang on, as on an edge shared by many, would take as many
    // rounds, each a pass over the mesh): stop, and the top tree splits the rest by position.
    if (static_cast<size_t>(applied) * 1024 < live_triangles_) break;
    // Contracted vertices leave the active list at the next filtering (their lists are empty).
  }
  for (size_t t = 0; t < m; ++t) {
    if (!alive_[slot_of[t]]) continue;
    release(slot_of[t]);
    tree.roots.push_back(holder_[slot_of[t]]);
  }
  contracted_into.assign(mesh_.positions.size(), kNone);
  for (size_t v = 0; v < n; ++v)
    if (into_[v] != kNone) contracted_into[original_[v]] = original_[into_[v]];
  stats.base_triangles = static_cast<uint32_t>(live_triangles_);
  stats.adopter_visits = adopter_visits_;
}

}  // namespace

// Phases 2 and 3: the 8-wide query tree and its bounds.
class HierarchyBuilder {
 public:
  HierarchyBuilder(const Mesh& mesh, Hierarchy& h) : mesh_(mesh), h_(h) {}
  void run(const BuildOptions& options);

 private:
  void buildChildLists();
  int32_t buildTop(std::vector<int32_t>::iterator first, std::vector<int32_t>::iterator last);
  void collapse();
  void collectFaces(int32_t raw, std::vector<TriangleIndex>& faces);
  // A face and the sum of its corners (3x its centroid), kept together for the median splits.
  struct FaceItem {
    Vec3 centroid;
    TriangleIndex face;
  };
  void spatialNode(FaceItem* first, FaceItem* last, int32_t node);
  template <class Emit>
  void splitFaces(FaceItem* first, FaceItem* last, size_t group, Emit&& emit) const;
  uint32_t addLeafBlock(const TriangleIndex* faces, size_t count);
  void setSlot(Node8& node, int k, ChildRef child, const Triangle& corners, const Box& box);
  void computeRadii();

  const Mesh& mesh_;
  Hierarchy& h_;
  CoverTree tree_;
  std::vector<uint32_t> child_begin_; // [raw node + 1] CSR into child_list_
  std::vector<int32_t> child_list_;
  Node8 empty_;                       // a node with eight empty slots
  std::vector<SlotBoxes> slot_boxes_;  // [node] the slots' boxes (scaled), packed after the tree
  std::vector<Vec3> centroid_;        // [face] sum of its corners (3x the centroid)
  std::vector<int32_t> collect_stack_;  // collectFaces()' stack
  std::vector<FaceItem> items_;         // the faces spatialNode() regroups
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

// A median-split binary tree over the roots; synthetic nodes take the triangle of their
// larger child (any triangle is valid: its radius is computed from its subtree).
int32_t HierarchyBuilder::buildTop(std::vector<int32_t>::iterator first,
                                   std::vector<int32_t>::iterator last) {
  if (last - first == 1) return *first;
  Box centers;
  for (auto it = first; it != last; ++it) centers.add(tree_.box[*it].center());
  int axis = 0;
  const Vec3 extent = centers.upper - centers.lower;
  if (extent.y() > extent[axis]) axis = 1;
  if (extent.z() > extent[axis]) axis = 2;
  auto middle = first + (last - first) / 2;
  std::nth_element(first, middle, last, [&](int32_t a, int32_t b) {
    return tree_.box[a].center()[axis] < tree_.box[b].center()[axis];
  });
  const int32_t left = buildTop(first, middle);
  const int32_t right = buildTop(middle, last);
  const int32_t node = static_cast<int32_t>(tree_.parent.size());
  tree_.parent.push_back(-1);
  tree_.corners.push_back(tree_.corners[tree_.faces[left] >= tree_.faces[right] ? left : right]);
  tree_.parent[left] = node;
  tree_.parent[right] = node;
  Box box = tree_.box[left];
  box.add(tree_.box[right]);
  tree_.box.push_back(box);
  tree_.faces.push_back(tree_.faces[left] + tree_.faces[right]);
  return node;
}

void HierarchyBuilder::collectFaces(int32_t raw, std::vector<TriangleIndex>& faces) {
  const int32_t m = static_cast<int32_t>(mesh_.triangles.size());
  std::vector<int32_t>& stack = collect_stack_;
  stack.assign(1, raw);
  while (!stack.empty()) {
    const int32_t x = stack.back();
    stack.pop_back();
    if (x < m) faces.push_back(static_cast<TriangleIndex>(x));
    for (uint32_t i = child_begin_[x]; i < child_begin_[x + 1]; ++i) stack.push_back(child_list_[i]);
  }
}

// Fills `node` with the faces [first, last) of a small subtree re-grouped by median splits
// (in place): groups of at most 8 faces become leaf blocks, larger groups child nodes
// (depth-first, like collapse()). Any grouping of whole faces is a valid cover; contraction
// groups are spatially looser.
void HierarchyBuilder::spatialNode(FaceItem* first, FaceItem* last, int32_t node) {
  const size_t count = static_cast<size_t>(last - first);
  size_t group = kLeafFaces;
  while (group * 8 < count) group *= 8;
  // At most 8 groups: count <= 8 * group and every group but the last is full.
  std::pair<FaceItem*, FaceItem*> groups[8];
  int group_count = 0;
  splitFaces(first, last, group, [&](FaceItem* begin, FaceItem* end) { groups[group_count++] = {begin, end}; });
  int k = 0;
  std::pair<int32_t, int> children[8];  // (node, group)
  int child_count = 0;
  for (int i = 0; i < group_count; ++i) {
    const auto [begin, end] = groups[i];
    Box box;
    for (const FaceItem* f = begin; f != end; ++f) box.add(tree_.box[f->face]);
    const Triangle& corners = mesh_.triangles[begin->face];
    if (static_cast<size_t>(end - begin) <= kLeafFaces) {
      TriangleIndex faces[kLeafFaces];
      for (const FaceItem* f = begin; f != end; ++f) faces[f - begin] = f->face;
      const uint32_t leaf = addLeafBlock(faces, static_cast<size_t>(end - begin));
      setSlot(h_.nodes_[node], k++, leafRef(static_cast<int32_t>(leaf)), corners, box);
      continue;
    }
    const int32_t child = static_cast<int32_t>(h_.nodes_.size());
    h_.nodes_.push_back(empty_);
    h_.parent_.push_back(node);
    h_.leaf_begin_.push_back(0);
    setSlot(h_.nodes_[node], k++, child, corners, box);
    children[child_count++] = {child, i};
  }
  for (int j = 0; j < child_count; ++j) {
    const auto [child, i] = children[j];
    h_.leaf_begin_[child] = static_cast<uint32_t>(h_.leaf_blocks_.size());
    spatialNode(groups[i].first, groups[i].second, child);
  }
}

// Splits faces at the median of their centroids along the widest axis into groups of at most
// `group` faces, the left part a multiple of `group` so that groups are full; emits them in order.
template <class Emit>
void HierarchyBuilder::splitFaces(FaceItem* first, FaceItem* last, size_t group, Emit&& emit) const {
  const size_t count = static_cast<size_t>(last - first);
  if (count <= group) {
    emit(first, last);
    return;
  }
  Box bounds;
  for (const FaceItem* it = first; it != last; ++it) bounds.add(it->centroid);
  int axis = 0;
  const Vec3 extent = bounds.upper - bounds.lower;
  if (extent.y() > extent[axis]) axis = 1;
  if (extent.z() > extent[axis]) axis = 2;
  const size_t blocks = (count + group - 1) / group;
  FaceItem* middle = first + group * ((blocks + 1) / 2);
  std::nth_element(first, middle, last, [axis](const FaceItem& a, const FaceItem& b) {
    const double ca = a.centroid[axis], cb = b.centroid[axis];
    return ca != cb ? ca < cb : a.face < b.face;
  });
  splitFaces(first, middle, group, emit);
  splitFaces(middle, last, group, emit);
}

uint32_t HierarchyBuilder::addLeafBlock(const TriangleIndex* faces, size_t count) {
  const uint32_t leaf = static_cast<uint32_t>(h_.leaf_blocks_.size());
  for (uint32_t lane = 0; lane < 8; ++lane) {
    h_.leaf_triangles_.push_back(lane < count ? faces[lane] : kInvalidIndex);
    h_.leaf_corners_.push_back(mesh_.triangles[faces[lane < count ? lane : 0]]);
  }
  gatherLeafBlock(&h_.leaf_corners_[8 * static_cast<size_t>(leaf)], mesh_.positions.data(), h_.leaf_blocks_.emplace_back());
  h_.leaf_lanes_.push_back(static_cast<uint8_t>(count));
  return leaf;
}

void HierarchyBuilder::setSlot(Node8& node, int k, ChildRef child, const Triangle& corners,
                               const Box& box) {
  // The box in scaled coordinates (packed relative to the node's origin once the tree is
  // built: packSlotBoxes, DESIGN.md section 1: conservative float boxes).
  const size_t index = static_cast<size_t>(&node - h_.nodes_.data());
  if (slot_boxes_.size() <= index) slot_boxes_.resize(h_.nodes_.size(), emptySlotBoxes());
  for (int axis = 0; axis < 3; ++axis) {
    slot_boxes_[index].lower[axis][k] = (box.lower[axis] - h_.center_[axis]) * h_.box_scale_;
    slot_boxes_[index].upper[axis][k] = (box.upper[axis] - h_.center_[axis]) * h_.box_scale_;
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
    if (k < 3) empty.origin[k] = 0;
    for (int c = 0; c < 3; ++c) empty.corner[c][k] = 0;
  }
  h_.nodes_.assign(1, empty);
  h_.parent_.assign(1, -1);
  h_.leaf_begin_.assign(1, 0);

  std::vector<TriangleIndex> faces;
  if (tree_.faces[top] <= kLeafFaces) {
    collectFaces(top, faces);
    setSlot(h_.nodes_[0], 0, leafRef(static_cast<int32_t>(addLeafBlock(faces.data(), faces.size()))),
            tree_.corners[top], tree_.box[top]);
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
    if (tree_.faces[x] <= kSpatialFaces) {
      faces.clear();
      collectFaces(x, faces);
      items_.resize(faces.size());
      for (size_t i = 0; i < faces.size(); ++i) items_[i] = {centroid_[faces[i]], faces[i]};
      spatialNode(items_.data(), items_.data() + items_.size(), node);
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
        return tree_.faces[a] != tree_.faces[b] ? tree_.faces[a] > tree_.faces[b] : a < b;
      });
      for (int32_t c : list) {
        if (tree_.faces[c] > kLeafFaces) { inner.push_back(c); continue; }
        Bin* fit = nullptr;
        for (Bin& bin : bins) if (bin.faces + tree_.faces[c] <= kLeafFaces) { fit = &bin; break; }
        if (!fit) fit = &bins.emplace_back();
        fit->faces += tree_.faces[c];
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
        if (tree_.box[c].area() > best_area) { best_area = tree_.box[c].area(); best = c; }
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
        box.add(tree_.box[c]);
      }
      const uint32_t leaf = addLeafBlock(faces.data(), faces.size());
      setSlot(h_.nodes_[node], k++, leafRef(static_cast<int32_t>(leaf)),
              tree_.corners[bin.members.front()], box);
    }
    for (int32_t c : inner) {
      const int32_t child = static_cast<int32_t>(h_.nodes_.size());
      h_.nodes_.push_back(empty);
      h_.parent_.push_back(node);
      h_.leaf_begin_.push_back(0);
      setSlot(h_.nodes_[node], k++, child, tree_.corners[c], tree_.box[c]);
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
  buildChildLists();
  Box bounds;
  for (int32_t r : tree_.roots) bounds.add(tree_.box[r]);
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
  // The boxes, relative to each node's origin, with the slack of the whole mesh's scaled
  // extent (at most 1): a surface point computed near a node holds in its box even where the
  // node itself is a point (every vertex at one place).
  slot_boxes_.resize(h_.nodes_.size(), emptySlotBoxes());
  for (size_t node = 0; node < h_.nodes_.size(); ++node)
    packSlotBoxes(h_.nodes_[node], slot_boxes_[node], 1.0);
  slot_boxes_ = {};
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
                      h_.leaf_blocks_.size() * (sizeof(TriangleBlock8) + 8 * (sizeof(TriangleIndex) + sizeof(Triangle)) + 1) +
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
