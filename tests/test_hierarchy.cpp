// Invariant tests of the hierarchy (DESIGN.md section 1), on procedural meshes (closed, open,
// soups, degenerate, several components, the edge cases of the 8-wide layout) and real ones:
//  (a) validate() finds nothing wrong;
//  (b) cover: for random fronts of the 8-wide tree, every sample point of every original face
//      (corners, edge midpoints, centroid, random barycentric points) lies in the volume of the
//      one front slot whose subtree holds the face: within eps of the slot's triangle and inside
//      the slot's box; every face is covered by exactly one front slot;
//  (c) full expansion gives back exactly the input faces, with their coordinates inline;
//  (d) every radius bounds its subtree and is tight (recomputed here independently);
//  (e) build statistics are filled and the tree is shallow;
//  (f) bad input throws MeshError with a message that names the mesh and the problem;
// and one hierarchy is shared by two threads with their own QueryStreams.
#include "core/brute_force.h"
#include "core/hierarchy.h"
#include "core/mesh_io.h"
#include "core/sweep_query.h"
#include "core/triangle_distance.h"
#include "scenes/procedural.h"

#include "tests/oracle.h"

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

using namespace meshsweeper;
using namespace meshsweeper::oracle;
using scenes::Random;

namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();
constexpr uint32_t kMaxDepth = 40;

// Rounding scale of a mesh: a few ulps of its largest coordinate. Points computed as barycentric
// combinations are off by about this much, so bounds are checked with it as absolute slack.
double roundingSlack(const Mesh& mesh) {
  Vec3 lower, upper;
  meshBounds(mesh, lower, upper);
  const double magnitude = std::max(lower.cwiseAbs().maxCoeff(), upper.cwiseAbs().maxCoeff());
  return 16 * kEps * magnitude;
}

double distanceToTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  return std::sqrt(closestPointOnTriangle(p, a, b, c).squared_distance);
}

// The original faces under one slot of a node, read from the leaf blocks: a leaf slot holds its
// block's lanes; an inner slot the leaf range of its child node.
std::vector<TriangleIndex> slotFaces(const Hierarchy& h, int32_t node, int slot) {
  const ChildRef c = h.nodes()[node].child[slot];
  uint32_t first = 0, last = 0;
  if (isLeafRef(c)) {
    first = static_cast<uint32_t>(leafIndex(c));
    last = first + 1;
  } else {
    first = h.leafBegin(c);
    last = h.leafEnd(c);
  }
  std::vector<TriangleIndex> faces;
  for (uint32_t leaf = first; leaf < last; ++leaf)
    for (uint32_t lane = 0; lane < h.leafLanes(static_cast<int32_t>(leaf)); ++lane)
      faces.push_back(h.leafTriangles()[8 * leaf + lane]);
  return faces;
}

struct SlotRef {
  int32_t node;
  int slot;
};

// A random front: from the root, each inner slot is opened with probability `open`, else it
// joins the front; leaf slots always join it.
void randomFront(const Hierarchy& h, int32_t node, double open, Random& random, std::vector<SlotRef>& front) {
  const Node8& n = h.nodes()[node];
  for (int k = 0; k < 8; ++k) {
    const ChildRef c = n.child[k];
    if (c == kEmptyChild) continue;
    if (!isLeafRef(c) && random.uniform() < open) {
      randomFront(h, c, open, random, front);
    } else {
      front.push_back({node, k});
    }
  }
}

// Sample points of one face: corners, edge midpoints, centroid and random barycentric points.
void faceSamples(const Mesh& mesh, TriangleIndex f, Random& random, std::vector<Vec3>& out) {
  out.clear();
  const Vec3& a = mesh.positions[mesh.triangles[f][0]];
  const Vec3& b = mesh.positions[mesh.triangles[f][1]];
  const Vec3& c = mesh.positions[mesh.triangles[f][2]];
  out.insert(out.end(), {a, b, c, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a), (a + b + c) / 3.0});
  for (int i = 0; i < 3; ++i) {
    double u = random.uniform(), v = random.uniform();
    if (u + v > 1) {
      u = 1 - u;
      v = 1 - v;
    }
    out.push_back((1 - u - v) * a + u * b + v * c);
  }
}

std::string describeSlot(const Hierarchy& h, SlotRef s) {
  std::ostringstream out;
  const Node8& n = h.nodes()[s.node];
  out << "node " << s.node << " slot " << s.slot << " child " << n.child[s.slot] << " corners ("
      << n.corner[0][s.slot] << ", " << n.corner[1][s.slot] << ", " << n.corner[2][s.slot] << ") eps "
      << n.eps[s.slot];
  return out.str();
}

