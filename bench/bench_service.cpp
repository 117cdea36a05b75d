// bench_service: the distance-query service (collision/) on a cloth-like sheet of points draped
// over several bodies, step by step, against Embree doing the same job.
//
// Scene: K bodies (K = 1, 4, 16), copies of armadillo, bunny00 and refined_elephant in turn, each
// scaled to a bounding-box diagonal of 1 and centred, on a square grid in the xy plane (spacing
// 0.9). A sheet of N points (N = 10k, 100k; a square grid) is draped over them: each point
// lies 0.01 above a height field of the bodies' vertices (max z per cell, dilated), or on the
// floor between bodies. Every step (100 by default) the sheet ripples (0.004 * sin) and slides
// (0.0003 per step), the bodies move a little:
//   rigid:     each body turns 0.002 rad about z and drifts 0.0003 per step (setPose);
//   deforming: each body's vertices move along a travelling wave of amplitude 0.003 about the
//              rest positions (setPositions, all bodies in one batch; displacement bound 0.0037,
//              which the wave never exceeds: the bounds are inflated once and never re-anchored).
//   carried (with --kinds=carried; not in the default run): the deforming scene carried across
//              the world by a rigid motion, bodies and sheet together (a cloth resting on soft
//              bodies that move): each step turns the whole scene 0.001 rad about z around its
//              centre and moves it by (0.002, 0.001, 0). The positions the service and Embree
//              get are world positions; the service follows the rigid part
//              (ServiceOptions::follow_frames).
//   limb (with --kinds=limb; not in the default run): each body stands still but for its part
//              within 0.2 of its largest x (armadillo's raised arm, the heads of the bunny and
//              the elephant), which swings up and down by 0.02 * sin(0.3 step), up to 0.006 a
//              step (setPositions, displacement bound 0.0201): a character moving one arm under
//              a cloth. The service keeps its drift by region (ServiceOptions::regional_drift;
//              --no-regions turns it off).
// Query: the closest hit within 0.02 of every point (QueryMode::kClosest); with --within=D every
// triangle within D of every point (QueryMode::kWithin; Embree: rtcPointQuery with radius D,
// the callback keeping every triangle within D with its closest point's barycentric
// coordinates, as the service returns them).
//
// Methods, both exact and fed by the same broadphase (collision/broadphase.h, body boxes from
// DistanceService::worldBox):
//   meshsweeper: DistanceService::step (coherent state per (point, body) pair), with T threads;
//   embree: one Embree 3 scene per body (rigid bodies of one mesh share a scene: the mesh does
//     not change), device "threads=T" (Embree caps the process at T threads while a device
//     lives, so each run has its own device); deforming bodies update the float vertex buffer and
//     refit (RTC_BUILD_QUALITY_REFIT) every step; per (point, body) the previous closest
//     triangle warm-starts rtcPointQuery (initial radius min(distance to it, 0.02) plus the
//     float slack of peers_embree.cpp); the callback runs Ericson's exact kernel in double
//     (Meshsweeper's kernel for flagged needle triangles). Points are transformed into a rigid
//     body's frame as the service does. T threads: tbb::parallel_for over the same blocks.
// A step's time covers the body updates (poses, positions, Embree refits), the broadphase and
// the queries. Reported: median and minimum wall time per step over the steps, CPU time of the
// calling thread per step (T = 1: robust to a loaded machine), and the checks: at the first and
// the last step both methods must agree on every point (1e-9 relative), else exit code 3. After
// the table, the ratios: Embree / Meshsweeper per configuration and thread count, and
// Meshsweeper's speedup on T threads over one.
//
// --broadphase: times the broadphase alone (flat SoA loop, the AoS reference, a uniform grid over
// the bodies) for 1, 4, 16, 64 bodies and 10k, 100k points.
//
// Flags: --quick (10k points, 1 and 4 bodies, 20 steps), --points=a,b  --bodies=a,b
// --kinds=rigid,deforming,carried,limb  --threads=1,2  --steps=N  --methods=meshsweeper,embree
// --reach=R (ServiceOptions::reach_steps)  --lead=L (ServiceOptions::lead_steps)
// --no-frames (ServiceOptions::follow_frames off)  --no-regions (ServiceOptions::regional_drift
// off)  --within=D  --data-dir=PATH  --broadphase  --per-step (after each row, every step's CPU
// time and, for Meshsweeper, the pairs certified and exact distances per pair). Exit code 77
// when a mesh is missing.
#include "bench/bench_util.h"
#include "collision/broadphase.h"
#include "collision/distance_service.h"
#include "core/mesh_io.h"
#include "core/triangle_distance.h"
#include "scenes/procedural.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace meshsweeper::bench {
namespace {

[[noreturn]] void usageError(const std::string& message) { bench::usageError("bench_service", message); }

using Clock = std::chrono::steady_clock;
constexpr double kMaxDistance = 0.02;
constexpr uint32_t kBlock = 128;

double secondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

double threadCpuSeconds() {
  timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

double processCpuSeconds() {
  timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

struct Options {
  std::vector<size_t> points = {10000, 100000};
  std::vector<size_t> bodies = {1, 4, 16};
  std::vector<std::string> kinds = {"rigid", "deforming"};
  std::vector<unsigned> threads = {1, 2};
  std::vector<std::string> methods = {"meshsweeper", "embree"};
  int steps = 100;
  float reach_steps = ServiceOptions{}.reach_steps;
  float lead_steps = ServiceOptions{}.lead_steps;
  std::string data_dir;
  bool broadphase = false;
  bool follow_frames = true;  // ServiceOptions::follow_frames (--no-frames: off)
  bool regional_drift = true;  // ServiceOptions::regional_drift (--no-regions: off)
  bool per_step = false;       // --per-step: every step's time (and Meshsweeper's work) after each row
  double within = 0;  // > 0: QueryMode::kWithin with this distance (--within=D)
};

std::vector<size_t> parseCounts(const std::string& flag, const std::string& value) {
  std::vector<size_t> out;
  for (const std::string& item : splitList(value)) {
    char* end = nullptr;
    const unsigned long long n = std::strtoull(item.c_str(), &end, 10);
    if (*end != '\0' || n == 0) usageError(flag + " needs positive integers");
    out.push_back(static_cast<size_t>(n));
  }
  if (out.empty()) usageError(flag + " needs a list");
  return out;
}

Options parseOptions(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const size_t eq = arg.find('=');
    const std::string flag = arg.substr(0, eq);
    const std::string value = eq == std::string::npos ? "" : arg.substr(eq + 1);
    if (flag == "--quick") {
      o.points = {10000};
      o.bodies = {1, 4};
      o.steps = 20;
    } else if (flag == "--points") {
      o.points = parseCounts(flag, value);
    } else if (flag == "--bodies") {
      o.bodies = parseCounts(flag, value);
    } else if (flag == "--threads") {
      o.threads.clear();
      for (size_t t : parseCounts(flag, value)) o.threads.push_back(static_cast<unsigned>(t));
    } else if (flag == "--steps") {
      o.steps = static_cast<int>(parseCounts(flag, value)[0]);
    } else if (flag == "--kinds") {
      o.kinds = splitList(value);
      for (const std::string& k : o.kinds)
        if (k != "rigid" && k != "deforming" && k != "carried" && k != "limb") usageError("unknown kind '" + k + "'");
    } else if (flag == "--methods") {
      o.methods = splitList(value);
      for (const std::string& m : o.methods)
        if (m != "meshsweeper" && m != "embree") usageError("unknown method '" + m + "'");
    } else if (flag == "--reach") {
      o.reach_steps = std::strtof(value.c_str(), nullptr);
    } else if (flag == "--lead") {
      o.lead_steps = std::strtof(value.c_str(), nullptr);
    } else if (flag == "--data-dir") {
      o.data_dir = value;
    } else if (flag == "--no-frames") {
      o.follow_frames = false;
    } else if (flag == "--no-regions") {
      o.regional_drift = false;
    } else if (flag == "--per-step") {
      o.per_step = true;
    } else if (flag == "--broadphase") {
      o.broadphase = true;
    } else if (flag == "--within") {
      o.within = std::strtod(value.c_str(), nullptr);
      if (!(o.within > 0) || !std::isfinite(o.within)) usageError("--within needs a positive distance");
    } else {
      usageError("unknown flag '" + arg + "'");
    }
  }
  return o;
}

// ---------------------------------------------------------------------------------------------
// Embree: one scene per body, exact double callback (Ericson's kernel as in peers_embree.cpp).

// An Embree device for one run. Embree's TBB task scheduler caps the whole process at the
// device's thread count (a tbb::global_control) while the device lives, so each run creates its
// own device ("threads=1" for the single-thread runs, "threads=T" for T threads) and releases
// it before the next run (Meshsweeper's runs happen with no device alive).
class EmbreeDevice {
 public:
  explicit EmbreeDevice(unsigned threads) {
    const std::string config = "threads=" + std::to_string(threads);
    device_ = rtcNewDevice(config.c_str());
    if (!device_) throw std::runtime_error("Embree: rtcNewDevice(\"" + config + "\") failed");
  }
  ~EmbreeDevice() { rtcReleaseDevice(device_); }
  EmbreeDevice(const EmbreeDevice&) = delete;
  EmbreeDevice& operator=(const EmbreeDevice&) = delete;
  RTCDevice get() const { return device_; }

 private:
  RTCDevice device_ = nullptr;
};

float roundUpToFloat(double x) {
  float f = static_cast<float>(x);
  if (static_cast<double>(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

// Ericson's closest point on a triangle (Real-Time Collision Detection, 5.1.5): its squared
// distance, and its barycentric coordinates v, w on ab, ac (point a + v ab + w ac), as a
// within-mode user needs them for every hit.
inline double ericsonClosest(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, double& v, double& w) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  v = w = 0;
  if (d1 <= 0 && d2 <= 0) return ap.squaredNorm();
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  v = 1;
  if (d3 >= 0 && d4 <= d3) return bp.squaredNorm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    v = d1 / (d1 - d3);
    return (ap - v * ab).squaredNorm();
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  v = 0;
  w = 1;
  if (d6 >= 0 && d5 <= d6) return cp.squaredNorm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    w = d2 / (d2 - d6);
    return (ap - w * ac).squaredNorm();
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
    w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    v = 1 - w;
    return (bp - w * (c - b)).squaredNorm();
  }
  const double inv = 1.0 / (va + vb + vc);
  v = vb * inv;
  w = vc * inv;
  return (ap - v * ab - w * ac).squaredNorm();
}

inline double ericsonSquaredDistance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  double v, w;
  return ericsonClosest(p, a, b, c, v, w);
}

bool needsRobustKernel(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double ab = (b - a).squaredNorm(), ac = (c - a).squaredNorm(), bc = (c - b).squaredNorm();
  const double twice_area_squared = (b - a).cross(c - a).squaredNorm();
  return !(twice_area_squared > 1e-10 * std::max({ab * ac, ab * bc, ac * bc}));
}

// What both callbacks read: the scene's double triangles, which of them need the robust kernel,
// and the query point.
struct EmbreeQueryBase {
  const std::vector<Triangle>* triangles;
  const Vec3* positions;
  const uint8_t* robust;
  Vec3 p;
  // Squared distance from p to triangle t (Ericson's routine; Meshsweeper's for the flagged
  // needles).
  double squared(TriangleIndex t) const {
    const Triangle& tri = (*triangles)[t];
    const Vec3 &a = positions[tri[0]], &b = positions[tri[1]], &c = positions[tri[2]];
    return robust[t] ? squaredDistanceToTriangle(p, a, b, c) : ericsonSquaredDistance(p, a, b, c);
  }
  // The same, and the closest point's barycentric coordinates v, w on b and c.
  double closest(TriangleIndex t, double& v, double& w) const {
    const Triangle& tri = (*triangles)[t];
    const Vec3 &a = positions[tri[0]], &b = positions[tri[1]], &c = positions[tri[2]];
    if (!robust[t]) return ericsonClosest(p, a, b, c, v, w);
    const TriangleClosest hit = closestPointOnTriangle(p, a, b, c);
    v = hit.barycentric[1];
    w = hit.barycentric[2];
    return hit.squared_distance;
  }
};

struct EmbreeQuery : EmbreeQueryBase {
  double slack;
  double best_squared;
  TriangleIndex best_triangle;
};

bool embreeCallback(RTCPointQueryFunctionArguments* args) {
  auto* q = static_cast<EmbreeQuery*>(args->userPtr);
  const TriangleIndex t = args->primID;
  const double sq = q->squared(t);
  if (sq < q->best_squared || (sq == q->best_squared && t < q->best_triangle)) {
    q->best_squared = sq;
    q->best_triangle = t;
    const float r = roundUpToFloat((std::sqrt(sq) + q->slack) * (1.0 + 1e-6));
    if (r < args->query->radius) {
      args->query->radius = r;
      return true;
    }
  }
  return false;
}

struct EmbreeHit {
  double distance;
  TriangleIndex triangle;
  double v, w;  // barycentric coordinates of the closest point on b and c
};

// Within mode: every triangle at exact distance <= d (the radius never shrinks), with its
// closest point's barycentric coordinates (what the service returns with each hit).
struct EmbreeWithin : EmbreeQueryBase {
  double d;
  std::vector<EmbreeHit>* out;
};

bool embreeWithinCallback(RTCPointQueryFunctionArguments* args) {
  auto* q = static_cast<EmbreeWithin*>(args->userPtr);
  const TriangleIndex t = args->primID;
  double v, w;
  const double distance = std::sqrt(q->closest(t, v, w));
  if (distance <= q->d) q->out->push_back({distance, t, v, w});
  return false;
}

// An Embree scene of one mesh; dynamic ones refit after setPositions().
class EmbreeScene {
 public:
  // Keeps a reference to `triangles` (must outlive the scene); copies the positions.
  EmbreeScene(RTCDevice device, const std::vector<Triangle>& triangles, const std::vector<Vec3>& positions,
              bool dynamic)
      : triangles_(&triangles), positions_(positions) {
    scene_ = rtcNewScene(device);
    geometry_ = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    if (dynamic) {
      rtcSetSceneFlags(scene_, RTC_SCENE_FLAG_DYNAMIC);
      rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_LOW);
      rtcSetGeometryBuildQuality(geometry_, RTC_BUILD_QUALITY_REFIT);
    }
    vertices_ = static_cast<float*>(rtcSetNewGeometryBuffer(geometry_, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                            3 * sizeof(float), positions_.size()));
    auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geometry_, RTC_BUFFER_TYPE_INDEX, 0,
                                                                   RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                                                   triangles.size()));
    for (size_t t = 0; t < triangles.size(); ++t)
      for (int c = 0; c < 3; ++c) indices[3 * t + c] = triangles[t][c];
    robust_.resize(triangles.size());
    for (size_t t = 0; t < triangles.size(); ++t) {
      const Triangle& tri = triangles[t];
      robust_[t] = needsRobustKernel(positions_[tri[0]], positions_[tri[1]], positions_[tri[2]]);
    }
    writeVertices();
    rtcCommitGeometry(geometry_);
    rtcAttachGeometry(scene_, geometry_);
    rtcCommitScene(scene_);
  }
  ~EmbreeScene() {
    rtcReleaseGeometry(geometry_);
    rtcReleaseScene(scene_);
  }
  EmbreeScene(const EmbreeScene&) = delete;
  EmbreeScene& operator=(const EmbreeScene&) = delete;

  // New double positions: float copy, refit (the per-step cost of a deforming body).
  void setPositions(const std::vector<Vec3>& positions) {
    positions_ = positions;
    writeVertices();
    rtcUpdateGeometryBuffer(geometry_, RTC_BUFFER_TYPE_VERTEX, 0);
    rtcCommitGeometry(geometry_);
    rtcCommitScene(scene_);
  }

  // Closest triangle to p within `radius` (exact), warm-started from triangle `warm`
  // (kInvalidIndex: none). Returns kInvalidIndex if none within radius.
  TriangleIndex closest(const Vec3& p, double radius, TriangleIndex warm, double& distance) const {
    EmbreeQuery q{{triangles_, positions_.data(), robust_.data(), p}, 0, std::numeric_limits<double>::infinity(),
                  kInvalidIndex};
    if (warm != kInvalidIndex) {
      const Triangle& t = (*triangles_)[warm];
      radius = std::min(radius, std::sqrt(squaredDistanceToTriangle(p, positions_[t[0]], positions_[t[1]], positions_[t[2]])));
    }
    RTCPointQuery query = pointQuery(p, radius, q.slack);
    RTCPointQueryContext context;
    rtcInitPointQueryContext(&context);
    rtcPointQuery(scene_, &query, &context, embreeCallback, &q);
    if (q.best_triangle == kInvalidIndex) return kInvalidIndex;
    distance = std::sqrt(q.best_squared);
    return q.best_triangle;
  }

  // Every triangle within d of p (exact distances), appended to out as (distance, triangle).
  void within(const Vec3& p, double d, std::vector<EmbreeHit>& out) const {
    EmbreeWithin q{{triangles_, positions_.data(), robust_.data(), p}, d, &out};
    double slack = 0;
    RTCPointQuery query = pointQuery(p, d, slack);
    RTCPointQueryContext context;
    rtcInitPointQueryContext(&context);
    rtcPointQuery(scene_, &query, &context, embreeWithinCallback, &q);
  }

 private:
  // A point query at p (float) whose radius covers `radius` around the double p: `slack` is
  // what the float vertices and the float point may be off by.
  RTCPointQuery pointQuery(const Vec3& p, double radius, double& slack) const {
    RTCPointQuery query;
    query.x = static_cast<float>(p.x());
    query.y = static_cast<float>(p.y());
    query.z = static_cast<float>(p.z());
    query.time = 0.f;
    const Vec3 pf(query.x, query.y, query.z);
    slack = vertex_error_ + (pf - p).norm() * (1.0 + 1e-12);
    query.radius = roundUpToFloat((radius + slack) * (1.0 + 1e-6));
    return query;
  }

  void writeVertices() {
    double worst = 0;
    for (size_t v = 0; v < positions_.size(); ++v) {
      double e2 = 0;
      for (int axis = 0; axis < 3; ++axis) {
        const float f = static_cast<float>(positions_[v][axis]);
        vertices_[3 * v + axis] = f;
        const double e = static_cast<double>(f) - positions_[v][axis];
        e2 += e * e;
      }
      worst = std::max(worst, e2);
    }
    vertex_error_ = std::sqrt(worst) * (1.0 + 1e-12);
  }

  const std::vector<Triangle>* triangles_;
  std::vector<Vec3> positions_;
  std::vector<uint8_t> robust_;
  RTCScene scene_ = nullptr;
  RTCGeometry geometry_ = nullptr;
  float* vertices_ = nullptr;
  double vertex_error_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Scene

