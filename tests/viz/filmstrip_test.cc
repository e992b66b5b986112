#include "viz/filmstrip.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <string>

#include "common/paths.h"

namespace perch {
namespace {

const Rgb kCentre{60, 60, 90};
const Rgb kSeat{190, 145, 95};

PoseFrame Standing(double x, double y) {
  PoseFrame f;
  f.root_pos = Eigen::Vector3d(x, y, 1.285);
  f.q.assign(HumanoidModel::kNumJoints, 0.0);
  // Knees must be inside their range (-160..-2 deg); a tiny bend keeps the pose legal.
  return f;
}

// Pixel of a world point in panel k of a strip rendered with a fixed window (mirrors the
// renderer's mapping: extent, centre, side-view ground 15% above the bottom).
struct Mapper {
  double scale, cx, cy_side, cy_top;
  int px;
  Eigen::Vector2i Side(int k, double x, double z) const {
    return Eigen::Vector2i(static_cast<int>(k * px + px * 0.5 + (x - cx) * scale),
                           static_cast<int>(px * 0.5 - (z - cy_side) * scale));
  }
  Eigen::Vector2i Top(int k, double x, double y) const {
    return Eigen::Vector2i(static_cast<int>(k * px + px * 0.5 + (x - cx) * scale),
                           static_cast<int>(px + 1 + px * 0.5 - (y - cy_top) * scale));
  }
};

TEST(Filmstrip, PoseFrameOfCopiesTheSimulatedStateInObservationOrder) {
  HumanoidState s;
  s.root_pos = Eigen::Vector3d(0.5, -1.25, 0.9);
  s.root_quat = Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()));
  for (int i = 0; i < HumanoidModel::kNumJoints; ++i) s.q[i] = 0.01 * (i + 1);
  s.qd.fill(3.0);  // speeds are not drawn
  const PoseFrame f = PoseFrameOf(s, 1.5, "sit");
  EXPECT_EQ(f.root_pos, s.root_pos);
  EXPECT_TRUE(f.root_quat.isApprox(s.root_quat));
  ASSERT_EQ(f.q.size(), static_cast<size_t>(HumanoidModel::kNumJoints));
  for (int i = 0; i < HumanoidModel::kNumJoints; ++i) EXPECT_EQ(f.q[i], s.q[i]) << i;
  EXPECT_EQ(f.time_s, 1.5);
  EXPECT_EQ(f.label, "sit");
  EXPECT_EQ(PoseFrameOf(s, 0.0).label, "");
}

TEST(Filmstrip, StandingHumanoidIsDrawnWhereFkPutsIt) {
  const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
  FilmstripOptions opt;
  opt.panel_px = 200;
  opt.min_extent_m = 2.0;
  opt.margin_m = 0.5;
  const Canvas c =
      RenderFilmstrip(model, nullptr, Eigen::Isometry3d::Identity(), {Standing(0, 0)}, opt);
  ASSERT_EQ(c.width(), 200);
  ASSERT_EQ(c.height(), 401 + 16);  // two panels, a separator and the caption row
  const Mapper m{200 / 2.0, 0.0, 0.35 * 2.0, 0.0, 200};
  // The head sphere (torso frame z = 0.19, r = 0.09) is torso-coloured in the side view...
  const Eigen::Vector2i head = m.Side(0, 0.03, 1.285 + 0.19);
  EXPECT_EQ(c.at(head.x(), head.y()), kCentre);
  // ...and nothing is drawn 10 cm above the top of the head.
  const Eigen::Vector2i above = m.Side(0, 0.03, 1.285 + 0.19 + 0.09 + 0.10);
  EXPECT_FALSE(c.at(above.x(), above.y()) == kCentre);
  // Top view: the torso is at the origin.
  const Eigen::Vector2i torso = m.Top(0, 0.03, 0.03);
  EXPECT_EQ(c.at(torso.x(), torso.y()), kCentre);
}

