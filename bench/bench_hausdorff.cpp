// bench_hausdorff: certified Hausdorff distance (issue 4), Meshsweeper against CGAL 5.5's
// Polygon Mesh Processing, one thread, same meshes, one binary.
//
// Pairs: an original mesh A (data/meshes/NAME.off) and B = its simplification by CGAL's edge
// collapse (Surface_mesh_simplification::edge_collapse, default Lindstrom-Turk policies,
// Count_stop_predicate; in CGAL 5.5 that predicate counts EDGES, so the threshold is 1.5 times
// the target face count). The simplification is made once, outside timing.
//   armadillo (52,000 triangles) vs ~8,000; bunny00 (75,408) vs ~7,500;
//   mannequin-devil (25,888) vs ~4,450.
// Tolerances: relative 1e-3, 1e-4, 1e-5 of A's bounding-box diagonal (mannequin also 4e-4, the
// paper's 0.04% case); every method gets the same absolute bound.
//
// Benchmarks hausdorff/PAIR/TOL/METHOD, one iteration = one full computation:
//   meshsweeper      meshsweeper::hausdorff(a, b, options) (Mesh overload: both hierarchy builds
//                    are inside the timing; result.build_seconds reported), threads = 1
//   cgal_symmetric   PMP::bounded_error_symmetric_Hausdorff_distance<Sequential_tag>(A, B, e)
//   cgal_bounded2    PMP::bounded_error_Hausdorff_distance<Sequential_tag> A->B and B->A
//   cgal_approx      PMP::approximate_Hausdorff_distance<Sequential_tag> A->B and B->A (random
//                    sampling, fixed seed, default density; not certified; run once per pair,
//                    reported under TOL "-")
// Timings are process CPU time (the machine is shared), medians over repetitions.
// After the report: a markdown summary table, and a check that Meshsweeper's [lower, upper]
// contains every CGAL bounded value within the tolerance (a WARNING line if not).
//
// Own flags: --quick (mannequin only, tolerance 1e-3), --pairs=a,b (armadillo,bunny,mannequin)
// --tolerances=1e-3,1e-4 (relative), --cgal-limit=S (default 20: once a CGAL bounded case took
// more than S seconds in one run on a pair, that pair's CGAL cases at 1e-5 are skipped, and a
// case that took more than S is not repeated), --data-dir=PATH. Exit code 77 when a mesh is
// missing.
#include "bench/bench_util.h"
#include "core/hausdorff.h"
#include "core/mesh.h"
#include "core/mesh_io.h"
#include "scenes/procedural.h"

// Simple_cartesian.h first: distance.h calls CGAL::midpoint (qualified), which must be declared
// before it.
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Polygon_mesh_processing/distance.h>
#include <CGAL/Polygon_mesh_processing/orient_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Polygon_mesh_processing/repair_polygon_soup.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Count_stop_predicate.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <array>
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

using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using SurfaceMesh = CGAL::Surface_mesh<Point>;
namespace PMP = CGAL::Polygon_mesh_processing;
namespace SMS = CGAL::Surface_mesh_simplification;

double processCpuSeconds() {
  timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

struct PairSpec {
  const char* name;  // short name
  const char* file;  // data/meshes/FILE.off
  size_t target_faces;
};
const PairSpec kPairs[] = {{"armadillo", "armadillo", 8000},
                           {"bunny", "bunny00", 7500},
                           {"mannequin", "mannequin-devil", 4450}};

struct Options {
  bool quick = false;
  std::vector<std::string> pairs = {"armadillo", "bunny", "mannequin"};
  std::vector<double> tolerances;  // empty: the defaults
  double cgal_limit = 20;
  std::string data_dir;
} g_options;

std::string meshPathOf(const std::string& file) {
  return g_options.data_dir.empty() ? scenes::meshPath(file) : g_options.data_dir + "/" + file + ".off";
}

void parseOwnFlags(int& argc, char** argv) {
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const size_t eq = arg.find('=');
    const std::string flag = arg.substr(0, eq);
    const std::string value = eq == std::string::npos ? "" : arg.substr(eq + 1);
    if (flag == "--quick") {
      g_options.quick = true;
    } else if (flag == "--pairs") {
      g_options.pairs = splitList(value);
    } else if (flag == "--tolerances") {
      for (const std::string& t : splitList(value)) g_options.tolerances.push_back(std::strtod(t.c_str(), nullptr));
    } else if (flag == "--cgal-limit") {
      g_options.cgal_limit = std::strtod(value.c_str(), nullptr);
    } else if (flag == "--data-dir") {
      g_options.data_dir = value;
    } else {
      argv[kept++] = argv[i];
    }
  }
  argc = kept;
  if (g_options.quick) {
    g_options.pairs = {"mannequin"};
    if (g_options.tolerances.empty()) g_options.tolerances = {1e-3};
  }
}