// A mesh scaled to diagonal 1 and centred at the origin.
Mesh normalised(const Mesh& mesh) {
  Vec3 lower, upper;
  meshBounds(mesh, lower, upper);
  const Vec3 center = 0.5 * (lower + upper);
  const double scale = 1.0 / (upper - lower).norm();
  Mesh out = mesh;
  for (Vec3& x : out.positions) x = (x - center) * scale;
  return out;
}

Eigen::Isometry3d rigidPose(const Vec3& origin, int step) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(0.002 * step, Vec3::UnitZ()).toRotationMatrix();
  pose.translation() = origin + Vec3(0.0003 * step, 0, 0);
  return pose;
}

// Deforming positions: rest (placed at origin) plus a travelling wave of amplitude 0.003.
void wavePositions(const Mesh& local, const Vec3& origin, int step, std::vector<Vec3>& out) {
  out.resize(local.positions.size());
  const double phase = 0.15 * step;
  for (size_t v = 0; v < out.size(); ++v) {
    const Vec3& x = local.positions[v];
    const double a = 0.003 * std::sin(9 * x.x() + 7 * x.y() + phase);
    out[v] = origin + x + Vec3(0.6 * a, 0.3 * a, a);
  }
}

struct Scene {
  std::vector<const Mesh*> meshes;      // [body] normalised local mesh
  std::vector<int> mesh_index;          // [body] which of the shared meshes
  std::vector<Vec3> origins;            // [body]
  std::vector<Vec3> rest_points;        // draped sheet
  bool deforming = false;
  bool limb = false;                    // deforming: one limb waves, the rest stays (limbPositions())
  bool carried = false;                 // deforming, and the whole scene carried (carry())
  Vec3 center = Vec3::Zero();           // the bodies' grid centre

