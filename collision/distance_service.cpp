// The distance-query service (DESIGN.md section 5; moving and deforming bodies: paper section 5,
// DESIGN.md section 3; signs: Baerentzen & Aanaes 2005).
//
// step(points, d, mode):
//   refresh the world box of every body changed since the last step (parallel over bodies)
//   parallel over fixed blocks of block_size points (one task per block, any thread):
//     for each point p of the block:
//       candidates <- the bodies whose world box is within d of p (flat SoA loop)
//     closest mode: the block's pair states are reused in place when every point has the same
//       candidates (slot and generation) as last step; else rebuilt: a pair found last step
//       keeps its state, a new pair starts cold, a pair not reached any more is dropped
//     for each point p, for each candidate body b (by slot):
//       q <- p in b's frame (rigid: the inverse pose; deforming: the inverse of its followed
//            frame, or p itself; key-framed: p itself; the thread's stream for b reads b's
//            current TreeGeometry)
//       closest: c <- stream.closestCoherent(q, pair state, d): the closest face within d, or
//                none, searched no farther than d (the pair's certificate often answers
//                without a search); keep the smallest c.distance
//       within:  every triangle within d (stream.within)
//     hits: world point and direction, sign from the pseudonormal at the closest feature
//   within mode: the blocks' hits are concatenated in block order
// Every point writes only its own result slots and its own pair states, and no answer depends
// on the stream (scratch only) that computes it, so the thread count never changes a result.
#include "collision/distance_service.h"

#include "core/threads.h"
#include "core/triangle_distance.h"
#include "deform/inflated_bounds.h"
#include "deform/keyframe_bounds.h"
#include "deform/rigid_body.h"

#include <Eigen/SVD>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>
#include <unordered_map>

namespace meshsweeper {
namespace {

// A deforming body turns inline faces on (DeformingBody::setInlineFaces) when its queries
// tested at least kInlineFacesOn leaf blocks per leaf block it has in the last step, and off
// below kInlineFacesOff (the refitted boxes open fewer leaves, so a lower bound to stay on
// keeps it from flipping every step). Measured (bench_service, one thread): refreshing a leaf
// block costs about 63 ns, and testing one inline instead of gathering its corners saves about
// 25 ns; so inline faces pay from about 2.5 tests a leaf.
constexpr double kInlineFacesOn = 2.5;
constexpr double kInlineFacesOff = 1.0;

constexpr double kInf = std::numeric_limits<double>::infinity();

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

const char* kindName(BodyKind kind) {
  switch (kind) {
    case BodyKind::kRigid: return "rigid";
    case BodyKind::kKeyframed: return "key-framed";
    case BodyKind::kDeforming: return "deforming";
  }
  return "?";
}

// The coherent state of one (point, body) pair.
struct PairState {
  uint32_t slot = 0;
  uint32_t generation = 0;
  CoherentState state = CoherentState();  // value-initialised: a cold start, faces zeroed
};

// Starts loading a pair's state (a cache hint).
void prefetchPair(const PairState& pair) {
  const char* base = reinterpret_cast<const char*>(&pair);
  for (size_t line = 0; line < sizeof(PairState); line += 64) __builtin_prefetch(base + line);
}

// The pair states of one block of points: [local point + 1] CSR into pairs, by increasing slot.
struct BlockStates {
  uint32_t points = 0;
  std::vector<uint32_t> begin;
  std::vector<PairState> pairs;
};

struct Body {
  bool alive = false;
  uint32_t generation = 0;
  BodyKind kind = BodyKind::kRigid;
  std::shared_ptr<const BodyShape> shape;
  std::unique_ptr<RigidBody> rigid;
  std::unique_ptr<KeyframeBody> keyframed;
  std::unique_ptr<DeformingBody> deforming;
  double displacement_bound = 0;
  uint64_t leaves_tested = 0;  // leaf blocks the last step's queries tested on this body
  TreeGeometry rest;  // the hierarchy's rest geometry (rigid bodies, in the body frame)
  Box3 box;
  double scale = 0;  // the largest coordinate of the box, plus the pose's translation's
  // At least the largest coordinate of a vertex in the frame the queries run in (the rest box's
  // for a rigid body, the box's for a body queried in the world; infinite for a framed one):
  // makeHit reads a hit's corners only for a distance within their rounding.
  double corner_scale = kInf;
  bool box_dirty = true;
  // The placement's orientation (BodyShape::orientationAt), refreshed with the box: a
  // key-framed or deforming closed body can be placed as a mirror image of its mesh. It is
  // recomputed (one pass over the faces) only when the references cannot vouch for it:
  // deforming, [0] at the anchor, whose vertices stay within the displacement bound of it;
  // key-framed, [i] at frame i, its vertices moving at most its reach to frame i + 1.
  // A deforming body whose anchor cannot vouch for its whole bound also keeps the last placement
  // computed, valid while the vertices' drift since then (TreeGeometry::drift) allows.
  struct OrientationRef {
    PlacementOrientation placement;
    double reach = 0;  // how far the vertices may move from it (straight paths)
  };
  double orientation = 1;
  std::vector<OrientationRef> orientation_refs;
  PlacementOrientation orientation_last;
  double orientation_last_drift = -1;  // the drift at orientation_last (-1: none)
  uint64_t orientation_last_lineage = 0;  // and its lineage

  // A deforming body's followed frame (ServiceOptions::follow_frames): the rigid motion fitted
  // to its positions (planPositions). The body keeps its positions in this frame
  // (frame_inverse * world), so its drift, displacement bound and pair states see the
  // deformation alone; queries run there, like a rigid body's. Identity (framed false) until
  // following a motion first pays.
  bool framed = false;
  Eigen::Isometry3d frame = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d frame_inverse = Eigen::Isometry3d::Identity();
  std::vector<Vec3> world_positions;  // framed: the positions as given (positions())
  std::vector<Vec3> local_positions;  // planPositions' scratch: the positions in a frame

  // The pose that places the body's frame in the world, or null where the queries run in the
  // world (key-framed bodies, and deforming bodies not framed).
  const Eigen::Isometry3d* pose() const {
    if (rigid) return &rigid->pose();
    return framed ? &frame : nullptr;
  }

  // What the body's streams read: null (rest geometry, body frame) for rigid bodies.
  const TreeGeometry* geometry() const {
    if (keyframed) return &keyframed->geometry();
    if (deforming) return &deforming->geometry();
    return nullptr;
  }
  const TreeGeometry& treeGeometry() const { return geometry() ? *geometry() : rest; }
  const Vec3* positions() const {
    if (keyframed) return keyframed->positions().data();
    if (deforming) return deforming->positions().data();
    return shape->mesh().positions.data();
  }
};

struct StreamSlot {
  uint32_t generation = 0;
  std::unique_ptr<QueryStream> stream;
  uint64_t leaves_tested = 0;  // this step, by this thread (summed per body after the step)
};

// The closest hit of one point over its bodies, kept between a step's two passes.
struct BestHit {
  uint32_t slot = 0;
  ClosestPoint c;
  Vec3 q = Vec3::Zero();  // the point in the body's frame
  double touch = 0;       // surfaceRounding() at q
};

// Per-thread scratch: one stream per body slot, candidate lists, rebuild buffers. Aligned to
// cache lines: neighbours in Impl::scratch belong to threads running at once.
struct alignas(64) Scratch {
  std::vector<StreamSlot> streams;      // [slot]
  std::vector<BestHit> best;            // [local point] closest hit of a block's point
  std::vector<uint32_t> found;          // one point's broadphase answer
  std::vector<uint32_t> candidates;     // a block's candidate slots, point after point
  std::vector<uint32_t> candidate_begin;  // [local point + 1] CSR into candidates
  std::vector<uint32_t> begin;          // rebuilt CSR of a block
  std::vector<PairState> pairs;
  std::vector<TriangleHit> triangle_hits;
  std::vector<size_t> runs;             // within: where each body's hits of a point begin
};

struct MeshCacheEntry {
  // Held weakly: while a body or the caller holds it. (Held strongly, a program that made and
  // dropped meshes kept every one's hierarchy, found by an audit.)
  std::weak_ptr<const Hierarchy> hierarchy;
  const Vec3* positions = nullptr;
  const Triangle* triangles = nullptr;
  size_t vertex_count = 0, triangle_count = 0;
};

// Runs a call into a body's own class (RigidBody, KeyframeBody, DeformingBody): its
// std::invalid_argument gets the service's call and the body in front ("DistanceService::setPose
// (body 3): RigidBody: ..."), so that a program with many bodies knows which one was refused.
template <class Call>
decltype(auto) naming(const char* what, const std::string& body, Call&& call) {
  try {
    return call();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("DistanceService::") + what + " (" + body + "): " + e.what());
  }
}

// A number for a message, in %g form: std::to_string wrote -1e-300 as "-0.000000".
std::string numberText(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", value);
  return text;
}

// Erases the entries of a cache whose weakly held table is gone (`expired(entry)`), once the
// cache has doubled since the last sweep (a sweep per new entry made adding many entries
// quadratic); `swept` keeps the size the last sweep left.
template <class Map, class Expired>
void sweepExpired(Map& cache, size_t& swept, Expired expired) {
  if (cache.size() < 2 * swept + 16) return;
  for (auto i = cache.begin(); i != cache.end();) i = expired(i->second) ? cache.erase(i) : std::next(i);
  swept = cache.size();
}

std::string bodyName(BodyHandle h) { return "body " + std::to_string(h.index); }

bool hitOrder(const DistanceHit& a, const DistanceHit& b) {
  if (a.distance != b.distance) return a.distance < b.distance;
  if (a.body.index != b.body.index) return a.body.index < b.body.index;
  return a.triangle < b.triangle;
}

}  // namespace