// ---------------------------------------------------------------------------------------------
// Fixtures

Mesh toMesh(const SurfaceMesh& sm, const std::string& name) {
  Mesh m;
  m.name = name;
  std::map<SurfaceMesh::Vertex_index, VertexIndex> index;
  for (auto v : sm.vertices()) {
    index[v] = static_cast<VertexIndex>(m.positions.size());
    const Point& p = sm.point(v);
    m.positions.emplace_back(p.x(), p.y(), p.z());
  }
  for (auto f : sm.faces()) {
    Triangle t{};
    int k = 0;
    for (auto v : CGAL::vertices_around_face(sm.halfedge(f), sm)) {
      if (k < 3) t[k] = index[v];
      ++k;
    }
    if (k == 3) m.triangles.push_back(t);
  }
  return m;
}

SurfaceMesh toSurfaceMesh(const Mesh& m) {
  std::vector<Point> points;
  points.reserve(m.positions.size());
  for (const Vec3& p : m.positions) points.emplace_back(p.x(), p.y(), p.z());
  std::vector<std::array<size_t, 3>> faces;
  faces.reserve(m.triangles.size());
  for (const Triangle& t : m.triangles) faces.push_back({size_t(t[0]), size_t(t[1]), size_t(t[2])});
  PMP::repair_polygon_soup(points, faces);
  PMP::orient_polygon_soup(points, faces);
  SurfaceMesh sm;
  PMP::polygon_soup_to_polygon_mesh(points, faces, sm);
  return sm;
}

struct Fixture {
  std::string name;
  Mesh a, b;
  SurfaceMesh sa, sb;
  double diagonal = 0;
};
std::map<std::string, std::unique_ptr<Fixture>> g_fixtures;

Fixture& fixture(const PairSpec& spec) {
  auto& slot = g_fixtures[spec.name];
  if (slot) return *slot;
  slot = std::make_unique<Fixture>();
  Fixture& f = *slot;
  f.name = spec.name;
  f.a = readMesh(meshPathOf(spec.file));
  f.diagonal = meshDiagonal(f.a);
  f.sa = toSurfaceMesh(f.a);
  SurfaceMesh simplified = f.sa;
  SMS::Count_stop_predicate<SurfaceMesh> stop(static_cast<size_t>(1.5 * static_cast<double>(spec.target_faces)));
  const auto start = std::chrono::steady_clock::now();
  const int removed = SMS::edge_collapse(simplified, stop);
  simplified.collect_garbage();
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  f.sb = simplified;
  f.b = toMesh(f.sb, std::string(spec.file) + "-simplified");
  std::fprintf(stderr,
               "[%s] A = %s: %zu triangles (CGAL mesh %zu faces), diagonal %.6g; B = edge collapse: %d "
               "edges removed, %zu triangles, %zu vertices (%.2f s, not timed)\n",
               spec.name, spec.file, f.a.triangles.size(), size_t(f.sa.number_of_faces()), f.diagonal,
               removed, f.b.triangles.size(), f.b.positions.size(), s);
  return f;
}

// ---------------------------------------------------------------------------------------------
// Results

struct Samples {
  std::vector<double> seconds;
  double value = NAN, lower = NAN, upper = NAN;  // last run
  std::vector<double> build_seconds;             // meshsweeper
  bool skipped = false;
  std::string skip_reason;
};
std::map<std::string, Samples> g_samples;  // key PAIR/TOL/METHOD
std::map<std::string, double> g_cgal_max_seconds;  // per pair: longest CGAL bounded run

std::string tolName(double t) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%g", t);
  return buffer;
}

double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

enum class Method { kMeshsweeper, kCgalSymmetric, kCgalBounded2, kCgalApprox };
const char* methodName(Method m) {
  switch (m) {
    case Method::kMeshsweeper: return "meshsweeper";
    case Method::kCgalSymmetric: return "cgal_symmetric";
    case Method::kCgalBounded2: return "cgal_bounded2";
    case Method::kCgalApprox: return "cgal_approx";
  }
  return "?";
}

