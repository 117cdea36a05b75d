#pragma once
// Queries on a Hierarchy from a per-stream state object (DESIGN.md section 2).
//
// A QueryStream holds the changing state of one query stream (scratch stacks, the priority
// front); the Hierarchy it reads is fixed and shared. A stream is cheap to create, reusable,
// and allocation-free once warm. One stream per thread.
#include "core/hierarchy.h"

#include <memory>
#include <vector>

namespace meshsweeper {

// Work done by one query, so a benchmark can show work as well as time.
struct QueryCounters {
  uint32_t nodes_visited = 0;      // 8-wide nodes whose children were bounded
  uint32_t leaves_tested = 0;      // leaf blocks tested
  uint32_t triangles_tested = 0;   // exact point-triangle distances (lanes used)
  uint32_t heap_max = 0;           // largest priority front (priority queries)
};

// The answer to a closest-point query.
struct ClosestPoint {
  double distance = 0;              // exact distance, or the upper bound for an anytime query
  double lower = 0, upper = 0;      // certified bounds; lower == upper == distance when exact
  Vec3 point = Vec3::Zero();        // a point of the mesh at `distance` (exactly closest if exact)
  TriangleIndex triangle = kInvalidIndex;  // original face index (file order)
  Vec3 barycentric = Vec3::Zero();  // point = b0*A + b1*B + b2*C of that face
  Feature feature = Feature::kFace;
  QueryCounters counters;
};

// One triangle found by k-closest or within-d queries.
struct TriangleHit {
  double distance = 0;
  TriangleIndex triangle = kInvalidIndex;
  Vec3 point = Vec3::Zero();
  Vec3 barycentric = Vec3::Zero();
  Feature feature = Feature::kFace;
};

class QueryStream {
 public:
  explicit QueryStream(std::shared_ptr<const Hierarchy> hierarchy);

  const Hierarchy& hierarchy() const { return *hierarchy_; }

  // Exact closest point: depth-first, closest child first, pruning with the best distance.
  ClosestPoint closest(const Vec3& p);

  // Anytime query (the paper's priority process): stops as soon as upper - lower <= tolerance
  // (absolute) and returns certified [lower, upper]; `point`/`triangle` is a surface point at
  // distance `upper`. tolerance 0 gives the exact answer.
  ClosestPoint closestWithin(const Vec3& p, double tolerance);

  // The k closest triangles, by increasing distance (fewer if the mesh has fewer).
  // Ties at equal distance are ordered by triangle index.
  void kClosest(const Vec3& p, size_t k, std::vector<TriangleHit>& out);

  // All triangles at distance <= d, by increasing distance (ties by triangle index).
  void within(const Vec3& p, double d, std::vector<TriangleHit>& out);

  // Counters of the last query.
  const QueryCounters& counters() const { return counters_; }

 private:
  struct FrontEntry {
    double key;       // lower bound of the entry's subtree (exact distance for a face)
    ChildRef ref;     // node or leaf block; for a face (lane < 8) its triangle index
    uint32_t lane;    // 8 for a node or leaf block
  };
  struct StackEntry {
    ChildRef ref;     // node or leaf block
    float bound;      // squared box distance in the hierarchy's scaled units
  };
  std::shared_ptr<const Hierarchy> hierarchy_;
  std::vector<StackEntry> stack_;
  std::vector<FrontEntry> heap_;
  QueryCounters counters_;
};

}  // namespace meshsweeper
