// OpenVDB cross-check of the exact distances (see vdb_check.h).
#include "collision/vdb_check.h"

#include "collision/body.h"
#include "core/hierarchy.h"
#include "core/sweep_query.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>
#include <sstream>
#include <stdexcept>

namespace meshsweeper {
namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

struct VdbDistanceGrid::Impl {
  openvdb::FloatGrid::Ptr grid;
  Vec3 origin = Vec3::Zero();  // the grid's frame: (x - origin) / voxel_size, voxels of 1
  double voxel_size = 0;
  double half_width = 0;
  bool signed_distance = false;
  double build_seconds = 0;
};

VdbDistanceGrid::VdbDistanceGrid(const Mesh& mesh, double voxel_size, double half_width, bool signed_distance)
    : impl_(std::make_unique<Impl>()) {
  if (!(voxel_size > 0) || !std::isfinite(voxel_size))
    throw std::invalid_argument("VdbDistanceGrid: voxel size must be finite and > 0");
  if (!(half_width >= 1) || !std::isfinite(half_width))
    throw std::invalid_argument("VdbDistanceGrid: half width must be finite and >= 1 voxel");
  const std::string problem = checkMesh(mesh);
  if (!problem.empty()) throw MeshError(problem);
  openvdb::initialize();
  const auto start = std::chrono::steady_clock::now();
  // The grid is built in voxel units about the mesh's centre: OpenVDB's float vertices would
  // not resolve a mesh far from the origin (a triangle at 1e12 left no voxel to compare), and
  // its transform refuses voxels below about 1e-5 (a mesh of size 1e-3 failed; found by
  // review). Distances are scaled back by the voxel size.
  Vec3 lower, upper;
  meshBounds(mesh, lower, upper);
  impl_->origin = 0.5 * (lower + upper);
  std::vector<openvdb::Vec3s> points(mesh.positions.size());
  for (size_t v = 0; v < points.size(); ++v) {
    const Vec3 x = (mesh.positions[v] - impl_->origin) / voxel_size;
    points[v] = openvdb::Vec3s(static_cast<float>(x.x()), static_cast<float>(x.y()), static_cast<float>(x.z()));
  }
  std::vector<openvdb::Vec3I> triangles(mesh.triangles.size());
  for (size_t t = 0; t < triangles.size(); ++t)
    triangles[t] = openvdb::Vec3I(mesh.triangles[t][0], mesh.triangles[t][1], mesh.triangles[t][2]);
  const openvdb::math::Transform::Ptr transform = openvdb::math::Transform::createLinearTransform(1.0);
  if (signed_distance) {
    impl_->grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*transform, points, triangles,
                                                                     static_cast<float>(half_width));
  } else {
    const std::vector<openvdb::Vec4I> quads;
    impl_->grid = openvdb::tools::meshToUnsignedDistanceField<openvdb::FloatGrid>(
        *transform, points, triangles, quads, static_cast<float>(half_width));
  }
  impl_->voxel_size = voxel_size;
  impl_->half_width = half_width;
  impl_->signed_distance = signed_distance;
  impl_->build_seconds = secondsSince(start);
}

VdbDistanceGrid::~VdbDistanceGrid() = default;

bool VdbDistanceGrid::sample(const Vec3& p, double& value) const {
  const openvdb::FloatGrid& grid = *impl_->grid;
  const Vec3 x = (p - impl_->origin) / impl_->voxel_size;
  const openvdb::Vec3d index = grid.transform().worldToIndex(openvdb::Vec3d(x.x(), x.y(), x.z()));
  const openvdb::Coord base(static_cast<int>(std::floor(index.x())), static_cast<int>(std::floor(index.y())),
                            static_cast<int>(std::floor(index.z())));
  openvdb::FloatGrid::ConstAccessor accessor = grid.getConstAccessor();
  for (int corner = 0; corner < 8; ++corner) {
    const openvdb::Coord c = base.offsetBy(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
    if (!accessor.isValueOn(c)) return false;
  }
  value = openvdb::tools::BoxSampler::sample(accessor, index) * impl_->voxel_size;
  return true;
}

double VdbDistanceGrid::voxelSize() const { return impl_->voxel_size; }
double VdbDistanceGrid::halfWidth() const { return impl_->half_width; }
bool VdbDistanceGrid::isSigned() const { return impl_->signed_distance; }
size_t VdbDistanceGrid::activeVoxels() const { return static_cast<size_t>(impl_->grid->activeVoxelCount()); }
size_t VdbDistanceGrid::memoryBytes() const { return static_cast<size_t>(impl_->grid->memUsage()); }
double VdbDistanceGrid::buildSeconds() const { return impl_->build_seconds; }

std::vector<Vec3> bandPoints(const Mesh& mesh, size_t n, double max_offset, uint64_t seed) {
  std::vector<double> cumulative(mesh.triangles.size());
  double total = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    total += triangleArea(mesh, t);
    cumulative[t] = total;
  }
  std::mt19937_64 engine(seed);
  auto uniform = [&] { return static_cast<double>(engine() >> 11) * 0x1.0p-53; };
  std::vector<Vec3> out;
  out.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    size_t t;
    if (total > 0) {
      t = static_cast<size_t>(std::upper_bound(cumulative.begin(), cumulative.end(), uniform() * total) -
                              cumulative.begin());
      t = std::min(t, cumulative.size() - 1);
    } else {
      t = std::min(static_cast<size_t>(uniform() * static_cast<double>(cumulative.size())), cumulative.size() - 1);
    }
    const Triangle& tri = mesh.triangles[t];
    const Vec3 &a = mesh.positions[tri[0]], &b = mesh.positions[tri[1]], &c = mesh.positions[tri[2]];
    double u = uniform(), v = uniform();
    if (u + v > 1) {
      u = 1 - u;
      v = 1 - v;
    }
    const Vec3 normal = unitFaceNormal(a, b, c);
    out.push_back(a + u * (b - a) + v * (c - a) + (2 * uniform() - 1) * max_offset * normal);
  }
  return out;
}