  // The rigid motion that carries a carried scene at `step` (identity otherwise).
  Eigen::Isometry3d carry(int step) const {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    if (!carried) return pose;
    pose.linear() = Eigen::AngleAxisd(0.001 * step, Vec3::UnitZ()).toRotationMatrix();
    pose.translation() = center - pose.linear() * center + Vec3(0.002, 0.001, 0) * step;
    return pose;
  }
};

Scene makeScene(const std::vector<Mesh>& meshes, size_t bodies, size_t points, const std::string& kind) {
  Scene s;
  s.deforming = kind != "rigid";
  s.carried = kind == "carried";
  s.limb = kind == "limb";
  const int side = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(bodies))));
  for (size_t b = 0; b < bodies; ++b) {
    s.mesh_index.push_back(static_cast<int>(b % meshes.size()));
    s.meshes.push_back(&meshes[b % meshes.size()]);
    s.origins.push_back(Vec3(0.9 * static_cast<double>(b % side), 0.9 * static_cast<double>(b / side), 0));
    s.center += s.origins.back() / static_cast<double>(bodies);
  }
  // Height field of the bodies' rest vertices over the sheet's area.
  Vec3 lower = Vec3::Constant(1e300), upper = Vec3::Constant(-1e300);
  for (size_t b = 0; b < bodies; ++b)
    for (const Vec3& x : s.meshes[b]->positions) {
      lower = lower.cwiseMin(x + s.origins[b]);
      upper = upper.cwiseMax(x + s.origins[b]);
    }
  lower -= Vec3(0.05, 0.05, 0);
  upper += Vec3(0.05, 0.05, 0);
  const int cells = 160 * side;
  std::vector<double> height(static_cast<size_t>(cells) * cells, lower.z());
  auto cellOf = [&](double v, int axis) {
    return std::clamp(static_cast<int>((v - lower[axis]) / (upper[axis] - lower[axis]) * cells), 0, cells - 1);
  };
  for (size_t b = 0; b < bodies; ++b)
    for (const Vec3& x0 : s.meshes[b]->positions) {
      const Vec3 x = x0 + s.origins[b];
      double& h = height[static_cast<size_t>(cellOf(x.y(), 1)) * cells + cellOf(x.x(), 0)];
      h = std::max(h, x.z());
    }
  std::vector<double> dilated = height;  // fill gaps between vertices
  for (int i = 0; i < cells; ++i)
    for (int j = 0; j < cells; ++j)
      for (int di = -2; di <= 2; ++di)
        for (int dj = -2; dj <= 2; ++dj) {
          const int a = i + di, c = j + dj;
          if (a >= 0 && a < cells && c >= 0 && c < cells)
            dilated[static_cast<size_t>(i) * cells + j] =
                std::max(dilated[static_cast<size_t>(i) * cells + j], height[static_cast<size_t>(a) * cells + c]);
        }
  const size_t n = static_cast<size_t>(std::ceil(std::sqrt(static_cast<double>(points))));
  for (size_t k = 0; k < points; ++k) {
    const double u = (static_cast<double>(k % n) + 0.5) / static_cast<double>(n);
    const double v = (static_cast<double>(k / n) + 0.5) / static_cast<double>(n);
    const double x = lower.x() + u * (upper.x() - lower.x());
    const double y = lower.y() + v * (upper.y() - lower.y());
    s.rest_points.push_back(Vec3(x, y, dilated[static_cast<size_t>(cellOf(y, 1)) * cells + cellOf(x, 0)] + 0.01));
  }
  return s;
}

