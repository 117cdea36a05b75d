// bench_closest: exact closest-point queries, Meshsweeper against its peers, one thread, same
// points, one binary.
//
// Per mesh (armadillo, bunny00, refined_elephant by default):
//   build/MESH/METHOD            one build per iteration (manual time: construction only, CPU)
//   closest/MESH/SET/METHOD      one iteration = every point of SET (brute force: a subset)
// METHOD: meshsweeper (Hierarchy::build + QueryStream::closest), embree (rtcPointQuery with an
// exact double callback; embree-mskernel: the same with Meshsweeper's kernel), cgal (AABB_tree +
// accelerate_distance_queries), brute (bruteForceClosest). SET: random (uniform in the bounding box
// grown by 10% per side length, centred), near (area-weighted surface samples moved along the face
// normal by a uniform offset in [-1%, +1%] of the diagonal). Fixed seeds.
//
// Before the first benchmark of a mesh, every method is checked on the first points of each set
// (all fast methods on --verify-points, brute force on --verify-brute-points); any distance that
// differs by more than 1e-9 relative stops the program with a message (exit code 3).
// After Google Benchmark's own report the program prints a summary table (markdown): medians
// over every timed build and every timed pass over the points, and ratios to Embree. Times are
// process CPU time (see processCpuSeconds).
//
// Own flags (removed before Google Benchmark parses the rest):
//   --quick                 2,000 points, brute force on 20, one build per build benchmark
//   --points=N              points per set (also env MESHSWEEPER_BENCH_POINTS)
//   --brute-points=N        points per brute-force pass (default 200)
//   --verify-points=N       --verify-brute-points=N
//   --build-runs=N          builds per build benchmark repetition (default 7)
//   --meshes=a,b,c          --methods=meshsweeper,embree,embree-mskernel,cgal,brute
//   --data-dir=PATH         where MESH.off is found (default: scenes::dataDir())
// Exit code 77 when a mesh file is missing (ctest skips).
#include "bench/bench_util.h"
#include "bench/peers.h"
#include "core/brute_force.h"
#include "core/hierarchy.h"
#include "core/mesh_io.h"
#include "core/sweep_query.h"
#include "core/triangle_distance.h"
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
#include <stdexcept>
#include <string>
#include <vector>