namespace {

// The voxel size of a check (given, or 1/256 of the diagonal); throws MeshError, naming the
// mesh, when none can be derived or the narrow band would need more than 2e8 voxels.
double checkVoxel(const Mesh& mesh, const VdbCheckOptions& options) {
  const std::string problem = checkMesh(mesh);
  if (!problem.empty()) throw MeshError(problem);
  const double voxel = options.voxel_size > 0 ? options.voxel_size : meshDiagonal(mesh) / 256;
  if (!(voxel > 0) || !std::isfinite(voxel))
    throw MeshError(mesh.name + ": the mesh has no extent (its vertices coincide), so no voxel size follows "
                                "from it; give one");
  const double voxels = (surfaceArea(mesh) / (voxel * voxel) + 1) * 2 * std::max(options.half_width, 1.0);
  if (voxels > 2e8) {
    std::ostringstream out;
    out << mesh.name << ": a voxel of " << voxel << " would need about " << voxels
        << " voxels in the narrow band (at most 2e8): choose a larger voxel";
    throw MeshError(out.str());
  }
  return voxel;
}

}  // namespace

VdbCheckReport vdbCheck(const Mesh& mesh, const std::vector<Vec3>& points, const VdbCheckOptions& options) {
  const double voxel = checkVoxel(mesh, options);
  VdbCheckReport report;
  report.mesh = mesh.name;
  report.triangles = mesh.triangles.size();
  report.requested = points.size();

  auto start = std::chrono::steady_clock::now();
  const std::shared_ptr<const Hierarchy> hierarchy = Hierarchy::build(mesh);
  const std::shared_ptr<const BodyShape> shape = BodyShape::build(hierarchy);
  report.exact_seconds = secondsSince(start);
  report.closed = shape->closed();
  report.signed_grid = options.use_sign && report.closed;
  const VdbDistanceGrid grid(mesh, voxel, options.half_width, report.signed_grid);
  report.voxel_size = voxel;
  report.half_width = options.half_width;
  report.build_seconds = grid.buildSeconds();

  start = std::chrono::steady_clock::now();
  QueryStream stream(hierarchy);
  double sum = 0;
  for (const Vec3& p : points) {
    double vdb = 0;
    if (!p.allFinite() || !grid.sample(p, vdb)) continue;
    const ClosestPoint c = stream.closest(p);
    const double error = std::abs(std::abs(vdb) - c.distance) / voxel;
    ++report.compared;
    sum += error;
    if (error > report.max_error_voxels) {
      report.max_error_voxels = error;
      report.worst_point = p;
    }
    if (report.signed_grid && c.distance > 0) {
      const Vec3 normal = shape->restPseudonormal(c.triangle, c.feature);
      const bool inside = (p - c.point).dot(normal) < 0;
      const bool agree = inside == (vdb < 0);
      ++report.sign_compared;
      report.sign_agreed += agree;
      if (c.distance >= voxel) {
        ++report.sign_compared_far;
        report.sign_agreed_far += agree;
      }
    }
  }
  report.exact_seconds += secondsSince(start);
  report.mean_error_voxels = report.compared ? sum / static_cast<double>(report.compared) : 0;
  return report;
}

VdbCheckReport vdbCheck(const Mesh& mesh, const VdbCheckOptions& options) {
  const double voxel = checkVoxel(mesh, options);
  VdbCheckOptions resolved = options;
  resolved.voxel_size = voxel;
  const double offset = std::max(0.0, options.half_width - 1.5) * voxel;
  return vdbCheck(mesh, bandPoints(mesh, options.points, offset, options.seed), resolved);
}

}  // namespace meshsweeper