void sheetAt(const Scene& s, int step, PointMatrix& out) {
  out.resize(static_cast<Eigen::Index>(s.rest_points.size()), 3);
  const Eigen::Isometry3d carry = s.carry(step);
  for (size_t i = 0; i < s.rest_points.size(); ++i) {
    const Vec3& p = s.rest_points[i];
    const Vec3 x(p.x() + 0.0003 * step, p.y(), p.z() + 0.004 * std::sin(5 * p.x() + 0.1 * step));
    out.row(static_cast<Eigen::Index>(i)) = (s.carried ? Vec3(carry * x) : x).transpose();
  }
}

// A limb scene's positions: the vertices within 0.2 of the body's largest x (armadillo's
// raised arm, the bunny's and the elephant's heads) swing up and down together, 0.02 * sin(0.3
// step) (up to 0.006 a step), blended over the first 0.1; the rest of the body stays at rest.
void limbPositions(const Mesh& local, const Vec3& origin, int step, std::vector<Vec3>& out) {
  out.resize(local.positions.size());
  double x_max = -std::numeric_limits<double>::infinity();
  for (const Vec3& x : local.positions) x_max = std::max(x_max, x.x());
  for (size_t v = 0; v < out.size(); ++v) {
    const Vec3& x = local.positions[v];
    const double weight = std::clamp((x.x() - (x_max - 0.2)) / 0.1, 0.0, 1.0);
    out[v] = origin + x + Vec3(0, 0, weight * 0.02 * std::sin(0.3 * step));
  }
}

