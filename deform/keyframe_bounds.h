#pragma once
// A body deforming through key frames (paper section 5.3, first method; DESIGN.md section 3).
// Positions are given per key frame with the mesh's connectivity; between frames i and i+1
// they are interpolated linearly. The slot bounds of every key frame are computed exactly once
// (same tree); at any time in between, every slot's box and radius is a proven bound for the
// interpolated positions, so queries through geometry() stay exact.
#include "core/hierarchy.h"

#include <memory>
#include <vector>

namespace meshsweeper {

class KeyframeBody {
 public:
  // frames[f][vertex]: at least one frame, each with as many positions as the mesh, all finite.
  // Throws std::invalid_argument otherwise. Costs one radius computation per frame.
  KeyframeBody(std::shared_ptr<const Hierarchy> hierarchy, std::vector<std::vector<Vec3>> frames);
  // Not copyable or movable: geometry() points into the body's own tables (hold bodies by
  // pointer, as the distance service does).
  KeyframeBody(const KeyframeBody&) = delete;
  KeyframeBody& operator=(const KeyframeBody&) = delete;

  // Sets the time t in [0, frameCount() - 1] (clamped; a time that is not finite throws
  // std::invalid_argument): frame floor(t) and the next, weight t - floor(t). Interpolates
  // positions and bounds (the per-frame cost; no geometry rebuilt).
  void setTime(double t);
  double time() const { return time_; }
  size_t frameCount() const { return frames_.size(); }
  // [frame][vertex] the key frames as given.
  const std::vector<std::vector<Vec3>>& frames() const { return frames_; }

  // What queries read (QueryStream::setGeometry); valid until the body is destroyed.
  const TreeGeometry& geometry() const { return geometry_; }
  // [vertex] the interpolated positions at time().
  const std::vector<Vec3>& positions() const { return positions_; }
  const std::shared_ptr<const Hierarchy>& hierarchy() const { return hierarchy_; }

  // The nodes setTime(t) gives, written to `out`; the body does not change (a time that is not
  // finite throws std::invalid_argument, as setTime). `out` is filled
  // with this body's nodes when its size differs, else (reused from an earlier call for this
  // body) only their bounds are written. The part of setTime() that a benchmark compares with
  // a BVH refit.
  void interpolatedBounds(double t, std::vector<Node8>& out) const;

 private:
  std::shared_ptr<const Hierarchy> hierarchy_;
  std::vector<std::vector<Vec3>> frames_;        // [frame][vertex]
  std::vector<std::vector<Node8>> frame_nodes_;  // [frame][node] exact bounds at the frame
  std::vector<std::vector<SlotBoxes>> frame_boxes_;  // [frame][node] their boxes, scaled double
  std::vector<std::vector<float>> delta_;        // [frame pair][8 * node + slot] Delta, rounded up
  std::vector<Node8> nodes_;                     // bounds at time_
  std::vector<Vec3> positions_;
  TreeGeometry geometry_;
  double time_ = 0;
  bool unused_vertices_ = false;  // some vertex no face uses (its motion is no drift)
  double interpolation_rounding_ = 0;  // added to the radii between frames (constructor)
};

}  // namespace meshsweeper