// (b) Cover on random fronts.
void checkCover(const Hierarchy& h, uint64_t seed) {
  const Mesh& mesh = h.mesh();
  const size_t m = mesh.triangles.size();
  const double slack = roundingSlack(mesh);
  Random random(seed);
  std::vector<Vec3> samples;
  Failures volume("cover: sample outside its front slot's swept triangle");
  Failures box("cover: sample outside its front slot's box");
  Failures once("cover: face not covered exactly once");
  const double opens[] = {0.0, 0.25, 0.5, 0.75, 0.9, 1.0};
  for (double open : opens) {
    std::vector<SlotRef> front;
    randomFront(h, 0, open, random, front);
    std::vector<uint32_t> covered(m, 0);
    for (const SlotRef s : front) {
      const Node8& n = h.nodes()[s.node];
      const Vec3& a = mesh.positions[n.corner[0][s.slot]];
      const Vec3& b = mesh.positions[n.corner[1][s.slot]];
      const Vec3& c = mesh.positions[n.corner[2][s.slot]];
      const double eps = n.eps[s.slot];
      for (TriangleIndex f : slotFaces(h, s.node, s.slot)) {
        if (f >= m) continue;  // reported by (c)
        ++covered[f];
        faceSamples(mesh, f, random, samples);
        for (const Vec3& x : samples) {
          const double d = distanceToTriangle(x, a, b, c);
          volume.check(d <= eps * (1 + 1e-12) + slack, [&] {
            std::ostringstream out;
            out.precision(17);
            out << "open " << open << ", face " << f << ", point " << text(x) << ", distance " << d
                << " > eps, " << describeSlot(h, s);
            return out.str();
          });
          const Vec3 scaled = (x - h.center()) * h.boxScale();
          double lower[3], upper[3];
          slotBox(n, s.slot, lower, upper);
          bool inside = true;
          for (int axis = 0; axis < 3; ++axis) inside = inside && lower[axis] <= scaled[axis] && scaled[axis] <= upper[axis];
          box.check(inside, [&] {
            return "open " + std::to_string(open) + ", face " + std::to_string(f) + ", point " +
                   text(x) + ", " + describeSlot(h, s);
          });
        }
      }
    }
    for (size_t f = 0; f < m; ++f)
      once.check(covered[f] == 1, [&] {
        return "open " + std::to_string(open) + ": face " + std::to_string(f) + " covered " +
               std::to_string(covered[f]) + " times by a front of " + std::to_string(front.size());
      });
  }
}