TEST(Filmstrip, ChairSeatVisibleAndFramesPicked) {
  const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
  const Chair chair = Chair::Load(Chair::PresetPath("authors"));
  std::vector<PoseFrame> all;
  for (int i = 0; i < 10; ++i) all.push_back(Standing(1.0 + 0.1 * i, 0.0));
  const std::vector<PoseFrame> picked = PickFrames(all, 3);
  ASSERT_EQ(picked.size(), 3u);
  EXPECT_DOUBLE_EQ(picked.front().root_pos.x(), 1.0);
  EXPECT_DOUBLE_EQ(picked.back().root_pos.x(), 1.9);
  FilmstripOptions opt;
  opt.panel_px = 200;
  const Canvas c = RenderFilmstrip(model, &chair, Eigen::Isometry3d::Identity(), picked, opt);
  EXPECT_EQ(c.width(), 600);
  // Window: roots x in [1.0, 1.9] and the chair at 0 -> lo 0, hi 1.9; extent = 1.9 + 1.2 = 3.1.
  const double extent = 3.1;
  const Mapper m{200 / extent, 0.95, 0.35 * extent, 0.0, 200};
  const Eigen::Vector2i seat = m.Top(1, 0.05, 0.05);  // seat top seen from above, panel 1
  EXPECT_EQ(c.at(seat.x(), seat.y()), kSeat);
}

TEST(Filmstrip, FarWalkTargetIsInsideTheFixedWindow) {
  const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
  FilmstripOptions opt;
  opt.panel_px = 200;
  opt.targets = {Eigen::Vector2d(4.0, 3.0)};
  const Canvas c =
      RenderFilmstrip(model, nullptr, Eigen::Isometry3d::Identity(), {Standing(0, 0)}, opt);
  const Rgb target{30, 160, 60};
  int green = 0;
  for (int y = 201; y < c.height(); ++y)
    for (int x = 0; x < c.width(); ++x) green += c.at(x, y) == target;
  EXPECT_GT(green, 10);
}

// A long episode (20 m of path) drawn following the humanoid keeps it humanoid-sized: each panel
// is the same picture as the same pose alone.
TEST(Filmstrip, FollowingKeepsTheHumanoidLargeOnLongPaths) {
  const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
  FilmstripOptions opt;
  opt.panel_px = 120;
  opt.follow = true;
  const Canvas alone =
      RenderFilmstrip(model, nullptr, Eigen::Isometry3d::Identity(), {Standing(20, 0)}, opt);
  const Canvas path = RenderFilmstrip(model, nullptr, Eigen::Isometry3d::Identity(),
                                      {Standing(0, 0), Standing(20, 0)}, opt);
  ASSERT_EQ(path.width(), 240);
  int torso = 0;
  for (int y = 0; y < alone.height(); ++y) {
    for (int x = 0; x < alone.width(); ++x) {
      torso += alone.at(x, y) == kCentre;
      if (x == 0) continue;  // the panel separator
      ASSERT_EQ(path.at(120 + x, y), alone.at(x, y)) << x << "," << y;
    }
  }
  // And at the default 2.2 m window the torso covers a visible area (not a few pixels).
  EXPECT_GT(torso, 40);
}

TEST(Filmstrip, EachFrameIsCaptionedWithItsTimeAndLabel) {
  const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
  FilmstripOptions opt;
  opt.panel_px = 150;
  PoseFrame a = Standing(0, 0), b = Standing(0, 0);
  a.time_s = 0.0;
  b.time_s = 1.25;
  b.label = "sit";
  const Canvas c = RenderFilmstrip(model, nullptr, Eigen::Isometry3d::Identity(), {a, b}, opt);
  ASSERT_EQ(c.height(), 2 * 150 + 1 + 16);
  // The caption row of each panel against the text drawn alone.
  auto caption_ink = [&](int panel) {
    int ink = 0;
    for (int y = 301; y < c.height(); ++y)
      for (int x = panel * 150 + 1; x < (panel + 1) * 150; ++x)
        ink += c.at(x, y) == Rgb{20, 20, 20};
    return ink;
  };
  auto ink_of = [](const std::string& text) {
    Canvas t(200, 20, Rgb{255, 255, 255});
    t.DrawText(0, 0, text, Rgb{20, 20, 20});
    int ink = 0;
    for (int y = 0; y < 20; ++y)
      for (int x = 0; x < 200; ++x) ink += t.at(x, y) == Rgb{20, 20, 20};
    return ink;
  };
  EXPECT_EQ(caption_ink(0), ink_of("0.00 s"));
  EXPECT_EQ(caption_ink(1), ink_of("1.25 s sit"));
  EXPECT_NE(ink_of("1"), ink_of("8"));  // glyphs differ
  EXPECT_EQ(Canvas::TextWidth("abc", 2), 3 * 8 - 2);
}

