// The chair's height grid (envs/chair_grid.h), the sit's view of a chair's shape (issue 51): what
// it reads on a box chair, that a mesh of the same boxes reads the same, its left/right mirror,
// and that the proprio_chair_shape observation carries it after the 57-d state.
#include "envs/chair_grid.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/paths.h"
#include "envs/humanoid_env.h"
#include "tests/support/box_obj.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

// The highest box top over (x, y), or the floor: the grid's definition, written out again.
double TopOver(const Chair& c, double x, double y) {
  double top = 0.0;
  for (const ChairBox& b : c.boxes) {
    if (x >= b.min.x() && x <= b.max.x() && y >= b.min.y() && y <= b.max.y()) {
      top = std::max(top, b.max.z());
    }
  }
  return top;
}

TEST(ChairGrid, ReadsTheSeatTheBackrestAndTheFloorOfTheAuthorsChair) {
  const Chair c = Chair::Load(Chair::PresetPath("authors"));
  const double s = 0.15;
  const ChairGrid g = ChairHeightGrid(c, s);
  const double z = c.seat_target.z();
  auto at = [&](int i, int j) { return g[i * kChairGridSide + j]; };
  // Centre: the seat top over the target; 0.15 m forward still seat; 0.30 m forward the floor.
  EXPECT_NEAR(at(2, 2), c.seat_height() - z, 1e-6);
  EXPECT_NEAR(at(3, 2), c.seat_height() - z, 1e-6);
  EXPECT_NEAR(at(4, 2), -z, 1e-6);
  // 0.15 m behind: the backrest, about 0.41 m above the seat target.
  double back_top = 0.0;
  for (const ChairBox& b : c.boxes) {
    if (b.role == "backrest") back_top = b.max.z();
  }
  EXPECT_NEAR(at(1, 2), back_top - z, 1e-6);
  EXPECT_GT(at(1, 2), 0.3f);
  // Every point agrees with the boxes read directly.
  for (int i = 0; i < kChairGridSide; ++i) {
    for (int j = 0; j < kChairGridSide; ++j) {
      EXPECT_NEAR(at(i, j), TopOver(c, (i - 2) * s, (j - 2) * s) - z, 1e-6) << i << "," << j;
    }
  }
  // Chairs differ where their shapes do: the stool has no backrest, the armchair has arms.
  const ChairGrid stool = ChairHeightGrid(Chair::Load(Chair::PresetPath("stool")), s);
  EXPECT_LT(stool[1 * kChairGridSide + 2], 0.05f);
  const Chair arm = Chair::Load(Chair::PresetPath("armchair"));
  const ChairBox* right = nullptr;  // the armrest on the chair's right (-y)
  for (const ChairBox& b : arm.boxes) {
    if (b.role == "armrest" && b.center().y() < 0) right = &b;
  }
  ASSERT_NE(right, nullptr);
  // A spacing that puts column 0 over the right armrest's centre line.
  const ChairGrid ga = ChairHeightGrid(arm, (arm.seat_target.y() - right->center().y()) / 2.0);
  EXPECT_NEAR(ga[2 * kChairGridSide + 0], right->max.z() - arm.seat_target.z(), 1e-6);
  EXPECT_GT(ga[2 * kChairGridSide + 0], 0.1f);
}