// (c) Full expansion, tree structure and leaf ranges, walked from the root independently of
// validate(). Returns the depth of the deepest node (root = 1).
uint32_t checkExpansion(const Hierarchy& h) {
  const Mesh& mesh = h.mesh();
  const size_t m = mesh.triangles.size();
  const auto& nodes = h.nodes();
  const auto& lanes = h.leafTriangles();
  REQUIRE(!nodes.empty());
  REQUIRE(lanes.size() == 8 * static_cast<size_t>(h.leafCount()));
  REQUIRE(h.leafLaneCounts().size() == h.leafCount());
  REQUIRE(h.leafCorners().size() == lanes.size());
  std::vector<uint32_t> face_seen(m, 0), node_seen(nodes.size(), 0), leaf_seen(h.leafCount(), 0);
  Failures structure("expansion");
  uint32_t deepest = 0;
  struct Visit {
    int32_t node;
    uint32_t depth;
  };
  // Leaves met under each node, to compare with leafBegin/leafEnd.
  std::vector<uint32_t> leaf_min(nodes.size(), UINT32_MAX), leaf_max(nodes.size(), 0),
      leaf_count(nodes.size(), 0);
  std::vector<Visit> stack{{0, 1}};
  std::vector<int32_t> order;
  while (!stack.empty()) {
    const Visit v = stack.back();
    stack.pop_back();
    if (v.node < 0 || static_cast<size_t>(v.node) >= nodes.size()) {
      structure.check(false, [&] { return "node index " + std::to_string(v.node) + " out of range"; });
      continue;
    }
    if (node_seen[v.node]++) {
      structure.check(false, [&] { return "node " + std::to_string(v.node) + " reached twice"; });
      continue;
    }
    order.push_back(v.node);
    deepest = std::max(deepest, v.depth);
    const Node8& n = nodes[v.node];
    for (int k = 0; k < 8; ++k) {
      const ChildRef c = n.child[k];
      if (c == kEmptyChild) {
        bool empty_box = true;
        for (int axis = 0; axis < 3; ++axis) empty_box = empty_box && n.lower[axis][k] > n.upper[axis][k];
        structure.check(empty_box,
                        [&] { return "empty slot with a non-empty box, node " + std::to_string(v.node); });
        continue;
      }
      if (!isLeafRef(c)) {
        structure.check(h.parentNode(c) == v.node, [&] {
          return "parentNode(" + std::to_string(c) + ") = " + std::to_string(h.parentNode(c)) +
                 ", reached from " + std::to_string(v.node);
        });
        stack.push_back({c, v.depth + 1});
        continue;
      }
      const int32_t leaf = leafIndex(c);
      if (leaf < 0 || static_cast<uint32_t>(leaf) >= h.leafCount()) {
        structure.check(false, [&] { return "leaf " + std::to_string(leaf) + " out of range"; });
        continue;
      }
      ++leaf_seen[leaf];
      // Every ancestor's range must hold this leaf.
      size_t up = 0;
      for (int32_t x = v.node; x >= 0 && static_cast<size_t>(x) < nodes.size() && up++ <= nodes.size();
           x = h.parentNode(x)) {
        leaf_min[x] = std::min(leaf_min[x], static_cast<uint32_t>(leaf));
        leaf_max[x] = std::max(leaf_max[x], static_cast<uint32_t>(leaf));
        ++leaf_count[x];
        if (x == 0) break;
      }
      const uint32_t used = h.leafLanes(leaf);
      structure.check(used >= 1 && used <= 8, [&] {
        return "leaf " + std::to_string(leaf) + " uses " + std::to_string(used) + " lanes";
      });
      const TriangleBlock8& block = h.leafBlocks()[leaf];
      for (uint32_t lane = 0; lane < 8; ++lane) {
        const TriangleIndex f = lanes[8 * leaf + lane];
        if (lane >= used) {
          structure.check(f == kInvalidIndex,
                          [&] { return "unused lane names a face, leaf " + std::to_string(leaf); });
          // Unused lanes copy lane 0 (never garbage).
          bool copy = true;
          for (int corner = 0; corner < 3; ++corner)
            for (int axis = 0; axis < 3; ++axis)
              copy = copy && block.v[corner][axis][lane] == block.v[corner][axis][0];
          structure.check(copy,
                          [&] { return "unused lane does not copy lane 0, leaf " + std::to_string(leaf); });
          structure.check(h.leafCorners()[8 * leaf + lane] == h.leafCorners()[8 * leaf],
                          [&] { return "unused lane's corners do not copy lane 0, leaf " + std::to_string(leaf); });
          continue;
        }
        if (f >= m) {
          structure.check(
              false, [&] { return "leaf " + std::to_string(leaf) + " names face " + std::to_string(f); });
          continue;
        }
        ++face_seen[f];
        bool same = true;
        for (int corner = 0; corner < 3; ++corner)
          for (int axis = 0; axis < 3; ++axis)
            same = same && block.v[corner][axis][lane] == mesh.positions[mesh.triangles[f][corner]][axis];
        structure.check(same, [&] { return "leaf block coordinates differ from face " + std::to_string(f); });
        structure.check(h.leafCorners()[8 * leaf + lane] == mesh.triangles[f],
                        [&] { return "leaf corners differ from face " + std::to_string(f); });
      }
    }
  }
  for (size_t f = 0; f < m; ++f)
    structure.check(face_seen[f] == 1, [&] {
      return "face " + std::to_string(f) + " found " + std::to_string(face_seen[f]) + " times";
    });
  for (size_t x = 0; x < nodes.size(); ++x)
    structure.check(node_seen[x] == 1, [&] { return "node " + std::to_string(x) + " not reached once"; });
  for (size_t leaf = 0; leaf < leaf_seen.size(); ++leaf)
    structure.check(leaf_seen[leaf] == 1,
                    [&] { return "leaf " + std::to_string(leaf) + " not reached once"; });
  // Leaves are laid out depth-first: each node's leaves are exactly [leafBegin, leafEnd).
  for (int32_t x : order) {
    structure.check(leaf_count[x] == h.leafEnd(x) - h.leafBegin(x) && leaf_min[x] == h.leafBegin(x) &&
                        leaf_max[x] + 1 == h.leafEnd(x),
                    [&] {
                      return "node " + std::to_string(x) + " range [" + std::to_string(h.leafBegin(x)) +
                             ", " + std::to_string(h.leafEnd(x)) + ") but its leaves span [" +
                             std::to_string(leaf_min[x]) + ", " + std::to_string(leaf_max[x] + 1) + "), " +
                             std::to_string(leaf_count[x]) + " leaves";
                    });
  }
  CHECK(h.parentNode(0) == -1);
  return deepest;
}

// (d) Every radius bounds its subtree and is tight: the largest distance from the subtree's
// original vertices to the slot triangle, recomputed with the scalar closest-point routine.
void checkRadii(const Hierarchy& h) {
  const Mesh& mesh = h.mesh();
  const double slack = roundingSlack(mesh);
  Failures bound("radius below a subtree vertex's distance");
  Failures tight("radius not tight");
  size_t slots = 0;
  for (size_t node = 0; node < h.nodes().size(); ++node) {
    const Node8& n = h.nodes()[node];
    for (int k = 0; k < 8; ++k) {
      if (n.child[k] == kEmptyChild) continue;
      ++slots;
      const Vec3& a = mesh.positions[n.corner[0][k]];
      const Vec3& b = mesh.positions[n.corner[1][k]];
      const Vec3& c = mesh.positions[n.corner[2][k]];
      double worst = 0;
      for (TriangleIndex f : slotFaces(h, static_cast<int32_t>(node), k))
        for (VertexIndex v : mesh.triangles[f])
          worst = std::max(worst, distanceToTriangle(mesh.positions[v], a, b, c));
      const double eps = n.eps[k];
      const SlotRef s{static_cast<int32_t>(node), k};
      bound.check(eps >= worst - slack, [&] {
        std::ostringstream out;
        out.precision(17);
        out << describeSlot(h, s) << " < " << worst;
        return out.str();
      });
      tight.check(eps <= worst * (1 + 1e-5) + slack, [&] {
        std::ostringstream out;
        out.precision(17);
        out << describeSlot(h, s) << ", true radius " << worst;
        return out.str();
      });
    }
  }
  CHECK(slots >= 1);
}