// A mesh chair is drawn from its triangles: the chair's pixels in the top view span its bounding
// box (x by y, to the pixel scale), the seat target's green cross is on them, and the side view
// shows the chair above the ground line.
TEST(Filmstrip, ChairViewsDrawAMeshChairToScaleWithItsSeatTarget) {
  if (SharedDir().empty()) GTEST_SKIP() << "../shared is absent";
  const Chair chair = Chair::Load(ResolveProjectPath("data/chairs/meshes/dining_scenic.json"));
  const int px = 300;
  const Canvas c = RenderChairViews(chair, px);
  ASSERT_EQ(c.width(), 2 * px + 1);
  auto brown = [](Rgb p) { return p.r > p.g + 15 && p.g > p.b + 10; };
  auto green = [](Rgb p) { return p.g > 120 && p.r < 80 && p.b < 100; };
  int x0 = px, x1 = -1, y0 = px, y1 = -1, greens = 0, side_brown = 0;
  for (int y = 0; y < px; ++y) {
    for (int x = 0; x < px; ++x) {
      const Rgb p = c.at(x, y);
      if (green(p)) ++greens;
      if (!brown(p)) continue;
      x0 = std::min(x0, x);
      x1 = std::max(x1, x);
      y0 = std::min(y0, y);
      y1 = std::max(y1, y);
    }
    for (int x = px + 1; x < 2 * px + 1; ++x) side_brown += brown(c.at(x, y));
  }
  ASSERT_GT(x1, x0);
  const Eigen::Vector3d size = chair.mesh->visual.Bounds().sizes();
  const double scale = px / std::max(1.0, size.maxCoeff() + 0.5);  // the renderer's px per m
  EXPECT_NEAR((x1 - x0 + 1) / scale, size.x(), 0.02);
  EXPECT_NEAR((y1 - y0 + 1) / scale, size.y(), 0.02);
  EXPECT_GT(greens, 20);
  EXPECT_GT(side_brown, 2000);
}

TEST(Canvas, PngRoundTripAndFailedSaveLeavesNothing) {
  Canvas c(17, 9, Rgb{1, 2, 3});
  c.FillCapsule(Eigen::Vector2d(2, 2), Eigen::Vector2d(14, 6), 2.0, Rgb{200, 100, 50});
  const std::string path = std::string(::testing::TempDir()) + "strip.png";
  c.SavePng(path);
  const Canvas back = Canvas::LoadPng(path);
  ASSERT_EQ(back.width(), 17);
  ASSERT_EQ(back.height(), 9);
  for (int y = 0; y < 9; ++y)
    for (int x = 0; x < 17; ++x) ASSERT_EQ(back.at(x, y), c.at(x, y));
  EXPECT_THROW(c.SavePng("/nonexistent_perch_dir/x.png"), std::runtime_error);
  std::FILE* f = std::fopen("/nonexistent_perch_dir/x.png.tmp", "rb");
  EXPECT_EQ(f, nullptr);
  // A file that is not a PNG is refused by name.
  const std::string bad = std::string(::testing::TempDir()) + "bad.png";
  std::FILE* w = std::fopen(bad.c_str(), "wb");
  std::fputs("not a png", w);
  std::fclose(w);
  try {
    Canvas::LoadPng(bad);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(bad), std::string::npos);
  }
}

}  // namespace
}  // namespace perch
