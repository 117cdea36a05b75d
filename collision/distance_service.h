#pragma once
// The distance-query service (DESIGN.md section 5): bodies in a world, a broadphase, and batched,
// parallel, exact closest-point / within-distance queries for many moving points (cloth
// vertices, particles) step after step.
//
// Lifetimes (STYLE.md):
//  - fixed, shared: Hierarchy (caller-built, or hierarchyFor()) and BodyShape (topology,
//    closedness, rest pseudonormals), one per mesh whatever the number of bodies using it;
//  - per body, per step: pose, key-frame time or deformed positions with their bounds
//    (deform/), and the body's world box, recomputed once per step when it changed;
//  - per (point, body) pair: a CoherentState (core/sweep_query.h, 376 bytes) carried from one
//    step to the next, plus one QueryStream per thread and body that lends scratch memory.
//
// Coherent-state policy: a step keeps exactly the states of the (point, body) pairs it queried
// (either mode: closest and within steps read and renew the same states); a pair that the
// broadphase no longer reports (the point left the body's box inflated by the query distance)
// is dropped, and starts cold if it comes back. Memory is therefore bounded by the pairs of
// the last step. A state is tied to the body's handle: removing a body drops its states (a new
// body in the same slot has a new generation and starts cold); the next step frees their
// memory, in one pass for every body removed since.
//
// Threads: step() splits the points into fixed blocks of ServiceOptions::block_size points and
// runs them with tbb::parallel_for in the service's own tbb::task_arena (setThreads()). Each
// point's work depends only on that point, its states and the bodies, and every result is
// written to its own slot, so results are bitwise identical for any number of threads.
// The service itself is not thread-safe: call its methods from one thread at a time, and do not
// change bodies during step(). Which thread that is may change from call to call, and a call may
// come from inside the caller's own TBB tasks (step() runs in the service's arena); separate
// services may step at once, sharing hierarchies.
//
// Exactness: every distance is exact (the hierarchy queries are exact, rigid bodies are queried
// in their own frame, deforming bodies through proven bounds), so no [lower, upper] is carried:
// lower == upper == distance.
#include "collision/body.h"
#include "collision/broadphase.h"
#include "core/sweep_query.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <initializer_list>
#include <memory>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace meshsweeper {

// Query points and positions: one row (x, y, z) per point.
using PointMatrix = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
using PointRows = Eigen::Ref<const PointMatrix>;

// The points (or positions) a call reads: any Eigen matrix or expression of doubles with three
// columns, one row (x, y, z) per point, or a std::vector<Vec3>. A PointMatrix, a row-major map with
// three columns or a std::vector<Vec3> is read in place; any other layout (a column-major
// Eigen::MatrixXd, a block) is copied once for the call. A matrix whose column count is fixed at
// another number does not compile; a dynamic one (Eigen::MatrixXd) with another count throws
// std::invalid_argument before the call does anything (Eigen::Ref alone does not check it in a
// release build: a MatrixXd of 2 columns was read past its end, found by an audit). It is a view
// for the call's duration, not to be kept.
class PointsRef {
 public:
  template <typename Derived>
  PointsRef(const Eigen::DenseBase<Derived>& points)  // NOLINT(google-explicit-constructor): like Eigen::Ref
      : matrix_((requireThreeColumns(points.cols()), points.derived())) {
    static_assert(Derived::ColsAtCompileTime == Eigen::Dynamic || Derived::ColsAtCompileTime == 3,
                  "points and positions need three columns (x, y, z)");
  }
  // A std::vector of points, read in place (Vec3 is three packed doubles: the vector is a
  // row-major n x 3 array).
  PointsRef(const std::vector<Vec3>& points)  // NOLINT(google-explicit-constructor): as above
      : matrix_(Eigen::Map<const PointMatrix>(points.empty() ? nullptr : points.front().data(),
                                              static_cast<Eigen::Index>(points.size()), 3)) {
    static_assert(sizeof(Vec3) == 3 * sizeof(double), "Vec3 is three packed doubles");
  }
  // Not copyable: the view may hold the copy it made, which a copy of Eigen::Ref would not own.
  PointsRef(const PointsRef&) = delete;
  PointsRef& operator=(const PointsRef&) = delete;

