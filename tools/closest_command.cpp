// meshsweep closest: closest points of a mesh to a list of query points, as CSV.
#include "collision/body.h"
#include "core/mesh_io.h"
#include "core/sweep_query.h"
#include "core/threads.h"
#include "tools/commands.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

namespace meshsweeper::cli {

const char kClosestHelp[] =
    "Usage: meshsweep closest MESH POINTS [--out FILE] [--tolerance T | --k N | --within D]\n"
    "                         [--path] [--signed] [--threads N]\n"
    "\n"
    "Reads MESH (OFF, OBJ, PLY or STL) and POINTS (text, one 'x y z' per line, '#' comments;\n"
    "'-' reads standard input), builds the hierarchy once and answers the points in parallel\n"
    "(one query stream per thread; the rows do not depend on the threads).\n"
    "\n"
    "Modes (at most one):\n"
    "  (none)          exact closest point                               mode \"closest\"\n"
    "  --tolerance T   anytime query: stop once upper - lower <= T (absolute, mesh units);\n"
    "                  distance = upper, the point lies on the mesh at that distance\n"
    "                                                                    mode \"anytime\"\n"
    "  --k N           the N closest triangles (N >= 1), one row each    mode \"k\"\n"
    "  --within D      every triangle at distance <= D, one row each     mode \"within\"\n"
    "  --out FILE      write the CSV to FILE instead of standard output\n"
    "  --threads N     worker threads, 0 = all (default)\n"
    "  --path          the points are consecutive samples of one moving point: answer them\n"
    "                  with one coherent stream (closest: the certified candidate set;\n"
    "                  --tolerance and --k: the paper's dynamic front). Same answers, less\n"
    "                  work per point; the summary adds the coherence counters. Not with\n"
    "                  --within; one thread (--threads 1, if given)\n"
    "  --signed        add the columns sign,signed_distance: -1 inside, 1 outside a closed\n"
    "                  mesh (from the angle-weighted pseudonormal at the closest point's\n"
    "                  vertex, edge or face, or the winding number where faces of both sides\n"
    "                  tie within rounding; a point on the surface, up to 16 eps times the\n"
    "                  coordinates involved, is outside). Every row of a point has its sign.\n"
    "                  The mesh must be closed (each edge in two faces, oriented alike,\n"
    "                  manifold vertices, no degenerate face, no self-intersection,\n"
    "                  enclosing a volume), else exit status 1 with the reason. Not with\n"
    "                  --tolerance\n"
    "\n"
    "CSV columns (header line first):\n"
    "  point,rank,distance,lower,upper,triangle,x,y,z,b0,b1,b2\n"
    "  point     0-based index of the query point in POINTS\n"
    "  rank      0 for closest/anytime; 0,1,2,... by increasing distance for --k/--within\n"
    "  distance  distance to the mesh (the upper bound for --tolerance)\n"
    "  lower, upper  certified bounds; both equal distance when exact\n"
    "  triangle  0-based triangle index: faces in file order, a polygon of k corners gives\n"
    "            k - 2 triangles: its fan (c0,c1,c2), (c0,c2,c3), ... where c0 sees the whole\n"
    "            polygon, else it is cut into ears (README \"Mesh input\")\n"
    "  x,y,z     the closest point; b0,b1,b2 its barycentric coordinates in that triangle\n"
    "  sign, signed_distance   with --signed: -1 or 1, and sign x distance\n"
    "Numbers are printed with 17 significant digits. A point with no triangle within D\n"
    "prints no row.\n"
    "\n"
    "A one-line JSON summary goes to standard error:\n"
    "  {\"mesh\": ..., \"vertices\": ..., \"triangles\": ..., \"points\": ..., \"rows\": ...,\n"
    "   \"build_seconds\": ..., \"query_seconds\": ..., \"mode\": ..., \"path\": ...,\n"
    "   \"threads\": ...}  (query_seconds: wall-clock time of the queries)\n"
    "  with --path also \"certified\", \"rebuilds\", \"searched\", \"front_resets\" (coherence counters)\n"
    "  with --signed also \"inside\" (points inside, of those with rows); build_seconds then\n"
    "  includes the closedness check and pseudonormals\n"
    "\n"
    "Exit status: 0 success, 1 unreadable/invalid input file or unwritable output,\n"
    "2 bad command line.\n";

namespace {

enum class Mode { kClosest, kAnytime, kK, kWithin };

const char* modeName(Mode mode) {
  switch (mode) {
    case Mode::kClosest: return "closest";
    case Mode::kAnytime: return "anytime";
    case Mode::kK: return "k";
    case Mode::kWithin: return "within";
  }
  return "?";
}

// One CSV row, kept in memory so that query_seconds times the queries only.
struct Row {
  uint32_t point;  // [query point]
  uint32_t rank;
  double distance, lower, upper;
  TriangleIndex triangle;  // [triangle] file order after triangulation (mesh_io.h)
  Vec3 position;
  Vec3 barycentric;
  Feature feature;
  int side = 0;  // --signed: the point's side (restSide), -1 inside or 1 outside
};

Row rowFromHit(uint32_t point, uint32_t rank, const TriangleHit& hit) {
  return {point, rank, hit.distance, hit.distance, hit.distance, hit.triangle, hit.point,
          hit.barycentric, hit.feature};
}

Row rowFromClosest(uint32_t point, const ClosestPoint& c) {
  return {point, 0, c.distance, c.lower, c.upper, c.triangle, c.point, c.barycentric, c.feature};
}

// The exact answer a row holds (its point's closest, for its first row).
ClosestPoint closestAnswer(const Row& r) {
  ClosestPoint c;
  c.distance = c.lower = c.upper = r.distance;
  c.point = r.position;
  c.triangle = r.triangle;
  c.barycentric = r.barycentric;
  c.feature = r.feature;
  return c;
}

}  // namespace

int runClosest(int argc, char** argv, int first) {
  const Args args("closest", argc, argv, first,
                  {{"--out", true}, {"--tolerance", true}, {"--k", true}, {"--within", true},
                   {"--path", false}, {"--signed", false}, {"--threads", true}});
  args.expectPositional({"MESH", "POINTS"});
  const std::string& mesh_path = args.positional()[0];
  const std::string& points_path = args.positional()[1];

  Mode mode = Mode::kClosest;
  int modes = 0;
  double tolerance = 0, within_distance = 0;
  uint64_t k = 0;
  if (args.has("--tolerance")) {
    mode = Mode::kAnytime;
    tolerance = args.nonNegativeDouble("--tolerance");
    ++modes;
  }
  if (args.has("--k")) {
    mode = Mode::kK;
    k = args.integer("--k", 1, std::numeric_limits<uint32_t>::max());
    ++modes;
  }
  if (args.has("--within")) {
    mode = Mode::kWithin;
    within_distance = args.nonNegativeDouble("--within");
    ++modes;
  }
  if (modes > 1)
    throw UsageError("closest: --tolerance, --k and --within cannot be combined");
  const bool path = args.has("--path");
  // This tool answers --within with plain within() only: --path would be silently ignored.
  if (path && mode == Mode::kWithin)
    throw UsageError("closest: --path cannot be combined with --within");
  // A path is one moving point: one stream answers its samples in order.
  const unsigned threads = args.has("--threads") ? static_cast<unsigned>(args.integer("--threads", 0, 4096)) : 0;
  if (path && args.has("--threads") && threads != 1)
    throw UsageError("closest: --path answers its points in order with one stream: --threads must be 1 with it");
  // An anytime answer's point is not the closest one, whose feature decides the side.
  const bool signed_rows = args.has("--signed");
  if (signed_rows && mode == Mode::kAnytime)
    throw UsageError("closest: --signed needs exact closest points: it cannot be combined with --tolerance");

  const Mesh mesh = readMeshArgument("closest", mesh_path);
  const std::vector<Vec3> points = readPoints(points_path);
  if (points.size() >= std::numeric_limits<uint32_t>::max())
    throw UsageError("closest: too many points (" + std::to_string(points.size()) + ")");
  Output out(args.has("--out") ? args.value("--out") : std::string("-"));

  // The build runs on the queries' threads too.
  tbb::task_arena arena(arenaConcurrency(path ? 1 : threads));
  const Timer build_timer;
  std::shared_ptr<const Hierarchy> hierarchy;
  std::shared_ptr<const BodyShape> shape;
  arena.execute([&] {
    hierarchy = Hierarchy::build(mesh);
    if (signed_rows) shape = BodyShape::build(hierarchy);
  });
  if (shape && !shape->closed())
    throw MeshError(mesh_path + ": distances cannot be signed: the mesh is not closed (" + shape->openReason() + ")");
  const double build_seconds = build_timer.seconds();

  // The hierarchy never has more triangles than the mesh: asking for more changes nothing.
  const size_t k_effective = static_cast<size_t>(std::min<uint64_t>(k, mesh.triangles.size()));
  // Points are answered a chunk at a time, in blocks run in parallel (one query stream per
  // thread; every answer is exact and ties go to the lowest triangle, so the rows do not depend
  // on the threads), and the chunk's rows written in point order. Memory stays bounded whatever
  // the rows per point (--within or --k can give many: 200 points within 1e9 of the armadillo
  // are 10 million rows, which a review ran out of memory holding):
  //  - a chunk is sized to hold about kBatchRows rows at the rows per point seen so far;
  //  - once a chunk holds kRowCap rows, its blocks stop before their next point, and the rows
  //    are written up to the first point not answered, where the next chunk starts (rows of
  //    later points already answered are dropped and answered again).
  // query_seconds counts the queries only.
  constexpr size_t kBatchRows = 1 << 16;
  constexpr size_t kRowCap = 2 * kBatchRows;
  constexpr size_t kMaxBlock = 64;      // points
  constexpr size_t kMaxChunk = 16384;  // points
  size_t total_rows = 0, inside = 0;
  double query_seconds = 0;
  out.write(signed_rows ? "point,rank,distance,lower,upper,triangle,x,y,z,b0,b1,b2,sign,signed_distance\n"
                        : "point,rank,distance,lower,upper,triangle,x,y,z,b0,b1,b2\n");
  // A block's rows as CSV text (made in parallel too: printing 17 digits costs about as much as
  // a query).
  const auto formatRows = [&](const Row* rows, size_t count, std::string& text) {
    text.clear();
    char line[512];
    for (size_t k = 0; k < count; ++k) {
      const Row& r = rows[k];
      int n = std::snprintf(line, sizeof line, "%u,%u,%.17g,%.17g,%.17g,%u,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g",
                            r.point, r.rank, r.distance, r.lower, r.upper, r.triangle, r.position.x(),
                            r.position.y(), r.position.z(), r.barycentric.x(), r.barycentric.y(),
                            r.barycentric.z());
      if (signed_rows)  // a row takes at most 15 numbers of 24 characters: it fits
        n += std::snprintf(line + n, sizeof line - static_cast<size_t>(n), ",%d,%.17g", r.side, r.side * r.distance);
      text.append(line, std::min(static_cast<size_t>(n), sizeof line - 1));
      text += '\n';
    }
  };
  // The rows of the chunk so far (kRowCap stops it).
  std::atomic<size_t> chunk_rows{0};
  // Answers points [first, last) with `stream`, appending their rows to `rows`, until the chunk
  // holds kRowCap rows (the chunk's first point is answered anyway, so every chunk moves on);
  // returns how many points it answered.
  // `sign_stream` checks the sides (checkedRestSide: it must not disturb a path's stream).
  const auto answer = [&](QueryStream& stream, QueryStream& sign_stream, std::vector<TriangleHit>& hits,
                          uint32_t first, uint32_t last, bool chunk_start, std::vector<Row>& rows) {
    uint32_t i = first;
    for (; i < last; ++i) {
      if (!(chunk_start && i == first) && chunk_rows.load(std::memory_order_relaxed) >= kRowCap) break;
      const Vec3& p = points[i];
      const size_t point_rows = rows.size();  // the point's rows: rows[point_rows, end)
      switch (mode) {
        case Mode::kClosest:
          rows.push_back(rowFromClosest(i, path ? stream.closestCoherent(p) : stream.closest(p)));
          break;
        case Mode::kAnytime:
          rows.push_back(rowFromClosest(i, path ? stream.closestWithinCoherent(p, tolerance)
                                                : stream.closestWithin(p, tolerance)));
          break;
        case Mode::kK:
        case Mode::kWithin:
          hits.clear();
          if (mode == Mode::kK && path)
            stream.kClosestCoherent(p, k_effective, hits);
          else if (mode == Mode::kK)
            stream.kClosest(p, k_effective, hits);
          else
            stream.within(p, within_distance, hits);
          for (uint32_t rank = 0; rank < hits.size(); ++rank)
            rows.push_back(rowFromHit(i, rank, hits[rank]));
          break;
      }
      // The point's first row is its closest point (within and k rows come by distance).
      if (signed_rows && rows.size() > point_rows && rows[point_rows].triangle != kInvalidIndex) {
        const Row& closest = rows[point_rows];
        const int side = checkedRestSide(*shape, sign_stream, p, closestAnswer(closest), hits);
        for (size_t r = point_rows; r < rows.size(); ++r) rows[r].side = side;
      }
      chunk_rows.fetch_add(rows.size() - point_rows, std::memory_order_relaxed);
    }
    return i - first;
  };

  // --path: one stream follows the points in order, on this thread.
  QueryStream path_stream(hierarchy), path_sign_stream(hierarchy);
  std::vector<TriangleHit> path_hits;
  const int thread_count = path ? 1 : arena.max_concurrency();
  struct Worker {
    QueryStream stream, sign_stream;
    std::vector<TriangleHit> hits;
  };
  tbb::enumerable_thread_specific<Worker> workers(
      [&] { return Worker{QueryStream(hierarchy), QueryStream(hierarchy), {}}; });
  std::vector<std::vector<Row>> block_rows;
  std::vector<uint32_t> block_answered;  // [block] points answered
  // The rows written are formatted in pieces of at most kPieceRows, in parallel.
  constexpr size_t kPieceRows = 4096;
  struct Piece {
    size_t block, begin, end;  // block_rows[block][begin, end)
    std::string text;
    size_t inside = 0;  // points inside (--signed): their first row is in the piece
  };
  std::vector<Piece> pieces;
  // Rows per point are known but in within mode.
  size_t chunk = mode == Mode::kWithin ? 4 * kMaxBlock : std::max<size_t>(1, kBatchRows / std::max<size_t>(1, k_effective));
  if (mode == Mode::kClosest || mode == Mode::kAnytime) chunk = kMaxChunk;
  for (size_t first = 0; first < points.size();) {
    chunk = std::min(chunk, kMaxChunk);
    const size_t last = std::min(points.size(), first + chunk);
    const size_t block_points = std::clamp<size_t>(chunk / 16, 1, kMaxBlock);
    const size_t blocks = (last - first + block_points - 1) / block_points;
    block_rows.assign(blocks, {});
    block_answered.assign(blocks, 0);
    chunk_rows = 0;
    const Timer query_timer;
    const auto block = [&](size_t b, QueryStream& stream, QueryStream& sign_stream, std::vector<TriangleHit>& hits) {
      const size_t from = first + b * block_points;
      block_answered[b] = answer(stream, sign_stream, hits, static_cast<uint32_t>(from),
                                 static_cast<uint32_t>(std::min(last, from + block_points)), b == 0, block_rows[b]);
    };
    if (path) {
      for (size_t b = 0; b < blocks; ++b) block(b, path_stream, path_sign_stream, path_hits);
    } else {
      arena.execute([&] {
        tbb::parallel_for(size_t(0), blocks, [&](size_t b) {
          Worker& w = workers.local();
          block(b, w.stream, w.sign_stream, w.hits);
        });
      });
    }
    query_seconds += query_timer.seconds();
    // What is written: whole blocks up to the first that stopped, and that one's rows.
    size_t written_blocks = 0, written_points = 0, written_rows = 0;
    for (size_t b = 0; b < blocks; ++b) {
      written_rows += block_rows[b].size();
      written_points += block_answered[b];
      ++written_blocks;
      if (first + b * block_points + block_answered[b] < std::min(last, first + (b + 1) * block_points)) break;
    }
    pieces.clear();
    for (size_t b = 0; b < written_blocks; ++b)
      for (size_t begin = 0; begin < block_rows[b].size(); begin += kPieceRows)
        pieces.push_back({b, begin, std::min(block_rows[b].size(), begin + kPieceRows), {}, 0});
    const auto format = [&](size_t k) {
      Piece& piece = pieces[k];
      const Row* rows = block_rows[piece.block].data();
      formatRows(rows + piece.begin, piece.end - piece.begin, piece.text);
      for (size_t r = piece.begin; r < piece.end; ++r) piece.inside += rows[r].rank == 0 && rows[r].side < 0;
    };
    if (path) {
      for (size_t k = 0; k < pieces.size(); ++k) format(k);
    } else {
      arena.execute([&] { tbb::parallel_for(size_t(0), pieces.size(), format); });
    }
    for (Piece& piece : pieces) {
      out.write(piece.text);
      inside += piece.inside;
      std::string().swap(piece.text);
    }
    total_rows += written_rows;
    chunk = written_rows == 0 ? kMaxChunk
                              : std::clamp<size_t>(written_points * kBatchRows / written_rows, 1, kMaxChunk);
    first += written_points;
  }
  out.close();

  std::string coherence;
  if (signed_rows) coherence = ", \"inside\": " + std::to_string(inside);
  if (path) {
    const CoherenceCounters& c = path_stream.coherence();
    coherence += ", \"certified\": " + std::to_string(c.certified) + ", \"rebuilds\": " +
                std::to_string(c.rebuilds) + ", \"searched\": " + std::to_string(c.searched) +
                ", \"front_resets\": " + std::to_string(c.front_resets);
  }
  std::fprintf(stderr,
               "{\"mesh\": %s, \"vertices\": %zu, \"triangles\": %zu, \"points\": %zu, "
               "\"rows\": %zu, \"build_seconds\": %.6f, \"query_seconds\": %.6f, "
               "\"mode\": \"%s\", \"path\": %s, \"threads\": %d%s}\n",
               jsonString(mesh_path).c_str(), mesh.positions.size(), mesh.triangles.size(),
               points.size(), total_rows, build_seconds, query_seconds, modeName(mode),
               path ? "true" : "false", thread_count, coherence.c_str());
  return kExitOk;
}

}  // namespace meshsweeper::cli
