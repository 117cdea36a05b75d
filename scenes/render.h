#pragma once
// A small software rasterizer for the demo scenes: a camera (perspective or orthographic), an
// RGB image with a z-buffer, Lambert-shaded triangles with per-vertex colours, lines, discs
// (points and spheres drawn in screen space), a bitmap font (stb_easy_font) and PNG output
// (libpng). Enough to make pictures a person can open; not a general renderer.
//
// Not done: clipping (a triangle with a corner behind the camera's near plane is skipped),
// anti-aliasing, shadows, textures. Colours are interpolated linearly in screen space.
#include "core/mesh.h"

#include <cstdint>
#include <string>
#include <vector>

namespace meshsweeper::scenes {

// An sRGB colour, components in [0, 1].
using Colour = Eigen::Vector3d;

// Blue (t = 0) -> cyan -> green -> yellow -> red (t = 1); t is clamped to [0, 1].
Colour rampColour(double t);

// Where a point lands on the image: pixel coordinates (x right, y down) and view depth (the
// distance along the view direction; smaller is nearer). `visible` is false behind the camera.
struct ScreenPoint {
  double x = 0, y = 0, depth = 0;
  bool visible = false;
};

class Camera {
 public:
  // A perspective camera at `eye` looking at `target`, `up` roughly upwards, vertical field of
  // view in degrees, for an image of width x height pixels.
  static Camera perspective(const Vec3& eye, const Vec3& target, const Vec3& up,
                            double fov_degrees, int width, int height);
  // An orthographic camera looking from `eye` towards `target`; `half_height` world units
  // from the image centre to its top edge.
  static Camera orthographic(const Vec3& eye, const Vec3& target, const Vec3& up,
                             double half_height, int width, int height);
  // A perspective camera looking at the sphere (center, radius) from `direction` (from the
  // centre towards the eye), placed so the sphere fills the image with a small margin.
  static Camera framing(const Vec3& center, double radius, const Vec3& direction, const Vec3& up,
                        int width, int height, double fov_degrees = 30);

  ScreenPoint project(const Vec3& p) const;
  // Pixels per world unit at view depth `depth` (for discs of a given world radius).
  double pixelsPerUnit(double depth) const;
  // Unit vector from the eye towards the scene (view direction).
  const Vec3& forward() const { return forward_; }
  const Vec3& eye() const { return eye_; }

 private:
  Vec3 eye_ = Vec3::Zero(), right_ = Vec3::UnitX(), up_ = Vec3::UnitY(), forward_ = -Vec3::UnitZ();
  bool perspective_ = true;
  double focal_ = 1;  // perspective: pixels per unit at depth 1; orthographic: pixels per unit
  int width_ = 1, height_ = 1;
};

// An RGB image with a depth buffer. Drawing calls clip to the image; those with depth test
// write a pixel only where it is nearer than what is there.
class Image {
 public:
  // width, height >= 1; filled with `background`, depth at infinity.
  Image(int width, int height, const Colour& background = Colour(1, 1, 1));

  int width() const { return width_; }
  int height() const { return height_; }
  Colour pixel(int x, int y) const;
  void setPixel(int x, int y, const Colour& c);

  // A triangle with per-corner colours, shaded with a Lambert term of its face normal against
  // a light at the eye (two-sided), plus ambient: colour * (ambient + (1 - ambient) * |n.l|).
  void drawTriangle(const Camera& camera, const Vec3& a, const Vec3& b, const Vec3& c,
                    const Colour& ca, const Colour& cb, const Colour& cc, double ambient = 0.25);
  // Every triangle of `mesh` at `positions` (empty: mesh.positions), coloured per vertex by
  // `vertex_colours` (empty: `colour` everywhere).
  void drawMesh(const Camera& camera, const Mesh& mesh, const std::vector<Vec3>& positions,
                const std::vector<Colour>& vertex_colours, const Colour& colour = Colour(0.8, 0.8, 0.8),
                double ambient = 0.25);
  // A line `pixels` wide between two world points, depth-tested (with a small bias towards the
  // eye, so lines on a surface stay visible).
  void drawLine(const Camera& camera, const Vec3& p, const Vec3& q, const Colour& colour,
                double pixels = 1.5);
  // A disc of `pixels` radius at a world point, depth-tested; `shaded` makes it look like a
  // sphere (darker towards its rim).
  void drawDisc(const Camera& camera, const Vec3& p, double pixels, const Colour& colour,
                bool shaded = false);
  // A sphere of world radius `radius` drawn as a shaded disc.
  void drawSphere(const Camera& camera, const Vec3& center, double radius, const Colour& colour);

  // 2-D overlays (no depth): a filled rectangle, text of the bitmap font at pixel (x, y) (top
  // left), `scale` pixels per font unit (a line is about 10 * scale pixels high).
  void fillRect(int x0, int y0, int x1, int y1, const Colour& colour);
  void drawText(int x, int y, const std::string& text, const Colour& colour, int scale = 2);
  // Width in pixels of `text` at `scale`.
  static int textWidth(const std::string& text, int scale = 2);
  // A vertical colour bar of the rampColour() ramp in the rectangle, `low` at the bottom and
  // `high` at the top labelled with the given texts, and a black frame.
  void drawColourBar(int x0, int y0, int x1, int y1, const std::string& low,
                     const std::string& high, int scale = 2);
  // Copies `image` with its top left at (x, y) (clipped).
  void paste(const Image& image, int x, int y);

  // Writes an 8-bit RGB PNG. Throws MeshError ("PATH: cannot write PNG ...") on failure.
  void writePng(const std::string& path) const;

 private:
  bool depthTest(int x, int y, double depth);
  int width_, height_;
  std::vector<float> rgb_;    // [3 * (y * width + x) + channel]
  std::vector<float> depth_;  // [y * width + x]
};

}  // namespace meshsweeper::scenes