  const PointRows& matrix() const { return matrix_; }

 private:
  static Eigen::Index requireThreeColumns(Eigen::Index columns);  // throws unless 3
  PointRows matrix_;
};

// The rows of `points` as positions, one Vec3 per row.
std::vector<Vec3> toPositions(const PointsRef& points);

// A body of a DistanceService: slot index, generation and the service's own number. A handle
// stays valid until its body is removed; after that every use throws std::invalid_argument
// ("stale body handle"), even if the slot holds a new body. A handle of another service is
// refused the same way ("a body handle of another DistanceService"), never taken for the body
// in the same slot of this one. A default-constructed handle is never valid.
struct BodyHandle {
  uint32_t index = kInvalidIndex;
  uint32_t generation = 0;
  uint32_t service = 0;  // the DistanceService that made it (0: none)
  friend bool operator==(const BodyHandle& a, const BodyHandle& b) {
    return a.index == b.index && a.generation == b.generation && a.service == b.service;
  }
  friend bool operator!=(const BodyHandle& a, const BodyHandle& b) { return !(a == b); }
};

enum class BodyKind : uint8_t {
  kRigid,      // shared hierarchy at a pose (setPose)
  kKeyframed,  // positions interpolated between key frames (setTime)
  kDeforming,  // arbitrary positions each step, displacement-inflated bounds (setPositions)
};

enum class QueryMode : uint8_t {
  kClosest,  // per point: the closest triangle over all bodies, if within the distance
  kWithin,   // per point: every triangle of every body within the distance
};

// Sign of a hit. Only closed bodies (BodyShape::closed()) are signed.
enum class HitSign : int8_t { kInside = -1, kUnsigned = 0, kOutside = 1 };

enum class PointStatus : uint8_t {
  kOk = 0,
  kNotFinite = 1,   // the point has a NaN or infinite coordinate: no hits, its states dropped
  kOutOfRange = 2,  // a coordinate beyond kMaxCoordinate (1e150, core/types.h), where squared
                    // distances would overflow: no hits, its states dropped
};

// One answer: a triangle of a body and the closest point on it. All vectors in world space.
struct DistanceHit {
  BodyHandle body;
  TriangleIndex triangle = kInvalidIndex;  // original face index of the body's mesh (file order)
  Feature feature = Feature::kFace;        // vertex, edge or face of `triangle` holding `point`
  HitSign sign = HitSign::kUnsigned;       // kUnsigned exactly when !closed_body
  bool closed_body = false;                // the body's mesh is closed (signed distances)
  double distance = 0;                     // exact Euclidean distance, >= 0
  double signed_distance = 0;              // -distance inside a closed body, else +distance
  Vec3 point = Vec3::Zero();               // closest point on the body's surface
  Vec3 barycentric = Vec3::Zero();         // point = b0*A + b1*B + b2*C of the triangle
  // Unit vector from `point` to the query point (inward for a point inside a closed body:
  // negate it there for the way out). On the surface (a distance of at most 16 eps times
  // the coordinates involved: the point's in the body's frame and the hit triangle's corners',
  // and for a rigid body or a framed deforming one also the query point's and the frame's
  // translation's; rounding alone can make that of a point lying exactly on a face, and the
  // offset's direction is noise there), the feature's
  // pseudonormal (outward for a closed body, whose sign is then kOutside), normalised; the zero
  // vector where that pseudonormal is zero: a feature whose faces all have zero area, or whose
  // face normals cancel (an open mesh whose two faces at an edge are oriented against each other
  // and lie in one plane, or a key-framed or deforming body placed flat).
  Vec3 direction = Vec3::Zero();
};

