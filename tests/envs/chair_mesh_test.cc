// Chairs from OBJ meshes: the shared meshes (../shared/chairs), a box chair written as an OBJ
// under a known transform (so the found seat and facing have an answer independent of the
// finder), given keys, and every refusal.
#include "envs/chair_mesh.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "common/paths.h"
#include "envs/chair.h"
#include "tests/support/box_obj.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

class ChairMeshTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("perch_chair_mesh_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) {
    const std::string p = (dir_ / name).string();
    std::ofstream(p) << text;
    return p;
  }
  std::string WriteJson(const std::string& name, const Json& j) { return Write(name, j.dump()); }
  // The ConfigError Chair::Load gives, "" when the file loads.
  std::string LoadError(const std::string& path) {
    try {
      Chair::Load(path);
    } catch (const ConfigError& e) {
      return e.what();
    }
    return "";
  }
  fs::path dir_;
};

double LowestZ(const Chair& c) {
  double z = 1e9;
  for (const ChairBox& b : c.boxes) z = std::min(z, b.min.z());
  return z;
}

TEST_F(ChairMeshTest, TheSharedMeshesSitWhereTheirReadmeMeasuredThemFacingAwayFromTheBack) {
  if (SharedDir().empty()) GTEST_SKIP() << "../shared is absent";
  // Seat heights from ../shared/chairs/README.md (measured independently of Perch).
  const std::pair<const char*, double> chairs[] = {
      {"dining_scenic", 0.41}, {"sofa_scenic", 0.50}, {"side_chair_aws", 0.40}};
  for (const auto& [name, height] : chairs) {
    SCOPED_TRACE(name);
    const Chair c =
        Chair::Load(ResolveProjectPath(std::string("data/chairs/meshes/") + name + ".json"));
    ASSERT_TRUE(c.mesh);
    EXPECT_TRUE(c.boxes.empty());
    EXPECT_NEAR(c.seat_height(), height, 0.015);
    EXPECT_EQ(c.mesh->info.seat_source, "found");
    EXPECT_EQ(c.mesh->info.facing_source, "backrest");
    EXPECT_FALSE(c.source.empty());  // the provenance travels with the chair
    // The chair frame: target over the origin, the backrest behind it (-x), floor at z = 0.
    EXPECT_NEAR(c.seat_target.head<2>().norm(), 0.0, 1e-9);
    ASSERT_TRUE(c.backrest_front_x());
    EXPECT_LT(*c.backrest_front_x(), -0.1);
    const Eigen::AlignedBox3d box = c.mesh->visual.Bounds();
    EXPECT_NEAR(box.min().z(), 0.0, 1e-9);
    // More of the chair lies behind the target (the backrest) than in front of it.
    EXPECT_LT(box.max().x(), -box.min().x() + 0.05);
  }
}

TEST_F(ChairMeshTest, FindsTheSeatAndFacingOfABoxChairWrittenAsAnObj) {
  const Chair boxes = Chair::Load(Chair::PresetPath("armchair"));
  for (const bool y_up : {false, true}) {
    for (const double yaw_deg : {0.0, 63.0, -140.0}) {
      SCOPED_TRACE(std::to_string(yaw_deg) + (y_up ? " y-up" : " z-up"));
      const double yaw = yaw_deg * M_PI / 180.0;
      const Eigen::Vector3d offset(0.7, -1.3, 0.25);  // the file's floor is at z = 0.25 m
      Write("c.obj", BoxesAsObj(boxes, yaw, offset, 0.01, y_up));
      const std::string path = WriteJson("c.json", {{"name", "c"},
                                                    {"mesh", "c.obj"},
                                                    {"scale", 0.01},
                                                    {"up_axis", y_up ? "y" : "z"},
                                                    {"static", true}});
      const Chair c = Chair::Load(path);
      ASSERT_TRUE(c.mesh);
      // A mesh's floor is its lowest point: the legs' 1 mm clearance is gone.
      EXPECT_NEAR(c.seat_height(), boxes.seat_height() - LowestZ(boxes), 1e-4);
      EXPECT_NEAR(std::remainder(c.mesh->info.facing_deg - yaw_deg, 360.0), 0.0, 1.0);
      EXPECT_FALSE(c.dynamic);
      // The seat in file coordinates is the box seat's top centre carried through the transform,
      // moved forward where the seat is deeper in front of it than max_front_depth (the
      // armchair's front edge is 0.225 m ahead of its centre).
      double front = 0.0;
      for (const ChairBox& b : boxes.boxes) {
        if (b.role == "seat") front = b.max.x() - boxes.seat_target.x();
      }
      const double shift = std::max(0.0, front - SeatFinderConfig().max_front_depth);
      EXPECT_NEAR(c.mesh->info.seat_moved_forward_m, shift, 1e-4);
      Eigen::Vector3d want = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                                  (boxes.seat_target + Eigen::Vector3d(shift, 0, 0)) +
                              offset) /
                             0.01;
      if (y_up) want = Eigen::Vector3d(want.x(), want.z(), -want.y());
      EXPECT_LT((c.mesh->info.seat_file - want).norm(), 0.5) << c.mesh->info.seat_file.transpose();
      // Back in the chair frame the mesh is the box chair again (shifted with its target).
      EXPECT_LT((c.mesh->visual.Bounds().min() - Eigen::Vector3d(-0.305 - shift, -0.31, 0)).norm(),
                1e-4);
      EXPECT_NEAR(*c.backrest_front_x(), *boxes.backrest_front_x() - shift, 0.005);
    }
  }
}