// Bookkeeping tables other than the tree: vertexFace and the contraction record.
void checkTables(const Hierarchy& h) {
  const Mesh& mesh = h.mesh();
  const size_t n = mesh.positions.size();
  std::vector<bool> used(n, false);
  for (const Triangle& t : mesh.triangles)
    for (VertexIndex v : t) used[v] = true;
  REQUIRE(h.vertexFace().size() == n);
  REQUIRE(h.contractedInto().size() == n);
  Failures tables("tables");
  for (size_t v = 0; v < n; ++v) {
    const TriangleIndex f = h.vertexFace()[v];
    if (!used[v]) {
      tables.check(f == kInvalidIndex && h.contractedInto()[v] == kInvalidIndex,
                   [&] { return "unused vertex " + std::to_string(v) + " has a face or a contraction"; });
      continue;
    }
    const bool holds =
        f < mesh.triangles.size() &&
        std::find(mesh.triangles[f].begin(), mesh.triangles[f].end(), v) != mesh.triangles[f].end();
    tables.check(holds, [&] { return "vertexFace(" + std::to_string(v) + ") does not use the vertex"; });
    // Following contractions ends at a base vertex, without cycles; r_v >= 0.
    VertexIndex x = static_cast<VertexIndex>(v);
    size_t steps = 0;
    while (h.contractedInto()[x] != kInvalidIndex && steps <= n) {
      x = h.contractedInto()[x];
      ++steps;
    }
    tables.check(steps <= n && x < n && used[x],
                 [&] { return "contraction chain of vertex " + std::to_string(v) + " is broken"; });
  }
}

// Everything of (a)-(e) on one mesh.
void checkHierarchy(const Mesh& mesh, uint64_t seed) {
  INFO("mesh " << mesh.name << ": " << mesh.triangles.size() << " triangles, " << mesh.positions.size()
               << " vertices");
  std::shared_ptr<const Hierarchy> h;
  REQUIRE_NOTHROW(h = Hierarchy::build(mesh));
  REQUIRE(h);
  INFO("nodes " << h->nodes().size() << ", leaves " << h->leafCount() << ", depth " << h->stats().depth
                << ", base triangles " << h->stats().base_triangles);
  // The copy kept by the hierarchy is the input.
  REQUIRE(h->mesh().triangles == mesh.triangles);
  REQUIRE(h->mesh().positions == mesh.positions);
  // The contraction's checks stay linear in the mesh per round.
  CHECK(h->stats().adopter_visits <= 32 * (mesh.triangles.size() + 1) * std::max<uint32_t>(h->stats().rounds, 1));

  // (a)
  CHECK(validate(*h) == "");
  // (c)
  const uint32_t depth = checkExpansion(*h);
  // (b)
  checkCover(*h, seed);
  // (d)
  checkRadii(*h);
  checkTables(*h);

  // (e) stats.
  const HierarchyStats& stats = h->stats();
  CHECK(stats.depth == depth);
  CHECK(stats.depth >= 1);
  CHECK(stats.depth <= kMaxDepth);
  CHECK(stats.fixed_bytes > 0);
  CHECK(stats.fixed_bytes >= h->nodes().size() * sizeof(Node8) + h->leafCount() * sizeof(TriangleBlock8));
  CHECK(stats.total_seconds >= 0);
  CHECK(stats.base_triangles >= 1);
  CHECK(stats.base_triangles <= mesh.triangles.size());
  CHECK(stats.contractions < std::max<size_t>(mesh.positions.size(), 1));
  // The base mesh is small once there is anything to contract (the default asks for 16; a
  // round may overshoot a little, a stalled contraction would leave far more).
  if (mesh.triangles.size() > 16) {
    CHECK(stats.rounds >= 1);
    CHECK(stats.base_triangles <= 64);
  }
  CHECK(h->boxScale() > 0);
  CHECK(std::ldexp(1.0, std::ilogb(h->boxScale())) == h->boxScale());  // a power of two
  const uint32_t leaves_needed = static_cast<uint32_t>((mesh.triangles.size() + 7) / 8);
  CHECK(h->leafCount() >= leaves_needed);
  CHECK(h->leafCount() <= mesh.triangles.size());
  if (mesh.triangles.size() <= 8) {
    CHECK(h->nodes().size() == 1);
    CHECK(h->leafCount() == 1);
  }
}

Mesh firstTriangles(const Mesh& mesh, size_t count, const std::string& name) {
  Mesh out = mesh;
  out.triangles.resize(count);
  out.name = name;
  return out;
}

// A closed sphere with unused vertices interleaved (and one far away): the tree, its boxes and
// its radii must ignore them.
Mesh withUnusedVertices() {
  const Mesh sphere = scenes::icosphere(2);
  Mesh mesh;
  mesh.name = "icosphere(2) with unused vertices";
  std::vector<VertexIndex> remap(sphere.positions.size());
  mesh.positions.push_back({1000, -2000, 3000});
  for (size_t v = 0; v < sphere.positions.size(); ++v) {
    remap[v] = static_cast<VertexIndex>(mesh.positions.size());
    mesh.positions.push_back(sphere.positions[v]);
    if (v % 3 == 0) mesh.positions.push_back(Vec3(5.0 + v, -7.0, 0.25 * v));
  }
  for (const Triangle& t : sphere.triangles)
    mesh.triangles.push_back({remap[t[0]], remap[t[1]], remap[t[2]]});
  return mesh;
}

