// The demo scenes' software rasterizer (see render.h): edge functions over each triangle's
// screen bounding box, depth interpolated in 1/z for perspective, PNG through libpng's
// simplified write API, text from stb_easy_font's quads.
#include "scenes/render.h"

#include "scenes/output_file.h"

#include <png.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

// stb_easy_font is a header with static functions; it warns about unused ones.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wsign-compare"
#include <stb/stb_easy_font.h>
#pragma GCC diagnostic pop

namespace meshsweeper::scenes {

Colour rampColour(double t) {
  t = std::clamp(std::isfinite(t) ? t : 0.0, 0.0, 1.0);
  // Blue -> cyan -> green -> yellow -> red in four equal pieces.
  static const Colour stops[5] = {{0.1, 0.2, 0.9}, {0.0, 0.8, 0.9}, {0.1, 0.8, 0.2},
                                  {0.95, 0.85, 0.1}, {0.9, 0.1, 0.1}};
  const double s = t * 4;
  const int i = std::min(3, static_cast<int>(s));
  const double w = s - i;
  return (1 - w) * stops[i] + w * stops[i + 1];
}

// ---- Camera ---------------------------------------------------------------------------------

namespace {

void basis(const Vec3& eye, const Vec3& target, const Vec3& up, Vec3& right, Vec3& true_up,
           Vec3& forward) {
  forward = (target - eye).normalized();
  right = forward.cross(up);
  if (right.norm() < 1e-12) right = forward.cross(std::abs(forward.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY());
  right.normalize();
  true_up = right.cross(forward);
}

}  // namespace

Camera Camera::perspective(const Vec3& eye, const Vec3& target, const Vec3& up,
                           double fov_degrees, int width, int height) {
  Camera c;
  c.eye_ = eye;
  basis(eye, target, up, c.right_, c.up_, c.forward_);
  c.perspective_ = true;
  c.width_ = width;
  c.height_ = height;
  c.focal_ = 0.5 * height / std::tan(0.5 * fov_degrees * M_PI / 180);
  return c;
}

Camera Camera::orthographic(const Vec3& eye, const Vec3& target, const Vec3& up,
                            double half_height, int width, int height) {
  Camera c;
  c.eye_ = eye;
  basis(eye, target, up, c.right_, c.up_, c.forward_);
  c.perspective_ = false;
  c.width_ = width;
  c.height_ = height;
  c.focal_ = 0.5 * height / half_height;
  return c;
}

Camera Camera::framing(const Vec3& center, double radius, const Vec3& direction, const Vec3& up,
                       int width, int height, double fov_degrees) {
  const double half = 0.5 * fov_degrees * M_PI / 180;
  // The narrower of the two image sides must hold the sphere.
  const double aspect = std::min(1.0, static_cast<double>(width) / height);
  const double half_narrow = std::atan(std::tan(half) * aspect);
  const double distance = 1.08 * radius / std::sin(half_narrow);
  return perspective(center + distance * direction.normalized(), center, up, fov_degrees, width,
                     height);
}

ScreenPoint Camera::project(const Vec3& p) const {
  const Vec3 v = p - eye_;
  ScreenPoint s;
  s.depth = v.dot(forward_);
  const double scale = perspective_ ? focal_ / s.depth : focal_;
  s.visible = !perspective_ || s.depth > 1e-9;
  s.x = 0.5 * width_ + scale * v.dot(right_);
  s.y = 0.5 * height_ - scale * v.dot(up_);
  return s;
}

double Camera::pixelsPerUnit(double depth) const {
  return perspective_ ? focal_ / std::max(depth, 1e-9) : focal_;
}

// ---- Image ----------------------------------------------------------------------------------

Image::Image(int width, int height, const Colour& background)
    : width_(std::max(1, width)), height_(std::max(1, height)),
      rgb_(3 * static_cast<size_t>(width_) * height_),
      depth_(static_cast<size_t>(width_) * height_, std::numeric_limits<float>::infinity()) {
  for (size_t i = 0; i < depth_.size(); ++i)
    for (int k = 0; k < 3; ++k) rgb_[3 * i + k] = static_cast<float>(background[k]);
}

Colour Image::pixel(int x, int y) const {
  const size_t i = 3 * (static_cast<size_t>(y) * width_ + x);
  return Colour(rgb_[i], rgb_[i + 1], rgb_[i + 2]);
}

void Image::setPixel(int x, int y, const Colour& c) {
  if (x < 0 || y < 0 || x >= width_ || y >= height_) return;
  const size_t i = 3 * (static_cast<size_t>(y) * width_ + x);
  for (int k = 0; k < 3; ++k) rgb_[i + k] = static_cast<float>(c[k]);
}

bool Image::depthTest(int x, int y, double depth) {
  // Compared as stored: a double depth against its own float rounding (rounded up half the
  // time) let a surface drawn twice win its own tie.
  float& d = depth_[static_cast<size_t>(y) * width_ + x];
  const float f = static_cast<float>(depth);
  if (!(f < d)) return false;
  d = f;
  return true;
}

void Image::drawTriangle(const Camera& camera, const Vec3& a, const Vec3& b, const Vec3& c,
                         const Colour& ca, const Colour& cb, const Colour& cc, double ambient) {
  const ScreenPoint s[3] = {camera.project(a), camera.project(b), camera.project(c)};
  if (!s[0].visible || !s[1].visible || !s[2].visible) return;
  const Vec3 normal = (b - a).cross(c - a);
  const double length = normal.norm();
  if (!(length > 0)) return;
  // Light at the eye: for a perspective camera, the direction from the triangle to the eye.
  const Vec3 centroid = (a + b + c) / 3;
  Vec3 to_light = camera.eye() - centroid;
  to_light = to_light.norm() > 0 ? to_light.normalized() : Vec3(-camera.forward());
  const double lambert = std::abs(normal.dot(to_light)) / length;
  const double shade = ambient + (1 - ambient) * lambert;

  const double area = (s[1].x - s[0].x) * (s[2].y - s[0].y) - (s[2].x - s[0].x) * (s[1].y - s[0].y);
  if (std::abs(area) < 1e-12) return;
  const int x0 = std::max(0, static_cast<int>(std::floor(std::min({s[0].x, s[1].x, s[2].x}))));
  const int x1 = std::min(width_ - 1, static_cast<int>(std::ceil(std::max({s[0].x, s[1].x, s[2].x}))));
  const int y0 = std::max(0, static_cast<int>(std::floor(std::min({s[0].y, s[1].y, s[2].y}))));
  const int y1 = std::min(height_ - 1, static_cast<int>(std::ceil(std::max({s[0].y, s[1].y, s[2].y}))));
  const double inv_depth[3] = {1 / s[0].depth, 1 / s[1].depth, 1 / s[2].depth};
  for (int y = y0; y <= y1; ++y) {
    const double py = y + 0.5;
    for (int x = x0; x <= x1; ++x) {
      const double px = x + 0.5;
      double w0 = (s[1].x - px) * (s[2].y - py) - (s[2].x - px) * (s[1].y - py);
      double w1 = (s[2].x - px) * (s[0].y - py) - (s[0].x - px) * (s[2].y - py);
      double w2 = (s[0].x - px) * (s[1].y - py) - (s[1].x - px) * (s[0].y - py);
      w0 /= area;
      w1 /= area;
      w2 /= area;
      if (w0 < 0 || w1 < 0 || w2 < 0) continue;
      // Perspective-correct depth: 1/z is linear in screen space (orthographic depth is linear).
      const double inv = w0 * inv_depth[0] + w1 * inv_depth[1] + w2 * inv_depth[2];
      const double depth = camera.pixelsPerUnit(1) == camera.pixelsPerUnit(2)
                               ? w0 * s[0].depth + w1 * s[1].depth + w2 * s[2].depth
                               : 1 / inv;
      if (!depthTest(x, y, depth)) continue;
      setPixel(x, y, shade * (w0 * ca + w1 * cb + w2 * cc));
    }
  }
}

void Image::drawMesh(const Camera& camera, const Mesh& mesh, const std::vector<Vec3>& positions,
                     const std::vector<Colour>& vertex_colours, const Colour& colour,
                     double ambient) {
  const std::vector<Vec3>& p = positions.empty() ? mesh.positions : positions;
  for (const Triangle& t : mesh.triangles) {
    const Colour& c0 = vertex_colours.empty() ? colour : vertex_colours[t[0]];
    const Colour& c1 = vertex_colours.empty() ? colour : vertex_colours[t[1]];
    const Colour& c2 = vertex_colours.empty() ? colour : vertex_colours[t[2]];
    drawTriangle(camera, p[t[0]], p[t[1]], p[t[2]], c0, c1, c2, ambient);
  }
}

void Image::drawLine(const Camera& camera, const Vec3& p, const Vec3& q, const Colour& colour,
                     double pixels) {
  const ScreenPoint a = camera.project(p), b = camera.project(q);
  if (!a.visible || !b.visible) return;
  const double length = std::hypot(b.x - a.x, b.y - a.y);
  const int steps = std::max(1, static_cast<int>(std::ceil(length * 2)));
  const double r = 0.5 * pixels;
  const int reach = static_cast<int>(std::ceil(r));
  for (int i = 0; i <= steps; ++i) {
    const double t = static_cast<double>(i) / steps;
    const double x = a.x + t * (b.x - a.x), y = a.y + t * (b.y - a.y);
    // Bias towards the eye: 1% of the depth, so a line lying on a surface wins.
    const double depth = (a.depth + t * (b.depth - a.depth)) * 0.99;
    for (int dy = -reach; dy <= reach; ++dy) {
      for (int dx = -reach; dx <= reach; ++dx) {
        const int px = static_cast<int>(std::floor(x)) + dx, py = static_cast<int>(std::floor(y)) + dy;
        if (px < 0 || py < 0 || px >= width_ || py >= height_) continue;
        if (std::hypot(px + 0.5 - x, py + 0.5 - y) > r + 0.25) continue;
        if (depthTest(px, py, depth)) setPixel(px, py, colour);
      }
    }
  }
}

void Image::drawDisc(const Camera& camera, const Vec3& p, double pixels, const Colour& colour,
                     bool shaded) {
  const ScreenPoint s = camera.project(p);
  if (!s.visible) return;
  const int x0 = std::max(0, static_cast<int>(std::floor(s.x - pixels)));
  const int x1 = std::min(width_ - 1, static_cast<int>(std::ceil(s.x + pixels)));
  const int y0 = std::max(0, static_cast<int>(std::floor(s.y - pixels)));
  const int y1 = std::min(height_ - 1, static_cast<int>(std::ceil(s.y + pixels)));
  const double world_radius = pixels / camera.pixelsPerUnit(s.depth);
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) {
      const double dx = (x + 0.5 - s.x) / pixels, dy = (y + 0.5 - s.y) / pixels;
      const double r2 = dx * dx + dy * dy;
      if (r2 > 1) continue;
      const double bulge = std::sqrt(1 - r2);
      // A sphere's front surface; a flat disc (a marker) sits just in front of its centre, and
      // of a line drawn to it (lines: 1%), so the line does not cut it in two.
      const double depth = shaded ? s.depth - world_radius * bulge : s.depth * 0.985;
      if (!depthTest(x, y, depth)) continue;
      if (!shaded) {
        setPixel(x, y, r2 > 0.6 ? Colour(0.1 * colour) : colour);
        continue;
      }
      // Light from the upper left, in front.
      const Vec3 n(dx, -dy, bulge);
      const double lambert = std::max(0.0, n.dot(Vec3(-0.4, 0.5, 0.77).normalized()));
      const double highlight = std::pow(std::max(0.0, n.dot(Vec3(-0.3, 0.4, 0.87).normalized())), 40);
      setPixel(x, y, (0.3 + 0.7 * lambert) * colour + Colour::Constant(0.6 * highlight));
    }
  }
}

