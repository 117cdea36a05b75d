#pragma once
// Queries on a Hierarchy from a per-stream state object (DESIGN.md section 2).
//
// A QueryStream holds the changing state of one query stream (scratch stacks, the priority
// front); the Hierarchy it reads is fixed and shared. A stream is cheap to create, reusable,
// and allocation-free once warm. One stream per thread.
#include "core/hierarchy.h"

#include <limits>
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

// Settings of the coherent queries (DESIGN.md section 2), shared by all streams that use them.
struct CoherenceOptions {
  // Set certificate: candidates are gathered within d + 2R of the anchor point, with
  // R = reach_steps * (running mean step length); a larger R means fewer rebuilds, larger sets.
  // Defaults measured in bench_dynamic (armadillo and refined_elephant, off5%/step0.05%).
  double reach_steps = 2;
  // At most this many candidate faces (the nearest are kept; the certificate shrinks to fit).
  uint32_t max_candidates = 64;
  // Dynamic front: back to the roots when the front holds more entries than this, or when the
  // point jumps farther than jump_factor times its last distance to the mesh.
  uint32_t front_budget = 4096;
  double jump_factor = 1.0;
};

// What the coherent queries of a stream did since the stream was created or reset.
struct CoherenceCounters {
  uint64_t steps = 0;           // coherent queries answered
  uint64_t certified = 0;       // answered from the cached candidate set
  uint64_t rebuilds = 0;        // candidate set rebuilt (a depth-first query)
  uint64_t searched = 0;        // closestCoherent(p) backing off: a depth-first query, no set
                                // (certified + rebuilds + searched = its queries, but for
                                // points not finite or beyond 1e153: answered without a
                                // search, they count in steps only)
  uint64_t candidates = 0;      // candidate faces gathered over all rebuilds
  uint64_t front_resets = 0;    // dynamic front restarted from the roots
  uint64_t recomputed = 0;      // stale front entries recomputed
};

// Compact coherent state of one moving point against one mesh (a cloth vertex against a body):
// a default-constructed state (or `CoherentState{}`) means a cold start. A memset to zero is
// not one: its tunings (reach_steps, lead_steps) read 0, and a state with reach_steps 0 never
// gathers a set (it answers exactly, by plain searches). Used with
// QueryStream::closestCoherent(p, state, ...), where the stream lends its scratch memory; the
// state keeps only the certificate: an anchor, a reach and up to kCoherentSetSize candidate
// faces sorted by distance from the anchor, tested eight at a time. The anchor is the point
// where the set was rebuilt, or lead_steps of its mean steps ahead of it (the point must then
// be certified by the new set too). It stays valid while the geometry moves within its lineage
// (TreeGeometry::lineage, ::drift): a deforming body's faces are re-read at their current
// positions and the certificate shrinks by how far they may have moved.
inline constexpr uint32_t kCoherentSetSize = 48;
struct CoherentState {
  Vec3 anchor = Vec3::Zero();        // where the candidate set was gathered
  double reach = 0;                  // every face outside the set was at least this far from anchor
  double drift_at = 0;               // the geometry's drift when the set was gathered
  double last_drift = 0;             // the drift the point's motion follows, at the last query
                                     // (its region's, last_local, or the geometry's)
  // With drift by region (TreeGeometry::regions): the region of the set's nearest face, that
  // face's distance from the anchor (rounded up) and the region's drift values at the gather.
  // The faces within the region's first width then count their own motion, those farther only
  // once they could come within the set's reach. region_epoch 0: the geometry's drift only.
  uint64_t region_epoch = 0;
  double region_at[2] = {0, 0};
  uint64_t lineage = 0;              // geometry lineage of the set and last face (0: cold)
  TriangleIndex last_face = kInvalidIndex;  // closest face of the last query (within its cap)
  uint32_t count = 0;                // candidate faces
  float mean_step = 0;               // running mean of the point's motion relative to the mesh
  float reach_steps = 2;             // R = reach_steps * mean_step (see CoherenceOptions); 0: no set
  float lead_steps = 3;              // a set is gathered this many mean steps ahead of the point,
                                     // along mean_velocity (when within 2 R; 0: at the point)
  float region_best = 0;             // (drift by region, above)
  uint16_t region = 0;               // (drift by region, above)
  bool last_local = false;           // last_drift is the region's first-level drift
  bool has_set = false;              // anchor, reach and faces hold a certificate
  uint8_t within_wait = 0;           // withinCoherent: steps to go before gathering a set again
                                     // (the last one could not hold every face within d)
  uint8_t closest_wait = 0;          // closestCoherent: steps to go before gathering a set again
                                     // (the last one failed within two tests: fast motion)
  uint8_t closest_backoff = 0;       // the next such wait (doubles while sets keep failing)
  uint8_t set_steps = 0;             // steps the set has certified since it was gathered (either mode)
  bool set_unmeasured = false;       // the set was gathered before the point's motion was measured
                                     // (a cold state's first): its failing is no sign of fast motion
  Vec3 last_point = Vec3::Zero();
  Eigen::Vector3f mean_velocity = Eigen::Vector3f::Zero();  // running mean of the point's steps
  TriangleIndex faces[kCoherentSetSize];        // candidates, in blocks of eight
  float block_lower[kCoherentSetSize / 8] = {};  // faces[8b..count) were at least this far from anchor
};