// A box chair written as an OBJ under a turn, an offset and centimetres reads the same grid as
// the boxes (the mesh's floor is its lowest point, so heights are compared above the seat).
TEST(ChairGrid, AMeshOfTheSameBoxesReadsTheSameGrid) {
  const fs::path dir =
      fs::temp_directory_path() / ("perch_chair_grid_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const Chair boxes = Chair::Load(Chair::PresetPath("armchair"));
  const double yaw = 63.0 * M_PI / 180.0;
  const Eigen::Vector3d offset(0.7, -1.3, 0.0);
  std::ofstream(dir / "c.obj") << BoxesAsObj(boxes, yaw, offset, 0.01, false);
  std::ofstream(dir / "c.json")
      << Json{{"name", "c"}, {"mesh", "c.obj"}, {"scale", 0.01}, {"static", true}}.dump();
  const Chair mesh = Chair::Load((dir / "c.json").string());
  fs::remove_all(dir);
  ASSERT_TRUE(mesh.mesh);
  // Grid points off the boxes' edges (0.13 m spacing), where the two must agree exactly.
  const ChairGrid gb = ChairHeightGrid(boxes, 0.13);
  const ChairGrid gm = ChairHeightGrid(mesh, 0.13);
  for (int k = 0; k < kChairGridDim; ++k) {
    const bool floor_b = gb[k] <= -boxes.seat_target.z() + 1e-6;
    if (floor_b) {
      EXPECT_NEAR(gm[k], -mesh.seat_target.z(), 1e-3) << k;  // the floor under both
    } else {
      EXPECT_NEAR(gm[k], gb[k], 2e-3) << k;
    }
  }
}

TEST(ChairGrid, TheMirroredChairReadsTheMirroredGrid) {
  Chair c = Chair::Load(Chair::PresetPath("authors"));  // its backrest is off-centre in y
  Chair m = c;
  for (ChairBox& b : m.boxes) {
    const double lo = -b.max.y(), hi = -b.min.y();
    b.min.y() = lo;
    b.max.y() = hi;
  }
  m.seat_target.y() = -c.seat_target.y();
  const ChairGrid g = ChairHeightGrid(c, 0.17), gm = ChairHeightGrid(m, 0.17);
  int differ = 0;
  for (int k = 0; k < kChairGridDim; ++k) {
    EXPECT_EQ(gm[MirroredGridIndex(k)], g[k]) << k;
    EXPECT_EQ(MirroredGridIndex(MirroredGridIndex(k)), k);
    differ += g[k] != g[MirroredGridIndex(k)];
  }
  EXPECT_GT(differ, 0) << "the chair should not be symmetric for this test to mean anything";
}

// proprio_chair_shape = proprio_chair's 57 + the grid; its mirror map reverses the grid's columns.
TEST(ChairGrid, TheShapeObservationIsTheChairStateThenTheGrid) {
  EnvConfig a;
  a.obs_layout = ObsLayout::kProprioChairShape;
  a.chair = "armchair";
  EnvConfig b = a;
  b.obs_layout = ObsLayout::kProprioChair;
  HumanoidChairEnv ea(a), eb(b);
  ASSERT_EQ(ea.spec().obs_dim, 82);
  std::vector<float> oa(82), ob(57);
  ea.Seed(3);
  eb.Seed(3);
  ea.Reset(oa.data());
  eb.Reset(ob.data());
  for (int i = 0; i < 57; ++i) EXPECT_EQ(oa[i], ob[i]) << i;
  const ChairGrid g = ChairHeightGrid(*ea.chair(), a.obs.chair_grid_spacing);
  for (int k = 0; k < kChairGridDim; ++k) EXPECT_EQ(oa[kObsShape + k], g[k]) << k;
  // The env writes any layout on request (the hierarchy's sit): the same numbers.
  std::vector<float> again(82);
  eb.WriteObservation(ObsLayout::kProprioChairShape, again.data());
  for (int k = 0; k < kChairGridDim; ++k) EXPECT_EQ(again[kObsShape + k], g[k]) << k;
  const MirrorMap& m = ea.spec().mirror;
  for (int k = 0; k < kChairGridDim; ++k) {
    EXPECT_EQ(m.obs_src[kObsShape + MirroredGridIndex(k)], kObsShape + k);
    EXPECT_EQ(m.obs_scale[kObsShape + k], 1.0f);
  }
  bool has_slice = false;
  for (const auto& s : ea.spec().obs_slices) has_slice |= s.name == "shape" && s.size == 25;
  EXPECT_TRUE(has_slice);
}

}  // namespace
}  // namespace perch
