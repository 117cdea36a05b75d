#pragma once
// OpenVDB cross-check of the exact distances (DESIGN.md section 5): a narrow-band distance grid
// of a body mesh, built by OpenVDB (openvdb::tools::meshToLevelSet for closed meshes, signed;
// meshToUnsignedDistanceField otherwise), sampled trilinearly (openvdb::tools::BoxSampler) and
// compared with Meshsweeper's exact answers. An independent implementation, used in tests and
// by `meshsweep check`; never used as an answer.
//
// The grid is built in voxel units about the mesh's centre, so a mesh far from the origin or
// of any size in the supported range is resolved as well as one of size 1 at the origin.
// What agreement to expect: OpenVDB stores distances at voxel centres (computed from float
// copies of the vertices); a trilinear sample of a 1-Lipschitz field can err by up to the
// distance to the farthest of the 8 voxel centres around it (sqrt(3) voxels), but near a
// smooth surface the field is almost linear. Measured with `meshsweep check` (voxel = diagonal
// / 256, band 3 voxels, 10,000 points within 1.5 voxels of the surface): armadillo max 0.46,
// mean 0.042 voxel; bunny00 max 0.33, mean 0.012 voxel; the tests allow 0.75 (max) and 0.1
// (mean). Signs: 98.4% (armadillo) and 99.6% (bunny00) agree overall, 100% for points at least
// one voxel from the surface; closer than that the level set's sign flips where the surface
// passes between the voxel centres (and wherever a feature is thinner than a voxel).
//
// Library target meshsweeper_vdb (links OpenVDB::openvdb); the core library never needs OpenVDB.
#include "core/mesh.h"

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace meshsweeper {

class VdbDistanceGrid {
 public:
  // Builds the grid of `mesh` with voxels of `voxel_size` (world units, > 0) and a narrow band
  // of `half_width` voxels (>= 1) on each side of the surface. signed_distance: a level set
  // (negative inside; needs a closed mesh to mean anything), else an unsigned field.
  // Throws std::invalid_argument for bad parameters, MeshError for an invalid mesh.
  VdbDistanceGrid(const Mesh& mesh, double voxel_size, double half_width, bool signed_distance);
  ~VdbDistanceGrid();
  VdbDistanceGrid(const VdbDistanceGrid&) = delete;
  VdbDistanceGrid& operator=(const VdbDistanceGrid&) = delete;

  // Trilinear sample at world point p. Returns false (value unchanged) when one of the 8 voxels
  // around p lies outside the narrow band (the sample would blend in the background value).
  // Not thread-safe (one value accessor).
  bool sample(const Vec3& p, double& value) const;

  double voxelSize() const;
  double halfWidth() const;
  bool isSigned() const;
  size_t activeVoxels() const;
  size_t memoryBytes() const;
  double buildSeconds() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct VdbCheckOptions {
  double voxel_size = 0;    // world units; 0: the bounding-box diagonal / 256
  double half_width = 3;    // narrow band half width, voxels
  size_t points = 10000;    // points for vdbCheck(mesh, options)
  uint64_t seed = 1;
  // Signed grid and sign comparison when the mesh is closed (BodyShape::closed()); false: always
  // an unsigned grid.
  bool use_sign = true;
};

struct VdbCheckReport {
  std::string mesh;             // the mesh's name
  size_t triangles = 0;
  bool closed = false;          // the mesh is closed (signed comparison possible)
  bool signed_grid = false;
  double voxel_size = 0;
  double half_width = 0;        // voxels
  double build_seconds = 0;     // the OpenVDB grid
  double exact_seconds = 0;     // Meshsweeper: hierarchy build and queries
  size_t requested = 0;         // points given
  size_t compared = 0;          // points inside the narrow band (sampled)
  // | |d_vdb| - d_exact | over the compared points, in voxels.
  double max_error_voxels = 0;
  double mean_error_voxels = 0;
  Vec3 worst_point = Vec3::Zero();
  // Signed grids: points whose VDB sign (value < 0: inside) equals the exact sign
  // (pseudonormal test); points at exactly zero exact distance are not counted.
  size_t sign_compared = 0;
  size_t sign_agreed = 0;
  double signAgreement() const { return sign_compared ? double(sign_agreed) / double(sign_compared) : 1.0; }
  // The same, restricted to points at least one voxel from the surface (exactly).
  size_t sign_compared_far = 0;
  size_t sign_agreed_far = 0;
};

// n points within `max_offset` of the surface: area-weighted uniform samples on the triangles,
// moved along the face normal by an offset uniform in [-max_offset, max_offset). Deterministic.
std::vector<Vec3> bandPoints(const Mesh& mesh, size_t n, double max_offset, uint64_t seed);

// Compares OpenVDB's grid with the exact distances (and signs) at `points`. Throws MeshError
// (naming the mesh) for an invalid mesh, a mesh with no extent and no voxel size given, a
// voxel and band whose narrow band would touch more than 400,000 of OpenVDB's 8^3-voxel leaf
// nodes (about 4 GB; counted from the triangles, so a needle counts by its length), or that
// reach beyond the coordinate range (1e150).
VdbCheckReport vdbCheck(const Mesh& mesh, const std::vector<Vec3>& points, const VdbCheckOptions& options);
// The same at options.points bandPoints() within (half_width - 1.5) voxels of the surface.
VdbCheckReport vdbCheck(const Mesh& mesh, const VdbCheckOptions& options = {});

}  // namespace meshsweeper