// Every vertex at one point: every triangle is that point.
Mesh coincidentVertices() {
  Mesh mesh;
  mesh.name = "all vertices coincide";
  Random random(77);
  for (int v = 0; v < 12; ++v) mesh.positions.push_back({0.5, -1.25, 3.0});
  for (int t = 0; t < 40; ++t)
    mesh.triangles.push_back({static_cast<VertexIndex>(random.index(12)),
                              static_cast<VertexIndex>(random.index(12)),
                              static_cast<VertexIndex>(random.index(12))});
  return mesh;
}

std::vector<Mesh> proceduralMeshes() {
  std::vector<Mesh> meshes;
  meshes.push_back(scenes::icosphere(3));
  meshes.push_back(scenes::torus(1.0, 0.3, 48, 24));
  meshes.push_back(scenes::randomSoup(2000, 11));
  meshes.push_back(scenes::degenerateMesh());
  meshes.push_back(scenes::gridPlane(20));
  meshes.push_back(scenes::uvSphere(12, 24));
  {
    Mesh parts = scenes::concatenate({scenes::icosphere(2, 0.5, Vec3(3, 0, 0)),
                                      scenes::torus(1.0, 0.25, 24, 12), scenes::randomSoup(150, 5),
                                      scenes::gridPlane(6, 2.0), scenes::degenerateMesh()});
    parts.name = "concatenated components";
    meshes.push_back(parts);
  }
  // The edge cases of the 8-wide layout: 1, 2, 8, 9, 65 faces, connected and as soups.
  const Mesh patch = scenes::icosphere(2);
  for (size_t count : {1, 2, 7, 8, 9, 16, 17, 64, 65}) {
    meshes.push_back(firstTriangles(patch, count, "icosphere patch of " + std::to_string(count)));
    Mesh soup = scenes::randomSoup(count, 100 + count);
    meshes.push_back(soup);
  }
  meshes.push_back(coincidentVertices());
  meshes.push_back(withUnusedVertices());
  // Far from the origin and tiny: float boxes in scaled coordinates must still be conservative.
  {
    Mesh far = scenes::icosphere(3, 1.0, Vec3(1e6, -2e6, 3e6));
    far.name = "icosphere(3) at 1e6";
    meshes.push_back(far);
    Mesh tiny = scenes::torus(1e-6, 3e-7, 32, 16);
    tiny.name = "torus of size 1e-6";
    meshes.push_back(tiny);
  }
  return meshes;
}

std::vector<Vec3> queryPoints(const Mesh& mesh) {
  std::vector<Vec3> points = scenes::randomPointsInBox(mesh, 300, 0.1, 3);
  const std::vector<Vec3> near = scenes::nearSurfacePoints(mesh, 300, 0.01, 4);
  points.insert(points.end(), near.begin(), near.end());
  return points;
}

struct Answer {
  ClosestPoint closest;
  ClosestPoint within;
  std::vector<TriangleHit> k;
};

std::vector<Answer> answer(std::shared_ptr<const Hierarchy> h, const std::vector<Vec3>& points, size_t begin,
                           size_t step) {
  QueryStream stream(std::move(h));
  std::vector<Answer> out;
  for (size_t i = begin; i < points.size(); i += step) {
    Answer a;
    a.closest = stream.closest(points[i]);
    a.within = stream.closestWithin(points[i], 1e-3);
    stream.kClosest(points[i], 5, a.k);
    out.push_back(std::move(a));
  }
  return out;
}

bool sameHits(const std::vector<TriangleHit>& a, const std::vector<TriangleHit>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].distance != b[i].distance || a[i].triangle != b[i].triangle || a[i].point != b[i].point)
      return false;
  return true;
}

bool sameClosest(const ClosestPoint& a, const ClosestPoint& b) {
  return a.distance == b.distance && a.lower == b.lower && a.upper == b.upper && a.triangle == b.triangle &&
         a.point == b.point && a.barycentric == b.barycentric;
}

}  // namespace

TEST_CASE("hierarchy invariants on procedural meshes", "[hierarchy]") {
  uint64_t seed = 1000;
  for (const Mesh& mesh : proceduralMeshes()) checkHierarchy(mesh, ++seed);
}

TEST_CASE("hierarchy invariants on real meshes", "[hierarchy][real]") {
  uint64_t seed = 2000;
  for (const char* name : {"armadillo", "holes", "blobby_3cc", "fandisk", "mannequin-devil"}) {
    const Mesh* mesh = realMesh(name);
    if (mesh) checkHierarchy(*mesh, ++seed);
  }
}

TEST_CASE("hierarchy: a 16-triangle base still gives a shallow tree on soups", "[hierarchy]") {
  // A soup has no edges to contract: every contraction crosses a gap. The top must stay small.
  for (size_t count : {500, 5000}) {
    const Mesh soup = scenes::randomSoup(count, 31 + count);
    INFO(soup.name);
    const auto h = Hierarchy::build(soup);
    CHECK(validate(*h) == "");
    CHECK(h->stats().depth <= kMaxDepth);
    // An 8-wide tree over n faces needs about log8(n / 8) levels; allow a generous factor.
    const double ideal = std::log(static_cast<double>(count) / 8) / std::log(8.0) + 1;
    CHECK(h->stats().depth <= 6 * ideal + 4);
  }
}

