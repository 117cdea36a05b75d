// meshsweep hausdorff: certified Hausdorff distance between two meshes (core/hausdorff.h), with
// a Metro-like summary, optional JSON and a per-vertex colour map of A.
#include "core/hausdorff.h"
#include "core/mesh_io.h"
#include "tools/bound_text.h"
#include "tools/commands.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <unistd.h>

namespace meshsweeper::cli {

const char kHausdorffHelp[] =
    "Usage: meshsweep hausdorff A B [--tolerance T | --relative R] [--json FILE]\n"
    "                           [--colors FILE.ply] [--threads N] [--both]\n"
    "                           [--max-seconds S] [--max-memory SIZE]\n"
    "\n"
    "Certified Hausdorff distance between meshes A and B (OFF, OBJ, PLY or STL), over every\n"
    "point of both surfaces, not only the vertices:\n"
    "  h(A,B) = max over points a of A of the distance from a to B   (A -> B)\n"
    "  H(A,B) = max(h(A,B), h(B,A))\n"
    "Each is reported as [lower, upper]: lower is the exact distance of a point of A (printed,\n"
    "with its closest point on B), upper is proven for every point; the computation stops once\n"
    "upper - lower <= the tolerance for H. Mean and RMS are area-weighted estimates (not\n"
    "certified). Percentages are of A's bounding-box diagonal.\n"
    "\n"
    "Options:\n"
    "  --tolerance T    absolute tolerance (mesh units, > 0)\n"
    "  --relative R     tolerance as a fraction of A's bounding-box diagonal (> 0);\n"
    "                   the default is --relative 1e-4\n"
    "  --both           refine both directions to the tolerance (by default the direction that\n"
    "                   cannot change H stops as soon as that is proven, so its interval may be\n"
    "                   wider)\n"
    "  --threads N      worker threads, 0 = all (default); results do not depend on N\n"
    "  --max-seconds S  stop refining after about S seconds (> 0) with the certified interval\n"
    "                   reached so far (converged false, timed_out true); where it stops then\n"
    "                   depends on the machine\n"
    "  --max-memory SIZE  stop refining before its tables would pass SIZE bytes (a whole\n"
    "                   number, or with K, M, G or T: powers of 1024) with the certified interval\n"
    "                   reached so far (converged false, memory_limited true); the default is\n"
    "                   half the machine's memory, or of its cgroups' lowest limit (the JSON's\n"
    "                   max_memory_bytes; 0 there: no limit found). The meshes and their\n"
    "                   hierarchies come on top\n"
    "  --json FILE      write the result as JSON to FILE ('-' or /dev/stdout: standard output,\n"
    "                   the summary then goes to standard error)\n"
    "  --colors FILE    write A as an ASCII PLY (double coordinates) with per-vertex 'quality'\n"
    "                   (distance to B) and red/green/blue on a blue (0) to red (largest vertex\n"
    "                   distance) ramp (a vertex no triangle uses: quality -1, grey); '-' as\n"
    "                   for --json; not to the destination of --json\n"
    "\n"
    "JSON keys: a, b {path, vertices, triangles, diagonal, area}; a_to_b, b_to_a {lower, upper,\n"
    "at [x,y,z], at_triangle, closest [x,y,z], closest_triangle, mean, rms, samples, queries,\n"
    "triangles_refined, cells}; hausdorff {lower, upper}; tolerance (used); requested_tolerance;\n"
    "converged; timed_out; memory_limited; max_memory_bytes; table_bytes; threads; seconds;\n"
    "build_seconds; samples; queries; triangles_refined.\n"
    "The tolerance used is the one asked for, raised where it is below the rounding floor (4e-12\n"
    "of the largest coordinate, measured from the centre of the meshes' joint box); the summary\n"
    "then says so.\n"
    "\n"
    "Exit status: 0 success, 1 unreadable/invalid/empty mesh or unwritable output,\n"
    "2 bad command line.\n";

namespace {

double percent(double value, double diagonal) { return diagonal > 0 ? 100 * value / diagonal : 0; }

// A bound as a percentage of the diagonal, rounded outward: 5 decimals, 7 significant digits
// in exponent form once that would print more than a dozen digits; "n/a" for a zero diagonal.
// A percentage past the largest double (a tiny A far from B, an absurd tolerance), in long
// double with 7 significant digits; a bound is first moved outward by a millionth, more than
// the rounding of both the division and the printing.
std::string hugePercent(double value, double diagonal, int outward) {
  const long double p = 100.0L * value / diagonal * (1 + outward * 1e-6L);
  char text[64];
  std::snprintf(text, sizeof text, "%.7Lg", p);
  return text;
}

std::string percentBound(double value, double diagonal, bool up) {
  if (!(diagonal > 0)) return "n/a";
  const double p = percent(value, diagonal);
  if (!std::isfinite(p) && std::isfinite(value)) return hugePercent(value, diagonal, up ? 1 : -1);
  return std::fabs(p) < 1e6 ? outwardFixed(p, 5, up) : outwardBound(p, 7, up);
}

// An estimate as a percentage of the diagonal, the same way (no outward rounding).
std::string percentEstimate(double value, double diagonal) {
  if (!(diagonal > 0)) return "n/a";
  const double p = percent(value, diagonal);
  if (!std::isfinite(p) && std::isfinite(value)) return hugePercent(value, diagonal, 0);
  char text[64];
  // Below 0.001% in exponent form (5 decimals printed 1.4e-6% as 0.00000%).
  const bool fixed = std::fabs(p) < 1e6 && (p == 0 || std::fabs(p) >= 1e-3);
  std::snprintf(text, sizeof text, fixed ? "%.5f" : "%.7g", p);
  return text;
}

// "-", or a name of the file standard output writes to (/dev/stdout, /proc/self/fd/1, ...).
bool namesStandardOutput(const std::string& path) { return standardStreamOf(path) == 1; }

// Whether two output paths are one destination: both standard output, the same existing file
// under two names, or one new file reached two ways ("r.json", "./r.json", a link to it).
bool sameDestination(const std::string& a, const std::string& b) {
  if (namesStandardOutput(a) || namesStandardOutput(b)) return namesStandardOutput(a) == namesStandardOutput(b);
  if (a == b) return true;
  std::error_code error;
  if (std::filesystem::equivalent(a, b, error)) return true;
  return outputDestination(a) == outputDestination(b);
}

std::string jsonNumber(double x) {
  if (!std::isfinite(x)) return "null";
  char text[32];
  std::snprintf(text, sizeof text, "%.17g", x);
  return text;
}

// --max-memory: a whole number of bytes, or one with K, M, G or T (either case; powers of
// 1024), from 1 byte to 2^62 bytes.
uint64_t byteSize(const std::string& text) {
  static const std::string kUnits = "KMGT";
  const char last = text.empty() ? '\0' : static_cast<char>(std::toupper(static_cast<unsigned char>(text.back())));
  const size_t unit = last == '\0' ? std::string::npos : kUnits.find(last);
  const int shift = unit == std::string::npos ? 0 : 10 * static_cast<int>(unit + 1);
  const std::string digits = unit == std::string::npos ? text : text.substr(0, text.size() - 1);
  const uint64_t most = (uint64_t{1} << 62) >> shift;
  errno = 0;
  const unsigned long long value =
      digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos ? 0 : std::strtoull(digits.c_str(), nullptr, 10);
  if (value == 0 || errno == ERANGE || value > most)
    throw UsageError("hausdorff: --max-memory must be a whole number of bytes from 1 to 2^62, or one with K, M, G or T "
                     "(powers of 1024) (got '" + text + "')");
  return static_cast<uint64_t>(value) << shift;
}

// A memory limit file's value (cgroup v1 memory.limit_in_bytes, v2 memory.max), or 0 where it
// is missing or says "max" (v1's "unlimited" is a number far above the machine's memory).
uint64_t cgroupLimit(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "r");
  if (!f) return 0;
  unsigned long long value = 0;
  const bool read = std::fscanf(f, "%llu", &value) == 1;
  std::fclose(f);
  return read ? value : 0;
}

// Half the memory this process may use: the machine's, or the lowest limit of the cgroups it
// runs in where that is lower (its own memory cgroup and each above it, v1 and v2, as
// /proc/self/cgroup names them; inside a container's namespace, the root's files).
uint64_t defaultMemoryLimit() {
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  uint64_t limit = pages > 0 && page > 0 ? static_cast<uint64_t>(pages) * static_cast<uint64_t>(page) : 0;
  auto lower = [&](uint64_t value) {
    if (value > 0 && (limit == 0 || value < limit)) limit = value;
  };
  // "ID:CONTROLLERS:PATH": v2 is "0::PATH", v1's memory controller lists "memory".
  std::vector<std::string> files;
  if (std::FILE* f = std::fopen("/proc/self/cgroup", "r")) {
    char text[4096];
    while (std::fgets(text, sizeof text, f)) {
      std::string line(text);
      if (!line.empty() && line.back() == '\n') line.pop_back();
      const size_t first = line.find(':'), second = first == std::string::npos ? first : line.find(':', first + 1);
      if (second == std::string::npos) continue;
      const std::string controllers = line.substr(first + 1, second - first - 1);
      std::string path = line.substr(second + 1);
      bool v1_memory = false;
      for (size_t at = 0; at <= controllers.size();) {
        const size_t end = std::min(controllers.find(',', at), controllers.size());
        v1_memory = v1_memory || controllers.compare(at, end - at, "memory") == 0;
        at = end + 1;
      }
      const bool v2 = line.compare(0, 2, "0:") == 0 && controllers.empty();
      if (!v2 && !v1_memory) continue;
      const std::string root = v2 ? "/sys/fs/cgroup" : "/sys/fs/cgroup/memory";
      const char* name = v2 ? "/memory.max" : "/memory.limit_in_bytes";
      while (true) {  // the cgroup and each one above it
        files.push_back(root + (path == "/" ? "" : path) + name);
        const size_t slash = path.find_last_of('/');
        if (path.empty() || path == "/" || slash == std::string::npos) break;
        path = slash == 0 ? "/" : path.substr(0, slash);
      }
    }
    std::fclose(f);
  }
  files.push_back("/sys/fs/cgroup/memory.max");  // a container's own, where the paths above are
  files.push_back("/sys/fs/cgroup/memory/memory.limit_in_bytes");  // not visible
  for (const std::string& file : files) lower(cgroupLimit(file));
  return limit / 2;  // 0 (no limit) where nothing says
}

std::string jsonPoint(const Vec3& p) {
  return "[" + jsonNumber(p.x()) + ", " + jsonNumber(p.y()) + ", " + jsonNumber(p.z()) + "]";
}

std::string jsonMesh(const std::string& path, const Mesh& mesh) {
  return "{\"path\": " + jsonString(path) +
         ", \"vertices\": " + std::to_string(mesh.positions.size()) +
         ", \"triangles\": " + std::to_string(mesh.triangles.size()) +
         ", \"diagonal\": " + jsonNumber(meshDiagonal(mesh)) +
         ", \"area\": " + jsonNumber(surfaceArea(mesh)) + "}";
}

std::string jsonOneSided(const OneSidedHausdorff& h) {
  return "{\"lower\": " + jsonNumber(h.lower) + ", \"upper\": " + jsonNumber(h.upper) +
         ", \"at\": " + jsonPoint(h.at) + ", \"at_triangle\": " + std::to_string(h.at_triangle) +
         ", \"closest\": " + jsonPoint(h.closest) +
         ", \"closest_triangle\": " + std::to_string(h.closest_triangle) +
         ", \"mean\": " + jsonNumber(h.mean) + ", \"rms\": " + jsonNumber(h.rms) +
         ", \"samples\": " + std::to_string(h.counters.samples) +
         ", \"queries\": " + std::to_string(h.counters.queries) +
         ", \"triangles_refined\": " + std::to_string(h.counters.triangles_refined) +
         ", \"cells\": " + std::to_string(h.counters.cells) + "}";
}

// Blue (t = 0) -> cyan -> green -> yellow -> red (t = 1).
void ramp(double t, int rgb[3]) {
  t = std::clamp(std::isfinite(t) ? t : 0.0, 0.0, 1.0);
  const double r = std::clamp(4 * t - 2, 0.0, 1.0);
  const double g = t < 0.25 ? 4 * t : t > 0.75 ? 4 - 4 * t : 1.0;
  const double b = std::clamp(2 - 4 * t, 0.0, 1.0);
  rgb[0] = static_cast<int>(std::lround(255 * r));
  rgb[1] = static_cast<int>(std::lround(255 * g));
  rgb[2] = static_cast<int>(std::lround(255 * b));
}

void writeColors(Output& out, const Mesh& mesh, const std::vector<double>& distance) {
  double largest = 0;
  for (double d : distance)
    if (std::isfinite(d)) largest = std::max(largest, d);
  out.printf("ply\nformat ascii 1.0\ncomment meshsweep hausdorff: quality = distance to B\n");
  out.printf("element vertex %zu\n", mesh.positions.size());
  out.printf("property double x\nproperty double y\nproperty double z\nproperty double quality\n");
  out.printf("property uchar red\nproperty uchar green\nproperty uchar blue\n");
  out.printf("element face %zu\nproperty list uchar int vertex_indices\nend_header\n",
             mesh.triangles.size());
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    // A vertex no triangle uses has no distance: quality -1 and grey (it was written as 0 and
    // blue, as if it touched B; found by an audit).
    const bool used = std::isfinite(distance[v]);
    const double d = used ? distance[v] : -1.0;
    int rgb[3] = {128, 128, 128};
    if (used) ramp(largest > 0 ? d / largest : 0.0, rgb);
    const Vec3& p = mesh.positions[v];
    out.printf("%.17g %.17g %.17g %.17g %d %d %d\n", p.x(), p.y(), p.z(), d, rgb[0], rgb[1], rgb[2]);
  }
  for (const Triangle& t : mesh.triangles) out.printf("3 %u %u %u\n", t[0], t[1], t[2]);
}