// A deforming body's positions at `step`: the wave (the limb's swing in a limb scene), carried
// in a carried scene.
void bodyPositions(const Scene& s, size_t b, int step, std::vector<Vec3>& out) {
  if (s.limb) return limbPositions(*s.meshes[b], s.origins[b], step, out);
  wavePositions(*s.meshes[b], s.origins[b], step, out);
  if (!s.carried) return;
  const Eigen::Isometry3d carry = s.carry(step);
  for (Vec3& x : out) x = carry * x;
}

// The answer of one point: the closest distance within kMaxDistance (or infinity) and its body.
struct Answer {
  double distance = std::numeric_limits<double>::infinity();
  uint32_t body = kInvalidIndex;
  uint32_t count = 0;  // hits (within mode: every triangle within the distance)
};

// The query of a run: the closest hit within kMaxDistance, or (within > 0) every triangle
// within `within`.
struct Query {
  QueryMode mode = QueryMode::kClosest;
  double distance = kMaxDistance;
};

struct RunResult {
  std::vector<double> wall, cpu, process_cpu;  // [step] seconds: wall, calling thread, process
  std::vector<Answer> first, last;
  double hits_fraction = 0;
  double pairs_per_point = 0;
  double certified_fraction = 0;
  size_t reanchored = 0;
  std::vector<double> certified_per_step, triangles_per_step;  // [step] Meshsweeper: per pair
};

// --per-step: each step's CPU time of the calling thread, and for Meshsweeper the fraction of
// pairs certified and the exact distances per pair.
void printSteps(const RunResult& r) {
  std::printf("\nstep | CPU ms%s\n", r.certified_per_step.empty() ? "" : " | certified | triangles/pair");
  for (size_t k = 0; k < r.cpu.size(); ++k) {
    std::printf("%zu | %.2f", k, 1e3 * r.cpu[k]);
    if (k < r.certified_per_step.size())
      std::printf(" | %.1f%% | %.1f", 100 * r.certified_per_step[k], r.triangles_per_step[k]);
    std::printf("\n");
  }
  std::printf("\n");
}

// Meshsweeper: the service.
RunResult runMeshsweeper(const Scene& scene, const std::vector<std::shared_ptr<const Hierarchy>>& hierarchies,
                         int steps, unsigned threads, float reach_steps, float lead_steps, bool follow_frames,
                         bool regional_drift,
                         const Query& query) {
  DistanceService service(ServiceOptions{threads, kBlock, reach_steps, lead_steps, follow_frames, regional_drift});
  std::vector<BodyHandle> handles;
  std::vector<std::vector<Vec3>> positions(scene.meshes.size());
  for (size_t b = 0; b < scene.meshes.size(); ++b) {
    const auto& h = hierarchies[scene.mesh_index[b]];
    if (scene.deforming) {
      bodyPositions(scene, b, 0, positions[b]);
      std::vector<Vec3> rest(scene.meshes[b]->positions.size());
      for (size_t v = 0; v < rest.size(); ++v) rest[v] = scene.meshes[b]->positions[v] + scene.origins[b];
      // The wave moves a vertex by at most 0.003 * |(0.6, 0.3, 1)| < 0.0037 from rest; the
      // limb by at most 0.02.
      handles.push_back(service.addDeforming(h, scene.limb ? 0.0201 : 0.0037, rest));
    } else {
      handles.push_back(service.addRigid(h, rigidPose(scene.origins[b], 0)));
    }
  }
  std::vector<BodyPositions> batch;  // deforming: every body's positions in one call
  for (size_t b = 0; scene.deforming && b < handles.size(); ++b) batch.push_back({handles[b], &positions[b]});
  RunResult r;
  PointMatrix sheet;
  StepResult out;
  uint64_t pairs = 0, certified = 0, hits = 0;
  for (int step = 0; step < steps; ++step) {
    sheetAt(scene, step, sheet);
    if (scene.deforming)
      for (size_t b = 0; b < handles.size(); ++b) bodyPositions(scene, b, step, positions[b]);
    const auto start = Clock::now();
    const double cpu0 = threadCpuSeconds();
    const double process0 = processCpuSeconds();
    if (scene.deforming) {
      for (const PositionsUpdate& u : service.setPositions(batch)) r.reanchored += u.reanchored;
    } else {
      for (size_t b = 0; b < handles.size(); ++b) service.setPose(handles[b], rigidPose(scene.origins[b], step));
    }
    service.step(sheet, query.distance, query.mode, out);
    r.cpu.push_back(threadCpuSeconds() - cpu0);
    r.process_cpu.push_back(processCpuSeconds() - process0);
    r.wall.push_back(secondsSince(start));
    pairs += out.stats().pairs;
    r.certified_per_step.push_back(out.stats().pairs ? static_cast<double>(out.stats().certified_pairs) / static_cast<double>(out.stats().pairs) : 0.0);
    r.triangles_per_step.push_back(out.stats().pairs ? static_cast<double>(out.stats().triangles_tested) / static_cast<double>(out.stats().pairs) : 0.0);
    certified += out.stats().certified_pairs;
    for (size_t i = 0; i < out.size(); ++i) hits += !out.hits(i).empty();
    if (step == 0 || step == steps - 1) {
      std::vector<Answer>& answers = step == 0 ? r.first : r.last;
      answers.assign(out.size(), Answer{});
      for (size_t i = 0; i < out.size(); ++i) {
        if (query.mode == QueryMode::kClosest) {
          if (const DistanceHit* hit = out.closest(i)) answers[i] = {hit->distance, hit->body.index, 1};
        } else if (!out.hits(i).empty()) {
          const StepResult::Hits h = out.hits(i);
          const DistanceHit& first = h[0];  // the closest
          answers[i] = {first.distance, first.body.index, static_cast<uint32_t>(h.last - h.first)};
        }
      }
    }
  }
  const double total = static_cast<double>(steps) * static_cast<double>(scene.rest_points.size());
  r.hits_fraction = static_cast<double>(hits) / total;
  r.pairs_per_point = static_cast<double>(pairs) / total;
  r.certified_fraction = pairs ? static_cast<double>(certified) / static_cast<double>(pairs) : 0;
  return r;
}

