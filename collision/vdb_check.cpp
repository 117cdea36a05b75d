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
#include <unordered_set>

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

// OpenVDB keeps a grid in leaf nodes of 8^3 voxels, and meshToVolume builds several grids of
// them: its memory goes by the leaves the narrow band touches, not by the band's voxels (a
// needle's band fills few voxels of each leaf along it). This counts the leaf-sized cells the
// band reaches: each triangle is sampled in rows parallel to its longest edge, a quarter of a
// cell apart along and across them (work in proportion to its area and length in cells, a
// needle's or a cap's too), the cells of the samples are marked, and those are grown by the
// band's reach plus the samples' spacing. It stops as soon as the count passes `limit`
// (returning a count above it), so its memory stays within about `limit` cells.
size_t bandLeafCells(const Mesh& mesh, const Vec3& lower, const Vec3& upper, double voxel, double half_width,
                     size_t limit) {
  const double cell = 8 * voxel;
  const Vec3 origin = (lower + upper) / 2;
  // Cells are indexed from the mesh's centre; past 2^20 cells on an axis the count is over
  // any limit anyway (a 2^40-cell slab).
  constexpr double kMaxIndex = 1 << 20;
  if (!(((upper - lower) / cell).maxCoeff() < kMaxIndex)) return limit + 1;
  // A cell's key: its three indices, offset by 2^21, in 21 bits each.
  constexpr int64_t kOffset = int64_t{1} << 21;
  auto key = [](int64_t i, int64_t j, int64_t k) {
    return (static_cast<uint64_t>(i + kOffset) << 42) | (static_cast<uint64_t>(j + kOffset) << 21) |
           static_cast<uint64_t>(k + kOffset);
  };
  auto indices = [](uint64_t key, int64_t out[3]) {
    for (int axis = 0; axis < 3; ++axis)
      out[axis] = static_cast<int64_t>((key >> (42 - 21 * axis)) & (kOffset - 1)) - kOffset;
  };
  std::unordered_set<uint64_t> core;
  auto mark = [&](const Vec3& x) {
    core.insert(key(static_cast<int64_t>(std::floor(x.x())), static_cast<int64_t>(std::floor(x.y())),
                    static_cast<int64_t>(std::floor(x.z()))));
  };
  constexpr double kSpacing = 0.25;  // cells
  for (const Triangle& t : mesh.triangles) {
    Vec3 a = (mesh.positions[t[0]] - origin) / cell, b = (mesh.positions[t[1]] - origin) / cell,
         c = (mesh.positions[t[2]] - origin) / cell;
    // a-b the longest edge, c opposite it.
    const double ab = (b - a).squaredNorm(), bc = (c - b).squaredNorm(), ca = (a - c).squaredNorm();
    if (bc > ab && bc >= ca) std::swap(a, c);
    else if (ca > ab && ca > bc) std::swap(b, c);
    const double length = (b - a).norm();
    const double height = length > 0 ? (b - a).cross(c - a).norm() / length : 0;
    const int64_t rows = static_cast<int64_t>(std::ceil(height / kSpacing));
    for (int64_t row = 0; row <= rows; ++row) {
      const double s = rows ? static_cast<double>(row) / static_cast<double>(rows) : 0;
      const Vec3 from = a + s * (c - a), to = b + s * (c - b);
      const int64_t steps = static_cast<int64_t>(std::ceil((1 - s) * length / kSpacing));
      for (int64_t step = 0; step <= steps; ++step)
        mark(steps ? from + (static_cast<double>(step) / static_cast<double>(steps)) * (to - from) : from);
      if (core.size() > limit) return core.size();
    }
  }
  // Grown by the band's reach, in whole cells on each axis: a point of the surface lies within
  // sqrt(2)/4 of a cell of a sample (0.36).
  const int64_t reach = static_cast<int64_t>(std::ceil(half_width / 8 + 0.36));
  const double per_cell = std::pow(2.0 * static_cast<double>(reach) + 1, 3);
  if (static_cast<double>(core.size()) * per_cell > 64.0 * static_cast<double>(limit)) {
    // Too much work to count exactly: the box of the core cells, grown, bounds the count.
    int64_t lo[3] = {INT64_MAX, INT64_MAX, INT64_MAX}, hi[3] = {INT64_MIN, INT64_MIN, INT64_MIN};
    for (uint64_t c : core) {
      int64_t idx[3];
      indices(c, idx);
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], idx[a]);
        hi[a] = std::max(hi[a], idx[a]);
      }
    }
    double box = 1;
    for (int a = 0; a < 3; ++a) box *= static_cast<double>(hi[a] - lo[a] + 1 + 2 * reach);
    if (box <= static_cast<double>(limit)) return static_cast<size_t>(box);
    return limit + 1;  // refused: a band this wide around this much surface is beyond the limit anyway
  }
  std::unordered_set<uint64_t> band;
  for (uint64_t c : core) {
    int64_t at[3];
    indices(c, at);
    for (int64_t i = at[0] - reach; i <= at[0] + reach; ++i)
      for (int64_t j = at[1] - reach; j <= at[1] + reach; ++j)
        for (int64_t k = at[2] - reach; k <= at[2] + reach; ++k) {
          band.insert(key(i, j, k));
          if (band.size() > limit) return band.size();
        }
  }
  return band.size();
}

