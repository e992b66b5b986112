// A small RGB raster with the few primitives the filmstrip needs, and PNG output (libpng).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace perch {

struct Rgb {
  uint8_t r = 0, g = 0, b = 0;
  bool operator==(const Rgb& o) const { return r == o.r && g == o.g && b == o.b; }
};

class Canvas {
 public:
  Canvas(int width, int height, Rgb background);
  int width() const { return width_; }
  int height() const { return height_; }
  Rgb at(int x, int y) const { return pixels_[static_cast<size_t>(y) * width_ + x]; }
  void Set(int x, int y, Rgb c);

  // Fills every pixel within `radius` pixels of the segment a-b (a capsule; a disc when a == b).
  void FillCapsule(const Eigen::Vector2d& a, const Eigen::Vector2d& b, double radius, Rgb c);
  // Fills the convex hull of `points` (pixel coordinates).
  void FillConvexHull(const std::vector<Eigen::Vector2d>& points, Rgb c);
  void FillRect(int x0, int y0, int x1, int y1, Rgb c);  // inclusive corners, clipped
  void DrawLine(const Eigen::Vector2d& a, const Eigen::Vector2d& b, Rgb c) {
    FillCapsule(a, b, 0.5, c);
  }
  // Draws `text` with a 3x5-pixel font magnified `scale` times, top-left at (x, y). Knows digits,
  // lower-case letters, space and . : - _ = % / ( ); other characters are drawn as a box.
  void DrawText(int x, int y, const std::string& text, Rgb c, int scale = 2);
  static int TextWidth(const std::string& text, int scale = 2) {
    return static_cast<int>(text.size()) * 4 * scale - scale;
  }
  // Blits `other` with its top-left corner at (x, y).
  void Blit(const Canvas& other, int x, int y);

  // Writes an 8-bit RGB PNG atomically (temporary file + rename); throws std::runtime_error
  // naming the path on failure.
  void SavePng(const std::string& path) const;
  // Reads an 8-bit RGB PNG (for tests and tools); throws std::runtime_error naming the path.
  static Canvas LoadPng(const std::string& path);

 private:
  int width_, height_;
  std::vector<Rgb> pixels_;
};

}  // namespace perch