// Work done by one step (summed over points; identical for any thread count).
struct StepStats {
  uint64_t points = 0;            // points in the batch
  uint64_t invalid_points = 0;    // points with status kNotFinite or kOutOfRange
  uint64_t pairs = 0;             // (point, body) pairs the broadphase passed to a body
  uint64_t warm_pairs = 0;        // pairs that had a state from the last step
  uint64_t certified_pairs = 0;   // pairs answered from the cached candidate set
  uint64_t out_of_reach_pairs = 0;  // closest mode: pairs with nothing within the distance (found
                                    // or certified without looking farther)
  uint64_t triangles_tested = 0;  // exact point-triangle distances
  uint64_t hits = 0;              // hits returned
  uint64_t states = 0;            // coherent states kept after the step
  uint32_t bodies_refreshed = 0;  // world boxes recomputed at the start of the step
  double bounds_seconds = 0;      // body boxes
  double query_seconds = 0;       // broadphase and queries
};

// The answers of one step, per point. Reused by step() (its memory is kept).
class StepResult {
 public:
  // A range of hits (C++17 stand-in for std::span).
  struct Hits {
    const DistanceHit* first = nullptr;
    const DistanceHit* last = nullptr;
    const DistanceHit* begin() const { return first; }
    const DistanceHit* end() const { return last; }
    size_t size() const { return static_cast<size_t>(last - first); }
    bool empty() const { return first == last; }
    const DistanceHit& operator[](size_t i) const { return first[i]; }
  };

  QueryMode mode() const { return mode_; }
  double maxDistance() const { return max_distance_; }
  size_t size() const { return status_.size(); }  // points
  PointStatus status(size_t point) const { return status_[point]; }

  // kClosest: the closest hit of the point within the distance (the lowest body slot among
  // bodies at exactly the same distance), or nullptr if none. kWithin: nullptr.
  const DistanceHit* closest(size_t point) const {
    return mode_ == QueryMode::kClosest && count_[point] ? &hits_[point] : nullptr;
  }
  // kClosest: 0 or 1 hit. kWithin: every hit of the point, by increasing distance, then body
  // slot, then triangle index.
  Hits hits(size_t point) const {
    const DistanceHit* first = mode_ == QueryMode::kClosest
                                   ? hits_.data() + point
                                   : block_hits_[point / block_size_].data() + begin_[point];
    return {first, first + count_[point]};
  }
  const StepStats& stats() const { return stats_; }

 private:
  friend class DistanceService;
  QueryMode mode_ = QueryMode::kClosest;
  double max_distance_ = 0;
  std::vector<PointStatus> status_;  // [point]
  std::vector<uint32_t> count_;      // [point] hits
  std::vector<size_t> begin_;        // [point] kWithin: first hit in its block's hits
  std::vector<DistanceHit> hits_;    // kClosest: [point] (valid where count_ is 1)
  // kWithin: the hits of points [b * block_size_, (b + 1) * block_size_), point by point.
  std::vector<std::vector<DistanceHit>> block_hits_;
  size_t block_size_ = 1;
  StepStats stats_;
};

// What setPositions() did.
struct PositionsUpdate {
  // false: every vertex stayed within its displacement bound; the bounds were kept (cheap).
  // true: the body was re-anchored at the new positions (bounds recomputed exactly there, then
  // inflated by the body's displacement bound again): some vertex left its bound, or the body's
  // coordinates started over in a new frame (its first followed frame, or back to world
  // coordinates; worst_vertex kInvalidIndex; ServiceOptions::follow_frames). Either way the
  // next queries are exact.
  bool reanchored = false;
  VertexIndex worst_vertex = kInvalidIndex;  // reanchored: the vertex farthest past its bound
  double excess = 0;                         // reanchored: how far past its bound it was
};

