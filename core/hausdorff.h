#pragma once
// Certified Hausdorff distances between triangle meshes (Guéziec, "Meshsweeper", section 6;
// DESIGN.md section 4).
//
//   h(A, B) = max over every point a of the surface A (not only its vertices) of d(a, B)
//   H(A, B) = max(h(A, B), h(B, A))
//
// Each is returned as a certified interval [lower, upper]: lower is the exact distance of a
// sample point of A (so h >= lower), upper is a proven bound over every point of A. The
// computation stops once upper - lower <= tolerance.
//
// Method: query every vertex of A for its closest point on B; bound every triangle of A from
// above by covering it, whole or in up to 64 midpoint pieces, with single faces of B taken from
// the hierarchy's leaf blocks that hold its corners' closest triangles (cover bound: the
// distance to one face is convex, so it peaks at a piece's corners), else with the closest
// points of its corners (bisector bound, paper Fig. 9); where a piece cannot be covered, query
// its centroid and add the leaf block of its closest face before giving up (that point is a
// sample for the lower bound too); split the triangles whose bound is highest into four by
// their edge midpoints until the highest bound is within the tolerance of the best sample. See
// hausdorff.cpp.
//
// Visiting order: the paper visits samples along "peels" (spiral triangle strips, Fig. 8) so
// successive queries are close and the coherent query pays off. A prototype measured that
// visiting the vertices in Morton (Z-curve) order gives the same locality at no construction
// cost and splits into fixed chunks that threads can take independently, so this
// implementation visits vertices in Morton order and does not build peels.
//
// Limits (what is not computed):
//  - mean and RMS are estimates (see OneSidedHausdorff), not certified;
//  - in the symmetric computation the direction that cannot change H is refined only until
//    that is proven, so its own [lower, upper] may be wider than the tolerance (set
//    HausdorffOptions::tighten_both to refine both to the tolerance);
//  - bounds are exact up to double rounding: every upper bound carries a margin of 1e-12 times
//    the largest coordinate magnitude, which also limits how small a tolerance can be (4e-12
//    times it: HausdorffResult::tolerance, with requested_tolerance beside it); a lower bound
//    is the computed distance of a point of A, which can exceed the true one by that rounding
//    (identical meshes give about 3e-17 at coordinates near 1, not 0). The Mesh entry points
//    compute about the centre of the meshes' joint box when that shrinks the coordinates at
//    least fourfold (a translation changes no distance; witnesses are reported in the given
//    coordinates, bounds widened by the translation's rounding, if any), so meshes far from
//    the origin get the margin of their own size; the Hierarchy entry points compute in the
//    hierarchies' coordinates;
//  - surfaces that coincide but are triangulated differently are split along the other's edges
//    down to the tolerance (a point there is covered by no single face of B): cells, time and
//    memory grow as 1 / tolerance (cube-meshed against cube: 5 s at 1e-5, 44 s and 2.3 GB at
//    1e-6, measured by review); HausdorffOptions::max_seconds and max_bytes bound them.
#include "core/hierarchy.h"

#include <functional>
#include <memory>
#include <vector>