// Embree: the same job, same broadphase, warm start per (point, body).
RunResult runEmbree(const Scene& scene, const std::vector<Mesh>& meshes, int steps, unsigned threads,
                    const Query& query) {
  const size_t bodies = scene.meshes.size();
  const size_t n = scene.rest_points.size();
  const EmbreeDevice device(threads);
  std::vector<std::unique_ptr<EmbreeScene>> shared(meshes.size());  // rigid: one scene per mesh
  std::vector<std::unique_ptr<EmbreeScene>> own;                     // deforming: one per body
  std::vector<const EmbreeScene*> scenes(bodies);
  std::vector<std::vector<Vec3>> positions(bodies);
  for (size_t b = 0; b < bodies; ++b) {
    if (scene.deforming) {
      std::vector<Vec3> placed;
      bodyPositions(scene, b, 0, placed);
      own.push_back(std::make_unique<EmbreeScene>(device.get(), scene.meshes[b]->triangles, placed, true));
      scenes[b] = own.back().get();
    } else {
      auto& s = shared[scene.mesh_index[b]];
      if (!s) s = std::make_unique<EmbreeScene>(device.get(), scene.meshes[b]->triangles, scene.meshes[b]->positions, false);
      scenes[b] = s.get();
    }
  }
  std::vector<Eigen::Isometry3d> inverse(bodies, Eigen::Isometry3d::Identity());
  Broadphase broadphase;
  broadphase.resize(bodies);
  std::vector<TriangleIndex> warm(n * bodies, kInvalidIndex);  // [point * bodies + body]
  std::vector<Answer> answers(n);
  tbb::task_arena arena(static_cast<int>(threads));
  RunResult r;
  PointMatrix sheet;
  uint64_t hits = 0, pairs = 0;
  for (int step = 0; step < steps; ++step) {
    sheetAt(scene, step, sheet);
    if (scene.deforming)
      for (size_t b = 0; b < bodies; ++b) bodyPositions(scene, b, step, positions[b]);
    const auto start = Clock::now();
    const double cpu0 = threadCpuSeconds();
    const double process0 = processCpuSeconds();
    // Body updates and world boxes, as the service computes them.
    for (size_t b = 0; b < bodies; ++b) {
      Box3 box;
      box.lower = Vec3::Constant(std::numeric_limits<double>::infinity());
      box.upper = -box.lower;
      if (scene.deforming) {
        own[b]->setPositions(positions[b]);
        for (const Vec3& x : positions[b]) {
          box.lower = box.lower.cwiseMin(x);
          box.upper = box.upper.cwiseMax(x);
        }
      } else {
        const Eigen::Isometry3d pose = rigidPose(scene.origins[b], step);
        inverse[b] = pose.inverse(Eigen::Isometry);
        Vec3 lo, hi;
        meshBounds(*scene.meshes[b], lo, hi);
        double extent = 0;
        for (int corner = 0; corner < 8; ++corner) {
          const Vec3 c((corner & 1) ? hi.x() : lo.x(), (corner & 2) ? hi.y() : lo.y(), (corner & 4) ? hi.z() : lo.z());
          const Vec3 w = pose * c;
          box.lower = box.lower.cwiseMin(w);
          box.upper = box.upper.cwiseMax(w);
          extent = std::max(extent, w.cwiseAbs().maxCoeff());
        }
        box.lower.array() -= 1e-12 * extent;
        box.upper.array() += 1e-12 * extent;
      }
      broadphase.set(b, box);
    }
    std::vector<uint64_t> block_hits((n + kBlock - 1) / kBlock, 0), block_pairs(block_hits.size(), 0);
    arena.execute([&] {
      tbb::parallel_for(
          tbb::blocked_range<size_t>(0, block_hits.size(), 1),
          [&](const tbb::blocked_range<size_t>& range) {
            std::vector<uint32_t> candidates(bodies);
            std::vector<EmbreeHit> found;
            for (size_t block = range.begin(); block != range.end(); ++block) {
              const size_t last = std::min(n, (block + 1) * kBlock);
              for (size_t i = block * kBlock; i < last; ++i) {
                const Vec3 p = sheet.row(static_cast<Eigen::Index>(i)).transpose();
                const size_t count = broadphase.candidates(p, query.distance, candidates.data());
                block_pairs[block] += count;
                Answer best;
                for (size_t k = 0; k < count; ++k) {
                  const uint32_t b = candidates[k];
                  const Vec3 q = scene.deforming ? p : Vec3(inverse[b] * p);
                  if (query.mode == QueryMode::kWithin) {
                    found.clear();
                    scenes[b]->within(q, query.distance, found);
                    for (const EmbreeHit& f : found)
                      if (f.distance < best.distance) {
                        best.distance = f.distance;
                        best.body = b;
                      }
                    best.count += static_cast<uint32_t>(found.size());
                    continue;
                  }
                  double d = 0;
                  TriangleIndex& w = warm[i * bodies + b];
                  const TriangleIndex t = scenes[b]->closest(q, kMaxDistance, w, d);
                  if (t != kInvalidIndex) w = t;
                  if (t != kInvalidIndex && d <= kMaxDistance && d < best.distance) best = {d, b, 1};
                }
                answers[i] = best;
                block_hits[block] += best.body != kInvalidIndex;
              }
            }
          },
          tbb::simple_partitioner());
    });
    r.cpu.push_back(threadCpuSeconds() - cpu0);
    r.process_cpu.push_back(processCpuSeconds() - process0);
    r.wall.push_back(secondsSince(start));
    for (size_t k = 0; k < block_hits.size(); ++k) {
      hits += block_hits[k];
      pairs += block_pairs[k];
    }
    if (step == 0) r.first = answers;
    if (step == steps - 1) r.last = answers;
  }
  const double total = static_cast<double>(steps) * static_cast<double>(n);
  r.hits_fraction = static_cast<double>(hits) / total;
  r.pairs_per_point = static_cast<double>(pairs) / total;
  return r;
}