// One entry of a batched setPositions(): a deforming body and its new positions, one per mesh
// vertex. The positions are a std::vector<Vec3> or any Eigen matrix or expression of doubles
// with three columns, one row (x, y, z) per vertex:
//  - a named vector or matrix with storage (a std::vector<Vec3>, `{body, &positions}` included;
//    a PointMatrix, an Eigen::MatrixXd of either storage order, an Eigen::Map with any
//    strides, an Eigen::Array) is a view, read during the call (matrices are copied then, in
//    parallel over the entries): it must outlive the call;
//  - anything else (a temporary vector or matrix, an expression such as V * 2, a block or a
//    Map written in place, a function's result) is copied into the entry when the entry is made,
//    so nothing the entry names can be gone before the call (found by an audit: views of
//    temporaries were read after they were freed).
// A matrix whose column count is fixed at another number does not compile; one whose count is
// not 3 at run time is refused by the call, with the entry named.
static_assert(sizeof(Vec3) == 3 * sizeof(double), "Vec3 is three packed doubles");
struct BodyPositions {
  BodyPositions() = default;
  BodyPositions(BodyHandle body, const std::vector<Vec3>* positions) : body(body), positions(positions) {}
  BodyPositions(BodyHandle body, const std::vector<Vec3>& positions) : body(body), positions(&positions) {}
  BodyPositions(BodyHandle body, std::vector<Vec3>&& positions)
      : body(body), owned(std::make_shared<const std::vector<Vec3>>(std::move(positions))), positions(owned.get()) {}
  template <typename Matrix, typename Plain = std::decay_t<Matrix>,
            typename = std::enable_if_t<std::is_base_of<Eigen::DenseBase<Plain>, Plain>::value>>
  BodyPositions(BodyHandle body, Matrix&& matrix) : body(body) {
    static_assert(std::is_same<typename Plain::Scalar, double>::value, "positions are doubles");
    static_assert(Plain::ColsAtCompileTime == Eigen::Dynamic || Plain::ColsAtCompileTime == 3,
                  "points and positions need three columns (x, y, z)");
    if constexpr (std::is_lvalue_reference<Matrix>::value && (Plain::Flags & Eigen::DirectAccessBit) != 0) {
      rows = {matrix.data(), matrix.rows(), matrix.cols(), matrix.rowStride(), matrix.colStride(), true};
    } else if (matrix.cols() != 3) {
      rows.cols = matrix.cols();  // refused by the call, with the entry named
      rows.given = true;
    } else {
      auto copy = std::make_shared<std::vector<Vec3>>(static_cast<size_t>(matrix.rows()));
      if (!copy->empty())  // Vec3 is three packed doubles: the vector is a row-major n x 3 array
        Eigen::Map<PointMatrix>(copy->front().data(), matrix.rows(), 3) = matrix;
      owned = std::move(copy);
      positions = owned.get();
    }
  }

  // The coordinates of a named Eigen matrix: x of vertex v at data[v * row_stride], y and z
  // one and two column strides further.
  struct MatrixView {
    const double* data = nullptr;
    Eigen::Index rows = 0, cols = 0, row_stride = 0, col_stride = 0;
    bool given = false;  // made from a matrix
  };

  BodyHandle body;
  std::shared_ptr<const std::vector<Vec3>> owned;  // the copy of a temporary, if any
  const std::vector<Vec3>* positions = nullptr;    // a vector's positions (or the copy), or
  MatrixView rows;                                 // (positions null) a named matrix's, if given
};