// One entry of the dynamic front, for pictures and diagnostics: the triangle whose swept
// volume bounds the entry (three original vertices) and its radius; an original face has
// eps = 0 and `face` set.
struct FrontTriangle {
  Triangle corners{};
  float eps = 0;
  bool face = false;
};

struct ScaledPoint;  // a query point as the node boxes read it (sweep_query.cpp)

class QueryStream {
 public:
  explicit QueryStream(std::shared_ptr<const Hierarchy> hierarchy, CoherenceOptions options = {});

  const Hierarchy& hierarchy() const { return *hierarchy_; }

  // Queries read `geometry` instead of the hierarchy's rest geometry (nullptr: back to rest).
  // The geometry must share the hierarchy's layout and outlive its use; when its version
  // changes, coherent state is rebuilt.
  void setGeometry(const TreeGeometry* geometry);

  // Every query takes a point with finite coordinates within kMaxQueryCoordinate (core/types.h);
  // any other point is answered, never searched: NaN distance and bounds, triangle
  // kInvalidIndex (closest*), no faces (kClosest*, within), and coherent state restarts.
  // Exact answers (closest(), closestCoherent(), and closestWithin*() with tolerance 0) give
  // ties at equal distance (as reported: two squared distances an ulp apart can have one root)
  // to the lowest triangle index, like kClosest() and the brute force, so they never depend on
  // the search order, the warm start or a cached set.

  // Exact closest point: depth-first, closest child first, pruning with the best distance.
  ClosestPoint closest(const Vec3& p);

  // Anytime query (the paper's priority process): stops as soon as upper - lower <= tolerance
  // (absolute) and returns certified [lower, upper]; `point`/`triangle` is a surface point at
  // distance `upper`. tolerance 0 (or negative, NaN) gives the exact answer, by closest(). The
  // heap costs more per node than the depth-first search: even a loose tolerance costs about
  // what the exact answer does (20,000 points near armadillo: exact 0.035 s; tolerance 0.1, 1,
  // 10: 0.15, 0.12, 0.036 s).
  ClosestPoint closestWithin(const Vec3& p, double tolerance);

  // The k closest triangles, by increasing distance (fewer if the mesh has fewer).
  // Ties at equal distance are ordered by triangle index.
  void kClosest(const Vec3& p, size_t k, std::vector<TriangleHit>& out);

  // All triangles at distance <= d, by increasing distance (ties by triangle index).
  void within(const Vec3& p, double d, std::vector<TriangleHit>& out);

  // Exact closest point for a point that moves a little between calls (a path): answered from
  // a cached candidate set while its certificate holds, else by a warm-started depth-first
  // query that rebuilds the set. Same answers as closest(), bit for bit, ties included (at any
  // distance from the origin: the set's margins count the coordinates' rounding). On a body's
  // geometry (setGeometry: key frames, a deforming body), whose every change is a new version,
  // the stream keeps a CoherentState of its own and answers as closestCoherent(p, state): its set
  // survives the changes within a lineage (found by an audit: the stream's set, copied faces,
  // held for one version only, and every query searched afresh).
  ClosestPoint closestCoherent(const Vec3& p);

