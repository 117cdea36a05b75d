// meshsweep sample: reproducible query points near a mesh or in its bounding box, written in the
// format readPoints() reads (and so `meshsweep closest` does).
#include "core/mesh_io.h"
#include "tools/bound_text.h"
#include "tools/commands.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>

namespace meshsweeper::cli {

const char kSampleHelp[] =
    "Usage: meshsweep sample MESH N [--near F | --box F] [--seed S] [--out FILE]\n"
    "\n"
    "Writes N query points (one 'x y z' per line, 17 significant digits, after a '#' comment\n"
    "line naming the command) to standard output or FILE. Distances are fractions of the\n"
    "diagonal of MESH's bounding box.\n"
    "  --near F   a uniformly random point of the surface (area-weighted), moved in a\n"
    "             uniformly random direction by a uniformly random distance in [0, F*diagonal]\n"
    "  --box F    uniform in the bounding box grown by F*diagonal on every side\n"
    "             (the default, with F = 0.1)\n"
    "  --seed S   seed of the random generator, 0 to 2^64 - 1 (default 1); the same seed gives\n"
    "             the same points\n"
    "F may be at most what keeps every coordinate within +-1e150 (the range that\n"
    "'meshsweep closest' reads); a larger F is refused.\n"
    "\n"
    "Exit status: 0 success, 1 unreadable/invalid mesh or unwritable output, 2 bad command line.\n";

namespace {

constexpr uint64_t kMaxSamples = 100'000'000;

// Uniform doubles in [0, 1) from a generator whose sequence the standard fixes, so a seed gives
// the same points with every standard library.
class Random {
 public:
  explicit Random(uint64_t seed) : engine_(seed) {}
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  // A uniformly random unit vector (rejection sampling in the unit ball).
  Vec3 direction() {
    for (;;) {
      const Vec3 v(2 * uniform() - 1, 2 * uniform() - 1, 2 * uniform() - 1);
      const double n2 = v.squaredNorm();
      if (n2 > 1e-6 && n2 <= 1) return v / std::sqrt(n2);
    }
  }

 private:
  std::mt19937_64 engine_;
};

// Samples triangles proportionally to their area; uniformly when every triangle is degenerate.
class SurfaceSampler {
 public:
  explicit SurfaceSampler(const Mesh& mesh) : mesh_(mesh) {
    cumulative_area_.reserve(mesh.triangles.size());
    double total = 0;
    for (const Triangle& t : mesh.triangles) {
      const Vec3& a = mesh.positions[t[0]];
      total += 0.5 * (mesh.positions[t[1]] - a).cross(mesh.positions[t[2]] - a).norm();
      cumulative_area_.push_back(total);
    }
    uniform_ = !(total > 0) || !std::isfinite(total);
  }

  Vec3 sample(Random& random) const {
    const size_t count = mesh_.triangles.size();
    size_t index;
    if (uniform_) {
      index = std::min(count - 1, static_cast<size_t>(random.uniform() * count));
    } else {
      const double target = random.uniform() * cumulative_area_.back();
      index = std::upper_bound(cumulative_area_.begin(), cumulative_area_.end(), target) -
              cumulative_area_.begin();
      index = std::min(index, count - 1);
    }
    const Triangle& t = mesh_.triangles[index];
    const double s = std::sqrt(random.uniform());
    const double r = random.uniform();
    return (1 - s) * mesh_.positions[t[0]] + s * (1 - r) * mesh_.positions[t[1]] +
           s * r * mesh_.positions[t[2]];
  }

 private:
  const Mesh& mesh_;
  std::vector<double> cumulative_area_;  // [triangle] running sum of areas
  bool uniform_ = false;
};

}  // namespace

int runSample(int argc, char** argv, int first) {
  const Args args("sample", argc, argv, first,
                  {{"--near", true}, {"--box", true}, {"--seed", true}, {"--out", true}});
  args.expectPositional({"MESH", "N"});
  const uint64_t count = parseInteger(args.positional()[1], "sample: N", 1, kMaxSamples);
  if (args.has("--near") && args.has("--box"))
    throw UsageError("sample: --near and --box cannot be combined");
  const bool near = args.has("--near");
  const double fraction = near ? args.nonNegativeDouble("--near")
                               : args.has("--box") ? args.nonNegativeDouble("--box") : 0.1;
  const uint64_t seed =
      args.has("--seed") ? args.integer("--seed", 0, std::numeric_limits<uint64_t>::max()) : 1;

  const Mesh mesh = readMeshArgument("sample", args.positional()[0]);
  const std::string problem = checkMesh(mesh);
  if (!problem.empty()) throw MeshError(problem);

  Vec3 lower, upper;
  meshBounds(mesh, lower, upper);
  const double diagonal = (upper - lower).norm();
  // Every point lies in the bounding box grown by reach, so the points stay in the coordinate
  // range that readPoints() (and so `meshsweep closest`) accepts while that box does; the
  // margin covers the rounding of the box.
  const double largest = std::max(lower.cwiseAbs().maxCoeff(), upper.cwiseAbs().maxCoeff());
  const double largest_fraction = (kMaxCoordinate * (1 - 1e-9) - largest) / diagonal;
  if (fraction > 0 && diagonal > 0 && !(fraction <= largest_fraction)) {
    const char* option = near ? "--near" : "--box";
    char limit[32];
    std::snprintf(limit, sizeof limit, "%g", kMaxCoordinate);
    throw UsageError("sample: " + std::string(option) + " must be at most " +
                     outwardBound(std::max(largest_fraction, 0.0), 6, false) + " for " +
                     args.positional()[0] + " (every coordinate must stay within +-" + limit +
                     "; got " + args.value(option) + ")");
  }
  const double reach = diagonal > 0 ? fraction * diagonal : 0;
  Output out(args.has("--out") ? args.value("--out") : std::string("-"));
  Random random(seed);

  std::string mesh_name = args.positional()[0];
  std::replace_if(mesh_name.begin(), mesh_name.end(), [](char c) { return c == '\n' || c == '\r'; },
                  ' ');
  out.write("# meshsweep sample " + mesh_name);
  const std::string fraction_text = near ? args.value("--near")
                                   : args.has("--box") ? args.value("--box") : "0.1";
  out.write(" " + std::to_string(count) + (near ? " --near " : " --box ") + fraction_text +
            " --seed " + std::to_string(seed) + "\n");
  // Rounding may carry a point an ulp past the grown box: it is kept inside, in range.
  const Vec3 grown_lower = lower.array() - reach, grown_upper = upper.array() + reach;
  if (near) {
    const SurfaceSampler sampler(mesh);
    for (uint64_t i = 0; i < count; ++i) {
      const Vec3 on_surface = sampler.sample(random);
      const Vec3 p = (on_surface + (reach * random.uniform()) * random.direction())
                         .cwiseMax(grown_lower)
                         .cwiseMin(grown_upper);
      out.printf("%.17g %.17g %.17g\n", p.x(), p.y(), p.z());
    }
  } else {
    const Vec3 extent = (upper - lower).array() + 2 * reach;
    for (uint64_t i = 0; i < count; ++i) {
      const Vec3 u(random.uniform(), random.uniform(), random.uniform());
      const Vec3 p =
          (grown_lower + extent.cwiseProduct(u)).cwiseMax(grown_lower).cwiseMin(grown_upper);
      out.printf("%.17g %.17g %.17g\n", p.x(), p.y(), p.z());
    }
  }
  out.close();
  return kExitOk;
}

}  // namespace meshsweeper::cli
