#include "viz/canvas.h"

#include <png.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <utility>

#include "common/file_util.h"

namespace perch {

Canvas::Canvas(int width, int height, Rgb background)
    : width_(width), height_(height), pixels_(static_cast<size_t>(width) * height, background) {
  if (width <= 0 || height <= 0) throw std::runtime_error("Canvas: size must be positive");
}

void Canvas::Set(int x, int y, Rgb c) {
  if (x < 0 || y < 0 || x >= width_ || y >= height_) return;
  pixels_[static_cast<size_t>(y) * width_ + x] = c;
}

void Canvas::FillCapsule(const Eigen::Vector2d& a, const Eigen::Vector2d& b, double radius, Rgb c) {
  const int x0 = std::max(0, static_cast<int>(std::floor(std::min(a.x(), b.x()) - radius)));
  const int x1 = std::min(width_ - 1, static_cast<int>(std::ceil(std::max(a.x(), b.x()) + radius)));
  const int y0 = std::max(0, static_cast<int>(std::floor(std::min(a.y(), b.y()) - radius)));
  const int y1 =
      std::min(height_ - 1, static_cast<int>(std::ceil(std::max(a.y(), b.y()) + radius)));
  const Eigen::Vector2d ab = b - a;
  const double len2 = ab.squaredNorm();
  const double r2 = radius * radius;
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) {
      const Eigen::Vector2d p(x + 0.5, y + 0.5);
      double t = len2 > 0 ? (p - a).dot(ab) / len2 : 0.0;
      t = std::clamp(t, 0.0, 1.0);
      if ((p - (a + t * ab)).squaredNorm() <= r2) Set(x, y, c);
    }
  }
}

void Canvas::FillConvexHull(const std::vector<Eigen::Vector2d>& points, Rgb c) {
  if (points.empty()) return;
  // Andrew's monotone chain.
  std::vector<Eigen::Vector2d> p = points;
  std::sort(p.begin(), p.end(), [](const Eigen::Vector2d& u, const Eigen::Vector2d& v) {
    return u.x() < v.x() || (u.x() == v.x() && u.y() < v.y());
  });
  auto cross = [](const Eigen::Vector2d& o, const Eigen::Vector2d& u, const Eigen::Vector2d& v) {
    return (u.x() - o.x()) * (v.y() - o.y()) - (u.y() - o.y()) * (v.x() - o.x());
  };
  std::vector<Eigen::Vector2d> hull(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross(hull[k - 2], hull[k - 1], p[i]) <= 0) --k;
    hull[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && cross(hull[k - 2], hull[k - 1], p[i - 1]) <= 0) --k;
    hull[k++] = p[i - 1];
  }
  hull.resize(k > 1 ? k - 1 : k);
  double ymin = hull[0].y(), ymax = hull[0].y();
  for (const auto& h : hull) {
    ymin = std::min(ymin, h.y());
    ymax = std::max(ymax, h.y());
  }
  const int y0 = std::max(0, static_cast<int>(std::floor(ymin)));
  const int y1 = std::min(height_ - 1, static_cast<int>(std::ceil(ymax)));
  for (int y = y0; y <= y1; ++y) {
    const double yc = y + 0.5;
    double xl = 1e30, xr = -1e30;
    for (size_t i = 0; i < hull.size(); ++i) {
      const Eigen::Vector2d& u = hull[i];
      const Eigen::Vector2d& v = hull[(i + 1) % hull.size()];
      if ((u.y() <= yc && v.y() >= yc) || (v.y() <= yc && u.y() >= yc)) {
        const double dy = v.y() - u.y();
        const double x = std::abs(dy) < 1e-12 ? std::min(u.x(), v.x())
                                              : u.x() + (yc - u.y()) / dy * (v.x() - u.x());
        const double x2 = std::abs(dy) < 1e-12 ? std::max(u.x(), v.x()) : x;
        xl = std::min(xl, std::min(x, x2));
        xr = std::max(xr, std::max(x, x2));
      }
    }
    if (xl > xr) continue;
    for (int x = std::max(0, static_cast<int>(std::floor(xl)));
         x <= std::min(width_ - 1, static_cast<int>(std::ceil(xr))); ++x) {
      if (x + 0.5 >= xl && x + 0.5 <= xr) Set(x, y, c);
    }
  }
}

void Canvas::FillRect(int x0, int y0, int x1, int y1, Rgb c) {
  for (int y = std::max(0, y0); y <= std::min(height_ - 1, y1); ++y)
    for (int x = std::max(0, x0); x <= std::min(width_ - 1, x1); ++x) Set(x, y, c);
}