// Each service's number, for its handles (BodyHandle::service): 1, 2, ... (0 is no service's).
uint32_t newServiceNumber() {
  static std::atomic<uint32_t> next{1};
  uint32_t number = next.fetch_add(1, std::memory_order_relaxed);
  while (number == 0) number = next.fetch_add(1, std::memory_order_relaxed);  // after 2^32 services
  return number;
}

struct DistanceService::Impl {
  const uint32_t number = newServiceNumber();
  ServiceOptions options;
  int arena_concurrency = 0;  // what the arena was made with (arenaConcurrency(threads))
  std::unique_ptr<tbb::task_arena> arena;
  std::vector<Body> bodies;         // [slot]
  std::vector<uint32_t> free_slots;
  size_t live = 0;
  Broadphase broadphase;
  std::map<const Mesh*, MeshCacheEntry> mesh_cache;
  size_t mesh_cache_swept = 0;  // entries left by the last sweep of expired hierarchies
  std::unordered_map<const Hierarchy*, std::weak_ptr<const BodyShape>> shapes;
  size_t shapes_swept = 0;  // entries left by the last sweep of expired shapes
  std::vector<BlockStates> blocks;                 // [block] closest-mode pair states
  std::vector<StepStats> block_stats;              // [block]
  std::vector<std::vector<DistanceHit>> block_hits;  // [block] within mode
  std::vector<Vec3> positions_scratch;
  double max_scale = 0;  // the largest Body::scale (refreshBoxes)
  // [the arena's thread slot] (tbb::this_task_arena::current_thread_index): one per thread that
  // can run in the arena at once, whichever threads those are. (Per OS thread, a program that
  // called step() from a new thread each time kept every such thread's scratch, found by an
  // audit.)
  std::vector<Scratch> scratch;

  Scratch& localScratch() {
    const int index = tbb::this_task_arena::current_thread_index();
    if (index < 0 || static_cast<size_t>(index) >= scratch.size())
      throw std::logic_error("DistanceService: a block ran outside the service's arena (thread slot " +
                             std::to_string(index) + " of " + std::to_string(scratch.size()) + ")");
    return scratch[static_cast<size_t>(index)];
  }

  BodyHandle handle(uint32_t slot) const { return {slot, bodies[slot].generation, number}; }
  bool holds(BodyHandle h) const {
    return h.service == number && h.index < bodies.size() && bodies[h.index].alive &&
           bodies[h.index].generation == h.generation;
  }
  Body& body(BodyHandle h, const char* what) {
    if (h.service == 0)
      throw std::invalid_argument(std::string("DistanceService::") + what +
                                  ": a body handle that no DistanceService made (default-constructed or built by hand)");
    if (h.service != number)
      throw std::invalid_argument(std::string("DistanceService::") + what +
                                  ": a body handle of another DistanceService (slot " + std::to_string(h.index) + ")");
    if (!holds(h))
      throw std::invalid_argument(std::string("DistanceService::") + what + ": stale body handle (slot " +
                                  (h.index == kInvalidIndex ? std::string("none") : std::to_string(h.index)) +
                                  ", generation " + std::to_string(h.generation) + ")");
    return bodies[h.index];
  }
  Body& body(BodyHandle h, const char* what, BodyKind kind) {
    Body& b = body(h, what);
    if (b.kind != kind)
      throw std::invalid_argument(std::string("DistanceService::") + what + ": body " + std::to_string(h.index) +
                                  " is " + kindName(b.kind) + ", not " + kindName(kind));
    return b;
  }

