// CGAL AABB-tree closest-point peer (see peers.h). Kept alone in this translation unit: the
// AABB tree headers are the slowest part of the benchmarks to compile.
#include "bench/peers.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <vector>

namespace meshsweeper::bench {
namespace {

using Kernel = CGAL::Simple_cartesian<double>;
using CgalPoint = Kernel::Point_3;
using CgalTriangle = Kernel::Triangle_3;
using TriangleIterator = std::vector<CgalTriangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<Kernel, TriangleIterator>;
using Traits = CGAL::AABB_traits<Kernel, Primitive>;
using Tree = CGAL::AABB_tree<Traits>;

CgalPoint toCgal(const Vec3& v) { return CgalPoint(v.x(), v.y(), v.z()); }

}  // namespace

struct CgalClosest::Impl {
  std::vector<CgalTriangle> triangles;  // [triangle] file order; the tree's primitives point here
  Tree tree;
};

CgalClosest::CgalClosest(const Mesh& mesh) : impl_(std::make_unique<Impl>()) {
  auto& triangles = impl_->triangles;
  triangles.reserve(mesh.triangles.size());
  for (const Triangle& t : mesh.triangles)
    triangles.emplace_back(toCgal(mesh.positions[t[0]]), toCgal(mesh.positions[t[1]]),
                           toCgal(mesh.positions[t[2]]));
  impl_->tree.insert(triangles.cbegin(), triangles.cend());
  impl_->tree.build();
  impl_->tree.accelerate_distance_queries();
}

CgalClosest::~CgalClosest() = default;

PeerHit CgalClosest::closest(const Vec3& p) const {
  const CgalPoint q = toCgal(p);
  const auto point_and_primitive = impl_->tree.closest_point_and_primitive(q);
  const CgalPoint& c = point_and_primitive.first;
  PeerHit hit;
  hit.point = Vec3(c.x(), c.y(), c.z());
  hit.distance = (hit.point - p).norm();
  hit.triangle = static_cast<TriangleIndex>(point_and_primitive.second - impl_->triangles.cbegin());
  return hit;
}

}  // namespace meshsweeper::bench