namespace meshsweeper::bench {
namespace {

[[noreturn]] void usageError(const std::string& message) { bench::usageError("bench_closest", message); }
size_t parseCount(const std::string& flag, const std::string& value) { return bench::parseCount("bench_closest", flag, value); }

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// CPU seconds of the whole process (every thread). The machine is shared, so timings use CPU
// time, as Google Benchmark's rates do: time spent descheduled does not count, and work that a
// library would hand to another thread would.
double processCpuSeconds() {
  timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// ---------------------------------------------------------------------------------------------
// Options

// kEmbree runs the fastest exact scalar kernel in its callback (EmbreeKernel::kEricson) and is
// the reference of every ratio; kEmbreeMsKernel runs meshsweeper::squaredDistanceToTriangle.
enum class Method { kMeshsweeper, kEmbree, kEmbreeMsKernel, kCgal, kBrute };
const Method kAllMethods[] = {Method::kMeshsweeper, Method::kEmbree, Method::kEmbreeMsKernel,
                              Method::kCgal, Method::kBrute};

bool isEmbree(Method m) { return m == Method::kEmbree || m == Method::kEmbreeMsKernel; }

const char* methodName(Method m) {
  switch (m) {
    case Method::kMeshsweeper:
      return "meshsweeper";
    case Method::kEmbree:
      return "embree";
    case Method::kEmbreeMsKernel:
      return "embree-mskernel";
    case Method::kCgal:
      return "cgal";
    case Method::kBrute:
      return "brute";
  }
  return "?";
}

struct Options {
  size_t points = 100000;
  size_t brute_points = 200;
  size_t verify_points = 4000;
  size_t verify_brute_points = 1000;
  int build_runs = 7;
  std::vector<std::string> meshes = {"armadillo", "bunny00", "refined_elephant"};
  std::vector<Method> methods = {Method::kMeshsweeper, Method::kEmbree, Method::kEmbreeMsKernel,
                                 Method::kCgal, Method::kBrute};
  std::string data_dir;  // empty: scenes::meshPath (MESHSWEEPER_DATA or <repo>/data/meshes)
  // The summary goes to stdout after a console report, to stderr when stdout carries JSON/CSV.
  bool summary_to_stderr = false;
};

Options g_options;
std::map<std::string, size_t> g_triangle_counts;  // [mesh name] triangles, for the summary

bool enabled(Method m) {
  return std::find(g_options.methods.begin(), g_options.methods.end(), m) !=
         g_options.methods.end();
}

// Parses and removes this program's flags from argv; the rest goes to Google Benchmark.
void parseOwnFlags(int& argc, char** argv) {
  if (const char* env = std::getenv("MESHSWEEPER_BENCH_POINTS"))
    g_options.points = parseCount("MESHSWEEPER_BENCH_POINTS", env);
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const size_t eq = arg.find('=');
    const std::string flag = arg.substr(0, eq);
    const std::string value = eq == std::string::npos ? "" : arg.substr(eq + 1);
    if (flag == "--quick") {
      g_options.points = 2000;
      g_options.brute_points = 20;
      g_options.verify_points = 500;
      g_options.verify_brute_points = 100;
      g_options.build_runs = 1;
    } else if (flag == "--points") {
      g_options.points = parseCount(flag, value);
    } else if (flag == "--brute-points") {
      g_options.brute_points = parseCount(flag, value);
    } else if (flag == "--verify-points") {
      g_options.verify_points = parseCount(flag, value);
    } else if (flag == "--verify-brute-points") {
      g_options.verify_brute_points = parseCount(flag, value);
    } else if (flag == "--build-runs") {
      g_options.build_runs = static_cast<int>(parseCount(flag, value));
    } else if (flag == "--meshes") {
      g_options.meshes = splitList(value);
      if (g_options.meshes.empty()) usageError("--meshes needs a list");
    } else if (flag == "--methods") {
      g_options.methods.clear();
      for (const std::string& name : splitList(value)) {
        bool found = false;
        for (Method m : kAllMethods)
          if (name == methodName(m)) g_options.methods.push_back(m), found = true;
        if (!found) usageError("unknown method '" + name + "'");
      }
    } else if (flag == "--data-dir") {
      g_options.data_dir = value;
    } else {
      if (flag == "--benchmark_format" && value != "console") g_options.summary_to_stderr = true;
      argv[kept++] = argv[i];
      continue;
    }
  }
  argc = kept;
  argv[argc] = nullptr;
}

// ---------------------------------------------------------------------------------------------
// Fixtures: one per mesh, built on first use, outside every timed loop.

struct PointSet {
  std::string name;
  std::vector<Vec3> points;
};

struct MeshFixture {
  std::string name;
  Mesh mesh;
  double diagonal = 0;
  std::vector<PointSet> point_sets;
  std::shared_ptr<const Hierarchy> hierarchy;
  std::unique_ptr<QueryStream> stream;
  std::unique_ptr<EmbreeClosest> embree;           // EmbreeKernel::kEricson
  std::unique_ptr<EmbreeClosest> embree_mskernel;  // EmbreeKernel::kMeshsweeper
  std::unique_ptr<CgalClosest> cgal;
};

const EmbreeClosest& embreeOf(const MeshFixture& f, Method m) {
  return m == Method::kEmbree ? *f.embree : *f.embree_mskernel;
}

std::string meshPathOf(const std::string& name) {
  return g_options.data_dir.empty() ? scenes::meshPath(name)
                                    : g_options.data_dir + "/" + name + ".off";
}

const char* const kPointSetNames[] = {"random", "near"};
constexpr uint64_t kRandomSeed = 0x5eed0001;
constexpr uint64_t kNearSeed = 0x5eed0002;

// Answers of one method on one point, for verification.
struct Answer {
  double distance;
  TriangleIndex triangle;
};

Answer answer(MeshFixture& f, Method m, const Vec3& p) {
  switch (m) {
    case Method::kMeshsweeper: {
      const ClosestPoint c = f.stream->closest(p);
      return {c.distance, c.triangle};
    }
    case Method::kEmbree:
    case Method::kEmbreeMsKernel: {
      const PeerHit h = embreeOf(f, m).closest(p);
      return {h.distance, h.triangle};
    }
    case Method::kCgal: {
      const PeerHit h = f.cgal->closest(p);
      return {h.distance, h.triangle};
    }
    case Method::kBrute: {
      const BruteHit h = bruteForceClosest(f.mesh, p);
      return {h.distance, h.triangle};
    }
  }
  return {0, kInvalidIndex};
}

// Every enabled method must give the same distance (1e-9 relative) on the first points of each
// set; brute force, when enabled, only on the first verify_brute_points.
void verifyAgreement(MeshFixture& f) {
  const auto start = Clock::now();
  size_t compared = 0;
  for (const PointSet& set : f.point_sets) {
    const size_t n = std::min(g_options.verify_points, set.points.size());
    const size_t n_brute = std::min(g_options.verify_brute_points, n);
    for (size_t i = 0; i < n; ++i) {
      const Vec3& p = set.points[i];
      std::vector<std::pair<Method, Answer>> answers;
      for (Method m : g_options.methods) {
        if (m == Method::kBrute && i >= n_brute) continue;
        answers.emplace_back(m, answer(f, m, p));
      }
      if (answers.size() < 2) continue;
      double lo = INFINITY, hi = -INFINITY;
      for (const auto& a : answers) {
        lo = std::min(lo, a.second.distance);
        hi = std::max(hi, a.second.distance);
      }
      ++compared;
      // Relative tolerance; the absolute floor only matters for points on the surface.
      if (std::isfinite(hi) && hi - lo <= 1e-9 * hi + 1e-15 * f.diagonal) continue;
      std::fprintf(stderr,
                   "bench_closest: methods disagree on %s, point set %s, point %zu "
                   "(%.17g %.17g %.17g):\n",
                   f.name.c_str(), set.name.c_str(), i, p.x(), p.y(), p.z());
      for (const auto& a : answers)
        std::fprintf(stderr, "  %-12s distance %.17g triangle %u\n", methodName(a.first),
                     a.second.distance, a.second.triangle);
      std::exit(3);
    }
  }
  std::fprintf(stderr, "[%s] %zu points agree across %zu methods (%.1f s)\n", f.name.c_str(),
               compared, g_options.methods.size(), secondsSince(start));
}

// Loads the mesh, makes the point sets and builds every enabled method. Throws on bad input.
void buildFixture(MeshFixture& f) {
  f.mesh = readMesh(meshPathOf(f.name));
  g_triangle_counts[f.name] = f.mesh.triangles.size();
  f.diagonal = meshDiagonal(f.mesh);
  // Each side of the bounding box grown by 10% (5% on each end); offsets up to 1% of the diagonal.
  f.point_sets.push_back(
      {"random", scenes::randomPointsInBox(f.mesh, g_options.points, 0.05, kRandomSeed)});
  f.point_sets.push_back(
      {"near", scenes::nearSurfacePoints(f.mesh, g_options.points, 0.01, kNearSeed)});
  if (enabled(Method::kMeshsweeper)) {
    f.hierarchy = Hierarchy::build(f.mesh);
    f.stream = std::make_unique<QueryStream>(f.hierarchy);
  }
  if (enabled(Method::kEmbree))
    f.embree = std::make_unique<EmbreeClosest>(f.mesh, EmbreeKernel::kEricson);
  if (enabled(Method::kEmbreeMsKernel))
    f.embree_mskernel = std::make_unique<EmbreeClosest>(f.mesh, EmbreeKernel::kMeshsweeper);
  if (enabled(Method::kCgal)) f.cgal = std::make_unique<CgalClosest>(f.mesh);
}

MeshFixture& fixture(const std::string& name) {
  static std::map<std::string, std::unique_ptr<MeshFixture>> fixtures;
  auto& slot = fixtures[name];
  if (slot) return *slot;
  const auto start = Clock::now();
  slot = std::make_unique<MeshFixture>();
  MeshFixture& f = *slot;
  f.name = name;
  try {
    buildFixture(f);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_closest: %s: %s\n", name.c_str(), e.what());
    std::exit(1);
  }
  std::fprintf(stderr, "[%s] %zu vertices, %zu triangles, diagonal %.6g; fixtures %.1f s\n",
               name.c_str(), f.mesh.positions.size(), f.mesh.triangles.size(), f.diagonal,
               secondsSince(start));
  verifyAgreement(f);
  return f;
}

// ---------------------------------------------------------------------------------------------
// Samples kept for the summary: every timed build and every timed pass over a point set.

struct Samples {
  std::vector<double> seconds;      // per build, or per pass over `queries` points
  size_t queries = 0;               // points per pass (query benchmarks)
  double nodes = 0, triangles = 0;  // work summed over every timed query
  size_t timed_queries = 0;
};

// key: "build/MESH/METHOD" or "closest/MESH/SET/METHOD"
std::map<std::string, Samples> g_samples;

double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const size_t h = v.size() / 2;
  return v.size() % 2 ? v[h] : 0.5 * (v[h - 1] + v[h]);
}

// ---------------------------------------------------------------------------------------------
// Benchmarks

void benchBuild(benchmark::State& state, std::string mesh_name, Method method) {
  MeshFixture& f = fixture(mesh_name);
  Samples& samples = g_samples["build/" + mesh_name + "/" + methodName(method)];
  for (auto _ : state) {
    const double start = processCpuSeconds();
    double seconds = 0;
    switch (method) {
      case Method::kMeshsweeper: {
        auto built = Hierarchy::build(f.mesh);
        seconds = processCpuSeconds() - start;
        state.counters["MB"] = static_cast<double>(built->stats().fixed_bytes) / 1e6;
        state.counters["depth"] = built->stats().depth;
        break;  // destroyed outside the measured time
      }
      case Method::kEmbree:
      case Method::kEmbreeMsKernel: {
        EmbreeClosest built(f.mesh, method == Method::kEmbree ? EmbreeKernel::kEricson
                                                              : EmbreeKernel::kMeshsweeper);
        seconds = processCpuSeconds() - start;
        break;
      }
      case Method::kCgal: {
        CgalClosest built(f.mesh);
        seconds = processCpuSeconds() - start;
        break;
      }
      case Method::kBrute:
        break;
    }
    state.SetIterationTime(seconds);
    samples.seconds.push_back(seconds);
  }
  state.counters["triangles"] = static_cast<double>(f.mesh.triangles.size());
}

void benchClosest(benchmark::State& state, std::string mesh_name, size_t set_index, Method method) {
  MeshFixture& f = fixture(mesh_name);
  const PointSet& set = f.point_sets[set_index];
  const size_t n = method == Method::kBrute ? std::min(g_options.brute_points, set.points.size())
                                            : set.points.size();
  const Vec3* points = set.points.data();
  Samples& samples = g_samples["closest/" + mesh_name + "/" + set.name + "/" + methodName(method)];
  samples.queries = n;
  double nodes = 0, triangles = 0;
  for (auto _ : state) {
    const double start = processCpuSeconds();
    double checksum = 0;
    switch (method) {
      case Method::kMeshsweeper: {
        QueryStream& stream = *f.stream;
        uint64_t node_sum = 0, triangle_sum = 0;
        for (size_t i = 0; i < n; ++i) {
          const ClosestPoint c = stream.closest(points[i]);
          checksum += c.distance;
          node_sum += c.counters.nodes_visited;
          triangle_sum += c.counters.triangles_tested;
        }
        nodes += static_cast<double>(node_sum);
        triangles += static_cast<double>(triangle_sum);
        break;
      }
      case Method::kEmbree:
      case Method::kEmbreeMsKernel: {
        const EmbreeClosest& embree = embreeOf(f, method);
        uint64_t triangle_sum = 0;
        for (size_t i = 0; i < n; ++i) {
          const PeerHit h = embree.closest(points[i]);
          checksum += h.distance;
          triangle_sum += h.triangles_tested;
        }
        triangles += static_cast<double>(triangle_sum);
        break;
      }
      case Method::kCgal:
        for (size_t i = 0; i < n; ++i) checksum += f.cgal->closest(points[i]).distance;
        break;
      case Method::kBrute:
        for (size_t i = 0; i < n; ++i) checksum += bruteForceClosest(f.mesh, points[i]).distance;
        break;
    }
    benchmark::DoNotOptimize(checksum);
    samples.seconds.push_back(processCpuSeconds() - start);
  }
  const double queries = static_cast<double>(n) * static_cast<double>(state.iterations());
  samples.nodes += nodes;
  samples.triangles += triangles;
  samples.timed_queries += static_cast<size_t>(queries);
  state.counters["queries/s"] = benchmark::Counter(queries, benchmark::Counter::kIsRate);
  state.counters["points"] = static_cast<double>(n);
  if (method == Method::kMeshsweeper) state.counters["nodes/q"] = nodes / queries;
  if (method == Method::kMeshsweeper || isEmbree(method))
    state.counters["tris/q"] = triangles / queries;
}

void registerBenchmarks() {
  for (const std::string& mesh : g_options.meshes) {
    for (Method m : g_options.methods) {
      if (m == Method::kBrute) continue;
      benchmark::RegisterBenchmark(("build/" + mesh + "/" + methodName(m)).c_str(), benchBuild,
                                   mesh, m)
          ->UseManualTime()
          ->MeasureProcessCPUTime()
          ->Iterations(g_options.build_runs)
          ->Unit(benchmark::kMillisecond);
    }
    for (size_t s = 0; s < 2; ++s)
      for (Method m : g_options.methods)
        benchmark::RegisterBenchmark(
            ("closest/" + mesh + "/" + kPointSetNames[s] + "/" + methodName(m)).c_str(),
            benchClosest, mesh, s, m)
            ->MeasureProcessCPUTime()
            ->Unit(benchmark::kMillisecond);
  }
}

// ---------------------------------------------------------------------------------------------
// Summary

void printSummary() {
  if (g_samples.empty()) return;
  FILE* out = g_options.summary_to_stderr ? stderr : stdout;
  std::fprintf(out,
               "\nSummary: medians of process CPU time over every timed build and every timed pass "
               "over the points; %zu points per set (brute force %zu); one thread\n\n",
               g_options.points, g_options.brute_points);
  std::fprintf(out,
               "| mesh | triangles | points | method | build s | build / Embree | queries/s | "
               "us/query | queries/s / Embree | tris tested/q | nodes/q |\n");
  std::fprintf(out, "|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
  auto find = [](const std::string& key) -> const Samples* {
    auto it = g_samples.find(key);
    return it == g_samples.end() || it->second.seconds.empty() ? nullptr : &it->second;
  };
  for (const std::string& mesh : g_options.meshes) {
    const Samples* embree_build = find("build/" + mesh + "/embree");
    const double embree_build_s = embree_build ? median(embree_build->seconds) : NAN;
    for (const char* set : kPointSetNames) {
      const Samples* embree_q = find("closest/" + mesh + "/" + set + "/embree");
      const double embree_qps =
          embree_q ? static_cast<double>(embree_q->queries) / median(embree_q->seconds) : NAN;
      for (Method m : g_options.methods) {
        const Samples* q = find("closest/" + mesh + "/" + set + "/" + methodName(m));
        const Samples* b = find("build/" + mesh + "/" + methodName(m));
        if (!q && !b) continue;
        const double build_s = b ? median(b->seconds) : NAN;
        const double qps = q ? static_cast<double>(q->queries) / median(q->seconds) : NAN;
        const double per_query = q && q->timed_queries ? 1.0 / q->timed_queries : NAN;
        const double tris =
            (m == Method::kMeshsweeper || isEmbree(m)) && q ? q->triangles * per_query : NAN;
        const double nodes = m == Method::kMeshsweeper && q ? q->nodes * per_query : NAN;
        std::fprintf(out, "| %s | %zu | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n",
                     mesh.c_str(), g_triangle_counts[mesh], set, methodName(m),
                     formatCell("%.3f", build_s).c_str(),
                     formatCell("%.2f", build_s / embree_build_s).c_str(), formatCell("%.0f", qps).c_str(),
                     formatCell("%.2f", 1e6 / qps).c_str(), formatCell("%.2f", qps / embree_qps).c_str(),
                     formatCell("%.1f", tris).c_str(), formatCell("%.1f", nodes).c_str());
      }
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
      std::fprintf(stderr,
                   "bench_closest: %s not found; run scripts/fetch_data.sh or pass --data-dir\n",
                   meshPathOf(mesh).c_str());
      return 77;
    }
  }
  // One thread everywhere: Meshsweeper's build may use TBB; Embree's device has threads=1.
  tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 2;
  registerBenchmarks();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  printSummary();
  return 0;
}
