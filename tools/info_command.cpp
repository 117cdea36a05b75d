// meshsweep info: what the hierarchy of a mesh looks like and what it costs (build phases,
// tree shape, memory of the fixed tables and of one query stream).
#include "collision/body.h"
#include "core/mesh_io.h"
#include "core/sweep_query.h"
#include "scenes/procedural.h"
#include "tools/commands.h"

#include <cstdio>

namespace meshsweeper::cli {

const char kInfoHelp[] =
    "Usage: meshsweep info MESH [--queries N]\n"
    "\n"
    "Builds the hierarchy of MESH and prints, as one JSON object on standard output: the mesh\n"
    "size, the build phases in seconds (contract, tree, bounds, total), the tree (contraction\n"
    "rounds, base triangles, 8-wide nodes, leaf blocks, depth), the fixed tables' memory\n"
    "(bytes, bytes per triangle) and the changing state of one query stream after N exact\n"
    "queries near the surface (default 1000): its bytes, and the mean nodes and triangles a\n"
    "query visited. Then whether the mesh is closed, so that its distances can be signed\n"
    "(closest --signed): \"closed\": true, or false and \"open_reason\" (the first problem).\n"
    "\n"
    "Exit status: 0 success, 1 unreadable/invalid mesh, 2 bad command line.\n";

int runInfo(int argc, char** argv, int first) {
  const Args args("info", argc, argv, first, {{"--queries", true}});
  args.expectPositional({"MESH"});
  const std::string& path = args.positional()[0];
  const uint64_t queries = args.has("--queries") ? args.integer("--queries", 0, 100000000) : 1000;
  const Mesh mesh = readMeshArgument("info", path);
  const std::shared_ptr<const Hierarchy> h = Hierarchy::build(mesh);
  const HierarchyStats& s = h->stats();
  QueryStream stream(h);
  double nodes = 0, triangles = 0;
  for (const Vec3& p : scenes::nearSurfacePoints(mesh, queries, 0.01, 1)) {
    const ClosestPoint c = stream.closest(p);
    nodes += c.counters.nodes_visited;
    triangles += c.counters.triangles_tested;
  }
  const std::shared_ptr<const BodyShape> shape = BodyShape::build(h);
  const double per = queries > 0 ? 1.0 / static_cast<double>(queries) : 0.0;
  std::printf(
      "{\"mesh\": %s, \"vertices\": %zu, \"triangles\": %zu,\n"
      " \"build_seconds\": {\"contract\": %.6f, \"tree\": %.6f, \"bounds\": %.6f, \"total\": %.6f},\n"
      " \"tree\": {\"rounds\": %u, \"contractions\": %u, \"base_triangles\": %u, \"nodes\": %zu,"
      " \"leaf_blocks\": %u, \"depth\": %u},\n"
      " \"fixed_bytes\": %zu, \"fixed_bytes_per_triangle\": %.1f,\n"
      " \"stream_state_bytes\": %zu, \"queries\": %llu, \"nodes_per_query\": %.2f,"
      " \"triangles_per_query\": %.2f,\n"
      " \"closed\": %s%s}\n",
      jsonString(path).c_str(), mesh.positions.size(), mesh.triangles.size(), s.contract_seconds,
      s.tree_seconds, s.bounds_seconds, s.total_seconds, s.rounds, s.contractions, s.base_triangles,
      h->nodes().size(), h->leafCount(), s.depth, s.fixed_bytes,
      static_cast<double>(s.fixed_bytes) / static_cast<double>(mesh.triangles.size()), stream.stateBytes(),
      static_cast<unsigned long long>(queries), nodes * per, triangles * per, shape->closed() ? "true" : "false",
      shape->closed() ? "" : (", \"open_reason\": " + jsonString(shape->openReason())).c_str());
  return kExitOk;
}

}  // namespace meshsweeper::cli