  // The same for a caller-held compact state (one per moving point and mesh); this stream only
  // lends scratch memory, so one stream per thread serves any number of states. `certified`
  // (optional) tells whether the cached set answered. A state belongs to one mesh; its set
  // survives changes of the geometry within a lineage (deforming bodies), else only its
  // previous face warm-starts the search.
  // With max_distance finite the question is "the closest face within max_distance": the same
  // answer as closest() when that is within max_distance (up to a relative 1e-12 and 1e-15 of
  // the rest mesh's size, the hierarchy's: the rounding of a computed distance; a deforming or
  // key-framed body far smaller than its rest mesh keeps that absolute slack), else no face
  // (triangle kInvalidIndex, distance +infinity), found or certified without looking farther.
  // A negative or NaN max_distance counts as 0: only a face the point lies on (distance 0, up
  // to that rounding) is an answer; lower is then 0.
  ClosestPoint closestCoherent(const Vec3& p, CoherentState& state, bool* certified = nullptr,
                               double max_distance = std::numeric_limits<double>::infinity());

  // All faces within d of a moving point (the answer of within(), the same faces, hits and
  // order), from the same compact state: a set gathered within d + 2R of its anchor (at most
  // kCoherentSetSize faces, the nearest) answers while d + (motion since) stays below its
  // reach; else it is gathered again. Where more faces than that lie within d, the step is a
  // plain within() query and the state waits a few steps before trying a set again. A state
  // serves closestCoherent and withinCoherent alike (both read the same certificate).
  void withinCoherent(const Vec3& p, double d, CoherentState& state, std::vector<TriangleHit>& out,
                      bool* certified = nullptr);

  // The paper's dynamic process for a moving point: the priority front persists between calls;
  // moving by delta lowers every bound by delta (a drift offset, O(1)), stale entries are
  // recomputed when they reach the front. Same contracts as closestWithin() and kClosest().
  ClosestPoint closestWithinCoherent(const Vec3& p, double tolerance);
  void kClosestCoherent(const Vec3& p, size_t k, std::vector<TriangleHit>& out);

  // Forgets the coherent state: the next coherent query starts from the roots.
  void reset();

  // Counters of the last query, and of the coherent queries so far.
  const QueryCounters& counters() const { return counters_; }
  const CoherenceCounters& coherence() const { return coherence_; }
  // Entries in the dynamic front (changing state, for memory reports).
  size_t frontSize() const { return front_.size(); }
  // The triangles of the dynamic front (the paper's refined mesh of Fig. 6): coarse slot
  // triangles far from the point, original faces near it. Does not change the stream.
  void frontTriangles(std::vector<FrontTriangle>& out) const;
  // Bytes of changing state this stream holds (its object and the capacity of its buffers):
  // the per-stream memory, nothing per vertex of the mesh.
  size_t stateBytes() const;
  // Frees the per-query buffers (search stack and heap, gathered faces, a within query's hits)
  // whose capacity exceeds `entries`: one query over many faces (within a large distance)
  // leaves them at their largest, and a stream kept for later would hold that memory. Answers
  // and coherent state are unchanged; the next such query allocates again.
  void trimScratch(size_t entries = 4096);

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
  // An entry of the dynamic front: key = bound + drift when computed, so the current bound is
  // key - drift_ and heap order never changes as the point moves.
  struct DriftEntry {
    double key;
    double drift_at;  // drift_ when the bound was computed; stale when < drift_
    ChildRef ref;     // node or leaf block, or a face's triangle index (lane < 8)
    int32_t parent;   // node holding the slot whose bounds apply (-1: the root)
    uint8_t slot;     // slot in the parent node
    uint8_t lane;     // 8 for a node or leaf block
  };