namespace meshsweeper {

// Snapshot passed to HausdorffOptions::progress between refinement rounds.
struct HausdorffProgress {
  double lower = 0, upper = 0;  // current bounds of the distance being computed
  double tolerance = 0;         // absolute
  uint64_t samples = 0;         // point queries so far
  double seconds = 0;           // since the call started
};

struct HausdorffOptions {
  // Absolute tolerance on upper - lower (mesh units). Used when > 0.
  double tolerance = 0;
  // Otherwise the tolerance is relative_tolerance times the bounding-box diagonal of A.
  double relative_tolerance = 1e-4;
  // Worker threads: 0 = all (TBB's default); at most TBB's limit (the cores, unless the
  // program set global_control's max_allowed_parallelism). The result does not depend on this
  // number.
  unsigned threads = 0;
  // Symmetric only: refine both directions until each one-sided interval meets the tolerance
  // (by default the dominated direction stops as soon as it provably cannot change H).
  bool tighten_both = false;
  // When > 0: refinement stops after about this many seconds (checked between rounds, after
  // the vertex pass and the first bounds, which always run), with the certified interval
  // reached so far (HausdorffResult::timed_out, converged false). Where it stops then depends
  // on the machine's speed. Surfaces that coincide but are triangulated differently are the
  // case that needs it (see Limits).
  double max_seconds = 0;
  // When > 0: refinement stops before a round could take its tables past about this many bytes,
  // with the certified interval reached so far (HausdorffResult::memory_limited, converged
  // false). The tables are what grows with refinement: the cells, samples, heap and edge map of
  // both directions (HausdorffResult::table_bytes; the meshes and hierarchies come on top), each
  // counted as the next round would grow it, old and new buffers together while one moves. The
  // vertex pass and the first bounds always run. Unlike max_seconds, where it stops does not
  // depend on the machine. Surfaces that coincide but are triangulated differently are the
  // case that needs it (see Limits: two triangles at a tolerance of 1e-9 would take hundreds of
  // gigabytes).
  uint64_t max_bytes = 0;
  // Called from the calling thread after the vertex pass and after each refinement round.
  // Optional; it must not throw.
  std::function<void(const HausdorffProgress&)> progress;
};

// Work done by one direction (or both, summed).
struct HausdorffCounters {
  uint64_t samples = 0;            // points of A whose distance to B was computed
  uint64_t queries = 0;            // closest-point queries on B
  uint64_t triangles_tested = 0;   // exact point-triangle distances inside those queries
  uint64_t triangles_refined = 0;  // (sub)triangles of A split (in four, or a thin one in two)
  uint64_t cells = 0;              // (sub)triangles bounded (original triangles included)
  uint64_t face_bound_wins = 0;    // cells bounded by faces of B (cover bound), not by the
                                   // corner bound (hausdorff.cpp) or bisectors
  uint32_t rounds = 0;             // refinement rounds
};

// h(A, B): one direction.
struct OneSidedHausdorff {
  double lower = 0;        // certified: h(A, B) >= lower (the exact distance of `at` to B;
                           // `at` is a vertex, a refinement midpoint or a point the cover
                           // bound queried)
  double upper = 0;        // certified: h(A, B) <= upper
  Vec3 at = Vec3::Zero();  // the point of A at distance `lower` from B
  TriangleIndex at_triangle = kInvalidIndex;       // a triangle of A that contains `at`
  Vec3 closest = Vec3::Zero();                     // its closest point on B
  TriangleIndex closest_triangle = kInvalidIndex;  // the triangle of B that holds `closest`
  // Area-weighted mean and root-mean-square distance from A to B. Estimates, error not
  // certified: the distance is taken as linear over every final sub-triangle of A between the
  // exact distances at its corners (vertices of A and refinement midpoints), then integrated
  // exactly. Both equal the exact values where the distance is linear (e.g. planes); curved
  // distance fields are estimated at the resolution the refinement reached. When A has no area
  // (only degenerate triangles) both are the plain average over the vertices.
  double mean = 0, rms = 0;
  double area = 0;  // total area of A
  // [vertex of A] exact distance to B; NaN for vertices no triangle uses.
  std::vector<double> vertex_distance;
  HausdorffCounters counters;
};

struct HausdorffResult {
  OneSidedHausdorff a_to_b;     // h(A, B)
  OneSidedHausdorff b_to_a;     // h(B, A); left empty (NaN bounds) by hausdorffOneSided()
  double lower = 0, upper = 0;  // certified bounds of H(A, B) (of h(A, B) for one-sided)
  double tolerance = 0;         // the absolute tolerance used: the requested one, raised to
                                // 4e-12 times the largest coordinate magnitude (the rounding
                                // margin; the Mesh entry points measure coordinates from the
                                // centre of the meshes' joint box, see Limits, and a tolerance
                                // raised there also covers that translation's rounding)
  double requested_tolerance = 0;  // the tolerance asked for (absolute, or relative times A's
                                   // diagonal); below `tolerance` where it was raised
  bool converged = true;        // upper - lower <= tolerance (false only if refinement hit its
                                // depth limit: sub-triangles below rounding size, or ran out of
                                // HausdorffOptions::max_seconds or max_bytes)
  bool timed_out = false;       // stopped by HausdorffOptions::max_seconds
  bool memory_limited = false;  // stopped by HausdorffOptions::max_bytes (or at 2^32 cells or
                                // samples in a direction, their ids' limit)
  uint64_t table_bytes = 0;     // the refinement's tables at the end (see max_bytes)
  HausdorffCounters counters;   // both directions summed
  unsigned threads = 0;         // the worker threads it could use (HausdorffOptions::threads)
  double build_seconds = 0;     // hierarchies (0 when the caller passed them)
  double seconds = 0;           // everything, builds included
};

// Symmetric Hausdorff distance H(A, B) with both one-sided distances.
// Throws MeshError if a mesh fails checkMesh() (empty, non-finite, indices out of range) and
// std::invalid_argument if the tolerance or max_seconds is negative, NaN or infinite, or if the effective
// tolerance is 0 (relative tolerance on a mesh of zero extent) or infinite (a relative one
// past the largest double over A's diagonal).
HausdorffResult hausdorff(const Mesh& a, const Mesh& b, const HausdorffOptions& options = {});
// The same with hierarchies the caller already built (shared, read-only; a null one throws
// std::invalid_argument). The relative tolerance uses the diagonal of a->mesh(). build_seconds
// is 0.
HausdorffResult hausdorff(const std::shared_ptr<const Hierarchy>& a,
                          const std::shared_ptr<const Hierarchy>& b,
                          const HausdorffOptions& options = {});

// One-sided h(A, B) only: needs B's hierarchy only. result.lower/upper bound h(A, B).
HausdorffResult hausdorffOneSided(const Mesh& a, const Mesh& b,
                                  const HausdorffOptions& options = {});
// The same with B's hierarchy already built (null: std::invalid_argument).
HausdorffResult hausdorffOneSided(const Mesh& a, const std::shared_ptr<const Hierarchy>& b,
                                  const HausdorffOptions& options = {});

}  // namespace meshsweeper