// One direction of the summary.
void printDirection(std::FILE* s, const char* name, const OneSidedHausdorff& h, double diagonal,
                    double tolerance, const char* from, const char* to) {
  std::fprintf(s, "  %s  max in [%s, %s]  (%s%% .. %s%% of diagonal)\n", name,
               outwardBound(h.lower, 7, false).c_str(), outwardBound(h.upper, 7, true).c_str(),
               percentBound(h.lower, diagonal, false).c_str(), percentBound(h.upper, diagonal, true).c_str());
  std::fprintf(s, "          mean %.7g  RMS %.7g  (%s%%, %s%%; estimates)\n", h.mean, h.rms,
               percentEstimate(h.mean, diagonal).c_str(), percentEstimate(h.rms, diagonal).c_str());
  std::fprintf(s, "          lower bound at (%.9g, %.9g, %.9g) on %s triangle %u,\n", h.at.x(),
               h.at.y(), h.at.z(), from, h.at_triangle);
  std::fprintf(s, "          closest point (%.9g, %.9g, %.9g) on %s triangle %u\n", h.closest.x(),
               h.closest.y(), h.closest.z(), to, h.closest_triangle);
  if (h.upper - h.lower > tolerance)
    std::fprintf(s,
                 "          (refined only until it could not change H; use --both to tighten)\n");
  std::fprintf(s, "          %llu samples, %llu triangles refined\n",
               static_cast<unsigned long long>(h.counters.samples),
               static_cast<unsigned long long>(h.counters.triangles_refined));
}

}  // namespace

