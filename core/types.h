#pragma once
// Basic types shared by every module of Meshsweeper.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstdint>

namespace meshsweeper {

using Vec3 = Eigen::Vector3d;
using VertexIndex = uint32_t;    // index into Mesh::positions
using TriangleIndex = uint32_t;  // index into Mesh::triangles (file order, after fan triangulation)
using Triangle = std::array<VertexIndex, 3>;

inline constexpr uint32_t kInvalidIndex = 0xffffffffu;

}  // namespace meshsweeper