  const TreeGeometry& geometry() const { return geometry_ ? *geometry_ : rest_; }
  uint32_t testLeaf(int32_t leaf, const Vec3& p, double out[8]);
  const TriangleBlock8& leafBlock(int32_t leaf);
  TriangleHit hitOn(TriangleIndex face, const Vec3& p) const;
  // Squared distance from p to `face` at the current geometry's positions.
  double squaredDistanceToFace(TriangleIndex face, const Vec3& p) const;
  double gatherCandidates(const Vec3& p, double start2, double reach, uint32_t capacity,
                          TriangleIndex& best_face, bool sorted = false);
  void orderIntoBlocks(float* block_lower, size_t blocks);
  void storeSet(const Vec3& anchor, double set_reach, CoherentState& state) const;
  void canonicalExact(const Vec3& p, ClosestPoint& out);
  bool testSet(const CoherentState& state, const Vec3& p, double moved, double within, double& best2,
               TriangleIndex& face);
  bool testSetWithin(const CoherentState& state, const Vec3& p, double moved, double d,
                     std::vector<TriangleHit>& out);
  // Within: the lanes of `block` (faces[lane]) within squared distance d2 of p, with their hits.
  void keepWithin(const Vec3& p, const TriangleBlock8& block, const TriangleIndex* faces, uint32_t lanes, double d2);
  void finishWithin(double d, std::vector<TriangleHit>& out);
  double depthFirst(const Vec3& p, double start2, double reach, TriangleIndex& best_face,
                    uint32_t capacity = 0);
  double entryBound(const DriftEntry& e, const Vec3& p, const ScaledPoint& sp) const;
  void frontStart(const Vec3& p);
  void frontMove(const Vec3& p);
  void frontPush(const DriftEntry& e);
  DriftEntry frontPop();
  void frontRefine(const Vec3& p, const ScaledPoint& sp, double& upper, TriangleIndex& upper_face,
                   VertexIndex& upper_vertex, bool stop_at_tolerance, double tolerance, size_t k,
                   std::vector<TriangleHit>* out);

  std::shared_ptr<const Hierarchy> hierarchy_;
  CoherenceOptions options_;
  TreeGeometry rest_;
  const TreeGeometry* geometry_ = nullptr;
  std::vector<StackEntry> stack_;
  std::vector<FrontEntry> heap_;
  QueryCounters counters_;
  CoherenceCounters coherence_;
  TriangleBlock8 gather_;
  // Set certificate (closestCoherent).
  bool has_set_ = false;
  uint64_t set_version_ = 0;
  Vec3 anchor_ = Vec3::Zero();
  double set_reach_ = 0;                    // every face outside the set is farther from anchor_
  std::vector<TriangleIndex> set_faces_;    // [candidate]
  std::vector<TriangleBlock8> set_blocks_;  // candidates' coordinates, 8 per block
  std::vector<float> set_block_lower_;      // per block: its and later faces' least distance
  std::vector<std::pair<double, TriangleIndex>> gathered_;
  // Within: the faces found, (distance, face) and their hits in within_hits_.
  struct WithinKey {
    double distance;
    TriangleIndex face;
    uint32_t hit;
    bool operator<(const WithinKey& o) const { return distance != o.distance ? distance < o.distance : face < o.face; }
  };
  std::vector<WithinKey> within_keys_;
  std::vector<TriangleHit> within_hits_;
  BlockClosest8 within_details_;
  double pruned_lower_ = 0;  // depthFirst with reach > 0: a lower bound on what it did not gather
  bool has_last_ = false;
  Vec3 last_point_ = Vec3::Zero();
  TriangleIndex last_face_ = kInvalidIndex;
  double mean_step_ = 0;
  // closestCoherent(p)'s back-off, as CoherentState's closest_wait, closest_backoff, set_steps
  // and set_unmeasured: after a set that failed within two tests, plain searches for a while.
  uint8_t closest_wait_ = 0, closest_backoff_ = 0, set_steps_ = 0;
  bool set_unmeasured_ = false;
  CoherentState body_state_;  // closestCoherent(p) on a body's geometry
  // Dynamic front (closestWithinCoherent, kClosestCoherent).
  std::vector<DriftEntry> front_;
  std::vector<DriftEntry> popped_;
  bool has_front_ = false;
  uint64_t front_version_ = 0;
  Vec3 front_point_ = Vec3::Zero();
  double drift_ = 0;
  double front_distance_ = 0;
  double lower_ = 0;  // the front's lower bound after the last refinement
  bool front_tie_ = true;  // the last refinement's answer may tie with another face
};

}  // namespace meshsweeper
