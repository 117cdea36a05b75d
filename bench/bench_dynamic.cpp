// bench_dynamic: moving query points and deforming meshes (issue 3), Meshsweeper against its
// peers, one thread, same inputs, one binary.
//
// Coherent paths (per mesh, per path variant; one iteration = one pass over the whole path):
//   path/MESH/VARIANT/METHOD
//   A path is a long walk of consecutive points whose direction turns smoothly at random and
//   whose distance to the surface follows a smooth target inside a band (steered with a fresh
//   Meshsweeper query at every step); fixed seeds. VARIANT: off5%/step0.05% (band 0.1-5% of
//   the bounding-box diagonal, steps of 0.05%), off0.1%/step0.05% (band 0.01-0.1%),
//   off5%/step0.01%, off1%/step0.05% (band 0.5-1.5%: DESIGN.md's prototype case).
//   METHOD: ms_coherent (QueryStream::closestCoherent, set certificate), ms_front
//   (closestWithinCoherent(p, 0), the paper's dynamic front), ms_fresh (QueryStream::closest),
//   embree_fresh (EmbreeClosest, peers.h), embree_warm (radius initialised from the exact
//   distance to the previous closest triangle, peers_dynamic.h; same callback kernel as
//   embree_fresh), cgal_hint (AABB_tree
//   closest_point_and_primitive(p, previous answer)), cgal_fresh (its KD-tree hint).
// Deformation (per mesh; key frames = rest and a smoothly deformed copy: a wave along the
// normals and a twist, every vertex moves; t advances through [0, 1]):
//   bounds/MESH/METHOD   one iteration = one frame: ms_kf_bounds (KeyframeBody::interpolatedBounds),
//     ms_kf_settime (setTime: bounds and positions), ms_setpositions (DeformingBody::setPositions,
//     the per-step check), ms_setpositions_inline (the same with inline faces: the check, the
//     leaf blocks refreshed and the boxes refitted), ms_inflate (DeformingBody::inflate with per-vertex bounds),
//     embree_refit (rtcCommitGeometry + rtcCommitScene of a DYNAMIC / LOW / REFIT scene after
//     new vertices; writing the buffer is not timed), embree_build (a fresh default-quality
//     scene, for reference: what a rebuild costs), cgal_rebuild (tree.rebuild +
//     accelerate_distance_queries), ms_build (Hierarchy::build of the deformed mesh).
//   deformed/MESH/METHOD one iteration = fresh closest-point queries for every point of a set of
//     near-surface points of the mesh deformed at t = 0.5: ms_keyframe (through KeyframeBody's
//     geometry), ms_inflated (DeformingBody, per-vertex bounds), ms_inflated_inline (the same
//     with inline faces and refitted boxes), ms_rebuilt (a hierarchy built
//     on the deformed mesh), embree_refit, embree_rebuilt, cgal_rebuilt.
//
// Before timing, every method is checked on every point of every path and query set (brute
// force on a sample): distances must agree to 1e-9 relative, else the program stops with a
// message (exit code 3). After Google Benchmark's report, a summary (markdown): medians of
// process CPU time over every timed pass or frame, and ratios to Embree.
//
// Own flags (removed before Google Benchmark parses the rest):
//   --quick          2,000 path steps, 2,000 query points
//   --steps=N        points per path (default 100,000)     --points=N   query points (20,000)
//   --meshes=a,b     default armadillo,refined_elephant    --data-dir=PATH
//   --reach-steps=R  --max-candidates=N   CoherenceOptions of ms_coherent/ms_front (default:
//                    the library's defaults), for tuning
// Exit code 77 when a mesh file is missing (ctest skips).
#include "bench/bench_util.h"
#include "bench/peers.h"
#include "bench/peers_dynamic.h"
#include "core/brute_force.h"
#include "core/hierarchy.h"
#include "core/mesh_io.h"
#include "core/sweep_query.h"
#include "core/triangle_distance.h"
#include "deform/inflated_bounds.h"
#include "deform/keyframe_bounds.h"
#include "scenes/procedural.h"

