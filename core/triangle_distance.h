#pragma once
// Exact closest point from a point to a triangle, robust for degenerate triangles (segments,
// points): every input gives a finite answer on the closed triangle.
#include "core/types.h"

namespace meshsweeper {

// Which feature of triangle (a, b, c) holds the closest point.
enum class Feature : uint8_t { kVertex0, kVertex1, kVertex2, kEdge01, kEdge12, kEdge20, kFace };

struct TriangleClosest {
  double squared_distance = 0;
  Vec3 point = Vec3::Zero();        // closest point on the triangle
  Vec3 barycentric = Vec3::Zero();  // point = b0*a + b1*b + b2*c, b_i >= 0, sum 1
  Feature feature = Feature::kFace;
};

// Closest point on triangle (a, b, c) to p, with barycentric coordinates and the feature.
TriangleClosest closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

// Squared distance only; equals closestPointOnTriangle(...).squared_distance up to rounding
// (relative 1e-14) and is cheaper.
double squaredDistanceToTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

// True when the triangle has no reliable normal in double precision: sin^2 of its largest
// angle at most 1e-15 (a segment, a point, or a cap within about 2e-6 degree of 180), or a
// coordinate that is not finite. (The functions above still answer such a cap exactly: its
// plane from quadruple precision, its segments only when collinear to that precision.)
bool isDegenerateTriangle(const Vec3& a, const Vec3& b, const Vec3& c);

// Eight triangles stored structure-of-arrays for testing several at a time:
// v[corner][axis][lane]. Unused lanes must hold a copy of a used lane (never garbage).
struct alignas(64) TriangleBlock8 {
  double v[3][3][8];
};

// Squared distances from p to the eight triangles of `block` (out[lane]). Each value equals
// squaredDistanceToTriangle for that lane's triangle up to rounding (relative 1e-14).
void squaredDistancesToBlock(const Vec3& p, const TriangleBlock8& block, double out[8]);

// What closestPointsInBlock keeps of each lane for blockLaneClosest: the closest point and the
// barycentric coordinates in the lane's rotated frame, its local feature and rotation, and
// whether the lane is thin (answered by the scalar function).
struct alignas(64) BlockClosest8 {
  double point[3][8];
  double bary[3][8];
  double feature[8];   // local feature, 0..6
  double rotation[8];  // local corner i is corner (i + rotation) % 3
  double thin[8];      // 1: slivers, needles, degenerate and non-finite lanes
};

// squaredDistancesToBlock, keeping each lane's closest point for blockLaneClosest.
void closestPointsInBlock(const Vec3& p, const TriangleBlock8& block, double out[8], BlockClosest8& details);

// Lane `lane` of a block that closestPointsInBlock(p, block, ...) filled: closestPointOnTriangle
// of that lane's triangle, bit for bit (the same formulas; thin lanes call it).
TriangleClosest blockLaneClosest(const Vec3& p, const TriangleBlock8& block, const BlockClosest8& details, int lane);

// Writes the triangle with corners t (indices into `positions`) into lane `lane` of the block.
inline void setBlockLane(TriangleBlock8& block, uint32_t lane, const Vec3* positions, const Triangle& t) {
  for (int k = 0; k < 3; ++k) {
    const Vec3& x = positions[t[k]];
    for (int axis = 0; axis < 3; ++axis) block.v[k][axis][lane] = x[axis];
  }
}

// Writes the faces faces[0, used) (indices into `triangles`, corners at `positions`) into the
// block's lanes; the lanes past `used` copy lane 0 (1 <= used <= 8).
inline void gatherTriangleBlock(const Triangle* triangles, const Vec3* positions, const TriangleIndex* faces,
                                uint32_t used, TriangleBlock8& block) {
  for (uint32_t lane = 0; lane < 8; ++lane) setBlockLane(block, lane, positions, triangles[faces[lane < used ? lane : 0]]);
}

// Writes eight faces given by their corners (corners[lane], every lane set) into the block.
inline void gatherLeafBlock(const Triangle* corners, const Vec3* positions, TriangleBlock8& block) {
  for (uint32_t lane = 0; lane < 8; ++lane) setBlockLane(block, lane, positions, corners[lane]);
}

}  // namespace meshsweeper