void runCase(benchmark::State& state, const PairSpec* spec, double rel_tol, Method method) {
  Fixture& f = fixture(*spec);
  const std::string key = std::string(spec->name) + "/" + (method == Method::kCgalApprox ? "-" : tolName(rel_tol)) +
                          "/" + methodName(method);
  Samples& samples = g_samples[key];
  const bool cgal_bounded = method == Method::kCgalSymmetric || method == Method::kCgalBounded2;
  if (cgal_bounded && rel_tol <= 1e-5 * 1.0001 && g_cgal_max_seconds[spec->name] > g_options.cgal_limit) {
    samples.skipped = true;
    samples.skip_reason = "CGAL took > " + tolName(g_options.cgal_limit) + " s per run at a looser tolerance";
    state.SkipWithError(samples.skip_reason.c_str());
    for (auto _ : state) {}
    return;
  }
  if (cgal_bounded && !samples.seconds.empty() && samples.seconds.back() > g_options.cgal_limit) {
    state.SkipWithError("not repeated: previous run > cgal-limit");
    for (auto _ : state) {}
    return;
  }
  const double abs_tol = rel_tol * f.diagonal;
  for (auto _ : state) {
    const double t0 = processCpuSeconds();
    switch (method) {
      case Method::kMeshsweeper: {
        HausdorffOptions options;
        options.relative_tolerance = rel_tol;
        options.threads = 1;
        const HausdorffResult r = hausdorff(f.a, f.b, options);
        samples.lower = r.lower;
        samples.upper = r.upper;
        samples.value = 0.5 * (r.lower + r.upper);
        samples.build_seconds.push_back(r.build_seconds);
        state.counters["build_s"] = r.build_seconds;
        state.counters["samples"] = static_cast<double>(r.counters.samples);
        state.counters["refined"] = static_cast<double>(r.counters.triangles_refined);
        break;
      }
      case Method::kCgalSymmetric:
        samples.value = PMP::bounded_error_symmetric_Hausdorff_distance<CGAL::Sequential_tag>(f.sa, f.sb, abs_tol);
        break;
      case Method::kCgalBounded2: {
        const double ab = PMP::bounded_error_Hausdorff_distance<CGAL::Sequential_tag>(f.sa, f.sb, abs_tol);
        const double ba = PMP::bounded_error_Hausdorff_distance<CGAL::Sequential_tag>(f.sb, f.sa, abs_tol);
        samples.value = std::max(ab, ba);
        break;
      }
      case Method::kCgalApprox: {
        const double ab = PMP::approximate_Hausdorff_distance<CGAL::Sequential_tag>(
            f.sa, f.sb, CGAL::parameters::random_seed(42), CGAL::parameters::all_default());
        const double ba = PMP::approximate_Hausdorff_distance<CGAL::Sequential_tag>(
            f.sb, f.sa, CGAL::parameters::random_seed(43), CGAL::parameters::all_default());
        samples.value = std::max(ab, ba);
        break;
      }
    }
    const double s = processCpuSeconds() - t0;
    state.SetIterationTime(s);
    samples.seconds.push_back(s);
    if (cgal_bounded) g_cgal_max_seconds[spec->name] = std::max(g_cgal_max_seconds[spec->name], s);
  }
  state.counters["H"] = samples.value;
  state.counters["H_rel"] = samples.value / f.diagonal;
}

std::vector<std::pair<const PairSpec*, double>> g_cases;  // (pair, relative tolerance), run order

void registerBenchmarks() {
  for (const PairSpec& spec : kPairs) {
    if (std::find(g_options.pairs.begin(), g_options.pairs.end(), spec.name) == g_options.pairs.end()) continue;
    std::vector<double> tols = g_options.tolerances;
    if (tols.empty()) {
      tols = {1e-3, 1e-4};
      if (std::string(spec.name) == "mannequin") tols.push_back(4e-4);
      tols.push_back(1e-5);
    }
    for (double t : tols) {
      g_cases.push_back({&spec, t});
      for (Method m : {Method::kMeshsweeper, Method::kCgalSymmetric, Method::kCgalBounded2}) {
        const std::string name = std::string("hausdorff/") + spec.name + "/" + tolName(t) + "/" + methodName(m);
        benchmark::RegisterBenchmark(name.c_str(), runCase, &spec, t, m)
            ->Iterations(1)
            ->UseManualTime()
            ->Unit(benchmark::kSecond);
      }
    }
    const std::string name = std::string("hausdorff/") + spec.name + "/-/cgal_approx";
    benchmark::RegisterBenchmark(name.c_str(), runCase, &spec, 0.0, Method::kCgalApprox)
        ->Iterations(1)
        ->UseManualTime()
        ->Unit(benchmark::kSecond);
  }
}