struct ServiceOptions {
  // Threads of the service's task arena; 0 = TBB's default (all cores). See setThreads().
  unsigned threads = 0;
  // Points per parallel task (fixed for the service's life; results never depend on it).
  uint32_t block_size = 128;
  // Coherent states gather candidates within d + 2 R, R = reach_steps times the point's mean
  // step relative to the body (CoherentState::reach_steps; for key-framed and deforming bodies
  // the step includes how far the faces moved): larger means fewer rebuilds but larger sets.
  // Answers never depend on it.
  float reach_steps = 2;
  // A state's set is gathered lead_steps of the point's mean steps ahead of it, along its mean
  // velocity (when that is within 2 R): on a steady path the set lasts about twice as long
  // (CoherentState::lead_steps; 0: gathered at the point). Answers never depend on it.
  float lead_steps = 3;
  // A deforming body's rigid motion is followed (frame()): each setPositions() fits the rigid
  // motion that best carries the last positions onto the new ones and keeps it when that cuts
  // the step's largest and its mean vertex motion by a quarter or more (an arm moving alone is
  // no rigid motion to follow). The body then holds its positions
  // in that frame and is queried there, like a rigid body: a soft body carried across the
  // world (with the points near it) keeps its coherent states and its displacement bound,
  // where in world coordinates every step's carry would count as deformation (bench_service's
  // carried sheets: 3.4-5.6x slower a step without it, bench/README.md). A body's first frame is fitted to its
  // mesh's own positions (its coordinates in the frame stay near the mesh's; its pair states
  // start over once). Answers agree either way up to rounding (the frame's transform, as for
  // a rigid body's pose).
  bool follow_frames = true;
  // A deforming body tracks its drift by region (DeformingBody::setRegionalDrift): a pair near
  // a part that stays still keeps its certificate while another part moves fast
  // (bench_service's limb sheets: 54-64% of the pairs certified against 40-48%, 0-14% less
  // time a step, bench/README.md).
  // Answers never depend on it.
  bool regional_drift = true;
};

class DistanceService {
 public:
  explicit DistanceService(const ServiceOptions& options = {});
  ~DistanceService();
  DistanceService(const DistanceService&) = delete;
  DistanceService& operator=(const DistanceService&) = delete;

  // ---- Shared tables ---------------------------------------------------------------------
  // The hierarchy of `mesh`, built on first use and cached by the mesh's address: later calls
  // with the same, unchanged Mesh object return the same shared hierarchy while a body or the
  // caller still holds it (the cache holds it weakly: a hierarchy nothing holds is freed, and
  // built again by the next call). Each call compares the mesh with the hierarchy's copy (one
  // pass over it, far cheaper than a build), so a mesh changed in place, or another mesh at the
  // same address, gets a new hierarchy. forgetMesh() drops an entry. Throws MeshError for an
  // invalid mesh.
  std::shared_ptr<const Hierarchy> hierarchyFor(const Mesh& mesh);
  void forgetMesh(const Mesh& mesh);
  // The shared per-mesh tables the service uses for `hierarchy` (built once per hierarchy and
  // shared by all its bodies while any of them exists).
  std::shared_ptr<const BodyShape> shapeFor(const std::shared_ptr<const Hierarchy>& hierarchy);

  // ---- Bodies ----------------------------------------------------------------------------
  // Each add* throws std::invalid_argument for a null hierarchy or bad parameters (as the
  // deform/ classes check them); the hierarchy is shared, not copied.

