#include "envs/chair_grid.h"

#include <algorithm>
#include <limits>

namespace perch {
namespace {

// The highest z of `m` over (x, y): the largest height among triangles whose projection on the
// floor holds the point; -inf when none does.
double MeshTopAt(const TriMesh& m, double x, double y) {
  double top = -std::numeric_limits<double>::infinity();
  for (const auto& t : m.triangles) {
    const Eigen::Vector3d& a = m.vertices[t[0]];
    const Eigen::Vector3d& b = m.vertices[t[1]];
    const Eigen::Vector3d& c = m.vertices[t[2]];
    // Cheap rejection on the bounding box first: most triangles are far from the point.
    if (x < std::min({a.x(), b.x(), c.x()}) || x > std::max({a.x(), b.x(), c.x()}) ||
        y < std::min({a.y(), b.y(), c.y()}) || y > std::max({a.y(), b.y(), c.y()})) {
      continue;
    }
    const double d = (b.y() - c.y()) * (a.x() - c.x()) + (c.x() - b.x()) * (a.y() - c.y());
    if (std::abs(d) < 1e-12) continue;  // seen edge-on from above: its neighbours hold the top
    const double l1 = ((b.y() - c.y()) * (x - c.x()) + (c.x() - b.x()) * (y - c.y())) / d;
    const double l2 = ((c.y() - a.y()) * (x - c.x()) + (a.x() - c.x()) * (y - c.y())) / d;
    const double l3 = 1.0 - l1 - l2;
    constexpr double kEps = -1e-9;
    if (l1 < kEps || l2 < kEps || l3 < kEps) continue;
    top = std::max(top, l1 * a.z() + l2 * b.z() + l3 * c.z());
  }
  return top;
}

double BoxesTopAt(const std::vector<ChairBox>& boxes, double x, double y) {
  double top = -std::numeric_limits<double>::infinity();
  for (const ChairBox& b : boxes) {
    if (x >= b.min.x() && x <= b.max.x() && y >= b.min.y() && y <= b.max.y()) {
      top = std::max(top, b.max.z());
    }
  }
  return top;
}

}  // namespace

ChairGrid ChairHeightGrid(const Chair& chair, double spacing_m) {
  ChairGrid g{};
  const Eigen::Vector3d& s = chair.seat_target;
  const int half = kChairGridSide / 2;
  for (int i = 0; i < kChairGridSide; ++i) {
    for (int j = 0; j < kChairGridSide; ++j) {
      const double x = s.x() + (i - half) * spacing_m;
      const double y = s.y() + (j - half) * spacing_m;
      double top = chair.mesh ? MeshTopAt(chair.mesh->visual, x, y) : BoxesTopAt(chair.boxes, x, y);
      top = std::max(top, 0.0);  // the floor
      g[i * kChairGridSide + j] = static_cast<float>(top - s.z());
    }
  }
  return g;
}

}  // namespace perch