// A deep seat (a sofa's) is sat on near its front, not at its centre: the found target moves to
// max_front_depth behind the seat's front edge; a seat shallower than that keeps its centre.
TEST_F(ChairMeshTest, ADeepSeatsTargetLiesNearItsFrontEdge) {
  const SeatFinderConfig finder;
  for (const double depth : {0.45, 0.7}) {
    SCOPED_TRACE(depth);
    const Chair boxes = Chair::FromJson(Json{{"name", "deep"},
                                             {"parametric",
                                              {{"seat_height", 0.45},
                                               {"seat_width", 0.5},
                                               {"seat_depth", depth},
                                               {"seat_thickness", 0.08},
                                               {"leg_size", 0.05},
                                               {"backrest_height", 0.4},
                                               {"backrest_thickness", 0.08}}}},
                                        "deep");
    double front = -1e9;  // the seat box's front face, box chair frame
    for (const ChairBox& b : boxes.boxes) {
      if (b.role == "seat") front = b.max.x();
    }
    const double centre_depth = front - boxes.seat_target.x();
    Write("c.obj", BoxesAsObj(boxes, 0.4, Eigen::Vector3d(1.0, 2.0, 0.0), 1.0, false));
    const Chair c = Chair::Load(WriteJson("c.json", {{"name", "c"}, {"mesh", "c.obj"}}));
    // The seat's front edge in the mesh chair's frame (+x forward, origin under the target).
    double mesh_front = -1e9;
    for (const Eigen::Vector3d& v : c.mesh->visual.vertices) {
      if (std::abs(v.z() - c.seat_height()) < 1e-6) mesh_front = std::max(mesh_front, v.x());
    }
    if (centre_depth > finder.max_front_depth) {
      EXPECT_NEAR(mesh_front, finder.max_front_depth, 2e-5);
      EXPECT_NEAR(c.mesh->info.seat_moved_forward_m, centre_depth - finder.max_front_depth, 2e-5);
    } else {
      EXPECT_NEAR(mesh_front, centre_depth, 2e-5);
      EXPECT_EQ(c.mesh->info.seat_moved_forward_m, 0.0);
    }
  }
}

TEST_F(ChairMeshTest, GivenSeatAndFacingAreUsedAsGiven) {
  const Chair boxes = Chair::Load(Chair::PresetPath("authors"));
  Write("c.obj", BoxesAsObj(boxes, 0.0, Eigen::Vector3d::Zero(), 1.0, false));
  const Chair c = Chair::Load(WriteJson("c.json", {{"name", "c"},
                                                   {"mesh", "c.obj"},
                                                   {"seat", {0.05, 0.02, 0.39}},
                                                   {"facing_deg", 90.0},
                                                   {"static", true}}));
  EXPECT_EQ(c.mesh->info.seat_source, "file");
  EXPECT_EQ(c.mesh->info.facing_source, "file");
  EXPECT_NEAR(c.seat_height(), 0.39 - LowestZ(boxes), 1e-9);
  EXPECT_NEAR(c.mesh->info.facing_deg, 90.0, 1e-12);
  // Facing +y in the file: the file's +y is the chair frame's +x.
  const Eigen::Vector3d p = c.mesh->info.file_to_chair * Eigen::Vector3d(0.05, 0.52, 0.0);
  EXPECT_NEAR(p.x(), 0.5, 1e-9);
  EXPECT_NEAR(p.y(), 0.0, 1e-9);
}