int printSummary() {
  int warnings = 0;
  std::printf("\nSummary: medians of process CPU time per full computation; one thread; ratio = CGAL "
              "time / Meshsweeper time; H relative to A's bounding-box diagonal\n\n");
  std::printf("| pair | A tris | B tris | tolerance | method | seconds | build s | H lower | H upper | H / diag | ratio |\n");
  std::printf("|---|---:|---:|---|---|---:|---:|---:|---:|---:|---:|\n");
  std::string last_pair;
  for (const auto& [spec, t] : g_cases) {
    const Fixture& f = *g_fixtures.at(spec->name);
    const std::string base = std::string(spec->name) + "/" + tolName(t) + "/";
    const Samples* ms = g_samples.count(base + "meshsweeper") ? &g_samples.at(base + "meshsweeper") : nullptr;
    const double ms_s = ms ? median(ms->seconds) : NAN;
    const double abs_tol = t * f.diagonal;
    for (Method m : {Method::kMeshsweeper, Method::kCgalSymmetric, Method::kCgalBounded2}) {
      auto it = g_samples.find(base + methodName(m));
      if (it == g_samples.end()) continue;
      const Samples& s = it->second;
      const double sec = median(s.seconds);
      const bool is_ms = m == Method::kMeshsweeper;
      std::printf("| %s | %zu | %zu | %s | %s | %s | %s | %s | %s | %s | %s |\n", spec->name, f.a.triangles.size(),
                  f.b.triangles.size(), tolName(t).c_str(), methodName(m),
                  s.skipped ? "skipped" : formatCell("%.3f", sec).c_str(),
                  is_ms ? formatCell("%.3f", median(s.build_seconds)).c_str() : "-",
                  formatCell("%.6g", is_ms ? s.lower : s.value).c_str(), formatCell("%.6g", is_ms ? s.upper : NAN).c_str(),
                  formatCell("%.4e", s.value / f.diagonal).c_str(), is_ms ? "1.00" : formatCell("%.2f", sec / ms_s).c_str());
      if (!is_ms && ms && std::isfinite(s.value) &&
          !(s.value >= ms->lower - abs_tol && s.value <= ms->upper + abs_tol)) {
        ++warnings;
        std::fprintf(stderr, "WARNING: %s: CGAL %s = %.9g outside Meshsweeper [%.9g, %.9g] +- tolerance %.3g\n",
                     base.c_str(), methodName(m), s.value, ms->lower, ms->upper, abs_tol);
      }
    }
    if (last_pair != spec->name) last_pair = spec->name;
  }
  for (const PairSpec& spec : kPairs) {
    auto it = g_samples.find(std::string(spec.name) + "/-/cgal_approx");
    if (it == g_samples.end()) continue;
    const Fixture& f = *g_fixtures.at(spec.name);
    std::printf("| %s | %zu | %zu | - | cgal_approx | %s | - | %s | - | %s | - |\n", spec.name, f.a.triangles.size(),
                f.b.triangles.size(), formatCell("%.3f", median(it->second.seconds)).c_str(),
                formatCell("%.6g", it->second.value).c_str(), formatCell("%.4e", it->second.value / f.diagonal).c_str());
  }
  std::printf("\n%s\n", warnings ? "Some CGAL values fall outside Meshsweeper's bounds (see WARNING lines)."
                                  : "Every CGAL bounded value lies within Meshsweeper's [lower, upper] +- tolerance.");
  std::fflush(stdout);
  return warnings;
}

}  // namespace
}  // namespace meshsweeper::bench

int main(int argc, char** argv) {
  using namespace meshsweeper::bench;
  parseOwnFlags(argc, argv);
  for (const PairSpec& spec : kPairs) {
    if (std::find(g_options.pairs.begin(), g_options.pairs.end(), spec.name) == g_options.pairs.end()) continue;
    if (!std::ifstream(meshPathOf(spec.file)).good()) {
      std::fprintf(stderr, "bench_hausdorff: %s not found; run scripts/fetch_data.sh or pass --data-dir\n",
                   meshPathOf(spec.file).c_str());
      return 77;
    }
  }
  tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 2;
  registerBenchmarks();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  printSummary();
  return 0;
}