// Valid but hostile topologies: 65,536 copies of one triangle, 65,536 triangles on one edge
// (a book), and a polygon with 65,536 corners fanned over four vertices. Each vertex takes one
// contraction a round and each proposal walked the stars pairwise, so these builds took
// seconds to minutes (quadratic); now linear. The trees must hold their invariants and answer
// exactly.
TEST_CASE("hierarchy: many triangles on one edge or one triangle build and answer exactly", "[hierarchy]") {
  constexpr uint32_t kCount = 1u << 16;
  constexpr double kPi = 3.14159265358979323846;
  Mesh copies, book, fan;
  copies.name = "copies";
  copies.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.2, 1, 0.1)};
  copies.triangles.assign(kCount, Triangle{0, 1, 2});
  book.name = "book";
  book.positions = {Vec3(0, 0, 0), Vec3(0, 0, 1)};
  for (uint32_t i = 0; i < kCount; ++i) {
    const double angle = 2 * kPi * i / kCount;
    book.positions.push_back(Vec3(std::cos(angle), std::sin(angle), 0.5));
    book.triangles.push_back(Triangle{0, 1, i + 2});
  }
  fan.name = "fan";
  fan.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0.2)};
  for (uint32_t k = 1; k + 1 < kCount; ++k) fan.triangles.push_back(Triangle{0, k % 4, (k + 1) % 4});
  // A vertex of high degree whose rim vertices are nearer to it than to each other (a gear:
  // rim radii 1 and 3 in turn), so each rim vertex is contracted into it: finding the adopters
  // of the two triangles each contraction deletes walked the hub's whole star (found by review:
  // 200,000 rim vertices took 54 s to build).
  Mesh sun;
  sun.name = "sun";
  sun.positions = {Vec3(0, 0, 0)};
  for (uint32_t i = 0; i < kCount; ++i) {
    const double angle = 2 * kPi * i / kCount, r = i % 2 ? 3 : 1;
    sun.positions.push_back(Vec3(r * std::cos(angle), r * std::sin(angle), 0));
    sun.triangles.push_back(Triangle{0, 1 + i, 1 + (i + 1) % kCount});
  }
  for (const Mesh* mesh : {&copies, &book, &fan, &sun}) {
    INFO(mesh->name);
    const auto h = Hierarchy::build(*mesh);
    CHECK(validate(*h) == "");
    // The contraction's work stays linear in the mesh per round.
    CHECK(h->stats().adopter_visits <= 32 * mesh->triangles.size() * h->stats().rounds);
    QueryStream stream(h);
    for (const Vec3& p : {Vec3(0.3, 0.2, 0.5), Vec3(-1, 2, 3), Vec3(0.5, 0.5, 0.5), Vec3(0, 0, 0.4)}) {
      const ClosestPoint c = stream.closest(p);
      const auto truth = bruteForceClosest(*mesh, p);
      CHECK(c.distance == Approx(truth.distance).epsilon(1e-12).margin(1e-15));
      // Ties go to the lowest index among the least squared distances (brute force compares
      // the distances, whose square roots can merge values an ulp apart).
      auto squared = [&](TriangleIndex t) {
        const Triangle& f = mesh->triangles[t];
        return squaredDistanceToTriangle(p, mesh->positions[f[0]], mesh->positions[f[1]], mesh->positions[f[2]]);
      };
      CHECK(squared(c.triangle) <= squared(truth.triangle));
      if (squared(c.triangle) == squared(truth.triangle)) CHECK(c.triangle <= truth.triangle);
    }
  }
}