void Image::drawSphere(const Camera& camera, const Vec3& center, double radius,
                       const Colour& colour) {
  const ScreenPoint s = camera.project(center);
  if (!s.visible) return;
  drawDisc(camera, center, std::max(1.5, radius * camera.pixelsPerUnit(s.depth)), colour, true);
}

void Image::fillRect(int x0, int y0, int x1, int y1, const Colour& colour) {
  for (int y = std::max(0, y0); y < std::min(height_, y1); ++y)
    for (int x = std::max(0, x0); x < std::min(width_, x1); ++x) setPixel(x, y, colour);
}

void Image::drawText(int x, int y, const std::string& text, const Colour& colour, int scale) {
  // About 270 bytes per character (stb_easy_font's estimate); 16-byte vertices, 4 per quad.
  std::vector<char> buffer(300 * (text.size() + 1));
  std::string copy = text;
  const int quads = stb_easy_font_print(0, 0, copy.data(), nullptr, buffer.data(),
                                        static_cast<int>(buffer.size()));
  for (int q = 0; q < quads; ++q) {
    const float* v0 = reinterpret_cast<const float*>(buffer.data() + 64 * q);
    const float* v2 = reinterpret_cast<const float*>(buffer.data() + 64 * q + 32);
    fillRect(x + static_cast<int>(std::lround(v0[0] * scale)), y + static_cast<int>(std::lround(v0[1] * scale)),
             x + static_cast<int>(std::lround(v2[0] * scale)), y + static_cast<int>(std::lround(v2[1] * scale)),
             colour);
  }
}