TEST_F(ChairMeshTest, ADynamicChairCollidesWithConvexPartsAStaticOneWithItsTriangles) {
  const Chair boxes = Chair::Load(Chair::PresetPath("authors"));
  Write("c.obj", BoxesAsObj(boxes, 0.0, Eigen::Vector3d::Zero(), 1.0, false));
  // The collision file: each box its own object.
  std::string parts;
  {
    std::istringstream in(BoxesAsObj(boxes, 0.0, Eigen::Vector3d::Zero(), 1.0, false));
    std::string line;
    int faces = 0;
    while (std::getline(in, line)) {
      if (line[0] == 'f' && faces++ % 12 == 0)
        parts += "o part" + std::to_string(faces / 12) + "\n";
      parts += line + "\n";
    }
  }
  Write("parts.obj", parts);
  const Chair st =
      Chair::Load(WriteJson("s.json", {{"name", "s"}, {"mesh", "c.obj"}, {"static", true}}));
  EXPECT_TRUE(st.mesh->convex_parts.empty());
  EXPECT_EQ(st.mesh->info.collision, "triangle mesh");
  EXPECT_EQ(st.mesh->collision_static.triangles.size(), 12 * boxes.boxes.size());
  const Chair filed = Chair::Load(
      WriteJson("f.json", {{"name", "f"}, {"mesh", "c.obj"}, {"collision_mesh", "parts.obj"}}));
  EXPECT_EQ(filed.mesh->info.collision, "file parts");
  ASSERT_EQ(filed.mesh->convex_parts.size(), boxes.boxes.size());
  for (const TriMesh& p : filed.mesh->convex_parts) EXPECT_EQ(p.vertices.size(), 8u);  // a box
  const Chair hacd = Chair::Load(WriteJson("d.json", {{"name", "d"}, {"mesh", "c.obj"}}));
  EXPECT_EQ(hacd.mesh->info.collision, "convex decomposition");
  EXPECT_GE(hacd.mesh->convex_parts.size(), 2u);
  // The parts cover the chair: their bounds are the boxes' bounds.
  Eigen::AlignedBox3d b;
  for (const TriMesh& p : hacd.mesh->convex_parts) b.extend(p.Bounds());
  EXPECT_LT((b.min() - hacd.mesh->visual.Bounds().min()).norm(), 0.01);
  EXPECT_LT((b.max() - hacd.mesh->visual.Bounds().max()).norm(), 0.01);
}

TEST_F(ChairMeshTest, BadMeshFilesAreRefusedNamingTheFileAndTheProblem) {
  const Chair boxes = Chair::Load(Chair::PresetPath("authors"));
  const std::string good = BoxesAsObj(boxes, 0.0, Eigen::Vector3d::Zero(), 1.0, false);
  Write("good.obj", good);
  auto chair = [&](const std::string& file, const Json& extra = Json::object()) {
    Json j{{"name", "c"}, {"mesh", file}, {"static", true}};
    j.update(extra);
    return WriteJson("c.json", j);
  };
  auto expect = [&](const std::string& path, const std::string& what) {
    const std::string e = LoadError(path);
    EXPECT_NE(e.find("c.json"), std::string::npos) << e;
    EXPECT_NE(e.find(what), std::string::npos) << e;
  };
  expect(chair("missing.obj"), "missing.obj' not found");
  Write("empty.obj", "# nothing\n");
  expect(chair("empty.obj"), "no faces");
  Write("nan.obj", "v 0 0 nan\n" + good);
  expect(chair("nan.obj"), "nan.obj:1: vertex coordinate 'nan' is not a finite number");
  Write("inf.obj", good + "v 1e999 0 0\n");
  expect(chair("inf.obj"), "is not a finite number");
  Write("index.obj", good + "f 1 2 999\n");
  expect(chair("index.obj"), "names vertex 999");
  expect(chair("good.obj", {{"scale", 100.0}}), "absurd size");
  expect(chair("good.obj", {{"scale", 0.001}}), "absurd size");
  expect(chair("good.obj", {{"scale", -1.0}}), ".scale: must be > 0");
  expect(chair("good.obj", {{"up_axis", "x"}}), ".up_axis");
  // A wall: no upward surface at all.
  Write("wall.obj", "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 2 3\nf 1 3 4\n");
  expect(chair("wall.obj"), "no upward-facing surface");
  expect(chair("good.obj", {{"seat_target", {0, 0, 0.4}}}), "a mesh chair takes 'seat'");
  expect(chair("good.obj", {{"seat", {0, 0}}}), ".seat: expected 3 finite numbers");
  expect(chair("good.obj", {{"dynamic", true}}), "not both");
  // Keys of a mesh chair on a box chair.
  const std::string e = LoadError(
      WriteJson("c.json", {{"name", "c"}, {"parametric", Json::object()}, {"up_axis", "y"}}));
  EXPECT_NE(e.find("only a 'mesh' chair takes it"), std::string::npos) << e;
}

TEST_F(ChairMeshTest, MeshesOverTheRealTimeLimitsAreRefusedNotDecomposed) {
  const Chair boxes = Chair::Load(Chair::PresetPath("armchair"));
  Write("c.obj", BoxesAsObj(boxes, 0.0, Eigen::Vector3d::Zero(), 1.0, false));
  const Json j{{"name", "c"}, {"mesh", "c.obj"}};
  const std::string ctx = (dir_ / "c.json").string();
  ChairMeshLimits few_parts;
  few_parts.max_convex_parts = 1;
  try {
    LoadMeshChair(j, ctx, /*need_convex=*/true, few_parts);
    ADD_FAILURE() << "accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("too concave for real-time stepping"), std::string::npos)
        << e.what();
  }
  ChairMeshLimits small;
  small.max_decompose_triangles = 50;
  small.max_static_triangles = 50;
  for (const bool dynamic : {true, false}) {
    try {
      LoadMeshChair(j, ctx, dynamic, small);
      ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("too"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("(limit 50)"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace perch