  // ---- Followed frames (ServiceOptions::follow_frames) -----------------------------------
  // A rigid motion fitted to carry `from` onto `to` (as many, in range): the rotation by least
  // squares over a sample of kFitSample vertices spread over them (Kabsch), the shift the centre
  // of the box of what the rotation leaves (which halves the largest motion of a shift, where
  // least squares follows every wobble of a deformation). `left2` bounds the largest remainder
  // (the box's half diagonal), `moved2` is the largest |to - from|, both squared, over the
  // sample or every vertex (measure()).
  static constexpr size_t kFitSample = 64;
  struct MotionFit {
    Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
    Vec3 shift = Vec3::Zero();
    double left2 = 0, moved2 = 0;
    double left_sum = 0, moved_sum = 0;  // the sums of |remainder| and |to - from|
    Eigen::Isometry3d motion() const {
      Eigen::Isometry3d m = Eigen::Isometry3d::Identity();
      m.linear() = rotation;
      m.translation() = shift;
      return m;
    }
  };
  static size_t sampled(size_t i, size_t n) { return i * n / std::min(n, kFitSample); }
  // The rotation; false when it is not finite.
  static bool fitRotation(const std::vector<Vec3>& from, const std::vector<Vec3>& to, MotionFit& fit) {
    const size_t n = from.size(), count = std::min(n, kFitSample);
    Vec3 from_mean = Vec3::Zero(), to_mean = Vec3::Zero();
    for (size_t i = 0; i < count; ++i) {
      from_mean += from[sampled(i, n)];
      to_mean += to[sampled(i, n)];
    }
    from_mean /= static_cast<double>(count);
    to_mean /= static_cast<double>(count);
    Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
    for (size_t i = 0; i < count; ++i)
      covariance += (from[sampled(i, n)] - from_mean) * (to[sampled(i, n)] - to_mean).transpose();
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d flip = Eigen::Matrix3d::Identity();
    flip(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1 : 1;
    Eigen::Quaterniond turn(Eigen::Matrix3d(svd.matrixV() * flip * svd.matrixU().transpose()));
    if (!turn.coeffs().allFinite()) return false;
    fit.rotation = turn.normalized().toRotationMatrix();
    return true;
  }
  // The shift and the bounds, given the rotation.
  static void measure(const std::vector<Vec3>& from, const std::vector<Vec3>& to, bool every, MotionFit& fit) {
    const size_t n = from.size();
    Vec3 lower = Vec3::Constant(kInf), upper = Vec3::Constant(-kInf);
    fit.moved2 = 0;
    for (size_t k = 0, end = every ? n : std::min(n, kFitSample); k < end; ++k) {
      const size_t v = every ? k : sampled(k, n);
      const Vec3 r = to[v] - fit.rotation * from[v];
      lower = lower.cwiseMin(r);
      upper = upper.cwiseMax(r);
      fit.moved2 = std::max(fit.moved2, (to[v] - from[v]).squaredNorm());
    }
    fit.shift = 0.5 * (lower + upper);
    fit.left2 = (0.5 * (upper - lower)).squaredNorm();
    // The mean motions: a part moving alone (an arm) is no rigid motion to follow, though
    // shifting the whole body by half its motion halves the largest.
    fit.moved_sum = fit.left_sum = 0;
    for (size_t k = 0, end = every ? n : std::min(n, kFitSample); k < end; ++k) {
      const size_t v = every ? k : sampled(k, n);
      fit.moved_sum += (to[v] - from[v]).norm();
      fit.left_sum += (to[v] - fit.rotation * from[v] - fit.shift).norm();
    }
  }
  // Whether the fit is worth following: a quarter less of the largest motion and of the mean.
  static bool gains(const MotionFit& fit) {
    constexpr double kGain = 0.75;
    return fit.left2 < kGain * kGain * fit.moved2 && fit.left_sum < kGain * fit.moved_sum;
  }
  static Eigen::Isometry3d orthonormal(Eigen::Isometry3d frame) {
    frame.linear() = Eigen::Quaterniond(frame.linear()).normalized().toRotationMatrix();
    return frame;
  }

  // How a deforming body takes new positions: in world coordinates (framed false), or in a
  // frame, with b.local_positions holding them there (frame^-1 * position). Planning changes
  // nothing but that scratch; commitPositions() applies the plan.
  struct PositionsPlan {
    bool framed = false;
    bool first = false;  // a first frame, or back to world coordinates: the body's coordinates
                         // start over (a new lineage)
    Eigen::Isometry3d frame = Eigen::Isometry3d::Identity();
  };
  // The step's rigid motion (from the last positions as given) is followed when it cuts the
  // step's largest and its mean vertex motion by a quarter or more (gains()), on a sample
  // first, then on every vertex (a poor fit is never taken). A body's first frame is fitted to its mesh's own positions,
  // so that its coordinates in the frame stay near the hierarchy's (a body first framed far
  // from the origin would otherwise keep that distance's rounding wherever it goes); that
  // starts its coherent states over, once. Later frames compose the step's motion onto the
  // last, keeping the states. The mesh's own coordinates set the rounding in the frame, so a
  // frame is taken, and kept, only while they are within kFrameReach times the world's scale
  // (the largest coordinate of the fit's sample, or the mesh's size if larger): a mesh authored at 1e9
  // whose body lives near the origin stays in world coordinates, or goes back to them, where
  // its answers keep the origin's rounding. Only a plan in a frame reads every position; one
  // with a coordinate not finite or beyond 1e150 is planned in world coordinates, where
  // DeformingBody::setPositions refuses it by name (its coordinates in the frame could pass).
  static constexpr double kFrameReach = 4;
  PositionsPlan planPositions(Body& b, const std::vector<Vec3>& positions) {
    PositionsPlan plan;
    plan.frame = b.frame;
    const std::vector<Vec3>& last = b.deforming->positions();  // in b.frame
    const size_t n = positions.size();
    if (!options.follow_frames || n != last.size() || n == 0) return plan;
    double world = 0;
    for (size_t i = 0; i < std::min(n, kFitSample); ++i)
      world = std::max(world, positions[sampled(i, n)].cwiseAbs().maxCoeff());
    const BodyShape& shape = *b.shape;
    const double mesh_reach = shape.restLower().cwiseAbs().cwiseMax(shape.restUpper().cwiseAbs()).maxCoeff();
    if (!(mesh_reach <= kFrameReach * std::max(world, (shape.restUpper() - shape.restLower()).norm()))) {
      if (b.framed) {  // back to world coordinates
        plan.first = true;
        plan.frame = Eigen::Isometry3d::Identity();
      }
      return plan;
    }
    // A frame serves while the positions' coordinates in it stay within the same reach of the
    // world's scale: a body carried far, then brought back (or torn back, part of it first)
    // would otherwise keep the far frame, and its distance's rounding, at the origin (found by
    // review: 1.6e-10 errors near the origin after a trip to 1e6).
    const double scale = std::max(world, (shape.restUpper() - shape.restLower()).norm());
    const auto serves = [&](const std::vector<Vec3>& in_frame) {
      double reach = 0;
      for (size_t i = 0; i < std::min(n, kFitSample); ++i)
        reach = std::max(reach, in_frame[sampled(i, n)].cwiseAbs().maxCoeff());
      return reach <= kFrameReach * scale;
    };
    const std::vector<Vec3>& last_world = b.framed ? b.world_positions : last;  // as given last
    constexpr double kGain2 = 0.75 * 0.75;  // a quarter less motion, squared
    MotionFit step;
    bool moving = fitRotation(last_world, positions, step);
    if (moving) {
      measure(last_world, positions, n <= kFitSample, step);
      moving = gains(step);
    }
    if (moving && n > kFitSample) {
      measure(last_world, positions, true, step);
      moving = gains(step);
    }
    std::vector<Vec3>& local = b.local_positions;
    if (moving && !b.framed) {
      const std::vector<Vec3>& rest = b.shape->mesh().positions;
      MotionFit placed;
      if (!fitRotation(rest, positions, placed)) return plan;
      measure(rest, positions, true, placed);
      const Eigen::Isometry3d frame = orthonormal(placed.motion());
      if (!frame.matrix().allFinite()) return plan;
      if (!toFrame(frame.inverse(Eigen::Isometry), positions, local)) return plan;
      plan.framed = plan.first = true;
      plan.frame = frame;
      return plan;
    }
    if (moving) {
      const Eigen::Isometry3d frame = orthonormal(step.motion() * b.frame);
      if (frame.matrix().allFinite() && toFrame(frame.inverse(Eigen::Isometry), positions, local) && serves(local)) {
        double moved2 = 0;
        for (size_t v = 0; v < n; ++v) moved2 = std::max(moved2, (local[v] - last[v]).squaredNorm());
        if (moved2 < kGain2 * step.moved2) {
          plan.framed = true;
          plan.frame = frame;
          return plan;
        }
      }
    }
    if (b.framed && toFrame(b.frame_inverse, positions, local)) {
      if (serves(local)) {
        plan.framed = true;  // the body's frame
      } else {  // back to world coordinates
        plan.first = true;
        plan.frame = Eigen::Isometry3d::Identity();
      }
    }
    return plan;
  }
  // local = inverse * positions; false (local unspecified) when a position is not finite or
  // beyond 1e150.
  static bool toFrame(const Eigen::Isometry3d& inverse, const std::vector<Vec3>& positions, std::vector<Vec3>& local) {
    local.resize(positions.size());
    bool valid = true;
    for (size_t v = 0; v < positions.size(); ++v) {
      valid &= inCoordinateRange(positions[v]);
      local[v] = inverse * positions[v];
    }
    return valid;
  }

  // A deforming body's new positions, as planned (planPositions), re-anchored past its bound.
  // DeformingBody checks them (a wrong count, a coordinate not finite or beyond 1e150, a span
  // beyond the supported mesh size throw) before it changes; the frame is committed after, so
  // positions that throw leave the body as it was.
  PositionsUpdate commitPositions(Body& b, const std::vector<Vec3>& positions, const PositionsPlan& plan) {
    const std::vector<Vec3>& local = plan.framed ? b.local_positions : positions;
    PositionsUpdate update;
    if (plan.first) {
      b.deforming->anchor(local);  // new coordinates: a new lineage
      update.reanchored = true;
    } else {
      const DisplacementCheck check = b.deforming->setPositions(local);
      if (!check.accepted) {
        b.deforming->reanchor(local);
        update.reanchored = true;
        update.worst_vertex = check.worst_vertex;
        update.excess = check.excess;
      }
    }
    if (update.reanchored) {
      b.deforming->inflate(b.displacement_bound);
      anchorOrientation(b, local);
    }
    if (plan.framed) {
      b.framed = true;
      b.frame = plan.frame;
      b.frame_inverse = plan.frame.inverse(Eigen::Isometry);
      b.world_positions = positions;
    } else if (b.framed) {  // back to world coordinates
      b.framed = false;
      b.frame = b.frame_inverse = Eigen::Isometry3d::Identity();
      std::vector<Vec3>().swap(b.world_positions);
    }
    // Inline faces when the last step's queries tested enough leaf blocks to pay for refreshing
    // them all (kInlineFacesOn, kInlineFacesOff). Decided once the positions are accepted, so
    // positions that throw leave the body as it was; turning them on fills them at the new
    // positions.
    const double per_leaf = static_cast<double>(b.leaves_tested) / b.deforming->hierarchy()->leafCount();
    b.deforming->setInlineFaces(per_leaf >= (b.deforming->inlineFaces() ? kInlineFacesOff : kInlineFacesOn));
    b.box_dirty = true;
    return update;
  }
  PositionsUpdate applyPositions(Body& b, const std::vector<Vec3>& positions) {
    return commitPositions(b, positions, planPositions(b, positions));
  }

  // remove() leaves the removed body's pair states for the next step, whose alignStates()
  // drops every pair the broadphase no longer reports (a compaction per remove() made removing
  // many bodies quadratic in the states); until then coherentStates() skips them.
  bool removed_states = false;

  BodyHandle add(Body&& b) {
    uint32_t slot;
    if (!free_slots.empty()) {
      slot = free_slots.back();
      free_slots.pop_back();
    } else {
      slot = static_cast<uint32_t>(bodies.size());
      if (slot == kInvalidIndex) throw std::length_error("DistanceService: too many bodies");
      bodies.emplace_back();
      broadphase.resize(bodies.size());
    }
    b.generation = bodies[slot].generation + 1;
    b.alive = true;
    b.box_dirty = true;
    b.orientation = b.shape->restOrientation();
    bodies[slot] = std::move(b);
    broadphase.set(slot, Box3{});
    ++live;
    return handle(slot);
  }

  // A closed key-framed or deforming body's orientation at `pos`, its current positions.
  static double placementOrientation(Body& b, const std::vector<Vec3>& pos) {
    size_t i = 0;
    if (b.keyframed && b.keyframed->frameCount() > 1)
      i = std::min(static_cast<size_t>(b.keyframed->time()), b.keyframed->frameCount() - 2);
    if (i < b.orientation_refs.size() && b.orientation_refs[i].placement.holdsWithin(b.orientation_refs[i].reach))
      return b.orientation_refs[i].placement.orientation;
    if (!b.deforming || b.orientation_refs.empty()) return b.shape->orientationAt(pos.data());
    // Within a lineage, every vertex moved at most the drift's growth since (hierarchy.h), and
    // every placement on the way lies within the bound of the anchor, whose grown area bounds
    // theirs: the last placement's volume alone is needed (a pass without square roots).
    const TreeGeometry& g = b.deforming->geometry();
    const double area2 = b.orientation_refs[0].placement.grownArea2(b.displacement_bound * DeformingBody::kBoundReach);
    if (!(b.orientation_last_drift >= 0 && b.orientation_last_lineage == g.lineage &&
          b.orientation_last.holdsWithin(g.drift - b.orientation_last_drift, area2))) {
      b.orientation_last = b.shape->placementOrientation(pos.data(), false);
      b.orientation_last_drift = g.drift;
      b.orientation_last_lineage = g.lineage;
    }
    return b.orientation_last.orientation;
  }

  // A deforming body anchored at `anchor` with its displacement bound.
  static void anchorOrientation(Body& b, const std::vector<Vec3>& anchor) {
    b.orientation_refs.clear();
    b.orientation_last_drift = -1;
    if (!b.shape->closed()) return;
    b.orientation_refs.push_back(
        {b.shape->placementOrientation(anchor.data()), b.displacement_bound * DeformingBody::kBoundReach});
  }

  // A key-framed body's references, one per pair of frames (or the single frame).
  static void keyframeOrientations(Body& b) {
    b.orientation_refs.clear();
    if (!b.shape->closed()) return;
    const std::vector<std::vector<Vec3>>& frames = b.keyframed->frames();
    for (size_t i = 0; i == 0 || i + 1 < frames.size(); ++i) {
      double reach = 0;
      if (i + 1 < frames.size())
        for (size_t v = 0; v < frames[i].size(); ++v) reach = std::max(reach, (frames[i + 1][v] - frames[i][v]).norm());
      b.orientation_refs.push_back({b.shape->placementOrientation(frames[i].data()), reach});
    }
  }

  void refreshBox(Body& b) {
    Box3 box;
    if (b.kind == BodyKind::kRigid) {
      const Vec3 &lo = b.shape->restLower(), &hi = b.shape->restUpper();
      box.lower = Vec3::Constant(kInf);
      box.upper = Vec3::Constant(-kInf);
      double extent = 0;
      for (int corner = 0; corner < 8; ++corner) {
        const Vec3 c((corner & 1) ? hi.x() : lo.x(), (corner & 2) ? hi.y() : lo.y(), (corner & 4) ? hi.z() : lo.z());
        const Vec3 w = b.rigid->toWorld(c);
        box.lower = box.lower.cwiseMin(w);
        box.upper = box.upper.cwiseMax(w);
        extent = std::max(extent, w.cwiseAbs().maxCoeff());
      }
      // Rounding of the transform (the query runs in the body frame): relative to the terms
      // summed, the rest coordinates and the translation, not to the result alone. A body
      // whose rest coordinates are about 1e6, posed near the world origin, rounds its corners
      // by about 1e-10 (found by an audit: surface points were missed at max_distance 0).
      extent += lo.cwiseAbs().cwiseMax(hi.cwiseAbs()).maxCoeff() +
                b.rigid->pose().translation().cwiseAbs().maxCoeff();
      const double margin = 1e-12 * extent;
      box.lower.array() -= margin;
      box.upper.array() += margin;
    } else {
      // A framed body's box is its world positions' with the rigid margin (the queries run in
      // its frame); its orientation is its positions' in the frame (a rotation keeps a volume).
      const std::vector<Vec3>& pos = b.keyframed ? b.keyframed->positions() : b.deforming->positions();
      positionsBounds(b.framed ? b.world_positions : pos, box.lower, box.upper);
      if (b.framed) {
        const double margin = 1e-12 * (box.lower.cwiseAbs().cwiseMax(box.upper.cwiseAbs()).maxCoeff() +
                                       b.frame.translation().cwiseAbs().maxCoeff());
        box.lower.array() -= margin;
        box.upper.array() += margin;
      }
      if (b.shape->closed()) b.orientation = placementOrientation(b, pos);
    }
    b.box = box;
    b.scale = box.lower.cwiseAbs().cwiseMax(box.upper.cwiseAbs()).maxCoeff();
    b.corner_scale = b.kind == BodyKind::kRigid
                         ? b.shape->restLower().cwiseAbs().cwiseMax(b.shape->restUpper().cwiseAbs()).maxCoeff()
                     : b.framed ? kInf
                                : b.scale;
    if (const Eigen::Isometry3d* pose = b.pose()) b.scale += pose->translation().cwiseAbs().maxCoeff();
  }

  // Refreshes the boxes of the bodies changed since the last call; returns how many.
  uint32_t refreshBoxes() {
    std::vector<uint32_t> dirty;
    for (uint32_t s = 0; s < bodies.size(); ++s)
      if (bodies[s].alive && bodies[s].box_dirty) dirty.push_back(s);
    if (dirty.size() == 1) {
      refreshBox(bodies[dirty[0]]);
    } else if (dirty.size() > 1) {
      arena->execute([&] {
        tbb::parallel_for(size_t(0), dirty.size(), [&](size_t i) { refreshBox(bodies[dirty[i]]); });
      });
    }
    for (uint32_t s : dirty) {
      bodies[s].box_dirty = false;
      broadphase.set(s, bodies[s].box);
    }
    broadphase.prepare();  // the tree over many bodies, before the threads read it
    max_scale = 0;  // read only past kTreeBodies (blockCandidates)
    if (broadphase.liveCount() > Broadphase::kTreeBodies)
      for (const Body& b : bodies)
        if (b.alive) max_scale = std::max(max_scale, b.scale);
    return static_cast<uint32_t>(dirty.size());
  }

  QueryStream& stream(Scratch& s, uint32_t slot) {
    if (s.streams.size() < bodies.size()) s.streams.resize(bodies.size());
    StreamSlot& ss = s.streams[slot];
    const Body& b = bodies[slot];
    if (!ss.stream || ss.generation != b.generation) {
      ss.stream = std::make_unique<QueryStream>(b.shape->hierarchy());
      ss.stream->setGeometry(b.geometry());
      ss.generation = b.generation;
    }
    return *ss.stream;
  }

  // How far from the surface a computed distance at q (the point p in the body's frame) can
  // be made of rounding alone: 16 eps times the coordinates involved (and, for a rigid body or
  // a deforming body in a followed frame, those of p and of the frame's translation, whose
  // difference q carries). A point exactly on a face is answered 1e-17 away at coordinates of
  // 0.5, say, with a closest point one ulp aside. A hit this close is on the surface: it counts
  // as within any max_distance, and its direction and sign come from its feature's
  // pseudonormal, not from that offset.
  static constexpr double kSurfaceRounding = 16 * std::numeric_limits<double>::epsilon();
  double surfaceRounding(uint32_t slot, const Vec3& p, const Vec3& q) const {
    const Body& b = bodies[slot];
    double scale = q.cwiseAbs().maxCoeff();
    if (const Eigen::Isometry3d* pose = b.pose())
      scale += p.cwiseAbs().maxCoeff() + pose->translation().cwiseAbs().maxCoeff();
    return kSurfaceRounding * scale;
  }

  // The hit of a query point q (in the body's frame) on `face` of body `slot`: closest point
  // c (body frame), feature, barycentric coordinates, distance; `touch` is surfaceRounding()
  // at q (a hit no farther is on the surface), widened here by the face's corners for the
  // hit's direction and sign.
  // `signed_hit` false: the caller sets the sign (signLikeClosest), so the pseudonormal is only
  // needed for the direction on the surface.
  DistanceHit makeHit(uint32_t slot, const Vec3& p, const Vec3& q, TriangleIndex face, Feature feature, const Vec3& c,
                      const Vec3& barycentric, double distance, double touch, bool signed_hit = true) const {
    const Body& b = bodies[slot];
    const BodyShape& shape = *b.shape;
    DistanceHit hit;
    hit.body = handle(slot);
    hit.triangle = face;
    hit.feature = feature;
    hit.barycentric = barycentric;
    hit.distance = distance;
    hit.closed_body = shape.closed();
    const Vec3 offset = q - c;
    const double length = offset.norm();
    // On the surface (up to rounding) the offset's direction is noise: the pseudonormal gives
    // the direction, and the point is outside. The rounding of c also counts the face's
    // corners (restSide's band): near a large face that passes close to the frame's origin, q's
    // coordinates are small but c carries those of the corners (found by review: a point 4e-12
    // inside a face whose corners lie 1e5 away was signed by the noise of its closest point).
    if (distance > touch && distance <= kSurfaceRounding * b.corner_scale) {
      const Triangle& corners = shape.mesh().triangles[face];
      const Vec3* x = b.positions();
      for (int k = 0; k < 3; ++k) touch = std::max(touch, kSurfaceRounding * x[corners[k]].cwiseAbs().maxCoeff());
    }
    const bool on_surface = !(distance > touch) || !(length > 0);
    // The pseudonormal gives a closed body's sign, and the direction on the surface; an open
    // moving body skips it otherwise (evaluated at the current positions, it is not free).
    Vec3 normal = Vec3::Zero();
    if ((signed_hit && hit.closed_body) || on_surface)
      normal = b.kind == BodyKind::kRigid ? shape.restPseudonormal(face, feature)
                                          : shape.pseudonormal(face, feature, b.positions(), b.orientation);
    Vec3 direction = Vec3::Zero();
    if (!on_surface) {
      direction = offset / length;
    } else {
      const double n = normal.norm();
      if (n > 0) direction = normal / n;
    }
    // A point outside the body's box (by more than the surface's rounding) is outside the
    // solid, whatever face it reached: far away (1e16 times the body's size) the distances of
    // opposite faces tie in doubles, and the pseudonormal of the far side said inside (found by
    // review).
    if (!hit.closed_body)
      hit.sign = HitSign::kUnsigned;
    else
      hit.sign = !on_surface && offset.dot(normal) < 0 && !(squaredBoxDistance(b.box, p) > touch * touch)
                     ? HitSign::kInside
                     : HitSign::kOutside;
    hit.signed_distance = hit.sign == HitSign::kInside ? -distance : distance;
    if (const Eigen::Isometry3d* pose = b.pose()) {
      hit.point = *pose * c;
      hit.direction = pose->linear() * direction;
    } else {
      hit.point = c;
      hit.direction = direction;
    }
    return hit;
  }

  Vec3 toBody(uint32_t slot, const Vec3& p) const {
    const Body& b = bodies[slot];
    if (b.rigid) return b.rigid->toBody(p);
    return b.framed ? b.frame_inverse * p : p;
  }

  // The broadphase of one block: candidate lists in s.candidates (point j's from
  // s.candidate_begin[j] to [j + 1]); statuses written. With `closest_only` (closest mode) a
  // body whose box lies farther than the farthest point of another candidate's box is left
  // out: that box holds a surface point nearer than anything the first can hold.
  void blockCandidates(Scratch& s, const PointRows& points, size_t first, uint32_t count, double d,
                       bool closest_only, StepResult& out, StepStats& stats) {
    s.found.resize(std::max<size_t>(1, broadphase.liveCount()));
    s.candidates.clear();
    s.candidate_begin.resize(count + 1);
    for (uint32_t j = 0; j < count; ++j) {
      s.candidate_begin[j] = static_cast<uint32_t>(s.candidates.size());
      const Vec3 p = points.row(first + j).transpose();
      if (!inCoordinateRange(p)) {
        out.status_[first + j] = p.allFinite() ? PointStatus::kOutOfRange : PointStatus::kNotFinite;
        ++stats.invalid_points;
        continue;
      }
      // Bodies within d, or within rounding of the point (twice surfaceRounding() of a
      // key-framed or deforming body, where q = p: a point on a surface one ulp outside such a
      // body's exact box is still on it; a rigid body's box has its own margin).
      double reach = std::max(d, 2 * kSurfaceRounding * p.cwiseAbs().maxCoeff());
      // With many bodies (a tree over them), the closest hit is first bounded by the nearest
      // box's farthest point, with the pruning's margin below at every body's scale: no body
      // that the pruning keeps is beyond that. (At d = infinity every body was a candidate, its
      // box measured point after point: 1.7 s a step for 1,000 points and 16,384 bodies, found
      // by an audit.)
      if (closest_only && broadphase.liveCount() > Broadphase::kTreeBodies)
        reach = std::min(reach, broadphase.nearestFar(p) * (1 + 2e-12) +
                                    4 * kSurfaceRounding * (p.cwiseAbs().maxCoeff() + max_scale));
      const size_t found = broadphase.candidates(p, reach, s.found.data());
      // The least distance to a candidate box's farthest point bounds the closest hit; a body
      // whose box is farther cannot hold it. The margin covers the rounding of the distances
      // the queries compute (a rigid body's are in its frame: surfaceRounding()'s scale), so
      // pruning never picks between two hits that rounding could order either way.
      double nearest_far = kInf, margin = 0;
      if (closest_only && found > 1) {
        double scale = p.cwiseAbs().maxCoeff();
        for (size_t k = 0; k < found; ++k) {
          const Body& b = bodies[s.found[k]];
          nearest_far = std::min(nearest_far, (p - b.box.lower).cwiseAbs().cwiseMax((p - b.box.upper).cwiseAbs()).norm());
          scale = std::max(scale, b.scale);
        }
        margin = 4 * kSurfaceRounding * scale;
      }
      for (size_t k = 0; k < found; ++k) {
        if (nearest_far < kInf &&
            std::sqrt(squaredBoxDistance(bodies[s.found[k]].box, p)) > nearest_far * (1 + 1e-12) + margin)
          continue;
        s.candidates.push_back(s.found[k]);
      }
      stats.pairs += s.candidates.size() - s.candidate_begin[j];
    }
    s.candidate_begin[count] = static_cast<uint32_t>(s.candidates.size());
  }

  // The block's pair states for this step's candidates (s.candidates): reused in place when
  // every point kept its bodies; else rebuilt, keeping the states of the pairs that remain.
  BlockStates& alignStates(Scratch& s, size_t block, uint32_t count) {
    BlockStates& states = blocks[block];
    bool same = states.points == count;
    for (uint32_t j = 0; same && j < count; ++j) {
      const uint32_t* cand = s.candidates.data() + s.candidate_begin[j];
      const uint32_t found = s.candidate_begin[j + 1] - s.candidate_begin[j];
      const uint32_t b0 = states.begin[j];
      // This pass is the first to touch the block's states: start loading the ones ahead (the
      // queries below read them whole).
      if (b0 + 4 < states.pairs.size()) prefetchPair(states.pairs[b0 + 4]);
      same = states.begin[j + 1] - b0 == found;
      for (uint32_t k = 0; same && k < found; ++k)
        same = states.pairs[b0 + k].slot == cand[k] && states.pairs[b0 + k].generation == bodies[cand[k]].generation;
    }
    if (!same) {
      s.begin.resize(count + 1);
      s.pairs.clear();
      for (uint32_t j = 0; j < count; ++j) {
        s.begin[j] = static_cast<uint32_t>(s.pairs.size());
        uint32_t o = j < states.points ? states.begin[j] : 0;
        const uint32_t o_end = j < states.points ? states.begin[j + 1] : 0;
        const uint32_t* cand = s.candidates.data() + s.candidate_begin[j];
        const uint32_t found = s.candidate_begin[j + 1] - s.candidate_begin[j];
        for (uint32_t k = 0; k < found; ++k) {
          const uint32_t slot = cand[k];
          while (o < o_end && states.pairs[o].slot < slot) ++o;
          if (o < o_end && states.pairs[o].slot == slot && states.pairs[o].generation == bodies[slot].generation) {
            s.pairs.push_back(states.pairs[o]);
          } else {
            PairState fresh;
            fresh.slot = slot;
            fresh.generation = bodies[slot].generation;
            fresh.state.reach_steps = options.reach_steps;
            fresh.state.lead_steps = options.lead_steps;
            s.pairs.push_back(fresh);
          }
        }
      }
      s.begin[count] = static_cast<uint32_t>(s.pairs.size());
      std::swap(states.begin, s.begin);
      std::swap(states.pairs, s.pairs);
      states.points = count;
      // Keep memory bounded by what the block needs now (with slack against churn; none when
      // no pair is left: its points left every body, or the bodies were removed).
      const size_t keep = states.pairs.empty() ? 0 : 4 * states.pairs.size() + 64;
      if (states.pairs.capacity() > keep) states.pairs.shrink_to_fit();
      if (s.pairs.capacity() > keep) {
        s.pairs.clear();
        s.pairs.shrink_to_fit();
      }
    }
    return states;
  }

  // A block's points [first, first + count): their candidates (broadphase) and pair states.
  struct BlockWork {
    Scratch& scratch;
    size_t first;
    uint32_t count;
    StepStats& stats;
    BlockStates& states;
  };
  BlockWork beginBlock(size_t block, const PointRows& points, double d, bool closest_only, StepResult& out) {
    Scratch& s = localScratch();
    const size_t first = block * options.block_size;
    const uint32_t count = static_cast<uint32_t>(std::min<size_t>(options.block_size, points.rows() - first));
    StepStats& stats = block_stats[block];
    blockCandidates(s, points, first, count, d, closest_only, out, stats);
    return {s, first, count, stats, alignStates(s, block, count)};
  }

  void closestBlock(size_t block, const PointRows& points, double d, StepResult& out) {
    auto&& [s, first, count, stats, states] = beginBlock(block, points, d, true, out);

    // Two passes: the queries, then the hits. A hit's pseudonormal is a table lookup that
    // usually misses the cache; the first pass starts loading it, the second reads it.
    s.best.resize(count);
    for (uint32_t j = 0; j < count; ++j) {
      const size_t i = first + j;
      const Vec3 p = points.row(i).transpose();
      double best = kInf;
      BestHit& hit = s.best[j];
      hit.c.triangle = kInvalidIndex;
      for (uint32_t k = states.begin[j]; k < states.begin[j + 1]; ++k) {
        if (k + 2 < states.pairs.size()) prefetchPair(states.pairs[k + 2]);  // the pair two ahead
        PairState& pair = states.pairs[k];
        const Vec3 q = toBody(pair.slot, p);
        // The closest face within d: a pair out of reach is answered (or certified) without
        // looking farther than d, and its state's certificate covers the next steps.
        if (pair.state.lineage != 0) ++stats.warm_pairs;
        bool certified = false;
        const double touch = surfaceRounding(pair.slot, p, q);
        const ClosestPoint c = stream(s, pair.slot).closestCoherent(q, pair.state, &certified, std::max(d, touch));
        stats.certified_pairs += certified;
        stats.out_of_reach_pairs += c.triangle == kInvalidIndex;
        stats.triangles_tested += c.counters.triangles_tested;
        s.streams[pair.slot].leaves_tested += c.counters.leaves_tested;
        if ((c.distance <= d || c.distance <= touch) && c.distance < best) {
          best = c.distance;
          hit = {pair.slot, c, q, touch};
        }
      }
      if (hit.c.triangle != kInvalidIndex && bodies[hit.slot].kind == BodyKind::kRigid)
        bodies[hit.slot].shape->prefetchRestPseudonormal(hit.c.triangle, hit.c.feature);
    }
    for (uint32_t j = 0; j < count; ++j) {
      const BestHit& hit = s.best[j];
      if (hit.c.triangle == kInvalidIndex) continue;  // set only for a hit within d
      const size_t i = first + j;
      out.hits_[i] = makeHit(hit.slot, points.row(i).transpose(), hit.q, hit.c.triangle, hit.c.feature,
                             hit.c.point, hit.c.barycentric, hit.c.distance, hit.touch);
      out.count_[i] = 1;
      ++stats.hits;
    }
    stats.states = states.pairs.size();
  }

  // The hits [first, last) of one point on one body, in QueryStream::within's order (by
  // distance, ties by triangle): on a closed body they all take the sign of the first, the
  // closest, where the pseudonormal test holds; a farther face's own feature says nothing about
  // inside and outside.
  static void signLikeClosest(DistanceHit* first, DistanceHit* last) {
    if (first == last || !first->closed_body) return;
    const HitSign sign = first->sign;
    for (DistanceHit* h = first; h != last; ++h) {
      h->sign = sign;
      h->signed_distance = sign == HitSign::kInside ? -h->distance : h->distance;
    }
  }

  // Each body's hits of a point come sorted (by distance, then triangle): the runs that start
  // at `runs` (and end at hits.end()) are merged in pairs, pass after pass, so a point within
  // reach of many bodies costs O(hits log bodies). (Merged into the point's list body after
  // body, it cost O(hits x bodies): 2 s a step for 20 points within reach of 4,000 bodies,
  // found by an audit.) Leaves `runs` empty.
  static void mergeRuns(std::vector<DistanceHit>& hits, std::vector<size_t>& runs) {
    if (runs.size() > 1) {
      const auto at = [&hits](size_t k) { return hits.begin() + static_cast<std::ptrdiff_t>(k); };
      runs.push_back(hits.size());  // runs[0, n) start the runs, runs[n] ends the last
      while (runs.size() > 2) {
        const size_t count = runs.size() - 1;
        size_t kept = 0;
        for (size_t r = 0; r < count; r += 2) {
          if (r + 1 < count) std::inplace_merge(at(runs[r]), at(runs[r + 1]), at(runs[r + 2]), hitOrder);
          runs[kept++] = runs[r];
        }
        runs[kept++] = hits.size();
        runs.resize(kept);
      }
    }
    runs.clear();
  }

  void withinBlock(size_t block, const PointRows& points, double d, StepResult& out) {
    auto&& [s, first, count, stats, states] = beginBlock(block, points, d, false, out);
    std::vector<DistanceHit>& hits = block_hits[block];
    hits.clear();
    s.runs.clear();  // (a step that threw may have left some)
    for (uint32_t j = 0; j < count; ++j) {
      const size_t i = first + j;
      const Vec3 p = points.row(i).transpose();
      const size_t point_from = hits.size();  // the point's hits: hits[point_from, end)
      for (uint32_t k = states.begin[j]; k < states.begin[j + 1]; ++k) {
        if (k + 2 < states.pairs.size()) prefetchPair(states.pairs[k + 2]);
        PairState& pair = states.pairs[k];
        const uint32_t slot = pair.slot;
        const Vec3 q = toBody(slot, p);
        QueryStream& qs = stream(s, slot);
        if (pair.state.lineage != 0) ++stats.warm_pairs;
        bool certified = false;
        const double touch = surfaceRounding(slot, p, q);  // hits on the surface count for any d
        qs.withinCoherent(q, std::max(d, touch), pair.state, s.triangle_hits, &certified);
        stats.certified_pairs += certified;
        stats.triangles_tested += qs.counters().triangles_tested;
        s.streams[slot].leaves_tested += qs.counters().leaves_tested;
        const size_t from = hits.size();
        if (s.triangle_hits.empty()) continue;
        // The first, closest hit gives every hit of this body its sign (signLikeClosest).
        for (const TriangleHit& t : s.triangle_hits)
          hits.push_back(makeHit(slot, p, q, t.triangle, t.feature, t.point, t.barycentric, t.distance, touch,
                                 hits.size() == from));
        signLikeClosest(hits.data() + from, hits.data() + hits.size());
        s.runs.push_back(from);
      }
      mergeRuns(hits, s.runs);
      out.begin_[i] = point_from;  // in the block's hits
      out.count_[i] = static_cast<uint32_t>(hits.size() - point_from);
      stats.hits += hits.size() - point_from;
    }
    stats.states = states.pairs.size();
  }
};

DistanceService::DistanceService(const ServiceOptions& options) : impl_(std::make_unique<Impl>()) {
  if (options.block_size == 0) throw std::invalid_argument("DistanceService: block_size must be > 0");
  if (!(options.reach_steps >= 0) || !std::isfinite(options.reach_steps))
    throw std::invalid_argument("DistanceService: reach_steps must be finite and >= 0");
  if (!(options.lead_steps >= 0) || !std::isfinite(options.lead_steps))
    throw std::invalid_argument("DistanceService: lead_steps must be finite and >= 0");
  impl_->options = options;
  setThreads(options.threads);
}

DistanceService::~DistanceService() = default;

// ---- Shared tables --------------------------------------------------------------------------

std::shared_ptr<const Hierarchy> DistanceService::hierarchyFor(const Mesh& mesh) {
  Impl& m = *impl_;
  auto it = m.mesh_cache.find(&mesh);
  if (it != m.mesh_cache.end()) {
    const MeshCacheEntry& e = it->second;
    // The same address can hold another mesh (a new one in the same storage): the contents
    // decide (the hierarchy keeps a copy; comparing costs far less than a build).
    std::shared_ptr<const Hierarchy> cached = e.hierarchy.lock();
    if (cached && e.positions == mesh.positions.data() && e.triangles == mesh.triangles.data() &&
        e.vertex_count == mesh.positions.size() && e.triangle_count == mesh.triangles.size() &&
        cached->mesh().positions == mesh.positions && cached->mesh().triangles == mesh.triangles)
      return cached;
  }
  std::shared_ptr<const Hierarchy> hierarchy = Hierarchy::build(mesh);
  MeshCacheEntry& e = m.mesh_cache[&mesh];
  e.hierarchy = hierarchy;
  e.positions = mesh.positions.data();
  e.triangles = mesh.triangles.data();
  e.vertex_count = mesh.positions.size();
  e.triangle_count = mesh.triangles.size();
  sweepExpired(m.mesh_cache, m.mesh_cache_swept, [](const MeshCacheEntry& entry) { return entry.hierarchy.expired(); });
  return hierarchy;
}

void DistanceService::forgetMesh(const Mesh& mesh) { impl_->mesh_cache.erase(&mesh); }

std::shared_ptr<const BodyShape> DistanceService::shapeFor(const std::shared_ptr<const Hierarchy>& hierarchy) {
  if (!hierarchy) throw std::invalid_argument("DistanceService: null hierarchy");
  auto& entry = impl_->shapes[hierarchy.get()];
  std::shared_ptr<const BodyShape> shape = entry.lock();
  // The shape holds its hierarchy, so a live entry cannot name a recycled address.
  if (shape && shape->hierarchy() == hierarchy) return shape;
  shape = BodyShape::build(hierarchy);
  entry = shape;
  sweepExpired(impl_->shapes, impl_->shapes_swept, [](const auto& weak) { return weak.expired(); });
  return shape;
}

// ---- Bodies ---------------------------------------------------------------------------------

BodyHandle DistanceService::addRigid(std::shared_ptr<const Hierarchy> hierarchy, const Eigen::Isometry3d& pose) {
  Body b;
  b.kind = BodyKind::kRigid;
  b.shape = shapeFor(hierarchy);
  b.rest = hierarchy->restGeometry();
  naming("addRigid", "a new body", [&] { b.rigid = std::make_unique<RigidBody>(std::move(hierarchy), pose); });
  return impl_->add(std::move(b));
}

BodyHandle DistanceService::addKeyframed(std::shared_ptr<const Hierarchy> hierarchy,
                                         std::vector<std::vector<Vec3>> frames, double time) {
  if (!std::isfinite(time)) throw std::invalid_argument("DistanceService::addKeyframed: time is not finite");
  Body b;
  b.kind = BodyKind::kKeyframed;
  b.shape = shapeFor(hierarchy);
  naming("addKeyframed", "a new body", [&] {
    b.keyframed = std::make_unique<KeyframeBody>(std::move(hierarchy), std::move(frames));
    b.keyframed->setTime(time);
  });
  Impl::keyframeOrientations(b);
  return impl_->add(std::move(b));
}

BodyHandle DistanceService::addDeforming(std::shared_ptr<const Hierarchy> hierarchy, double displacement_bound,
                                         const std::vector<Vec3>& positions) {
  if (!(displacement_bound >= 0) || !std::isfinite(displacement_bound))
    throw std::invalid_argument("DistanceService::addDeforming: displacement_bound must be finite and >= 0");
  Body b;
  b.kind = BodyKind::kDeforming;
  b.shape = shapeFor(hierarchy);
  naming("addDeforming", "a new body", [&] {
    b.deforming = std::make_unique<DeformingBody>(std::move(hierarchy));
    b.deforming->setRadii(false);  // the service's queries read boxes only: anchors skip the radius phase
    b.deforming->setRegionalDrift(impl_->options.regional_drift);
    if (!positions.empty()) b.deforming->anchor(positions);
    b.deforming->inflate(displacement_bound);
  });
  b.displacement_bound = displacement_bound;
  Impl::anchorOrientation(b, b.deforming->positions());
  return impl_->add(std::move(b));
}

BodyHandle DistanceService::addKeyframed(std::shared_ptr<const Hierarchy> hierarchy,
                                         std::initializer_list<PointsRef> frames, double time) {
  std::vector<std::vector<Vec3>> copied;
  copied.reserve(frames.size());
  for (const PointsRef& frame : frames) copied.push_back(toPositions(frame));
  return addKeyframed(std::move(hierarchy), std::move(copied), time);
}

BodyHandle DistanceService::addDeforming(std::shared_ptr<const Hierarchy> hierarchy, double displacement_bound,
                                         const PointsRef& positions) {
  // Unlike the vector's default (empty: the mesh's positions), a matrix always gives positions:
  // one of 0 rows is a wrong count (found by an audit: it started the body at the mesh's own).
  // Other counts are checked where the vector's are.
  if (hierarchy && positions.matrix().rows() == 0)
    throw std::invalid_argument("DistanceService::addDeforming (a new body): 0 positions, the mesh has " +
                                std::to_string(hierarchy->mesh().positions.size()) + " vertices");
  return addDeforming(std::move(hierarchy), displacement_bound, toPositions(positions));
}

void DistanceService::remove(BodyHandle handle) {
  Body& b = impl_->body(handle, "remove");
  const uint32_t generation = b.generation;
  b = Body{};
  b.generation = generation;  // the next body in this slot gets generation + 1
  impl_->broadphase.set(handle.index, Box3{});
  impl_->free_slots.push_back(handle.index);
  --impl_->live;
  for (Scratch& s : impl_->scratch)
    if (handle.index < s.streams.size()) s.streams[handle.index] = StreamSlot{};
  impl_->removed_states = true;  // its states are dropped at the next step
}

bool DistanceService::contains(BodyHandle h) const { return impl_->holds(h); }

size_t DistanceService::bodyCount() const { return impl_->live; }

std::vector<BodyHandle> DistanceService::bodies() const {
  std::vector<BodyHandle> out;
  for (uint32_t s = 0; s < impl_->bodies.size(); ++s)
    if (impl_->bodies[s].alive) out.push_back(impl_->handle(s));
  return out;
}

BodyKind DistanceService::kind(BodyHandle body) const { return impl_->body(body, "kind").kind; }

const BodyShape& DistanceService::shape(BodyHandle body) const { return *impl_->body(body, "shape").shape; }

void DistanceService::setPose(BodyHandle body, const Eigen::Isometry3d& pose) {
  Body& b = impl_->body(body, "setPose", BodyKind::kRigid);
  naming("setPose", bodyName(body), [&] { b.rigid->setPose(pose); });
  b.box_dirty = true;
}

const Eigen::Isometry3d& DistanceService::pose(BodyHandle body) const {
  return impl_->body(body, "pose", BodyKind::kRigid).rigid->pose();
}

Eigen::Isometry3d DistanceService::frame(BodyHandle body) const {
  const Eigen::Isometry3d* pose = impl_->body(body, "frame").pose();
  return pose ? *pose : Eigen::Isometry3d::Identity();
}

void DistanceService::setTime(BodyHandle body, double t) {
  Body& b = impl_->body(body, "setTime", BodyKind::kKeyframed);
  if (!std::isfinite(t)) throw std::invalid_argument("DistanceService::setTime: time is not finite");
  b.keyframed->setTime(t);
  b.box_dirty = true;
}

namespace {
void copyRows(const PointRows& rows, std::vector<Vec3>& out) {
  out.resize(static_cast<size_t>(rows.rows()));
  for (Eigen::Index i = 0; i < rows.rows(); ++i) out[i] = rows.row(i).transpose();
}
}  // namespace

std::vector<Vec3> toPositions(const PointsRef& points) {
  std::vector<Vec3> v;
  copyRows(points.matrix(), v);
  return v;
}

PositionsUpdate DistanceService::setPositions(BodyHandle body, const PointsRef& points) {
  impl_->body(body, "setPositions", BodyKind::kDeforming);
  copyRows(points.matrix(), impl_->positions_scratch);  // its capacity kept from step to step
  return setPositions(body, impl_->positions_scratch);
}

PositionsUpdate DistanceService::setPositions(BodyHandle body, const std::vector<Vec3>& positions) {
  Body& b = impl_->body(body, "setPositions", BodyKind::kDeforming);
  // In the service's arena: the inline faces' refresh runs on its threads.
  PositionsUpdate update;
  naming("setPositions", bodyName(body),
         [&] { impl_->arena->execute([&] { update = impl_->applyPositions(b, positions); }); });
  return update;
}

std::vector<PositionsUpdate> DistanceService::setPositions(const std::vector<BodyPositions>& batch) {
  // "setPositions: batch entry i (body n)": the call and the entry, in front of every error.
  auto entry = [&](size_t i) {
    const uint32_t slot = batch[i].body.index;
    return "setPositions: batch entry " + std::to_string(i) + " (body " +
           (slot == kInvalidIndex ? std::string("none") : std::to_string(slot)) + ")";
  };
  auto error = [&](size_t i, const std::string& what) {
    return std::invalid_argument("DistanceService::" + entry(i) + what);
  };
  // Every entry checked before any body changes.
  std::vector<Body*> targets(batch.size());
  std::unordered_map<uint32_t, size_t> first_entry;  // slot -> the first entry naming it
  for (size_t i = 0; i < batch.size(); ++i) {
    Body& b = impl_->body(batch[i].body, entry(i).c_str(), BodyKind::kDeforming);
    const BodyPositions::MatrixView& rows = batch[i].rows;
    if (!batch[i].positions && !rows.given) throw error(i, ": null positions");
    if (!batch[i].positions && rows.cols != 3)
      throw error(i, ": positions need 3 columns (x, y, z), got " + std::to_string(rows.cols));
    const size_t count = batch[i].positions ? batch[i].positions->size() : static_cast<size_t>(rows.rows);
    const size_t expected = b.deforming->positions().size();
    if (count != expected)
      throw error(i, ": " + std::to_string(count) + " positions, the mesh has " + std::to_string(expected) +
                         " vertices");
    targets[i] = &b;
    const auto [first, fresh] = first_entry.emplace(batch[i].body.index, i);
    if (!fresh)
      throw error(i, ": body " + std::to_string(batch[i].body.index) + " appears twice in the batch (entries " +
                         std::to_string(first->second) + " and " + std::to_string(i) + ")");
  }
  // The bodies commit in parallel: an entry whose positions are a batch body's own vectors
  // (positions(other) of a deforming body) would read them while that body changes them. Such
  // entries are copied first, so every entry sees the positions as they were before the call.
  // An Eigen matrix's entry is always copied (in parallel, below), so it is safe too.
  std::vector<const std::vector<Vec3>*> inputs(batch.size());
  std::vector<const std::vector<Vec3>*> owned;
  for (const Body* t : targets) {
    owned.push_back(&t->world_positions);
    owned.push_back(&t->local_positions);
    owned.push_back(&t->deforming->positions());
  }
  const std::less<const std::vector<Vec3>*> before;  // a total order on unrelated pointers
  std::sort(owned.begin(), owned.end(), before);
  std::vector<std::vector<Vec3>> copies(batch.size());
  for (size_t i = 0; i < batch.size(); ++i) {
    inputs[i] = batch[i].positions;
    if (!inputs[i]) {
      inputs[i] = &copies[i];
    } else if (std::binary_search(owned.begin(), owned.end(), inputs[i], before)) {
      copies[i] = *inputs[i];
      inputs[i] = &copies[i];
    }
  }
  std::vector<PositionsUpdate> updates(batch.size());
  impl_->arena->execute([&] {
    // Coordinates, plans and extent first (changing nothing but the bodies' scratch), so an
    // error leaves every body unchanged. The extent is the one the body will hold: in its
    // frame, if it takes one (a rotation changes a box's diagonal).
    std::vector<const char*> problem(batch.size(), nullptr);
    std::vector<Impl::PositionsPlan> plans(batch.size());
    auto inRange = [](const std::vector<Vec3>& positions) {
      bool ok = true;
      for (const Vec3& x : positions) ok &= inCoordinateRange(x);
      return ok;
    };
    tbb::parallel_for(size_t{0}, batch.size(), [&](size_t i) {
      if (!batch[i].positions) {  // an Eigen matrix's rows
        const BodyPositions::MatrixView& m = batch[i].rows;
        copies[i].resize(static_cast<size_t>(m.rows));
        for (Eigen::Index v = 0; v < m.rows; ++v) {
          const double* x = m.data + v * m.row_stride;
          copies[i][v] = Vec3(x[0], x[m.col_stride], x[2 * m.col_stride]);
        }
      }
      if (!inRange(*inputs[i])) {
        problem[i] = " has a non-finite position or one beyond 1e150 in magnitude";
        return;
      }
      plans[i] = impl_->planPositions(*targets[i], *inputs[i]);
      const std::vector<Vec3>& held = plans[i].framed ? targets[i]->local_positions : *inputs[i];
      if (plans[i].framed && !inRange(held))
        problem[i] = " has a position beyond 1e150 in magnitude in the body's frame";
      else if (!withinMeshSize(targets[i]->shape->mesh(), held))
        problem[i] = " has positions spanning more than the supported mesh size 1e50";
    });
    for (size_t i = 0; i < batch.size(); ++i)
      if (problem[i]) throw error(i, problem[i]);
    tbb::parallel_for(size_t{0}, batch.size(), [&](size_t i) {
      updates[i] = impl_->commitPositions(*targets[i], *inputs[i], plans[i]);
    });
  });
  return updates;
}

void DistanceService::setDisplacementBound(BodyHandle body, double displacement_bound) {
  Body& b = impl_->body(body, "setDisplacementBound", BodyKind::kDeforming);
  if (!(displacement_bound >= 0) || !std::isfinite(displacement_bound))
    throw std::invalid_argument("DistanceService::setDisplacementBound: the bound must be finite and >= 0");
  const std::vector<Vec3> current = b.deforming->positions();
  impl_->arena->execute([&] {
    b.deforming->anchor(current);
    b.deforming->inflate(displacement_bound);
  });
  b.displacement_bound = displacement_bound;
  Impl::anchorOrientation(b, current);
}

bool DistanceService::inlineFaces(BodyHandle body) const {
  return impl_->body(body, "inlineFaces", BodyKind::kDeforming).deforming->inlineFaces();
}

const std::vector<Vec3>& DistanceService::positions(BodyHandle body) const {
  Body& b = impl_->body(body, "positions");
  if (b.keyframed) return b.keyframed->positions();
  if (b.deforming) return b.framed ? b.world_positions : b.deforming->positions();
  throw std::invalid_argument("DistanceService::positions: body " + std::to_string(body.index) +
                              " is rigid (its positions are the mesh's, placed by its pose)");
}

Box3 DistanceService::worldBox(BodyHandle body) {
  Body& b = impl_->body(body, "worldBox");
  if (b.box_dirty) {
    impl_->refreshBox(b);
    b.box_dirty = false;
    impl_->broadphase.set(body.index, b.box);
  }
  return b.box;
}

// ---- Queries --------------------------------------------------------------------------------

Eigen::Index PointsRef::requireThreeColumns(Eigen::Index columns) {
  if (columns != 3)
    throw std::invalid_argument("meshsweeper: points and positions need 3 columns (x, y, z), got " +
                                std::to_string(columns));
  return columns;
}

StepResult DistanceService::step(const PointsRef& points, double max_distance, QueryMode mode) {
  StepResult out;
  step(points, max_distance, mode, out);
  return out;
}

void DistanceService::step(const PointsRef& points, double max_distance, QueryMode mode, StepResult& out) {
  if (std::isnan(max_distance) || max_distance < 0)
    throw std::invalid_argument("DistanceService::step: max_distance must be >= 0 (got " +
                                numberText(max_distance) + ")");
  if (mode != QueryMode::kClosest && mode != QueryMode::kWithin)
    throw std::invalid_argument("DistanceService::step: unknown query mode " +
                                std::to_string(static_cast<int>(mode)));
  Impl& m = *impl_;
  try {
    stepInto(points.matrix(), max_distance, mode, out);
  } catch (...) {
    // Out of memory (or a thread's exception): the result is left empty, not half-written (a
    // within step's hits are swapped out while it runs, found by review), and a removed body's
    // states still count as removed until a step completes. Its memory goes with it.
    out = StepResult();
    throw;
  }
  m.removed_states = false;  // this step's alignStates() dropped them (see remove())
}

void DistanceService::stepInto(const PointRows& points, double max_distance, QueryMode mode, StepResult& out) {
  Impl& m = *impl_;
  auto start = std::chrono::steady_clock::now();
  const uint32_t refreshed = m.refreshBoxes();
  const double bounds_seconds = secondsSince(start);
  start = std::chrono::steady_clock::now();

  const size_t n = static_cast<size_t>(points.rows());
  const size_t bs = m.options.block_size;
  const size_t block_count = (n + bs - 1) / bs;
  out.mode_ = mode;
  out.max_distance_ = max_distance;
  out.status_.assign(n, PointStatus::kOk);
  out.count_.assign(n, 0);
  out.stats_ = {};
  m.block_stats.assign(block_count, StepStats{});
  m.blocks.resize(block_count);  // blocks past the batch drop their states
  if (mode == QueryMode::kClosest) {
    out.begin_.clear();
    out.hits_.resize(n);
    std::vector<std::vector<DistanceHit>>().swap(m.block_hits);  // a within step's hits
    std::vector<std::vector<DistanceHit>>().swap(out.block_hits_);
  } else {
    // Each block writes its hits into a vector of its own, which the result then takes (no
    // copy); the result's vectors from its last within step come back as the blocks' room.
    out.hits_.clear();
    out.begin_.resize(n);
    out.block_size_ = bs;
    m.block_hits.swap(out.block_hits_);
    m.block_hits.resize(block_count);
  }
  m.arena->execute([&] {
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, block_count, 1),
        [&](const tbb::blocked_range<size_t>& r) {
          for (size_t b = r.begin(); b != r.end(); ++b) {
            if (mode == QueryMode::kClosest)
              m.closestBlock(b, points, max_distance, out);
            else
              m.withinBlock(b, points, max_distance, out);
          }
        },
        tbb::simple_partitioner());
  });
  if (mode == QueryMode::kWithin) {
    for (std::vector<DistanceHit>& hits : m.block_hits) {
      // Keep room for about as many hits as this step's, no more.
      if (hits.capacity() > 2 * hits.size() + 64) hits.shrink_to_fit();
    }
    out.block_hits_.swap(m.block_hits);
  }
  // Leaf blocks tested per body: how much a deforming body's inline faces would save.
  for (Body& b : m.bodies) b.leaves_tested = 0;
  // Scratch left at its largest by one big step (a within step at a large distance: megabytes
  // per thread and body) is freed, found by an audit; what a usual step uses stays.
  constexpr size_t kKeepHits = 4096, kKeepSlots = size_t{1} << 16;
  for (Scratch& s : m.scratch) {
    for (size_t slot = 0; slot < s.streams.size(); ++slot) {
      StreamSlot& ss = s.streams[slot];
      if (slot < m.bodies.size() && m.bodies[slot].generation == ss.generation)
        m.bodies[slot].leaves_tested += ss.leaves_tested;
      ss.leaves_tested = 0;
      if (ss.stream) ss.stream->trimScratch(kKeepHits);
    }
    if (s.triangle_hits.capacity() > kKeepHits) std::vector<TriangleHit>().swap(s.triangle_hits);
    if (s.candidates.capacity() > kKeepSlots) std::vector<uint32_t>().swap(s.candidates);
  }
  StepStats& stats = out.stats_;
  for (const StepStats& s : m.block_stats) {
    stats.invalid_points += s.invalid_points;
    stats.pairs += s.pairs;
    stats.warm_pairs += s.warm_pairs;
    stats.certified_pairs += s.certified_pairs;
    stats.out_of_reach_pairs += s.out_of_reach_pairs;
    stats.triangles_tested += s.triangles_tested;
    stats.hits += s.hits;
    stats.states += s.states;
  }
  if (mode == QueryMode::kWithin) stats.states = coherentStates();
  stats.points = n;
  stats.bodies_refreshed = refreshed;
  stats.bounds_seconds = bounds_seconds;
  stats.query_seconds = secondsSince(start);
}