int Image::textWidth(const std::string& text, int scale) {
  std::string copy = text;
  return stb_easy_font_width(copy.data()) * scale;
}

void Image::drawColourBar(int x0, int y0, int x1, int y1, const std::string& low,
                          const std::string& high, int scale) {
  for (int y = y0; y < y1; ++y) {
    const double t = y1 - 1 > y0 ? static_cast<double>(y1 - 1 - y) / (y1 - 1 - y0) : 0;
    fillRect(x0, y, x1, y + 1, rampColour(t));
  }
  const Colour black(0, 0, 0);
  fillRect(x0 - 1, y0 - 1, x1 + 1, y0, black);
  fillRect(x0 - 1, y1, x1 + 1, y1 + 1, black);
  fillRect(x0 - 1, y0 - 1, x0, y1 + 1, black);
  fillRect(x1, y0 - 1, x1 + 1, y1 + 1, black);
  drawText(x1 + 6, y0 - 4 * scale, high, black, scale);
  drawText(x1 + 6, y1 - 6 * scale, low, black, scale);
}

void Image::paste(const Image& image, int x, int y) {
  for (int j = 0; j < image.height(); ++j)
    for (int i = 0; i < image.width(); ++i) setPixel(x + i, y + j, image.pixel(i, j));
}

void Image::writePng(const std::string& path) const {
  std::vector<png_byte> bytes(rgb_.size());
  for (size_t i = 0; i < rgb_.size(); ++i)
    bytes[i] = static_cast<png_byte>(std::lround(255 * std::clamp(rgb_[i], 0.0f, 1.0f)));
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  image.width = static_cast<png_uint_32>(width_);
  image.height = static_cast<png_uint_32>(height_);
  image.format = PNG_FORMAT_RGB;
  // Encoded in memory first, then written as a whole: a run that fails or is interrupted leaves
  // an existing picture as it was, never half written.
  auto fail = [&](const std::string& why) {
    png_image_free(&image);
    return MeshError(path + ": cannot write PNG (" + why + ")");
  };
  png_alloc_size_t size = 0;
  if (!png_image_write_get_memory_size(image, size, 0, bytes.data(), 3 * width_, nullptr)) throw fail(image.message);
  std::vector<png_byte> encoded(size);
  if (!png_image_write_to_memory(&image, encoded.data(), &size, 0, bytes.data(), 3 * width_, nullptr))
    throw fail(image.message);
  // Written as the tool's output files are (scenes/output_file.h): beside the destination,
  // then renamed over it.
  OpenOutput out;
  if (const int error = openOutput(path, out)) throw fail(std::strerror(error));
  const bool write_failed = !writeOutput(out, encoded.data(), size);
  const int write_error = write_failed ? errno : 0;
  if (const int error = finishOutput(out, write_failed)) throw fail(std::strerror(write_error ? write_error : error));
  png_image_free(&image);
}

}  // namespace meshsweeper::scenes