// Both methods must give the same distances (1e-9 relative) and hit the same points.
bool sameAnswers(const std::vector<Answer>& a, const std::vector<Answer>& b, std::string& message) {
  if (a.size() != b.size()) {
    message = "different sizes";
    return false;
  }
  for (size_t i = 0; i < a.size(); ++i) {
    const bool ha = a[i].body != kInvalidIndex, hb = b[i].body != kInvalidIndex;
    if (ha != hb || a[i].count != b[i].count ||
        (ha && std::abs(a[i].distance - b[i].distance) > 1e-9 * std::max(1.0, a[i].distance))) {
      char text[200];
      std::snprintf(text, sizeof(text), "point %zu: %.17g (body %u, %u hits) vs %.17g (body %u, %u hits)", i,
                    a[i].distance, a[i].body, a[i].count, b[i].distance, b[i].body, b[i].count);
      message = text;
      return false;
    }
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// Broadphase alone

// A uniform grid over the bodies' inflated boxes: each cell lists the bodies overlapping it.
class GridBroadphase {
 public:
  GridBroadphase(const std::vector<Box3>& boxes, double distance) : boxes_(boxes) {
    lower_ = Vec3::Constant(1e300);
    Vec3 upper = Vec3::Constant(-1e300);
    double size = 0;
    for (const Box3& b : boxes) {
      lower_ = lower_.cwiseMin(b.lower - Vec3::Constant(distance));
      upper = upper.cwiseMax(b.upper + Vec3::Constant(distance));
      size += (b.upper - b.lower).maxCoeff();
    }
    cell_ = std::max(1e-9, size / static_cast<double>(boxes.size()));
    for (int axis = 0; axis < 3; ++axis)
      dims_[axis] = std::max(1, static_cast<int>(std::ceil((upper[axis] - lower_[axis]) / cell_)));
    begin_.assign(static_cast<size_t>(dims_[0]) * dims_[1] * dims_[2] + 1, 0);
    std::vector<std::vector<uint32_t>> lists(begin_.size() - 1);
    for (uint32_t s = 0; s < boxes.size(); ++s) {
      int lo[3], hi[3];
      for (int axis = 0; axis < 3; ++axis) {
        lo[axis] = cellIndex(boxes[s].lower[axis] - distance, axis);
        hi[axis] = cellIndex(boxes[s].upper[axis] + distance, axis);
      }
      for (int x = lo[0]; x <= hi[0]; ++x)
        for (int y = lo[1]; y <= hi[1]; ++y)
          for (int z = lo[2]; z <= hi[2]; ++z) lists[(static_cast<size_t>(z) * dims_[1] + y) * dims_[0] + x].push_back(s);
    }
    for (size_t c = 0; c < lists.size(); ++c) {
      begin_[c + 1] = begin_[c] + static_cast<uint32_t>(lists[c].size());
      items_.insert(items_.end(), lists[c].begin(), lists[c].end());
    }
  }
  size_t candidates(const Vec3& p, double distance, uint32_t* out) const {
    int c[3];
    for (int axis = 0; axis < 3; ++axis) {
      const double v = (p[axis] - lower_[axis]) / cell_;
      if (v < 0 || v >= dims_[axis]) return 0;
      c[axis] = static_cast<int>(v);
    }
    const size_t cell = (static_cast<size_t>(c[2]) * dims_[1] + c[1]) * dims_[0] + c[0];
    size_t n = 0;
    for (uint32_t k = begin_[cell]; k < begin_[cell + 1]; ++k)
      if (boxWithin(boxes_[items_[k]], p, distance)) out[n++] = items_[k];
    return n;
  }

 private:
  int cellIndex(double v, int axis) const {
    return std::clamp(static_cast<int>((v - lower_[axis]) / cell_), 0, dims_[axis] - 1);
  }
  std::vector<Box3> boxes_;
  Vec3 lower_;
  double cell_ = 1;
  int dims_[3] = {1, 1, 1};
  std::vector<uint32_t> begin_, items_;
};

void benchBroadphase() {
  std::printf("\n## broadphase alone (ns per point, median of 15 passes, 3 from 256 bodies; thread CPU time)\n\n");
  std::printf("| bodies | points | flat SoA | Broadphase (tree past 256) | reference AoS | uniform grid | candidates/point |\n"
              "|---|---|---|---|---|---|---|\n");
  for (size_t bodies : {size_t(1), size_t(4), size_t(16), size_t(64), size_t(256), size_t(1024), size_t(4096)}) {
    const int side = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(bodies))));
    std::vector<Box3> boxes(bodies);
    scenes::Random random(5);
    for (size_t b = 0; b < bodies; ++b) {
      const Vec3 o(0.9 * static_cast<double>(b % side), 0.9 * static_cast<double>(b / side), 0);
      boxes[b].lower = o - Vec3(0.3, 0.3, 0.4) + 0.02 * random.inBox(Vec3::Zero(), Vec3::Ones());
      boxes[b].upper = o + Vec3(0.3, 0.3, 0.4) + 0.02 * random.inBox(Vec3::Zero(), Vec3::Ones());
    }
    Broadphase flat, tree;
    flat.resize(bodies);
    tree.resize(bodies);
    BroadphaseReference reference;
    reference.boxes = boxes;
    for (size_t b = 0; b < bodies; ++b) {
      flat.set(b, boxes[b]);
      tree.set(b, boxes[b]);
    }
    tree.prepare();  // the flat one is never prepared: it keeps the flat loop
    const GridBroadphase grid(boxes, kMaxDistance);
    for (size_t points : {size_t(10000), size_t(100000)}) {
      std::vector<Vec3> p(points);
      for (Vec3& x : p)
        x = random.inBox(Vec3(-0.4, -0.4, -0.45), Vec3(0.9 * (side - 1) + 0.4, 0.9 * (side - 1) + 0.4, 0.45));
      std::vector<uint32_t> out(bodies);
      double times[4];
      size_t total = 0, check[4] = {0, 0, 0, 0};
      for (int method = 0; method < 4; ++method) {
        std::vector<double> runs;
        for (int rep = 0; rep < (bodies >= 256 ? 3 : 15); ++rep) {
          size_t sum = 0;
          const double t0 = threadCpuSeconds();
          for (const Vec3& x : p) {
            sum += method == 0   ? flat.candidates(x, kMaxDistance, out.data())
                   : method == 1 ? tree.candidates(x, kMaxDistance, out.data())
                   : method == 2 ? reference.candidates(x, kMaxDistance, out.data())
                                 : grid.candidates(x, kMaxDistance, out.data());
          }
          runs.push_back(threadCpuSeconds() - t0);
          check[method] = sum;
        }
        times[method] = 1e9 * median(runs) / static_cast<double>(points);
      }
      total = check[0];
      if (check[0] != check[1] || check[0] != check[2] || check[0] != check[3]) {
        std::fprintf(stderr, "bench_service: broadphase variants disagree (%zu %zu %zu %zu)\n", check[0], check[1],
                     check[2], check[3]);
        std::exit(3);
      }
      std::printf("| %zu | %zu | %.1f | %.1f | %.1f | %.1f | %.2f |\n", bodies, points, times[0], times[1], times[2],
                  times[3], static_cast<double>(total) / static_cast<double>(points));
    }
  }
}

}  // namespace
}  // namespace meshsweeper::bench