TEST_CASE("hierarchy: bad input throws MeshError with a useful message", "[hierarchy]") {
  SECTION("empty mesh") {
    Mesh mesh;
    mesh.name = "empty-mesh";
    CHECK_THROWS_AS(Hierarchy::build(mesh), MeshError);
    CHECK_THROWS_WITH(Hierarchy::build(mesh),
                      Catch::Contains("empty-mesh") && Catch::Contains("no triangles"));
    mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    CHECK_THROWS_WITH(Hierarchy::build(mesh),
                      Catch::Contains("empty-mesh") && Catch::Contains("no triangles"));
  }
  SECTION("NaN vertex") {
    Mesh mesh = scenes::icosphere(1);
    mesh.name = "nan-sphere";
    mesh.positions[7].y() = std::numeric_limits<double>::quiet_NaN();
    CHECK_THROWS_AS(Hierarchy::build(mesh), MeshError);
    CHECK_THROWS_WITH(Hierarchy::build(mesh), Catch::Contains("nan-sphere") && Catch::Contains("vertex 7") &&
                                                  Catch::Contains("non-finite"));
  }
  SECTION("vertex beyond 1e150 (distances would overflow)") {
    Mesh mesh = scenes::icosphere(1);
    mesh.name = "huge-sphere";
    mesh.positions[5].x() = 2e150;
    CHECK_THROWS_WITH(Hierarchy::build(mesh), Catch::Contains("huge-sphere") && Catch::Contains("vertex 5") &&
                                                  Catch::Contains("beyond 1e150"));
    mesh = scenes::icosphere(1, 1.0, Vec3(1e150 - 2, 0, 0));  // up to the limit itself: accepted
    CHECK_NOTHROW(Hierarchy::build(mesh));
  }
  SECTION("sizes outside [1e-50, 1e50] (the exact distance would overflow or underflow)") {
    // Below about 1e-154 the diagonal's square underflows: it must not pass for a point (found
    // by review: a sphere of size 1e-300 was accepted and answered 0 at 1e-300 from it).
    for (const double scale : {1e60, 1e-60, 1e-160, 1e-300, 4e-320}) {
      Mesh mesh = scenes::icosphere(1, scale);
      mesh.name = "scaled-sphere";
      CHECK_THROWS_WITH(Hierarchy::build(mesh), Catch::Contains("scaled-sphere") && Catch::Contains("rescale"));
    }
    // Within the range, exact; a mesh of one point (size 0) too.
    for (const double scale : {1e45, 1e-45}) {
      const Mesh mesh = scenes::icosphere(1, scale);
      const auto h = Hierarchy::build(mesh);
      QueryStream stream(h);
      for (const Vec3& unit : {Vec3(0.3, 0.2, 0.1), Vec3(2, -1, 0.5), Vec3(0.57, 0.01, 0.81)}) {
        const Vec3 p = unit * scale;
        const double expected = bruteForceClosest(mesh, p).distance;
        CHECK(std::abs(stream.closest(p).distance - expected) <= 1e-12 * expected);
      }
    }
    Mesh point;
    point.positions = {Vec3(1, 2, 3), Vec3(1, 2, 3), Vec3(1, 2, 3)};
    point.triangles = {Triangle{0, 1, 2}};
    CHECK_NOTHROW(Hierarchy::build(point));
  }
  SECTION("infinite vertex") {
    Mesh mesh = scenes::icosphere(1);
    mesh.name = "inf-sphere";
    mesh.positions[3].z() = -std::numeric_limits<double>::infinity();
    CHECK_THROWS_WITH(Hierarchy::build(mesh), Catch::Contains("inf-sphere") && Catch::Contains("vertex 3"));
  }
  SECTION("out-of-range index") {
    Mesh mesh = scenes::gridPlane(3);
    mesh.name = "bad-grid";
    mesh.triangles[5][2] = static_cast<VertexIndex>(mesh.positions.size());
    CHECK_THROWS_AS(Hierarchy::build(mesh), MeshError);
    CHECK_THROWS_WITH(Hierarchy::build(mesh), Catch::Contains("bad-grid") && Catch::Contains("triangle 5") &&
                                                  Catch::Contains("vertex 16"));
    mesh.triangles[5][2] = kInvalidIndex;
    CHECK_THROWS_AS(Hierarchy::build(mesh), MeshError);
  }
}

TEST_CASE("hierarchy: shared read-only by two threads", "[hierarchy][threads]") {
  std::vector<Mesh> meshes;
  meshes.push_back(scenes::torus(1.0, 0.3, 64, 32));
  if (const Mesh* armadillo = realMesh("armadillo")) meshes.push_back(*armadillo);
  for (const Mesh& mesh : meshes) {
    INFO(mesh.name);
    const std::shared_ptr<const Hierarchy> h = Hierarchy::build(mesh);
    const std::vector<Vec3> points = queryPoints(mesh);
    const std::vector<Answer> single = answer(h, points, 0, 1);
    // Two threads over interleaved halves, at the same time, one stream each.
    std::vector<Answer> even, odd;
    std::thread first([&] { even = answer(h, points, 0, 2); });
    std::thread second([&] { odd = answer(h, points, 1, 2); });
    first.join();
    second.join();
    REQUIRE(even.size() + odd.size() == single.size());
    size_t differ = 0;
    for (size_t i = 0; i < single.size(); ++i) {
      const Answer& a = i % 2 == 0 ? even[i / 2] : odd[i / 2];
      const bool same = sameClosest(a.closest, single[i].closest) &&
                        sameClosest(a.within, single[i].within) && sameHits(a.k, single[i].k);
      if (!same && ++differ <= 5)
        FAIL_CHECK("point " << i << " " << text(points[i]) << " differs between threads");
    }
    CHECK(differ == 0);
  }
}