// The voxel size of a check (given, or 1/256 of the diagonal); throws MeshError, naming the
// mesh, when none can be derived, when the band's points would leave the coordinate range, or
// when the narrow band would touch more than kMaxBandLeaves leaf nodes of OpenVDB.
double checkVoxel(const Mesh& mesh, const VdbCheckOptions& options) {
  const std::string problem = checkMesh(mesh);
  if (!problem.empty()) throw MeshError(problem);
  const double voxel = options.voxel_size > 0 ? options.voxel_size : meshDiagonal(mesh) / 256;
  if (!(voxel > 0) || !std::isfinite(voxel))
    throw MeshError(mesh.name + ": the mesh has no extent (its vertices coincide), so no voxel size follows "
                                "from it; give one");
  const double half_width = std::max(options.half_width, 1.0);
  Vec3 lower, upper;
  meshBounds(mesh, lower, upper);
  const double reach = lower.cwiseAbs().cwiseMax(upper.cwiseAbs()).maxCoeff() + (half_width + 1) * voxel;
  if (!(reach <= kMaxCoordinate)) {
    std::ostringstream out;
    out << mesh.name << ": a voxel of " << voxel << " and a band of " << half_width
        << " voxels reach beyond the coordinate range 1e150: choose a smaller voxel or a narrower band";
    throw MeshError(out.str());
  }
  // Measured (OpenVDB 10, peak resident memory of `meshsweep check` over the leaves counted
  // here, which overestimates a surface's about 3 times and a needle's hardly): 4-5 KB a leaf
  // on bunny00 at voxels of 0.001 and 0.0005 (0.8 and 2.7 GB), 8-11 KB on a needle at 1e-5 and
  // 1e-6 (1 and 8 GB). 400,000 leaves: at most about 4.4 GB.
  constexpr size_t kMaxBandLeaves = 400'000;
  const size_t leaves = bandLeafCells(mesh, lower, upper, voxel, half_width, kMaxBandLeaves);
  if (leaves > kMaxBandLeaves) {
    std::ostringstream out;
    out << mesh.name << ": a voxel of " << voxel << " and a band of " << half_width
        << " voxels would touch more than " << kMaxBandLeaves
        << " of OpenVDB's 8^3-voxel leaf nodes (about 4 GB): choose a larger voxel or a narrower band";
    throw MeshError(out.str());
  }
  return voxel;
}

// vdbCheck() at a voxel checkVoxel() gave.
VdbCheckReport checkAt(const Mesh& mesh, const std::vector<Vec3>& points, const VdbCheckOptions& options,
                       double voxel) {
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
    if (!std::isfinite(c.distance)) continue;  // beyond the query range: not compared
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

}  // namespace

VdbCheckReport vdbCheck(const Mesh& mesh, const std::vector<Vec3>& points, const VdbCheckOptions& options) {
  return checkAt(mesh, points, options, checkVoxel(mesh, options));
}

VdbCheckReport vdbCheck(const Mesh& mesh, const VdbCheckOptions& options) {
  const double voxel = checkVoxel(mesh, options);
  const double offset = std::max(0.0, options.half_width - 1.5) * voxel;
  return checkAt(mesh, bandPoints(mesh, options.points, offset, options.seed), options, voxel);
}

}  // namespace meshsweeper