void DistanceService::setThreads(unsigned threads) {
  // TBB takes any count and crashed or ran out of memory at the next step past about 1e7 (found
  // by review): far beyond any machine, so refused.
  constexpr unsigned kMaxThreads = 1u << 16;
  if (threads > kMaxThreads)
    throw std::invalid_argument("DistanceService: threads must be at most " + std::to_string(kMaxThreads) +
                                " (0: TBB's default), got " + std::to_string(threads));
  // The same count keeps its arena (a new oneTBB arena each call also kept some memory, found by
  // an audit).
  const int concurrency = arenaConcurrency(threads);
  if (impl_->arena && concurrency == impl_->arena_concurrency) return;
  auto arena = std::make_unique<tbb::task_arena>(concurrency);
  impl_->scratch.resize(static_cast<size_t>(arena->max_concurrency()));
  impl_->arena = std::move(arena);
  impl_->arena_concurrency = concurrency;
}

unsigned DistanceService::threads() const { return static_cast<unsigned>(impl_->arena->max_concurrency()); }

size_t DistanceService::coherentStates() const {
  size_t total = 0;
  for (const BlockStates& b : impl_->blocks) {
    if (!impl_->removed_states) {
      total += b.pairs.size();
      continue;
    }
    for (const PairState& pair : b.pairs) {  // a removed body's states wait for the next step
      const Body& body = impl_->bodies[pair.slot];
      total += body.alive && body.generation == pair.generation;
    }
  }
  return total;
}

size_t DistanceService::coherentStateBytes() const {
  size_t total = 0;
  for (const BlockStates& b : impl_->blocks)
    total += b.pairs.capacity() * sizeof(PairState) + b.begin.capacity() * sizeof(uint32_t);
  return total;
}

size_t DistanceService::scratchBytes() const {
  size_t total = 0;
  for (const Scratch& s : impl_->scratch) {
    total += sizeof(Scratch) + s.streams.capacity() * sizeof(StreamSlot) + s.best.capacity() * sizeof(BestHit) +
             (s.found.capacity() + s.candidates.capacity() + s.candidate_begin.capacity() + s.begin.capacity()) *
                 sizeof(uint32_t) +
             s.pairs.capacity() * sizeof(PairState) + s.triangle_hits.capacity() * sizeof(TriangleHit) +
             s.runs.capacity() * sizeof(size_t);
    for (const StreamSlot& ss : s.streams)
      if (ss.stream) total += ss.stream->stateBytes();
  }
  return total;
}

void DistanceService::clearCoherentStates() { impl_->blocks.clear(); }

}  // namespace meshsweeper