TEST_CASE("hierarchy: refitted radii are the exact maxima over each subtree", "[hierarchy]") {
  // refitBounds skips subtrees whose box cannot raise a slot's radius (branch and bound); the
  // result must equal the plain maximum over every subtree vertex, bit for bit, at the rest
  // positions (the build's radii) and at moved ones.
  std::vector<Mesh> meshes = {scenes::torus(1.0, 0.3, 48, 24), scenes::randomSoup(2000, 77),
                              scenes::concatenate({scenes::icosphere(3), scenes::gridPlane(12)})};
  if (const Mesh* holes = realMesh("holes")) meshes.push_back(*holes);
  for (const Mesh& mesh : meshes) {
    INFO(mesh.name);
    const auto h = Hierarchy::build(mesh);
    Random random(5);
    std::vector<Vec3> moved = mesh.positions;
    for (Vec3& x : moved) x += 0.05 * Vec3(random.uniform(-1, 1), random.uniform(-1, 1), random.uniform(-1, 1));
    const std::vector<Vec3>* position_sets[] = {&mesh.positions, &moved};
    for (const std::vector<Vec3>* positions : position_sets) {
      std::vector<Node8> nodes = h->nodes();
      refitBounds(*h, positions->data(), nodes, true);
      CHECK(validateGeometry(*h, TreeGeometry{nodes.data(), nullptr, positions->data(), h->center(),
                                              h->boxScale(), 1}) == "");
      size_t differ = 0;
      for (size_t node = 0; node < nodes.size(); ++node) {
        for (int k = 0; k < 8; ++k) {
          if (nodes[node].child[k] == kEmptyChild) continue;
          const Vec3& a = (*positions)[nodes[node].corner[0][k]];
          const Vec3& b = (*positions)[nodes[node].corner[1][k]];
          const Vec3& c = (*positions)[nodes[node].corner[2][k]];
          double worst = 0;
          for (TriangleIndex f : slotFaces(*h, static_cast<int32_t>(node), k))
            for (VertexIndex v : mesh.triangles[f])
              worst = std::max(worst, squaredDistanceToTriangle((*positions)[v], a, b, c));
          const float expected = std::nextafter(static_cast<float>(std::sqrt(worst) * (1 + 1e-9)),
                                                std::numeric_limits<float>::infinity());
          const bool rest_differs = positions == &mesh.positions && nodes[node].eps[k] != h->nodes()[node].eps[k];
          if ((nodes[node].eps[k] != expected || rest_differs) && ++differ <= 5)
            FAIL_CHECK("node " << node << " slot " << k << ": eps " << nodes[node].eps[k] << ", exhaustive "
                               << expected << ", built " << h->nodes()[node].eps[k]);
        }
      }
      CHECK(differ == 0);
    }
  }
}

// The float roundings that keep float boxes and radii conservative: never on the wrong side of
// the double they stand for, at any sign and magnitude (normal, subnormal, zero), and within a
// few float ulps of it.
TEST_CASE("float roundings: floatAtLeast, floatAbove, floatBelow", "[hierarchy]") {
  Random random(41);
  size_t checked = 0;
  for (int i = 0; i < 50000; ++i) {
    const double magnitude = std::ldexp(random.uniform(0.5, 1.0), static_cast<int>(random.uniform(-160, 120)));
    const double x = i % 2 ? magnitude : -magnitude;
    const float above = floatAbove(x), below = floatBelow(x);
    REQUIRE(static_cast<double>(above) >= x);
    REQUIRE(static_cast<double>(below) <= x);
    // Within a few float ulps: 2^-21 relative, 2^-146 absolute (subnormal floats).
    const double slack = std::abs(x) * 0x1p-21 + 0x1p-146;
    REQUIRE(static_cast<double>(above) - x <= slack);
    REQUIRE(x - static_cast<double>(below) <= slack);
    if (x >= 0) REQUIRE(static_cast<double>(floatAtLeast(x)) >= x);
    ++checked;
  }
  for (double x : {0.0, -0.0, 1e-300, -1e-300, 1.0, -1.0, 0x1p-149, -0x1p-149}) {
    CHECK(static_cast<double>(floatAbove(x)) >= x);
    CHECK(static_cast<double>(floatBelow(x)) <= x);
  }
  CHECK(checked == 50000);
}

// The mesh's size check reads its diagonal through stableLength: a plain norm's square
// underflows to 0 below about 1e-154 (a tiny mesh would pass as a point) and overflows above
// about 1e154. Checked against long double (whose exponent range holds every square of a
// double) at every scale a double has, and on the special values.
TEST_CASE("stableLength: no underflow or overflow at any scale; NaN and infinity kept", "[hierarchy]") {
  Random random(43);
  for (int i = 0; i < 20000; ++i) {
    const int exponent = static_cast<int>(random.uniform(-1070, 1020));
    Vec3 d;
    for (int c = 0; c < 3; ++c)
      d[c] = std::ldexp(random.uniform(-1.0, 1.0), exponent + static_cast<int>(random.uniform(-40, 2)));
    if (i % 7 == 0) d[i % 3] = 0;
    const long double x = d.x(), y = d.y(), z = d.z();
    const long double expected = std::sqrt(x * x + y * y + z * z);
    const double length = stableLength(d);
    INFO(d.transpose() << " -> " << length);
    REQUIRE(std::isfinite(length));
    // A few ulps (of the result, or of the smallest subnormal when the result is one).
    REQUIRE(std::abs(static_cast<long double>(length) - expected) <= 1e-15L * expected + 1e-323L);
  }
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  CHECK(stableLength(Vec3(0, 0, 0)) == 0);
  CHECK(stableLength(Vec3(-3, 4, 0)) == 5);
  CHECK(std::isnan(stableLength(Vec3(0, 0, nan))));  // Eigen's stableNorm gives 0 here
  CHECK(std::isnan(stableLength(Vec3(inf, 0, nan))));
  CHECK(stableLength(Vec3(1, -inf, 2)) == inf);
  CHECK(stableLength(Vec3(1e-300, 1e-300, 0)) > 1.4e-300);
  CHECK(stableLength(Vec3(1e300, -1e300, 1e300)) > 1.7e300);
}