namespace {

// 3x5 glyphs, bit (row * 3 + col) set where the pixel is on.
uint16_t Glyph(char ch) {
  static const std::pair<char, uint16_t> kGlyphs[] = {
      {'0', 0x7b6f}, {'1', 0x749a}, {'2', 0x73e7}, {'3', 0x79e7}, {'4', 0x49ed}, {'5', 0x79cf},
      {'6', 0x7bcf}, {'7', 0x24a7}, {'8', 0x7bef}, {'9', 0x79ef}, {'.', 0x2000}, {':', 0x0410},
      {'_', 0x7000}, {'-', 0x01c0}, {'=', 0x0e38}, {' ', 0x0000}, {'%', 0x52a5}, {'/', 0x12a4},
      {'(', 0x224a}, {')', 0x2922}, {'a', 0x6b70}, {'b', 0x3b59}, {'c', 0x6270}, {'d', 0x6b74},
      {'e', 0x63d0}, {'f', 0x12ce}, {'g', 0x39ae}, {'h', 0x5b59}, {'i', 0x2482}, {'j', 0x2b04},
      {'k', 0x5ae9}, {'l', 0x7493}, {'m', 0x5bf8}, {'n', 0x5b58}, {'o', 0x2b50}, {'p', 0x1758},
      {'q', 0x4d70}, {'r', 0x1270}, {'s', 0x3cf0}, {'t', 0x64ba}, {'u', 0x6b68}, {'v', 0x2b68},
      {'w', 0x7f68}, {'x', 0x54a8}, {'y', 0x39a8}, {'z', 0x7338},
  };
  for (const auto& [c, bits] : kGlyphs) {
    if (c == ch) return bits;
  }
  return 0x7fff;  // unknown: a filled box
}

}  // namespace

void Canvas::DrawText(int x, int y, const std::string& text, Rgb c, int scale) {
  for (size_t i = 0; i < text.size(); ++i) {
    const uint16_t g = Glyph(static_cast<char>(std::tolower(static_cast<unsigned char>(text[i]))));
    const int gx = x + static_cast<int>(i) * 4 * scale;
    for (int r = 0; r < 5; ++r) {
      for (int col = 0; col < 3; ++col) {
        if (g & (1u << (r * 3 + col))) {
          FillRect(gx + col * scale, y + r * scale, gx + (col + 1) * scale - 1,
                   y + (r + 1) * scale - 1, c);
        }
      }
    }
  }
}

void Canvas::Blit(const Canvas& other, int x, int y) {
  for (int j = 0; j < other.height(); ++j)
    for (int i = 0; i < other.width(); ++i) Set(x + i, y + j, other.at(i, j));
}

namespace {

void AppendPngBytes(png_structp png, png_bytep data, png_size_t n) {
  static_cast<std::string*>(png_get_io_ptr(png))->append(reinterpret_cast<const char*>(data), n);
}
void FlushNothing(png_structp) {}

}  // namespace

void Canvas::SavePng(const std::string& path) const {
  // Encoded in memory, then written by the one atomic writer (common/file_util.h).
  std::string bytes;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    throw std::runtime_error(path + ": PNG encoding failed");
  }
  png_set_write_fn(png, &bytes, AppendPngBytes, FlushNothing);
  png_set_IHDR(png, info, width_, height_, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  std::vector<uint8_t> row(static_cast<size_t>(width_) * 3);
  for (int y = 0; y < height_; ++y) {
    for (int x = 0; x < width_; ++x) {
      const Rgb c = at(x, y);
      row[3 * x] = c.r;
      row[3 * x + 1] = c.g;
      row[3 * x + 2] = c.b;
    }
    png_write_row(png, row.data());
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  WriteFileAtomic(path, bytes);
}

Canvas Canvas::LoadPng(const std::string& path) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) throw std::runtime_error(path + ": cannot open PNG");
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info || setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    std::fclose(f);
    throw std::runtime_error(path + ": not a readable PNG");
  }
  png_init_io(png, f);
  png_read_info(png, info);
  const int w = png_get_image_width(png, info);
  const int h = png_get_image_height(png, info);
  if (png_get_color_type(png, info) != PNG_COLOR_TYPE_RGB || png_get_bit_depth(png, info) != 8) {
    png_destroy_read_struct(&png, &info, nullptr);
    std::fclose(f);
    throw std::runtime_error(path + ": only 8-bit RGB PNG is supported");
  }
  Canvas c(w, h, Rgb{});
  std::vector<uint8_t> row(static_cast<size_t>(w) * 3);
  for (int y = 0; y < h; ++y) {
    png_read_row(png, row.data(), nullptr);
    for (int x = 0; x < w; ++x) c.Set(x, y, Rgb{row[3 * x], row[3 * x + 1], row[3 * x + 2]});
  }
  png_destroy_read_struct(&png, &info, nullptr);
  std::fclose(f);
  return c;
}

}  // namespace perch
