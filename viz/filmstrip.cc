#include "viz/filmstrip.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <utility>

namespace perch {
namespace {

const Rgb kBackground{250, 250, 247};
const Rgb kGround{200, 200, 195};
const Rgb kGrid{228, 228, 222};
const Rgb kSeparator{120, 120, 120};
const Rgb kCentre{60, 60, 90};
const Rgb kRight{200, 70, 60};
const Rgb kLeft{70, 110, 200};
const Rgb kChair{150, 110, 70};
const Rgb kSeat{190, 145, 95};
const Rgb kTarget{30, 160, 60};

// A drawable item with a depth for painter's ordering (larger depth is drawn first).
struct Item {
  double depth;
  bool is_box;           // a box or a mesh triangle: the convex hull of `corners`
  Eigen::Vector3d a, b;  // capsule ends (world)
  double radius;
  std::vector<Eigen::Vector3d> corners;  // box corners or triangle vertices (world)
  Rgb color;
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // a triangle's, for shading; zero: flat
};

// A mesh triangle is shaded by how squarely it faces the viewer, so its shape reads.
Rgb Shade(const Item& it, bool top) {
  if (it.normal.isZero()) return it.color;
  const double f = 0.55 + 0.45 * std::abs(top ? it.normal.z() : it.normal.y());
  return Rgb{static_cast<uint8_t>(it.color.r * f), static_cast<uint8_t>(it.color.g * f),
             static_cast<uint8_t>(it.color.b * f)};
}

// The chair's boxes, or its mesh's triangles (those of the seat surface in the seat colour).
std::vector<Item> ChairItems(const Chair& chair, const Eigen::Isometry3d& pose) {
  std::vector<Item> items;
  for (size_t i = 0; i < chair.boxes.size(); ++i) {
    const ChairBox& b = chair.boxes[i];
    Item it{};
    it.is_box = true;
    for (int c = 0; c < 8; ++c) {
      const Eigen::Vector3d local((c & 1) ? b.max.x() : b.min.x(), (c & 2) ? b.max.y() : b.min.y(),
                                  (c & 4) ? b.max.z() : b.min.z());
      it.corners.push_back(pose * local);
    }
    it.color = static_cast<int>(i) == chair.seat_box ? kSeat : kChair;
    items.push_back(it);
  }
  if (chair.mesh) {
    const TriMesh& m = chair.mesh->visual;
    constexpr double kSeatBand = 0.03;  // [m] upward triangles this near the seat height
    for (const auto& t : m.triangles) {
      Item it{};
      it.is_box = true;
      for (int k : t) it.corners.push_back(m.vertices[k]);
      const Eigen::Vector3d n =
          (it.corners[1] - it.corners[0]).cross(it.corners[2] - it.corners[0]);
      if (n.norm() <= 0.0) continue;
      it.normal = n.normalized();
      const double z = (it.corners[0].z() + it.corners[1].z() + it.corners[2].z()) / 3.0;
      it.color =
          it.normal.z() > 0.9 && std::abs(z - chair.seat_height()) < kSeatBand ? kSeat : kChair;
      for (auto& p : it.corners) p = pose * p;
      it.normal = pose.linear() * it.normal;
      items.push_back(it);
    }
  }
  return items;
}

Rgb BodyColor(const std::string& name) {
  if (name.rfind("right_", 0) == 0) return kRight;
  if (name.rfind("left_", 0) == 0) return kLeft;
  return kCentre;
}

struct View {
  // Maps world to pixels: side view uses (x, z), top view uses (x, y).
  bool top;
  double cx, cy;  // world centre of the panel (x and z or y) [m]
  double scale;   // px per m
  int px;
  Eigen::Vector2d Map(const Eigen::Vector3d& w) const {
    const double u = w.x();
    const double v = top ? w.y() : w.z();
    return Eigen::Vector2d(px * 0.5 + (u - cx) * scale, px * 0.5 - (v - cy) * scale);
  }
};

// Painter's depths of the same items for the side view (mean y: farther first) and the top view
// (highest point: lower first).
void SideAndTopDepths(const std::vector<Item>& items, std::vector<Item>* side,
                      std::vector<Item>* top) {
  *side = items;
  *top = items;
  for (auto& it : *side) {
    double y = 0;
    for (const auto& c : it.corners) y += c.y() / static_cast<double>(it.corners.size());
    it.depth = y;
  }
  for (auto& it : *top) {
    double z = 0;
    for (const auto& c : it.corners) z = std::max(z, c.z());
    it.depth = -z;
  }
}

void DrawPanel(Canvas& panel, const View& view, const std::vector<Item>& items_in,
               const std::vector<Eigen::Vector2d>& targets) {
  // Grid every 0.5 m, then the ground line in the side view.
  const double half = panel.width() * 0.5 / view.scale;
  for (double g = std::floor((view.cx - half) * 2) / 2; g <= view.cx + half; g += 0.5) {
    const Eigen::Vector2d p = view.Map(Eigen::Vector3d(g, 0, 0));
    panel.FillRect(static_cast<int>(p.x()), 0, static_cast<int>(p.x()), panel.height() - 1, kGrid);
  }
  if (view.top) {
    for (double g = std::floor((view.cy - half) * 2) / 2; g <= view.cy + half; g += 0.5) {
      const Eigen::Vector2d p = view.Map(Eigen::Vector3d(0, g, 0));
      panel.FillRect(0, static_cast<int>(p.y()), panel.width() - 1, static_cast<int>(p.y()), kGrid);
    }
  } else {
    const Eigen::Vector2d p = view.Map(Eigen::Vector3d(0, 0, 0));
    panel.FillRect(0, static_cast<int>(p.y()), panel.width() - 1, panel.height() - 1, kGround);
  }
  std::vector<Item> items = items_in;
  std::stable_sort(items.begin(), items.end(),
                   [](const Item& x, const Item& y) { return x.depth > y.depth; });
  for (const Item& it : items) {
    if (it.is_box) {
      std::vector<Eigen::Vector2d> pts;
      for (const auto& c : it.corners) pts.push_back(view.Map(c));
      panel.FillConvexHull(pts, Shade(it, view.top));
    } else {
      panel.FillCapsule(view.Map(it.a), view.Map(it.b), std::max(1.0, it.radius * view.scale),
                        it.color);
    }
  }
  if (view.top) {
    for (const auto& t : targets) {
      const Eigen::Vector2d p = view.Map(Eigen::Vector3d(t.x(), t.y(), 0));
      panel.FillCapsule(p + Eigen::Vector2d(-5, -5), p + Eigen::Vector2d(5, 5), 1.5, kTarget);
      panel.FillCapsule(p + Eigen::Vector2d(-5, 5), p + Eigen::Vector2d(5, -5), 1.5, kTarget);
    }
  }
}

}  // namespace

std::vector<PoseFrame> PickFrames(const std::vector<PoseFrame>& all, int count) {
  std::vector<PoseFrame> out;
  if (all.empty() || count <= 0) return out;
  if (count == 1 || all.size() == 1) return {all.front()};
  for (int i = 0; i < count; ++i) {
    const size_t idx =
        static_cast<size_t>(std::llround(static_cast<double>(i) * (all.size() - 1) / (count - 1)));
    out.push_back(all[idx]);
  }
  return out;
}

Canvas RenderFilmstrip(const HumanoidModel& model, const Chair* chair,
                       const Eigen::Isometry3d& chair_pose, const std::vector<PoseFrame>& frames,
                       const FilmstripOptions& options) {
  if (frames.empty()) throw std::runtime_error("RenderFilmstrip: no frames");
  const int px = options.panel_px;
  // Chair items are the same in every frame.
  std::vector<Item> chair_side, chair_top;
  if (chair) SideAndTopDepths(ChairItems(*chair, chair_pose), &chair_side, &chair_top);
  // One fixed window over all roots and the chair, unless following.
  Eigen::Vector2d lo(1e9, 1e9), hi(-1e9, -1e9);
  for (const auto& f : frames) {
    lo = lo.cwiseMin(f.root_pos.head<2>());
    hi = hi.cwiseMax(f.root_pos.head<2>());
  }
  if (chair) {
    lo = lo.cwiseMin(chair_pose.translation().head<2>());
    hi = hi.cwiseMax(chair_pose.translation().head<2>());
  }
  for (const Eigen::Vector2d& t : options.targets) {
    lo = lo.cwiseMin(t);
    hi = hi.cwiseMax(t);
  }
  // Following: a humanoid-sized window, so the gait stays readable on long episodes (the fixed
  // window is the overview of the whole path).
  const double extent = options.follow ? options.min_extent_m
                                       : std::max(options.min_extent_m,
                                                  (hi - lo).maxCoeff() + 2.0 * options.margin_m);
  const double scale = px / extent;
  const Eigen::Vector2d centre = 0.5 * (lo + hi);

  constexpr int kCaption = 16;  // caption row under the panels [px]
  Canvas strip(px * static_cast<int>(frames.size()), 2 * px + 1 + kCaption, kBackground);
  for (size_t k = 0; k < frames.size(); ++k) {
    const PoseFrame& f = frames[k];
    if (static_cast<int>(f.q.size()) != model.num_joints())
      throw std::runtime_error("RenderFilmstrip: frame has wrong number of joint angles");
    const FkResult fk = ForwardKinematics(model, f.root_pos, f.root_quat, f.q.data());
    std::vector<Item> side = chair_side, top = chair_top;
    for (int bi = 0; bi < model.num_bodies(); ++bi) {
      const Body& body = model.body(bi);
      for (const Geom& g : body.geoms) {
        Item it{};
        it.is_box = false;
        it.a = fk.body_world[bi] * g.from;
        it.b = fk.body_world[bi] * g.to;
        it.radius = g.radius;
        it.color = BodyColor(body.name);
        it.depth = 0.5 * (it.a.y() + it.b.y());
        side.push_back(it);
        it.depth = -0.5 * (it.a.z() + it.b.z()) - g.radius;
        top.push_back(it);
      }
    }
    const Eigen::Vector2d c = options.follow ? Eigen::Vector2d(f.root_pos.head<2>()) : centre;
    Canvas side_panel(px, px, kBackground), top_panel(px, px, kBackground);
    // Side view: the ground line 15% of the panel above its bottom edge.
    const View sv{false, c.x(), 0.35 * extent, scale, px};
    View tv{true, c.x(), c.y(), scale, px};
    DrawPanel(side_panel, sv, side, {});
    DrawPanel(top_panel, tv, top, options.targets);
    strip.Blit(side_panel, static_cast<int>(k) * px, 0);
    strip.Blit(top_panel, static_cast<int>(k) * px, px + 1);
    char caption[64];
    std::snprintf(caption, sizeof(caption), "%.2f s", f.time_s);
    std::string text = caption;
    if (!f.label.empty()) text += " " + f.label;
    while (text.size() > 4 && Canvas::TextWidth(text) > px - 4) text.pop_back();
    strip.DrawText(static_cast<int>(k) * px + 3, 2 * px + 4, text, Rgb{20, 20, 20});
    if (k > 0) {
      strip.FillRect(static_cast<int>(k) * px, 0, static_cast<int>(k) * px, 2 * px + kCaption,
                     kSeparator);
    }
  }
  strip.FillRect(0, px, strip.width() - 1, px, kSeparator);
  return strip;
}

Canvas RenderChairViews(const Chair& chair, int panel_px) {
  const std::vector<Item> items = ChairItems(chair, Eigen::Isometry3d::Identity());
  Eigen::AlignedBox3d box;
  for (const Item& it : items) {
    for (const auto& c : it.corners) box.extend(c);
  }
  box.extend(chair.seat_target);
  const double extent = std::max(1.0, box.sizes().maxCoeff() + 0.5);
  const double scale = panel_px / extent;
  const Eigen::Vector3d mid = box.center();
  const View tv{true, mid.x(), mid.y(), scale, panel_px};
  const View sv{false, mid.x(), mid.z(), scale, panel_px};
  std::vector<Item> side, top;
  SideAndTopDepths(items, &side, &top);  // a chair stands on z = 0: no corner below the floor
  Canvas top_panel(panel_px, panel_px, kBackground), side_panel(panel_px, panel_px, kBackground);
  DrawPanel(top_panel, tv, top, {});
  DrawPanel(side_panel, sv, side, {});
  // The seat target (a green cross) and the facing (+x of the chair frame, a 0.3 m arrow).
  const Eigen::Vector3d s = chair.seat_target;
  const Eigen::Vector3d tip = s + Eigen::Vector3d(0.3, 0, 0);
  for (auto [panel, view] : {std::pair<Canvas*, const View*>{&top_panel, &tv},
                             std::pair<Canvas*, const View*>{&side_panel, &sv}}) {
    const Eigen::Vector2d p = view->Map(s), q = view->Map(tip);
    panel->FillCapsule(p + Eigen::Vector2d(-6, -6), p + Eigen::Vector2d(6, 6), 1.5, kTarget);
    panel->FillCapsule(p + Eigen::Vector2d(-6, 6), p + Eigen::Vector2d(6, -6), 1.5, kTarget);
    panel->FillCapsule(p, q, 1.5, kTarget);
    const Eigen::Vector2d d = (q - p).normalized(), n(-d.y(), d.x());
    panel->FillCapsule(q, q - 8 * d + 5 * n, 1.5, kTarget);
    panel->FillCapsule(q, q - 8 * d - 5 * n, 1.5, kTarget);
  }
  constexpr int kCaption = 16;
  Canvas out(2 * panel_px + 1, panel_px + kCaption, kBackground);
  out.Blit(top_panel, 0, 0);
  out.Blit(side_panel, panel_px + 1, 0);
  out.FillRect(panel_px, 0, panel_px, panel_px + kCaption - 1, kSeparator);
  out.DrawText(3, panel_px + 4, "top", Rgb{20, 20, 20});
  out.DrawText(panel_px + 4, panel_px + 4, "side", Rgb{20, 20, 20});
  return out;
}

}  // namespace perch
