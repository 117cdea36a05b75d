#pragma once
// Shared situations for tests, benchmarks and demos: procedural meshes with known properties,
// seeded point sets, and the paths of the real meshes in data/meshes.
//
// Everything here is deterministic: the same arguments give the same mesh or points on every
// platform (std::mt19937_64 is specified bit-exactly by the standard, and the mapping to doubles
// is ours, not std::uniform_real_distribution, which differs between standard libraries).
// Invalid arguments throw std::invalid_argument.
#include "core/mesh.h"

#include <cstddef>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace meshsweeper::scenes {

// Seeded random numbers with the same sequence on every platform.
class Random {
 public:
  explicit Random(uint64_t seed) : engine_(seed) {}
  // A double in [0, 1), from the top 53 bits of one 64-bit draw.
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  // A double in [lo, hi).
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  // An index in [0, n). Precondition: n > 0.
  size_t index(size_t n);
  // A point in the box [lower, upper).
  Vec3 inBox(const Vec3& lower, const Vec3& upper);

 private:
  std::mt19937_64 engine_;
};

// ---- Meshes ---------------------------------------------------------------------------------

// Geodesic sphere: an icosahedron whose triangles are split in four `subdivisions` times, every
// vertex projected onto the sphere. Returns a closed, manifold, outward-oriented mesh with
// 10 * 4^s + 2 vertices and 20 * 4^s triangles.
// Preconditions: 0 <= subdivisions <= 10; radius > 0.
Mesh icosphere(int subdivisions, double radius = 1, const Vec3& center = Vec3::Zero());

// Latitude-longitude sphere about the origin: `rings` bands from pole to pole, `segments` around.
// Returns a closed, outward-oriented mesh with 2 + (rings - 1) * segments vertices (one per
// pole) and 2 * segments * (rings - 1) triangles. Fine tessellations give the hard case for
// distance queries from the centre: every triangle is at nearly the same distance.
// Preconditions: rings >= 2; segments >= 3; radius > 0.
Mesh uvSphere(int rings, int segments, double radius = 1);

// Torus about the z axis: tube of radius r around a circle of radius R, nu segments around the
// axis and nv around the tube. Returns a closed, outward-oriented mesh with nu * nv vertices and
// 2 * nu * nv triangles (self-intersecting when R < r).
// Preconditions: r > 0; R >= 0; nu >= 3; nv >= 3.
Mesh torus(double R, double r, int nu, int nv);

// Square of side `size` in the plane z = 0, centred at the origin, split into n x n cells of two
// triangles. Returns an open mesh (a boundary of 4n edges) with (n + 1)^2 vertices, row-major
// (vertex i * (n + 1) + j at x = -size/2 + size * j / n, y = -size/2 + size * i / n), and
// 2 n^2 triangles facing +z. Preconditions: n >= 1; size > 0.
Mesh gridPlane(int n, double size = 1);

// `triangles` disconnected triangles in the unit box [0, 1]^3, sizes spread log-uniformly from
// about 0.001 to 0.2. Returns a mesh with 3 * triangles vertices, none shared: triangle t uses
// vertices 3t, 3t + 1, 3t + 2. Precondition: triangles >= 1.
Mesh randomSoup(size_t triangles, uint64_t seed);

// A small mesh of valid oddities (drawn in procedural.cpp): a proper square (triangles 0, 1),
// a repeated index (2), collinear corners (3), three coincident corners with distinct indices
// (4), one index three times (5), a triangle on a duplicate vertex (6), a sliver of height 1e-9
// (7), and an edge shared by three triangles (8, 9, 10); vertex 11 is isolated. Triangles 2-5
// have zero area.
Mesh degenerateMesh();

// All meshes in one, in order: positions appended, indices shifted. The name joins the names
// with " + ". Precondition: at most 2^32 - 2 vertices in all.
Mesh concatenate(const std::vector<Mesh>& meshes);

// ---- Point sets -----------------------------------------------------------------------------
// Preconditions for all: checkMesh(mesh) passes.

// n points uniform in the mesh's bounding box grown by `enlarge` times each side on both ends
// (0.1: 10%). A side shorter than 10% of the diagonal is grown as if it were that long, so flat
// meshes still get points off their plane. Precondition: enlarge >= 0.
std::vector<Vec3> randomPointsInBox(const Mesh& mesh, size_t n, double enlarge, uint64_t seed);

// n points near the surface: area-weighted uniform samples on the triangles, each moved along its
// face normal by a signed offset uniform in [-m, m), m = max_offset_fraction_of_diagonal times
// the bounding-box diagonal. So every point lies within m of the mesh. Zero-area triangles are
// never picked, unless all are (then they are picked uniformly and not moved).
// Precondition: max_offset_fraction_of_diagonal >= 0.
std::vector<Vec3> nearSurfacePoints(const Mesh& mesh, size_t n,
                                    double max_offset_fraction_of_diagonal, uint64_t seed);

// n points on the triangles (area-weighted, uniform on each), exact up to rounding.
std::vector<Vec3> surfacePoints(const Mesh& mesh, size_t n, uint64_t seed);

// The positions of the vertices used by triangles, by increasing index (isolated ones left out).
std::vector<Vec3> vertexPoints(const Mesh& mesh);

// n points on triangle edges: a triangle chosen uniformly by index, one of its three edges, a
// uniform position along it.
std::vector<Vec3> edgePoints(const Mesh& mesh, size_t n, uint64_t seed);

// ---- Real meshes ----------------------------------------------------------------------------

// Folder of the real meshes: the environment variable MESHSWEEPER_DATA when set and non-empty,
// else the build's MESHSWEEPER_DEFAULT_DATA_DIR (<repo>/data/meshes, filled by
// scripts/fetch_data.sh).
std::string dataDir();

// dataDir() + "/" + name + ".off", e.g. meshPath("armadillo"). Does not check that it exists.
std::string meshPath(const std::string& name);

}  // namespace meshsweeper::scenes