int runHausdorff(int argc, char** argv, int first) {
  const Args args("hausdorff", argc, argv, first,
                  {{"--tolerance", true},
                   {"--relative", true},
                   {"--json", true},
                   {"--colors", true},
                   {"--threads", true},
                   {"--max-seconds", true},
                   {"--max-memory", true},
                   {"--both", false}});
  args.expectPositional({"A", "B"});
  const std::string& a_path = args.positional()[0];
  const std::string& b_path = args.positional()[1];

  HausdorffOptions options;
  if (args.has("--tolerance") && args.has("--relative"))
    throw UsageError("hausdorff: --tolerance and --relative cannot be combined");
  if (args.has("--tolerance")) options.tolerance = args.positiveDouble("--tolerance");
  if (args.has("--relative")) options.relative_tolerance = args.positiveDouble("--relative");
  if (args.has("--threads"))
    options.threads = static_cast<unsigned>(args.integer("--threads", 0, 4096));
  options.tighten_both = args.has("--both");
  if (args.has("--max-seconds")) options.max_seconds = args.positiveDouble("--max-seconds");
  options.max_bytes = args.has("--max-memory") ? byteSize(args.value("--max-memory")) : defaultMemoryLimit();
  // A file written to standard output ("-", /dev/stdout, ...) takes it over: it is written
  // through the stream itself (reopening /dev/stdout would truncate what went before), and
  // the summary goes to standard error.
  const bool json_to_stdout = args.has("--json") && namesStandardOutput(args.value("--json"));
  const bool colors_to_stdout = args.has("--colors") && namesStandardOutput(args.value("--colors"));
  // Both are written at the end, the PLY last: one path for both would silently lose the JSON.
  if (args.has("--json") && args.has("--colors") &&
      sameDestination(args.value("--json"), args.value("--colors")))
    throw UsageError("hausdorff: --json and --colors cannot write to the same " +
                     (json_to_stdout ? std::string("standard output")
                                     : "file '" + args.value("--colors") + "'"));

  const Mesh a = readMeshArgument("hausdorff", a_path);
  const Mesh b = readMeshArgument("hausdorff", b_path);
  const double diagonal = meshDiagonal(a);
  if (!(diagonal > 0) && !(options.tolerance > 0))
    throw MeshError(a_path + ": all vertices coincide (zero diagonal); give --tolerance");
  if (!(options.tolerance > 0) && !std::isfinite(options.relative_tolerance * diagonal))
    throw UsageError("hausdorff: --relative " + args.value("--relative") +
                     " times A's diagonal is beyond the largest double");
  // Output files are opened (created) before the computation, so a bad path fails at once.
  std::unique_ptr<Output> json_out, colors_out;
  if (args.has("--json"))
    json_out = std::make_unique<Output>(json_to_stdout ? std::string("-") : args.value("--json"));
  if (args.has("--colors"))
    colors_out = std::make_unique<Output>(colors_to_stdout ? std::string("-") : args.value("--colors"));

  // Progress on a terminal only: the bounds as they tighten, at most ten times a second.
  double last_print = -1;
  const bool progress = isatty(fileno(stderr));
  if (progress) {
    options.progress = [&](const HausdorffProgress& p) {
      if (p.seconds - last_print < 0.1) return;
      last_print = p.seconds;
      std::fprintf(
          stderr,
          "\r\033[Khausdorff: [%.7g, %.7g]  gap %.3g (tolerance %.3g)  %llu samples  %.1f s",
          p.lower, p.upper, p.upper - p.lower, p.tolerance,
          static_cast<unsigned long long>(p.samples), p.seconds);
      std::fflush(stderr);
    };
  }
  const HausdorffResult r = hausdorff(a, b, options);
  if (progress && last_print >= 0) std::fprintf(stderr, "\r\033[K");

  std::FILE* s = json_to_stdout || colors_to_stdout ? stderr : stdout;
  std::fprintf(s, "Hausdorff distance between A and B (certified bounds)\n");
  std::fprintf(s, "  A: %s  %zu vertices, %zu triangles, area %.7g, diagonal %.7g\n",
               oneLine(a_path).c_str(), a.positions.size(), a.triangles.size(), surfaceArea(a), diagonal);
  std::fprintf(s, "  B: %s  %zu vertices, %zu triangles, area %.7g, diagonal %.7g\n",
               oneLine(b_path).c_str(), b.positions.size(), b.triangles.size(), surfaceArea(b),
               meshDiagonal(b));
  std::fprintf(s, "  tolerance %.7g (%s%% of A's diagonal)\n", r.tolerance,
               percentEstimate(r.tolerance, diagonal).c_str());
  // Raised to the rounding floor (4e-12 of the coordinates): said, not only shown (found by an
  // audit: "converged" alone read as the precision asked for).
  if (r.tolerance > r.requested_tolerance)
    std::fprintf(s, "  (raised from the %.7g asked for: the least tolerance at these coordinates)\n",
                 r.requested_tolerance);
  std::fprintf(s, "\n");
  printDirection(s, "A -> B", r.a_to_b, diagonal, r.tolerance, "A", "B");
  printDirection(s, "B -> A", r.b_to_a, diagonal, r.tolerance, "B", "A");
  std::fprintf(s, "\n  Hausdorff distance in [%s, %s]  (%s%% .. %s%% of diagonal)%s\n",
               outwardBound(r.lower, 7, false).c_str(), outwardBound(r.upper, 7, true).c_str(),
               percentBound(r.lower, diagonal, false).c_str(), percentBound(r.upper, diagonal, true).c_str(),
               r.converged ? ""
               : r.timed_out      ? "  (tolerance not reached: stopped by --max-seconds)"
               : r.memory_limited ? "  (tolerance not reached: stopped by the memory limit, --max-memory)"
                                  : "  (tolerance not reached: refinement hit rounding size)");
  std::fprintf(s, "  time %.3f s (hierarchies %.3f s), %llu samples, %llu triangles refined\n",
               r.seconds, r.build_seconds, static_cast<unsigned long long>(r.counters.samples),
               static_cast<unsigned long long>(r.counters.triangles_refined));

  if (json_out) {
    Output& out = *json_out;
    out.write(
        "{\n  \"a\": " + jsonMesh(a_path, a) + ",\n  \"b\": " + jsonMesh(b_path, b) +
        ",\n  \"a_to_b\": " + jsonOneSided(r.a_to_b) + ",\n  \"b_to_a\": " +
        jsonOneSided(r.b_to_a) + ",\n  \"hausdorff\": {\"lower\": " + jsonNumber(r.lower) +
        ", \"upper\": " + jsonNumber(r.upper) + "},\n  \"tolerance\": " + jsonNumber(r.tolerance) +
        ",\n  \"requested_tolerance\": " + jsonNumber(r.requested_tolerance) +
        ",\n  \"converged\": " + (r.converged ? "true" : "false") +
        ",\n  \"timed_out\": " + (r.timed_out ? "true" : "false") +
        ",\n  \"memory_limited\": " + (r.memory_limited ? "true" : "false") +
        ",\n  \"max_memory_bytes\": " + std::to_string(options.max_bytes) +
        ",\n  \"table_bytes\": " + std::to_string(r.table_bytes) + ",\n  \"threads\": " +
        std::to_string(r.threads) + ",\n  \"seconds\": " + jsonNumber(r.seconds) +
        ",\n  \"build_seconds\": " + jsonNumber(r.build_seconds) +
        ",\n  \"samples\": " + std::to_string(r.counters.samples) +
        ",\n  \"queries\": " + std::to_string(r.counters.queries) +
        ",\n  \"triangles_refined\": " + std::to_string(r.counters.triangles_refined) + "\n}\n");
  }
  if (colors_out) writeColors(*colors_out, a, r.a_to_b.vertex_distance);
  // Both written whole before either replaces its destination: those with a temporary file
  // first, then the PLY, then the JSON (buffered whole, it reaches a file written in place only
  // once the others are written). So a failed write leaves both as they were; only a large PLY
  // written in place (a device, a file with several names) may be left partly written.
  // The summary first: a stream that cannot take it (full, or a closed pipe) fails the run
  // before any file is replaced (found by an audit).
  if (std::fflush(s) != 0 || std::ferror(s))
    throw IoError(std::string(s == stdout ? "standard output" : "standard error") + ": write failed");
  std::vector<Output*> outputs;
  for (Output* out : {colors_out.get(), json_out.get()})
    if (out) outputs.push_back(out);
  std::stable_partition(outputs.begin(), outputs.end(), [](const Output* out) { return !out->inPlace(); });
  for (Output* out : outputs) out->flush();
  for (Output* out : outputs) out->close();
  return kExitOk;
}

}  // namespace meshsweeper::cli