  // A rigid body at `pose` (rotation + translation; std::invalid_argument if not rigid).
  BodyHandle addRigid(std::shared_ptr<const Hierarchy> hierarchy,
                      const Eigen::Isometry3d& pose = Eigen::Isometry3d::Identity());
  // A key-framed body: frames[f][vertex] world positions, at time `time` (see setTime()).
  BodyHandle addKeyframed(std::shared_ptr<const Hierarchy> hierarchy,
                          std::vector<std::vector<Vec3>> frames, double time = 0);
  // The same with frames held as Eigen matrices (three columns each, as PointsRef takes them):
  // a std::vector of them, or a braced list ({V0, V1}, of any matrix types; there a frame with
  // another column count throws PointsRef's error as the list is made, before the call).
  template <typename Matrix, typename = std::enable_if_t<std::is_base_of<Eigen::DenseBase<Matrix>, Matrix>::value>>
  BodyHandle addKeyframed(std::shared_ptr<const Hierarchy> hierarchy, const std::vector<Matrix>& frames,
                          double time = 0) {
    std::vector<std::vector<Vec3>> copied;
    copied.reserve(frames.size());
    for (size_t f = 0; f < frames.size(); ++f) {
      try {
        copied.push_back(toPositions(frames[f]));
      } catch (const std::invalid_argument& e) {  // a column count: the frame named
        throw std::invalid_argument("DistanceService::addKeyframed (a new body): frame " + std::to_string(f) +
                                    ": " + e.what());
      }
    }
    return addKeyframed(std::move(hierarchy), std::move(copied), time);
  }
  BodyHandle addKeyframed(std::shared_ptr<const Hierarchy> hierarchy, std::initializer_list<PointsRef> frames,
                          double time = 0);
  // A freely deforming body starting at `positions` (empty: the mesh's positions), whose
  // vertices may each move up to `displacement_bound` (>= 0, finite; world units) from where
  // the bounds were last computed before setPositions() re-anchors (see PositionsUpdate),
  // measured in the body's followed frame (ServiceOptions::follow_frames): a rigid motion of
  // the whole body does not use the bound up. A bound of a few steps' deformation keeps
  // re-anchoring rare.
  BodyHandle addDeforming(std::shared_ptr<const Hierarchy> hierarchy, double displacement_bound,
                          const std::vector<Vec3>& positions = {});
  BodyHandle addDeforming(std::shared_ptr<const Hierarchy> hierarchy, double displacement_bound,
                          const PointsRef& positions);

  // Removes the body; its handle becomes stale. Throws std::invalid_argument for a stale handle.
  void remove(BodyHandle body);
  // True when `body` names a body of this service.
  bool contains(BodyHandle body) const;
  size_t bodyCount() const;
  // The live bodies by increasing slot.
  std::vector<BodyHandle> bodies() const;

  // Every accessor and setter below throws std::invalid_argument for a stale handle, or for a
  // body of the wrong kind.
  BodyKind kind(BodyHandle body) const;
  // The body's shape (closed or open, why, inward or not). The reference is valid until the
  // body's remove(), and no longer unless another body shares the shape: the service holds a
  // shape only while a body uses it. shapeFor(hierarchy) gives a shared_ptr that keeps it.
  const BodyShape& shape(BodyHandle body) const;
  // kRigid. pose(): the pose answers are exact for (setPose's, re-orthonormalised); the
  // reference reads the latest setPose() and is valid until the body's remove().
  void setPose(BodyHandle body, const Eigen::Isometry3d& pose);
  const Eigen::Isometry3d& pose(BodyHandle body) const;
  // The frame the body's queries run in, placed in the world: a rigid body's pose; a deforming
  // body's followed rigid motion (ServiceOptions::follow_frames; identity until one is
  // followed); identity for a key-framed body.
  Eigen::Isometry3d frame(BodyHandle body) const;
  // kKeyframed: t in [0, frames - 1] (clamped; std::invalid_argument if not finite).
  void setTime(BodyHandle body, double t);
  // kDeforming: one position per mesh vertex (std::invalid_argument on a wrong count or a
  // non-finite coordinate; the body is then unchanged).
  PositionsUpdate setPositions(BodyHandle body, const PointsRef& positions);
  PositionsUpdate setPositions(BodyHandle body, const std::vector<Vec3>& positions);
  // kDeforming, several bodies at once: the same as setPositions(b.body, *b.positions) for
  // each entry (result i for entry i), the bodies updated in parallel on the service's threads.
  // Every entry is checked before any body changes (std::invalid_argument for a stale handle, a
  // body that is not deforming or appears twice, no positions, a wrong count of them, a matrix
  // without 3 columns, a non-finite coordinate, positions spanning more than 1e50): on an error
  // no body of the batch has changed. Every entry reads its positions as they were before the
  // call, even where they are another batch body's positions() (those, and every matrix entry,
  // are copied first; the bodies change at once).
  std::vector<PositionsUpdate> setPositions(const std::vector<BodyPositions>& batch);
  // kDeforming: changes the displacement bound and re-anchors at the current positions.
  void setDisplacementBound(BodyHandle body, double displacement_bound);
  // kDeforming: whether the body keeps inline faces (DeformingBody::setInlineFaces). Each
  // setPositions() decides it from the last step's work on the body: on when its queries
  // tested at least 2.5 leaf blocks per leaf block of its hierarchy (a cloth draped over it),
  // off again below 1 (a body few points reach). Answers never depend on it.
  bool inlineFaces(BodyHandle body) const;
  // kKeyframed, kDeforming: the current world positions [vertex]. The reference (and any
  // pointer or Eigen::Map into it) is valid until the body's next setTime(), setPositions(),
  // setDisplacementBound() or remove(): a deforming body keeps its world positions in another
  // vector while it follows a frame (found by an audit: a reference kept from before the
  // first frame then held the frame's coordinates, and a Map kept across a return to world
  // coordinates read freed memory). Copy the positions to keep them.
  const std::vector<Vec3>& positions(BodyHandle body) const;
  // The body's world box: rigid, its rest box's 8 corners transformed (with a 1e-12 relative
  // margin for rounding); otherwise the box of its current positions (a deforming body in a
  // followed frame: with the same margin, for the rounding of the frame's transform).
  Box3 worldBox(BodyHandle body);

