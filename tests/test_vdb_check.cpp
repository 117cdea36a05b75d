// Exact distances against OpenVDB's narrow-band distance grids (collision/vdb_check.h), an
// independent implementation: trilinear samples agree with the exact distance within the grid's
// own error, and the signs of a level set agree with the pseudonormal signs away from the
// surface. Thresholds (voxels) are what the grids achieve here with margin, see vdb_check.h.
#include "collision/distance_service.h"
#include "collision/vdb_check.h"
#include "core/mesh_io.h"
#include "scenes/procedural.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <stdexcept>

using namespace meshsweeper;

namespace {

// Error bound of a trilinear sample of a distance grid, in voxels: measured maxima 0.46 voxel
// (armadillo, 256 voxels per diagonal) and below on the smooth meshes, means 0.02-0.05 (see
// vdb_check.h); the bounds leave a margin for other seeds.
constexpr double kMaxErrorVoxels = 0.75;
constexpr double kMeanErrorVoxels = 0.1;

void checkReport(const VdbCheckReport& r, bool expect_signed) {
  INFO(r.mesh << ": voxel " << r.voxel_size << ", compared " << r.compared << " of " << r.requested
               << ", max " << r.max_error_voxels << " voxels, mean " << r.mean_error_voxels << ", sign "
               << r.sign_agreed << "/" << r.sign_compared << ", far " << r.sign_agreed_far << "/"
               << r.sign_compared_far);
  CHECK(r.signed_grid == expect_signed);
  CHECK(r.compared > r.requested * 9 / 10);
  CHECK(r.max_error_voxels <= kMaxErrorVoxels);
  CHECK(r.mean_error_voxels <= kMeanErrorVoxels);
  if (expect_signed) {
    CHECK(r.sign_compared == r.compared);
    // Within a voxel of the surface the grid's sign can flip where the surface passes between
    // voxel centres (armadillo: 98.3% agree); a voxel or more off the surface all agree.
    CHECK(r.signAgreement() >= 0.95);
    CHECK(r.sign_agreed_far == r.sign_compared_far);
    CHECK(r.sign_compared_far > r.compared / 4);
  }
}

}  // namespace

TEST_CASE("OpenVDB agrees with the exact distances on an icosphere", "[vdb]") {
  const Mesh sphere = scenes::icosphere(4, 1.0);
  VdbCheckOptions options;
  options.voxel_size = 0.02;
  options.points = 4000;
  checkReport(vdbCheck(sphere, options), true);
  options.use_sign = false;
  checkReport(vdbCheck(sphere, options), false);
}

// Found by review: OpenVDB's float vertices did not resolve a mesh far from the origin (no
// point was compared, and the report read as perfect agreement), and its transform refused the
// voxels of a mesh of size 1e-3. The grid is built in voxel units about the mesh's centre.
TEST_CASE("OpenVDB cross-check far from the origin and at small and large sizes", "[vdb]") {
  for (const auto& [scale, offset] : {std::pair{1.0, 1e12}, std::pair{1e-3, 0.0}, std::pair{1e-30, 1e-25},
                                      std::pair{1e30, 1e32}}) {
    INFO("scale " << scale << ", offset " << offset);
    Mesh sphere = scenes::icosphere(3, 1.0);
    for (Vec3& x : sphere.positions) x = scale * x + Vec3::Constant(offset);
    VdbCheckOptions options;
    options.voxel_size = 0.03 * scale;
    options.points = 2000;
    const VdbCheckReport r = vdbCheck(sphere, options);
    INFO("compared " << r.compared << ", max " << r.max_error_voxels << ", sign " << r.sign_agreed << "/"
                     << r.sign_compared << ", far " << r.sign_agreed_far << "/" << r.sign_compared_far);
    CHECK(r.compared > r.requested * 9 / 10);
    CHECK(r.max_error_voxels <= kMaxErrorVoxels);
    CHECK(r.mean_error_voxels <= kMeanErrorVoxels);
    // (At 1e12 a few sampled points are at exact distance 0, which has no sign to compare.)
    CHECK(r.sign_compared > r.compared * 99 / 100);
    CHECK(r.signAgreement() >= 0.95);
    CHECK(r.sign_agreed_far == r.sign_compared_far);
  }
}