#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace meshsweeper::bench {
namespace {

[[noreturn]] void usageError(const std::string& message) { bench::usageError("bench_dynamic", message); }
size_t parseCount(const std::string& flag, const std::string& value) { return bench::parseCount("bench_dynamic", flag, value); }

using Clock = std::chrono::steady_clock;
constexpr double kPi = 3.14159265358979323846;

double secondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// CPU seconds of the whole process (see bench_closest.cpp: the machine is shared).
double processCpuSeconds() {
  timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// ---------------------------------------------------------------------------------------------
// Options

struct Options {
  size_t steps = 100000;
  size_t points = 20000;
  std::vector<std::string> meshes = {"armadillo", "refined_elephant"};
  std::string data_dir;
  CoherenceOptions coherence;  // of the ms_coherent and ms_front streams
  bool summary_to_stderr = false;
};
Options g_options;

void parseOwnFlags(int& argc, char** argv) {
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const size_t eq = arg.find('=');
    const std::string flag = arg.substr(0, eq);
    const std::string value = eq == std::string::npos ? "" : arg.substr(eq + 1);
    if (flag == "--quick") {
      g_options.steps = 2000;
      g_options.points = 2000;
    } else if (flag == "--steps") {
      g_options.steps = parseCount(flag, value);
    } else if (flag == "--points") {
      g_options.points = parseCount(flag, value);
    } else if (flag == "--meshes") {
      g_options.meshes = splitList(value);
      if (g_options.meshes.empty()) usageError("--meshes needs a list");
    } else if (flag == "--data-dir") {
      g_options.data_dir = value;
    } else if (flag == "--reach-steps") {
      char* end = nullptr;
      g_options.coherence.reach_steps = std::strtod(value.c_str(), &end);
      if (value.empty() || *end != '\0' || !(g_options.coherence.reach_steps >= 0)) usageError("--reach-steps needs a number >= 0");
    } else if (flag == "--max-candidates") {
      g_options.coherence.max_candidates = static_cast<uint32_t>(parseCount(flag, value));
    } else {
      if (flag == "--benchmark_format" && value != "console") g_options.summary_to_stderr = true;
      argv[kept++] = argv[i];
    }
  }
  argc = kept;
  argv[argc] = nullptr;
}

std::string meshPathOf(const std::string& name) {
  return g_options.data_dir.empty() ? scenes::meshPath(name) : g_options.data_dir + "/" + name + ".off";
}

bool agree(double lo, double hi, double diagonal) {
  return std::isfinite(hi) && hi - lo <= 1e-9 * hi + 1e-15 * diagonal;
}

// ---------------------------------------------------------------------------------------------
// Paths

struct PathVariant {
  const char* name;  // label in benchmark names and tables
  double step;       // fraction of the diagonal
  double near, far;  // band of distances to the surface, fractions of the diagonal
  uint64_t seed;
};
const PathVariant kVariants[] = {
    {"off5%/step0.05%", 0.0005, 0.001, 0.05, 0xd1a0001},
    {"off0.1%/step0.05%", 0.0005, 0.0001, 0.001, 0xd1a0002},
    {"off5%/step0.01%", 0.0001, 0.001, 0.05, 0xd1a0003},
    {"off1%/step0.05%", 0.0005, 0.005, 0.015, 0xd1a0004},
};

struct Path {
  const PathVariant* variant;
  std::vector<Vec3> points;
  double min_offset = 0, mean_offset = 0, max_offset = 0;  // fractions of the diagonal
};

Vec3 randomUnit(scenes::Random& random) {
  while (true) {
    const Vec3 v(random.uniform(-1, 1), random.uniform(-1, 1), random.uniform(-1, 1));
    const double n = v.norm();
    if (n > 1e-3 && n <= 1) return v / n;
  }
}

// A walk of consecutive points, each `step` from the last: a tangent direction that turns
// smoothly at random, and a normal part that tracks a target distance to the surface which
// wanders smoothly through [near, far] (both found with a fresh Meshsweeper query per step).
std::vector<Vec3> makePath(const Mesh& mesh, const std::shared_ptr<const Hierarchy>& h, const PathVariant& v,
                           size_t steps) {
  const double diagonal = meshDiagonal(mesh);
  const double step = v.step * diagonal;
  scenes::Random random(v.seed);
  QueryStream steer(h);
  const double a1 = random.uniform(0, 2 * kPi), a2 = random.uniform(0, 2 * kPi);
  auto target = [&](double length) {  // length: path length so far, in diagonals
    const double w = 0.5 + 0.5 * std::sin(a1 + 2 * kPi * length / 0.37) * std::cos(a2 + 2 * kPi * length / 1.13);
    return (v.near + (v.far - v.near) * w) * diagonal;
  };
  Vec3 p = scenes::surfacePoints(mesh, 1, v.seed).front();
  {
    const ClosestPoint c = steer.closest(p);
    const Triangle& t = mesh.triangles[c.triangle];
    Vec3 n = (mesh.positions[t[1]] - mesh.positions[t[0]]).cross(mesh.positions[t[2]] - mesh.positions[t[0]]);
    n = n.norm() > 0 ? Vec3(n.normalized()) : randomUnit(random);
    p += target(0) * n;
  }
  Vec3 direction = randomUnit(random);
  Vec3 normal = randomUnit(random);
  const double turn = 0.1 * std::sqrt(v.step / 0.0005);  // same curvature per unit length
  std::vector<Vec3> out;
  out.reserve(steps);
  for (size_t i = 0; i < steps; ++i) {
    out.push_back(p);
    const ClosestPoint c = steer.closest(p);
    if (c.distance > 0) normal = (p - c.point) / c.distance;
    direction += turn * randomUnit(random);
    Vec3 tangent = direction - direction.dot(normal) * normal;
    if (tangent.norm() < 1e-9) tangent = normal.unitOrthogonal();
    tangent.normalize();
    direction = tangent;
    const double length = static_cast<double>(i + 1) * v.step;
    const double dn = std::clamp(target(length) - c.distance, -0.5 * step, 0.5 * step);
    p += std::sqrt(step * step - dn * dn) * tangent + dn * normal;
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Methods

enum class PathMethod { kMsCoherent, kMsFront, kMsFresh, kEmbreeFresh, kEmbreeWarm, kCgalHint, kCgalFresh };
const PathMethod kPathMethods[] = {PathMethod::kMsCoherent, PathMethod::kMsFront,    PathMethod::kMsFresh,
                                   PathMethod::kEmbreeFresh, PathMethod::kEmbreeWarm, PathMethod::kCgalHint,
                                   PathMethod::kCgalFresh};
const char* pathMethodName(PathMethod m) {
  switch (m) {
    case PathMethod::kMsCoherent: return "ms_coherent";
    case PathMethod::kMsFront: return "ms_front";
    case PathMethod::kMsFresh: return "ms_fresh";
    case PathMethod::kEmbreeFresh: return "embree_fresh";
    case PathMethod::kEmbreeWarm: return "embree_warm";
    case PathMethod::kCgalHint: return "cgal_hint";
    case PathMethod::kCgalFresh: return "cgal_fresh";
  }
  return "?";
}

enum class BoundsMethod {
  kKfBounds, kKfSetTime, kSetPositions, kSetPositionsInline, kInflate, kEmbreeRefit, kEmbreeBuild, kCgalRebuild, kMsBuild
};
const BoundsMethod kBoundsMethods[] = {BoundsMethod::kKfBounds,    BoundsMethod::kKfSetTime,   BoundsMethod::kSetPositions,
                                       BoundsMethod::kSetPositionsInline, BoundsMethod::kInflate,
                                       BoundsMethod::kEmbreeRefit, BoundsMethod::kEmbreeBuild,
                                       BoundsMethod::kCgalRebuild, BoundsMethod::kMsBuild};
const char* boundsMethodName(BoundsMethod m) {
  switch (m) {
    case BoundsMethod::kKfBounds: return "ms_kf_bounds";
    case BoundsMethod::kKfSetTime: return "ms_kf_settime";
    case BoundsMethod::kSetPositions: return "ms_setpositions";
    case BoundsMethod::kSetPositionsInline: return "ms_setpositions_inline";
    case BoundsMethod::kInflate: return "ms_inflate";
    case BoundsMethod::kEmbreeRefit: return "embree_refit";
    case BoundsMethod::kEmbreeBuild: return "embree_build";
    case BoundsMethod::kCgalRebuild: return "cgal_rebuild";
    case BoundsMethod::kMsBuild: return "ms_build";
  }
  return "?";
}

enum class DeformedMethod { kMsKeyframe, kMsInflated, kMsInflatedInline, kMsRebuilt, kEmbreeRefit, kEmbreeRebuilt, kCgalRebuilt };
const DeformedMethod kDeformedMethods[] = {DeformedMethod::kMsKeyframe, DeformedMethod::kMsInflated,
                                           DeformedMethod::kMsInflatedInline,
                                           DeformedMethod::kMsRebuilt,  DeformedMethod::kEmbreeRefit,
                                           DeformedMethod::kEmbreeRebuilt, DeformedMethod::kCgalRebuilt};
const char* deformedMethodName(DeformedMethod m) {
  switch (m) {
    case DeformedMethod::kMsKeyframe: return "ms_keyframe";
    case DeformedMethod::kMsInflated: return "ms_inflated";
    case DeformedMethod::kMsInflatedInline: return "ms_inflated_inline";
    case DeformedMethod::kMsRebuilt: return "ms_rebuilt";
    case DeformedMethod::kEmbreeRefit: return "embree_refit";
    case DeformedMethod::kEmbreeRebuilt: return "embree_rebuilt";
    case DeformedMethod::kCgalRebuilt: return "cgal_rebuilt";
  }
  return "?";
}

// ---------------------------------------------------------------------------------------------
// Fixtures, built on first use, outside every timed loop.

struct PathFixture {
  std::string name;
  Mesh mesh;
  double diagonal = 0;
  std::shared_ptr<const Hierarchy> hierarchy;
  std::unique_ptr<QueryStream> coherent, front, fresh;
  std::unique_ptr<EmbreeClosest> embree;
  std::unique_ptr<EmbreeWarmClosest> embree_warm;
  std::unique_ptr<CgalHintedClosest> cgal;
  std::vector<Path> paths;  // [variant]
};

std::vector<Vec3> lerp(const std::vector<Vec3>& a, const std::vector<Vec3>& b, double s) {
  std::vector<Vec3> out(a.size());
  for (size_t v = 0; v < a.size(); ++v) out[v] = (1 - s) * a[v] + s * b[v];
  return out;
}

// The deformed key frame: every vertex moves along its normal by a wave of 1% of the diagonal
// (3 waves along y), then the whole mesh twists about z by up to 0.15 rad at the ends.
std::vector<Vec3> deformedFrame(const Mesh& mesh) {
  const double diagonal = meshDiagonal(mesh);
  std::vector<Vec3> normals(mesh.positions.size(), Vec3::Zero());
  for (const Triangle& t : mesh.triangles) {
    const Vec3 a = (mesh.positions[t[1]] - mesh.positions[t[0]]).cross(mesh.positions[t[2]] - mesh.positions[t[0]]);
    for (VertexIndex v : t) normals[v] += a;
  }
  Vec3 lower, upper;
  meshBounds(mesh, lower, upper);
  const Vec3 c = 0.5 * (lower + upper);
  const double half = 0.5 * (upper.z() - lower.z());
  std::vector<Vec3> out(mesh.positions.size());
  for (size_t v = 0; v < out.size(); ++v) {
    const Vec3& x = mesh.positions[v];
    const Vec3 n = normals[v].norm() > 0 ? Vec3(normals[v].normalized()) : Vec3::Zero();
    const Vec3 w = x + 0.01 * diagonal * std::sin(2 * kPi * 3 * (x.y() - lower.y()) / diagonal) * n - c;
    const double angle = 0.15 * w.z() / half;
    out[v] = c + Vec3(std::cos(angle) * w.x() - std::sin(angle) * w.y(),
                      std::sin(angle) * w.x() + std::cos(angle) * w.y(), w.z());
  }
  return out;
}

struct DeformFixture {
  std::string name;
  const PathFixture* base = nullptr;
  std::vector<Vec3> rest, deformed;               // the two key frames
  std::vector<std::vector<Vec3>> frames;          // positions at the times the bounds benchmarks cycle through
  std::vector<double> times;
  std::vector<double> delta;                      // [vertex] |deformed - rest|: bound for any t
  std::unique_ptr<KeyframeBody> keyframe;
  std::unique_ptr<DeformingBody> deforming;
  std::unique_ptr<DeformingBody> deforming_inline;  // the same with inline faces
  std::unique_ptr<EmbreeRefitScene> refit;
  std::vector<Node8> bounds_scratch;            // interpolatedBounds output
  std::unique_ptr<CgalHintedClosest> cgal;
  // At t = 0.5:
  Mesh half;                                      // the deformed mesh
  std::vector<Vec3> points;                       // near-surface query points
  std::shared_ptr<const Hierarchy> rebuilt;
  std::unique_ptr<QueryStream> keyframe_stream, inflated_stream, inflated_inline_stream, rebuilt_stream;
  std::unique_ptr<EmbreeClosest> embree_rebuilt;
};

[[noreturn]] void disagree(const std::string& where, const Vec3& p, const std::vector<std::pair<std::string, double>>& answers) {
  std::fprintf(stderr, "bench_dynamic: methods disagree on %s at (%.17g %.17g %.17g):\n", where.c_str(), p.x(), p.y(), p.z());
  for (const auto& a : answers) std::fprintf(stderr, "  %-14s %.17g\n", a.first.c_str(), a.second);
  std::exit(3);
}

// Every method on every point of the path, in path order with each method's own warm state,
// as the timed loops run them; brute force on every 997th point.
void verifyPath(PathFixture& f, Path& path) {
  const auto start = Clock::now();
  f.coherent->reset();
  f.front->reset();
  PeerHit cgal_previous;
  TriangleIndex embree_previous = kInvalidIndex;
  double sum = 0;
  path.min_offset = INFINITY;
  path.max_offset = 0;
  for (size_t i = 0; i < path.points.size(); ++i) {
    const Vec3& p = path.points[i];
    std::vector<std::pair<std::string, double>> answers;
    answers.emplace_back("ms_coherent", f.coherent->closestCoherent(p).distance);
    answers.emplace_back("ms_front", f.front->closestWithinCoherent(p, 0).distance);
    answers.emplace_back("ms_fresh", f.fresh->closest(p).distance);
    answers.emplace_back("embree_fresh", f.embree->closest(p).distance);
    const PeerHit warm = f.embree_warm->closest(p, embree_previous);
    embree_previous = warm.triangle;
    answers.emplace_back("embree_warm", warm.distance);
    const PeerHit hinted = i == 0 ? f.cgal->closest(p) : f.cgal->closest(p, cgal_previous);
    cgal_previous = hinted;
    answers.emplace_back("cgal_hint", hinted.distance);
    answers.emplace_back("cgal_fresh", f.cgal->closest(p).distance);
    if (i % 997 == 0) answers.emplace_back("brute", bruteForceClosest(f.mesh, p).distance);
    double lo = INFINITY, hi = -INFINITY;
    for (const auto& a : answers) lo = std::min(lo, a.second), hi = std::max(hi, a.second);
    if (!agree(lo, hi, f.diagonal)) disagree(f.name + ", path " + path.variant->name + ", step " + std::to_string(i), p, answers);
    const double offset = answers.front().second / f.diagonal;
    sum += offset;
    path.min_offset = std::min(path.min_offset, offset);
    path.max_offset = std::max(path.max_offset, offset);
  }
  path.mean_offset = sum / static_cast<double>(path.points.size());
  std::fprintf(stderr,
               "[%s] path %s: %zu steps agree across 7 methods (+ brute force every 997th); distance to the "
               "surface %.4f%% .. %.3f%% (mean %.3f%%) of the diagonal (%.1f s)\n",
               f.name.c_str(), path.variant->name, path.points.size(), 100 * path.min_offset, 100 * path.max_offset,
               100 * path.mean_offset, secondsSince(start));
}

PathFixture& pathFixture(const std::string& name) {
  static std::map<std::string, std::unique_ptr<PathFixture>> fixtures;
  auto& slot = fixtures[name];
  if (slot) return *slot;
  const auto start = Clock::now();
  slot = std::make_unique<PathFixture>();
  PathFixture& f = *slot;
  f.name = name;
  try {
    f.mesh = readMesh(meshPathOf(name));
    f.diagonal = meshDiagonal(f.mesh);
    f.hierarchy = Hierarchy::build(f.mesh);
    f.coherent = std::make_unique<QueryStream>(f.hierarchy, g_options.coherence);
    f.front = std::make_unique<QueryStream>(f.hierarchy, g_options.coherence);
    f.fresh = std::make_unique<QueryStream>(f.hierarchy);
    f.embree = std::make_unique<EmbreeClosest>(f.mesh);
    f.embree_warm = std::make_unique<EmbreeWarmClosest>(f.mesh);
    f.cgal = std::make_unique<CgalHintedClosest>(f.mesh);
    for (const PathVariant& v : kVariants) f.paths.push_back({&v, makePath(f.mesh, f.hierarchy, v, g_options.steps)});
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_dynamic: %s: %s\n", name.c_str(), e.what());
    std::exit(1);
  }
  std::fprintf(stderr, "[%s] %zu vertices, %zu triangles, diagonal %.6g; fixtures and paths %.1f s\n", name.c_str(),
               f.mesh.positions.size(), f.mesh.triangles.size(), f.diagonal, secondsSince(start));
  for (Path& path : f.paths) verifyPath(f, path);
  return f;
}

void verifyDeformed(DeformFixture& d) {
  const auto start = Clock::now();
  const double diagonal = d.base->diagonal;
  for (size_t i = 0; i < d.points.size(); ++i) {
    const Vec3& p = d.points[i];
    std::vector<std::pair<std::string, double>> answers;
    answers.emplace_back("ms_keyframe", d.keyframe_stream->closest(p).distance);
    answers.emplace_back("ms_inflated", d.inflated_stream->closest(p).distance);
    answers.emplace_back("ms_inflated_inline", d.inflated_inline_stream->closest(p).distance);
    answers.emplace_back("ms_rebuilt", d.rebuilt_stream->closest(p).distance);
    answers.emplace_back("embree_refit", d.refit->closest(p).distance);
    answers.emplace_back("embree_rebuilt", d.embree_rebuilt->closest(p).distance);
    answers.emplace_back("cgal_rebuilt", d.cgal->closest(p).distance);
    if (i % 199 == 0) answers.emplace_back("brute", bruteForceClosest(d.half, p).distance);
    double lo = INFINITY, hi = -INFINITY;
    for (const auto& a : answers) lo = std::min(lo, a.second), hi = std::max(hi, a.second);
    if (!agree(lo, hi, diagonal)) disagree(d.name + ", deformed at t = 0.5, point " + std::to_string(i), p, answers);
  }
  std::fprintf(stderr, "[%s] deformed (t = 0.5): %zu points agree across 7 methods (+ brute force every 199th) (%.1f s)\n",
               d.name.c_str(), d.points.size(), secondsSince(start));
}

DeformFixture& deformFixture(const std::string& name) {
  static std::map<std::string, std::unique_ptr<DeformFixture>> fixtures;
  auto& slot = fixtures[name];
  if (slot) return *slot;
  const auto start = Clock::now();
  const PathFixture& base = pathFixture(name);
  slot = std::make_unique<DeformFixture>();
  DeformFixture& d = *slot;
  d.name = name;
  d.base = &base;
  try {
    const Mesh& mesh = base.mesh;
    d.rest = mesh.positions;
    d.deformed = deformedFrame(mesh);
    for (int j = 0; j < 16; ++j) {
      // t advances through [0, 1] in 16 frames, then starts again.
      const double t = static_cast<double>(j) / 15.0;
      d.times.push_back(t);
      d.frames.push_back(lerp(d.rest, d.deformed, t));
    }
    d.delta.resize(d.rest.size());
    double largest = 0;
    for (size_t v = 0; v < d.rest.size(); ++v) {
      d.delta[v] = (d.deformed[v] - d.rest[v]).norm() * (1 + 1e-12);
      largest = std::max(largest, d.delta[v]);
    }
    std::fprintf(stderr, "[%s] deformation: largest vertex displacement %.3f%% of the diagonal\n", name.c_str(),
                 100 * largest / base.diagonal);
    d.keyframe = std::make_unique<KeyframeBody>(base.hierarchy, std::vector<std::vector<Vec3>>{d.rest, d.deformed});
    d.deforming = std::make_unique<DeformingBody>(base.hierarchy);
    d.deforming->inflate(d.delta);
    d.deforming_inline = std::make_unique<DeformingBody>(base.hierarchy);
    d.deforming_inline->inflate(d.delta);
    d.deforming_inline->setInlineFaces(true);
    d.refit = std::make_unique<EmbreeRefitScene>(mesh);
    d.cgal = std::make_unique<CgalHintedClosest>(mesh);

    d.half = mesh;
    d.half.positions = lerp(d.rest, d.deformed, 0.5);
    d.points = scenes::nearSurfacePoints(d.half, g_options.points, 0.01, 0x5eed0d1f);
    d.rebuilt = Hierarchy::build(d.half);
    d.rebuilt_stream = std::make_unique<QueryStream>(d.rebuilt);
    d.keyframe_stream = std::make_unique<QueryStream>(base.hierarchy);
    d.keyframe_stream->setGeometry(&d.keyframe->geometry());
    d.inflated_stream = std::make_unique<QueryStream>(base.hierarchy);
    d.inflated_stream->setGeometry(&d.deforming->geometry());
    d.inflated_inline_stream = std::make_unique<QueryStream>(base.hierarchy);
    d.inflated_inline_stream->setGeometry(&d.deforming_inline->geometry());
    d.embree_rebuilt = std::make_unique<EmbreeClosest>(d.half);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_dynamic: %s (deformation): %s\n", name.c_str(), e.what());
    std::exit(1);
  }
  std::fprintf(stderr, "[%s] deformation fixtures %.1f s\n", name.c_str(), secondsSince(start));
  return d;
}

// Puts every deformable method at t = 0.5 (the query benchmarks' state).
void setHalf(DeformFixture& d) {
  d.keyframe->setTime(0.5);
  if (!d.deforming->setPositions(d.half.positions).accepted ||
      !d.deforming_inline->setPositions(d.half.positions).accepted) {
    std::fprintf(stderr, "bench_dynamic: %s: DeformingBody refused positions within its bounds\n", d.name.c_str());
    std::exit(3);
  }
  d.refit->setPositions(d.half.positions);
  d.refit->commit();
  d.cgal->rebuild(d.half.positions);
}

DeformFixture& deformedAtHalf(const std::string& name) {
  static std::map<std::string, bool> verified;
  DeformFixture& d = deformFixture(name);
  setHalf(d);
  if (!verified[name]) {
    verifyDeformed(d);
    verified[name] = true;
  }
  return d;
}

// ---------------------------------------------------------------------------------------------
// Samples for the summary

struct Samples {
  std::vector<double> seconds;  // per pass (paths, queries) or per frame (bounds)
  size_t count = 0;             // steps or points per pass
  double triangles = 0;         // work summed over every timed pass
  double passes = 0;
  double certified = 0, steps = 0, rebuilds = 0, candidates = 0;  // ms_coherent
};
std::map<std::string, Samples> g_samples;

double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const size_t h = v.size() / 2;
  return v.size() % 2 ? v[h] : 0.5 * (v[h - 1] + v[h]);
}

// ---------------------------------------------------------------------------------------------
// Benchmarks

void benchPath(benchmark::State& state, std::string mesh_name, size_t variant, PathMethod method) {
  PathFixture& f = pathFixture(mesh_name);
  const Path& path = f.paths[variant];
  const Vec3* points = path.points.data();
  const size_t n = path.points.size();
  Samples& samples = g_samples["path/" + mesh_name + "/" + path.variant->name + "/" + pathMethodName(method)];
  samples.count = n;
  double triangles = 0;
  CoherenceCounters before{}, after{};
  for (auto _ : state) {
    if (method == PathMethod::kMsCoherent) f.coherent->reset();
    if (method == PathMethod::kMsFront) f.front->reset();
    before = method == PathMethod::kMsFront ? f.front->coherence() : f.coherent->coherence();
    const double start = processCpuSeconds();
    double checksum = 0;
    uint64_t tested = 0;
    switch (method) {
      case PathMethod::kMsCoherent: {
        QueryStream& s = *f.coherent;
        for (size_t i = 0; i < n; ++i) {
          const ClosestPoint c = s.closestCoherent(points[i]);
          checksum += c.distance;
          tested += c.counters.triangles_tested;
        }
        break;
      }
      case PathMethod::kMsFront: {
        QueryStream& s = *f.front;
        for (size_t i = 0; i < n; ++i) {
          const ClosestPoint c = s.closestWithinCoherent(points[i], 0);
          checksum += c.distance;
          tested += c.counters.triangles_tested;
        }
        break;
      }
      case PathMethod::kMsFresh: {
        QueryStream& s = *f.fresh;
        for (size_t i = 0; i < n; ++i) {
          const ClosestPoint c = s.closest(points[i]);
          checksum += c.distance;
          tested += c.counters.triangles_tested;
        }
        break;
      }
      case PathMethod::kEmbreeFresh:
        for (size_t i = 0; i < n; ++i) {
          const PeerHit h = f.embree->closest(points[i]);
          checksum += h.distance;
          tested += h.triangles_tested;
        }
        break;
      case PathMethod::kEmbreeWarm: {
        TriangleIndex previous = kInvalidIndex;
        for (size_t i = 0; i < n; ++i) {
          const PeerHit h = f.embree_warm->closest(points[i], previous);
          previous = h.triangle;
          checksum += h.distance;
          tested += h.triangles_tested;
        }
        break;
      }
      case PathMethod::kCgalHint: {
        PeerHit previous = f.cgal->closest(points[0]);
        checksum += previous.distance;
        for (size_t i = 1; i < n; ++i) {
          previous = f.cgal->closest(points[i], previous);
          checksum += previous.distance;
        }
        break;
      }
      case PathMethod::kCgalFresh:
        for (size_t i = 0; i < n; ++i) checksum += f.cgal->closest(points[i]).distance;
        break;
    }
    benchmark::DoNotOptimize(checksum);
    samples.seconds.push_back(processCpuSeconds() - start);
    triangles += static_cast<double>(tested);
    after = method == PathMethod::kMsFront ? f.front->coherence() : f.coherent->coherence();
    if (method == PathMethod::kMsCoherent) {
      samples.certified += static_cast<double>(after.certified - before.certified);
      samples.rebuilds += static_cast<double>(after.rebuilds - before.rebuilds);
      samples.candidates += static_cast<double>(after.candidates - before.candidates);
      samples.steps += static_cast<double>(after.steps - before.steps);
    }
    if (method == PathMethod::kMsFront) {
      samples.rebuilds += static_cast<double>(after.front_resets - before.front_resets);
      samples.steps += static_cast<double>(after.steps - before.steps);
    }
  }
  const double steps = static_cast<double>(n) * static_cast<double>(state.iterations());
  samples.triangles += triangles;
  samples.passes += static_cast<double>(state.iterations());
  state.counters["steps/s"] = benchmark::Counter(steps, benchmark::Counter::kIsRate);
  state.counters["steps"] = static_cast<double>(n);
  if (method != PathMethod::kCgalHint && method != PathMethod::kCgalFresh) state.counters["tris/step"] = triangles / steps;
  if (method == PathMethod::kMsCoherent && samples.steps > 0) {
    state.counters["certified%"] = 100 * samples.certified / samples.steps;
    state.counters["cand/rebuild"] = samples.rebuilds > 0 ? samples.candidates / samples.rebuilds : 0;
  }
  if (method == PathMethod::kMsFront && samples.steps > 0) state.counters["resets%"] = 100 * samples.rebuilds / samples.steps;
}

void benchBounds(benchmark::State& state, std::string mesh_name, BoundsMethod method) {
  DeformFixture& d = deformFixture(mesh_name);
  const Mesh& mesh = d.base->mesh;
  Samples& samples = g_samples["bounds/" + mesh_name + "/" + boundsMethodName(method)];
  size_t frame = 0;
  Mesh scratch = mesh;  // for the rebuilds
  for (auto _ : state) {
    const size_t j = frame++ % d.frames.size();
    const std::vector<Vec3>& positions = d.frames[j];
    double seconds = 0;
    switch (method) {
      case BoundsMethod::kKfBounds: {
        const double start = processCpuSeconds();
        d.keyframe->interpolatedBounds(d.times[j], d.bounds_scratch);
        seconds = processCpuSeconds() - start;
        break;
      }
      case BoundsMethod::kKfSetTime: {
        const double start = processCpuSeconds();
        d.keyframe->setTime(d.times[j]);
        seconds = processCpuSeconds() - start;
        break;
      }
      case BoundsMethod::kSetPositions:
      case BoundsMethod::kSetPositionsInline: {
        DeformingBody& body = method == BoundsMethod::kSetPositions ? *d.deforming : *d.deforming_inline;
        const double start = processCpuSeconds();
        const DisplacementCheck check = body.setPositions(positions);
        seconds = processCpuSeconds() - start;
        if (!check.accepted) {
          state.SkipWithError("DeformingBody refused positions within its bounds");
          return;
        }
        break;
      }
      case BoundsMethod::kInflate: {
        const double start = processCpuSeconds();
        d.deforming->inflate(d.delta);
        seconds = processCpuSeconds() - start;
        break;
      }
      case BoundsMethod::kEmbreeRefit: {
        d.refit->setPositions(positions);  // the vertex buffer: not timed
        const double start = processCpuSeconds();
        d.refit->commit();
        seconds = processCpuSeconds() - start;
        break;
      }
      case BoundsMethod::kEmbreeBuild: {
        scratch.positions = positions;
        const double start = processCpuSeconds();
        {
          EmbreeClosest built(scratch);
          seconds = processCpuSeconds() - start;
        }
        break;
      }
      case BoundsMethod::kCgalRebuild: {
        const double start = processCpuSeconds();
        d.cgal->rebuild(positions);
        seconds = processCpuSeconds() - start;
        break;
      }
      case BoundsMethod::kMsBuild: {
        scratch.positions = positions;
        const double start = processCpuSeconds();
        auto built = Hierarchy::build(scratch);
        seconds = processCpuSeconds() - start;
        break;
      }
    }
    state.SetIterationTime(seconds);
    samples.seconds.push_back(seconds);
  }
  state.counters["vertices"] = static_cast<double>(mesh.positions.size());
}

void benchDeformed(benchmark::State& state, std::string mesh_name, DeformedMethod method) {
  DeformFixture& d = deformedAtHalf(mesh_name);
  const Vec3* points = d.points.data();
  const size_t n = d.points.size();
  Samples& samples = g_samples["deformed/" + mesh_name + "/" + deformedMethodName(method)];
  samples.count = n;
  double triangles = 0;
  for (auto _ : state) {
    const double start = processCpuSeconds();
    double checksum = 0;
    uint64_t tested = 0;
    auto meshsweeper = [&](QueryStream& s) {
      for (size_t i = 0; i < n; ++i) {
        const ClosestPoint c = s.closest(points[i]);
        checksum += c.distance;
        tested += c.counters.triangles_tested;
      }
    };
    switch (method) {
      case DeformedMethod::kMsKeyframe: meshsweeper(*d.keyframe_stream); break;
      case DeformedMethod::kMsInflated: meshsweeper(*d.inflated_stream); break;
      case DeformedMethod::kMsInflatedInline: meshsweeper(*d.inflated_inline_stream); break;
      case DeformedMethod::kMsRebuilt: meshsweeper(*d.rebuilt_stream); break;
      case DeformedMethod::kEmbreeRefit:
        for (size_t i = 0; i < n; ++i) {
          const PeerHit h = d.refit->closest(points[i]);
          checksum += h.distance;
          tested += h.triangles_tested;
        }
        break;
      case DeformedMethod::kEmbreeRebuilt:
        for (size_t i = 0; i < n; ++i) {
          const PeerHit h = d.embree_rebuilt->closest(points[i]);
          checksum += h.distance;
          tested += h.triangles_tested;
        }
        break;
      case DeformedMethod::kCgalRebuilt:
        for (size_t i = 0; i < n; ++i) checksum += d.cgal->closest(points[i]).distance;
        break;
    }
    benchmark::DoNotOptimize(checksum);
    samples.seconds.push_back(processCpuSeconds() - start);
    triangles += static_cast<double>(tested);
  }
  const double queries = static_cast<double>(n) * static_cast<double>(state.iterations());
  samples.triangles += triangles;
  samples.passes += static_cast<double>(state.iterations());
  state.counters["queries/s"] = benchmark::Counter(queries, benchmark::Counter::kIsRate);
  if (method != DeformedMethod::kCgalRebuilt) state.counters["tris/q"] = triangles / queries;
}

void registerBenchmarks() {
  for (const std::string& mesh : g_options.meshes) {
    for (size_t v = 0; v < std::size(kVariants); ++v)
      for (PathMethod m : kPathMethods)
        benchmark::RegisterBenchmark(("path/" + mesh + "/" + kVariants[v].name + "/" + pathMethodName(m)).c_str(),
                                     benchPath, mesh, v, m)
            ->MeasureProcessCPUTime()
            ->Unit(benchmark::kMillisecond);
    for (BoundsMethod m : kBoundsMethods) {
      auto* b = benchmark::RegisterBenchmark(("bounds/" + mesh + "/" + boundsMethodName(m)).c_str(), benchBounds, mesh, m)
                    ->UseManualTime()
                    ->MeasureProcessCPUTime()
                    ->Unit(benchmark::kMicrosecond);
      // Builds are slow: a fixed number of frames; the rest run for Google Benchmark's min time.
      if (m == BoundsMethod::kEmbreeBuild || m == BoundsMethod::kCgalRebuild || m == BoundsMethod::kMsBuild)
        b->Iterations(5);
    }
    for (DeformedMethod m : kDeformedMethods)
      benchmark::RegisterBenchmark(("deformed/" + mesh + "/" + deformedMethodName(m)).c_str(), benchDeformed, mesh, m)
          ->MeasureProcessCPUTime()
          ->Unit(benchmark::kMillisecond);
  }
}

// ---------------------------------------------------------------------------------------------
// Summary

const Samples* findSamples(const std::string& key) {
  auto it = g_samples.find(key);
  return it == g_samples.end() || it->second.seconds.empty() ? nullptr : &it->second;
}

void printSummary() {
  if (g_samples.empty()) return;
  FILE* out = g_options.summary_to_stderr ? stderr : stdout;
  std::fprintf(out,
               "\nSummary: medians of process CPU time over every timed pass (paths, queries) or frame (bounds); "
               "%zu steps per path, %zu query points; one thread\n",
               g_options.steps, g_options.points);
  std::fprintf(out, "\nCoherent paths\n\n| mesh | path | method | ns/step | steps/s | speed vs Embree warm | tris/step | notes |\n");
  std::fprintf(out, "|---|---|---|---:|---:|---:|---:|---|\n");
  for (const std::string& mesh : g_options.meshes) {
    for (const PathVariant& v : kVariants) {
      const std::string prefix = "path/" + mesh + "/" + v.name + "/";
      const Samples* warm = findSamples(prefix + "embree_warm");
      const double warm_ns = warm ? 1e9 * median(warm->seconds) / static_cast<double>(warm->count) : NAN;
      for (PathMethod m : kPathMethods) {
        const Samples* s = findSamples(prefix + pathMethodName(m));
        if (!s) continue;
        const double ns = 1e9 * median(s->seconds) / static_cast<double>(s->count);
        const double per_step = s->passes > 0 ? s->triangles / (s->passes * static_cast<double>(s->count)) : NAN;
        std::string notes;
        if (m == PathMethod::kMsCoherent && s->steps > 0)
          notes = formatCell("%.1f", 100 * s->certified / s->steps) + "% certified, " +
                  formatCell("%.1f", s->rebuilds > 0 ? s->candidates / s->rebuilds : NAN) + " candidates/rebuild";
        if (m == PathMethod::kMsFront && s->steps > 0) notes = formatCell("%.2f", 100 * s->rebuilds / s->steps) + "% front resets";
        const bool has_tris = m != PathMethod::kCgalHint && m != PathMethod::kCgalFresh;
        std::fprintf(out, "| %s | %s | %s | %s | %s | %s | %s | %s |\n", mesh.c_str(), v.name, pathMethodName(m),
                     formatCell("%.0f", ns).c_str(), formatCell("%.0f", 1e9 / ns).c_str(), formatCell("%.2f", warm_ns / ns).c_str(),
                     has_tris ? formatCell("%.1f", per_step).c_str() : "-", notes.c_str());
      }
    }
  }
  std::fprintf(out, "\nBound updates per frame\n\n| mesh | method | ms/frame | time / Embree refit |\n|---|---|---:|---:|\n");
  for (const std::string& mesh : g_options.meshes) {
    const Samples* refit = findSamples("bounds/" + mesh + "/embree_refit");
    const double refit_s = refit ? median(refit->seconds) : NAN;
    for (BoundsMethod m : kBoundsMethods) {
      const Samples* s = findSamples("bounds/" + mesh + "/" + boundsMethodName(m));
      if (!s) continue;
      const double sec = median(s->seconds);
      std::fprintf(out, "| %s | %s | %s | %s |\n", mesh.c_str(), boundsMethodName(m), formatCell("%.4f", 1e3 * sec).c_str(),
                   formatCell("%.3f", sec / refit_s).c_str());
    }
  }
  std::fprintf(out,
               "\nFresh queries on the deformed mesh (t = 0.5)\n\n| mesh | method | us/query | queries/s | speed vs "
               "Embree refit | tris/q |\n|---|---|---:|---:|---:|---:|\n");
  for (const std::string& mesh : g_options.meshes) {
    const Samples* refit = findSamples("deformed/" + mesh + "/embree_refit");
    const double refit_us = refit ? 1e6 * median(refit->seconds) / static_cast<double>(refit->count) : NAN;
    for (DeformedMethod m : kDeformedMethods) {
      const Samples* s = findSamples("deformed/" + mesh + "/" + deformedMethodName(m));
      if (!s) continue;
      const double us = 1e6 * median(s->seconds) / static_cast<double>(s->count);
      const double per_q = s->passes > 0 ? s->triangles / (s->passes * static_cast<double>(s->count)) : NAN;
      std::fprintf(out, "| %s | %s | %s | %s | %s | %s |\n", mesh.c_str(), deformedMethodName(m), formatCell("%.3f", us).c_str(),
                   formatCell("%.0f", 1e6 / us).c_str(), formatCell("%.2f", refit_us / us).c_str(),
                   m != DeformedMethod::kCgalRebuilt ? formatCell("%.1f", per_q).c_str() : "-");
    }
  }
  std::fflush(out);
}

}  // namespace
}  // namespace meshsweeper::bench

int main(int argc, char** argv) {
  using namespace meshsweeper::bench;
  parseOwnFlags(argc, argv);
  for (const std::string& mesh : g_options.meshes) {
    if (!std::ifstream(meshPathOf(mesh)).good()) {
      std::fprintf(stderr, "bench_dynamic: %s not found; run scripts/fetch_data.sh or pass --data-dir\n",
                   meshPathOf(mesh).c_str());
      return 77;
    }
  }
  // One thread everywhere: Meshsweeper's radius refits may use TBB; Embree's devices have threads=1.
  tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 2;
  registerBenchmarks();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  printSummary();
  return 0;
}