  // ---- Queries ---------------------------------------------------------------------------
  // Answers every point (one row each) against every body within `max_distance` (>= 0;
  // +infinity allowed): kClosest keeps the closest hit over all bodies, kWithin every triangle
  // within the distance; a hit on the surface up to rounding (see DistanceHit::direction)
  // counts as within any max_distance, 0 included, with its distance as computed. Points with a NaN or infinite coordinate get PointStatus::kNotFinite,
  // finite ones beyond 1e150 kOutOfRange, and no hits (the step goes on). Throws std::invalid_argument if max_distance is NaN or negative.
  // Results are written into `out` (its memory reused). A step refused for its arguments
  // (max_distance, mode, the points' columns) throws before it starts: `out` and the service
  // are as they were. If a running step throws (out of memory), `out` is left empty (size() 0,
  // its memory released); the service stays usable and the next step answers exactly.
  void step(const PointsRef& points, double max_distance, QueryMode mode, StepResult& out);
  StepResult step(const PointsRef& points, double max_distance, QueryMode mode = QueryMode::kClosest);

  // Threads used by step(): 0 = TBB's default; at most 65536 (std::invalid_argument beyond,
  // the service unchanged; ServiceOptions::threads too). Results do not depend on it.
  // threads() says how many step() uses: the count asked for, at most TBB's limit (the cores,
  // unless the program set global_control's max_allowed_parallelism; more could not run at
  // once, and TBB would warn on standard error).
  void setThreads(unsigned threads);
  unsigned threads() const;

  // Coherent states currently kept (not counting removed bodies'), and their memory in bytes
  // (capacity; a removed body's states until the next step).
  size_t coherentStates() const;
  size_t coherentStateBytes() const;
  // Bytes of scratch the service keeps for the threads of its arena between steps (per thread:
  // a query stream per body it queried, candidate lists, buffers): bounded by the arena's
  // threads whatever threads called step(), and a step that needed much more (a within step at
  // a large distance) leaves no more than a usual step's.
  size_t scratchBytes() const;
  // Drops every coherent state (the next step starts cold).
  void clearCoherentStates();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  void stepInto(const PointRows& points, double max_distance, QueryMode mode, StepResult& out);
};

}  // namespace meshsweeper