TEST_CASE("OpenVDB agrees with the exact distances on armadillo", "[vdb]") {
  const std::string path = scenes::meshPath("armadillo");
  if (!std::filesystem::exists(path)) {
    FAIL_CHECK("missing real mesh " << path << " (run scripts/fetch_data.sh)");
    return;
  }
  Mesh mesh = readMesh(path);
  mesh.name = "armadillo";
  VdbCheckOptions options;  // voxel = diagonal / 256
  options.points = 4000;
  checkReport(vdbCheck(mesh, options), true);
}

TEST_CASE("OpenVDB unsigned grid of an open mesh", "[vdb]") {
  const Mesh plane = scenes::gridPlane(16, 2.0);
  VdbCheckOptions options;
  options.voxel_size = 0.01;
  options.points = 3000;
  const VdbCheckReport r = vdbCheck(plane, options);
  CHECK_FALSE(r.closed);
  checkReport(r, false);
}

TEST_CASE("the service's signed distances against a level set", "[vdb]") {
  const Mesh sphere = scenes::icosphere(4, 1.0);
  const double voxel = 0.02;
  const VdbDistanceGrid grid(sphere, voxel, 3, true);
  CHECK(grid.isSigned());
  CHECK(grid.activeVoxels() > 0);
  DistanceService service;
  service.addRigid(service.hierarchyFor(sphere));
  const std::vector<Vec3> points = bandPoints(sphere, 2000, 1.5 * voxel, 4);
  PointMatrix m(points.size(), 3);
  for (size_t i = 0; i < points.size(); ++i) m.row(i) = points[i].transpose();
  const StepResult r = service.step(m, 3 * voxel);
  size_t compared = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    double value = 0;
    const DistanceHit* hit = r.closest(i);
    REQUIRE(hit);
    if (!grid.sample(points[i], value)) continue;
    ++compared;
    CHECK(std::abs(value - hit->signed_distance) <= kMaxErrorVoxels * voxel);
  }
  CHECK(compared > points.size() * 9 / 10);
  // Outside the narrow band there is no sample.
  double value = 0;
  CHECK_FALSE(grid.sample(Vec3(0, 0, 0), value));
  CHECK_FALSE(grid.sample(Vec3(5, 0, 0), value));
}

TEST_CASE("VdbDistanceGrid rejects bad parameters", "[vdb]") {
  const Mesh sphere = scenes::icosphere(1);
  CHECK_THROWS_AS(VdbDistanceGrid(sphere, 0.0, 3, true), std::invalid_argument);
  CHECK_THROWS_AS(VdbDistanceGrid(sphere, 0.1, 0.5, true), std::invalid_argument);
  CHECK_THROWS_AS(VdbDistanceGrid(Mesh{}, 0.1, 3, true), MeshError);
}

// The band's leaf nodes are counted from the triangles before OpenVDB builds anything (found by
// review: a needle's band passed an area-based estimate as 9 voxels and took 8 GB at a voxel of
// 1e-6; a voxel of 1e160 put the points beyond the query range and printed a perfect score).
TEST_CASE("vdbCheck refuses bands beyond memory or the coordinate range, naming the mesh", "[vdb]") {
  Mesh needle;
  needle.name = "needle.off";
  needle.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1e-12, 0)};
  needle.triangles = {{0, 1, 2}};
  VdbCheckOptions options;
  options.points = 50;
  options.voxel_size = 1e-6;  // 125,000 leaves along it, grown by the band: refused
  CHECK_THROWS_WITH(vdbCheck(needle, options), Catch::Contains("needle.off") && Catch::Contains("leaf nodes"));
  options.voxel_size = 1e-3;  // 1,000 voxels along it: checked
  const VdbCheckReport fine = vdbCheck(needle, options);
  CHECK(fine.compared > 0);
  CHECK(fine.max_error_voxels <= kMaxErrorVoxels);

  Mesh sphere = scenes::icosphere(2);
  sphere.name = "sphere";
  options.voxel_size = 0;  // 1/256 of the diagonal
  options.half_width = 1000;
  CHECK_THROWS_WITH(vdbCheck(sphere, options), Catch::Contains("sphere") && Catch::Contains("narrower band"));
  options.half_width = 3;
  options.voxel_size = 1e160;
  CHECK_THROWS_WITH(vdbCheck(sphere, options), Catch::Contains("beyond the coordinate range"));
  options.voxel_size = 0;
  CHECK(vdbCheck(sphere, options).compared > 0);
}