int main(int argc, char** argv) {
  using namespace meshsweeper;
  using namespace meshsweeper::bench;
  const Options options = parseOptions(argc, argv);
  if (options.broadphase) {
    benchBroadphase();
    return 0;
  }
  const std::string dir = options.data_dir.empty() ? scenes::dataDir() : options.data_dir;
  std::vector<Mesh> meshes;
  for (const char* name : {"armadillo", "bunny00", "refined_elephant"}) {
    const std::string path = dir + "/" + name + ".off";
    if (!std::ifstream(path).good()) {
      std::fprintf(stderr, "bench_service: %s not found; run scripts/fetch_data.sh or pass --data-dir\n", path.c_str());
      return 77;
    }
    meshes.push_back(normalised(readMesh(path)));
    meshes.back().name = name;
  }
  std::vector<std::shared_ptr<const Hierarchy>> hierarchies;
  for (const Mesh& m : meshes) hierarchies.push_back(Hierarchy::build(m));
  Query query;
  if (options.within > 0) query = {QueryMode::kWithin, options.within};
  std::printf("Query: %s %g of every point.\n\n", query.mode == QueryMode::kWithin ? "every triangle within" : "the closest hit within",
              query.distance);
  std::vector<std::string> ratios;  // printed after the table
  std::printf("| kind | bodies | points | method | threads | median ms/step | min ms/step | CPU ms/step | "
              "all threads CPU ms/step | pairs/point | hits | certified |\n"
              "|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  for (const std::string& kind : options.kinds) {
    for (size_t bodies : options.bodies) {
      for (size_t points : options.points) {
        const Scene scene = makeScene(meshes, bodies, points, kind);
        std::vector<RunResult> results;
        for (const std::string& method : options.methods) {
          for (unsigned threads : options.threads) {
            const RunResult r = method == "meshsweeper" ? runMeshsweeper(scene, hierarchies, options.steps, threads, options.reach_steps, options.lead_steps,
                                                                         options.follow_frames, options.regional_drift, query)
                                                        : runEmbree(scene, meshes, options.steps, threads, query);
            std::printf("| %s | %zu | %zu | %s | %u | %.2f | %.2f | %.2f | %.2f | %.2f | %.1f%% | %s |\n",
                        kind.c_str(), bodies, points, method.c_str(), threads, 1e3 * median(r.wall),
                        1e3 * *std::min_element(r.wall.begin(), r.wall.end()), 1e3 * median(r.cpu),
                        1e3 * median(r.process_cpu),
                        r.pairs_per_point, 100 * r.hits_fraction,
                        method == "meshsweeper" ? (std::to_string(static_cast<int>(100 * r.certified_fraction)) + "%").c_str()
                                                : "-");
            std::fflush(stdout);
            if (options.per_step) printSteps(r);
            if (!results.empty()) {
              std::string message;
              if (!sameAnswers(results.front().first, r.first, message) ||
                  !sameAnswers(results.front().last, r.last, message)) {
                std::fprintf(stderr, "bench_service: %s %zu bodies %zu points: methods disagree: %s\n", kind.c_str(),
                             bodies, points, message.c_str());
                return 3;
              }
            }
            results.push_back(r);
          }
        }
        // Ratios: Embree over Meshsweeper, per thread count (one thread: the calling thread's CPU
        // time, robust to a loaded machine; more: median wall time).
        if (results.size() == options.methods.size() * options.threads.size() && options.methods.size() == 2) {
          const size_t embree_first = options.methods[0] == "embree" ? 0 : options.threads.size();
          const size_t ours_first = options.threads.size() - embree_first;
          for (size_t t = 0; t < options.threads.size(); ++t) {
            const RunResult& e = results[embree_first + t];
            const RunResult& m = results[ours_first + t];
            const bool one = options.threads[t] == 1;
            const double ratio = one ? median(e.cpu) / median(m.cpu) : median(e.wall) / median(m.wall);
            char line[200];
            std::snprintf(line, sizeof line, "%s, %zu bodies, %zu points, %u thread%s: Embree / Meshsweeper %.2fx (%s)",
                          kind.c_str(), bodies, points, options.threads[t], one ? "" : "s", ratio,
                          one ? "CPU time" : "median wall time");
            ratios.push_back(line);
            if (!one && options.threads[0] == 1) {  // scaling: the first thread count is 1
              std::snprintf(line, sizeof line, "%s, %zu bodies, %zu points: Meshsweeper %u threads %.2fx one (median wall time)",
                            kind.c_str(), bodies, points, options.threads[t],
                            median(results[ours_first].wall) / median(m.wall));
              ratios.push_back(line);
            }
          }
        }
      }
    }
  }
  if (!ratios.empty()) {
    std::printf("\n## Ratios\n\n");
    for (const std::string& line : ratios) std::printf("- %s\n", line.c_str());
  }
  return 0;
}
