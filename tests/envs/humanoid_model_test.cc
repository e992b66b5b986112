#include "envs/humanoid_model.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "common/json_util.h"

namespace perch {
namespace {

class HumanoidModelTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { model_ = new HumanoidModel(HumanoidModel::Load(HumanoidModel::DefaultPath())); }
  static void TearDownTestSuite() { delete model_; }
  static HumanoidModel* model_;
};
HumanoidModel* HumanoidModelTest::model_ = nullptr;

TEST_F(HumanoidModelTest, TopologyAndOrders) {
  const HumanoidModel& m = *model_;
  EXPECT_EQ(m.num_bodies(), 13);
  ASSERT_EQ(m.num_joints(), 21);
  EXPECT_EQ(m.joint(0).name, "abdomen_z");
  EXPECT_EQ(m.joint(7).name, "right_ankle_y");
  EXPECT_EQ(m.joint(8).name, "right_ankle_x");
  // Actions swap the ankle pairs (notes 1.4).
  EXPECT_EQ(m.action_to_joint()[7], 8);
  EXPECT_EQ(m.action_to_joint()[8], 7);
  EXPECT_EQ(m.action_to_joint()[13], 14);
  EXPECT_EQ(m.action_to_joint()[0], 0);
  for (int j = 0; j < m.num_joints(); ++j) {
    EXPECT_NEAR(m.joint(j).axis.norm(), 1.0, 1e-12);
    EXPECT_EQ(m.action_to_joint()[m.joint(j).action_index], j);
    EXPECT_NEAR(m.joint(j).max_torque, 0.41 * m.joint(j).power, 1e-12);
  }
  EXPECT_NEAR(m.joint(m.FindJoint("right_knee")).lower, -160.0 * M_PI / 180.0, 1e-12);
  EXPECT_NEAR(m.joint(m.FindJoint("left_hip_y")).lower, -120.0 * M_PI / 180.0, 1e-12);
  EXPECT_EQ(m.body(m.pelvis_body()).name, "pelvis");
  EXPECT_EQ(m.body(m.foot_bodies()[0]).name, "right_foot");
}

TEST_F(HumanoidModelTest, MassesMatchDensityTimesVolume) {
  // Notes 1.2: torso 8.91 kg, thigh 4.75, total 40.8 kg (density 1000 x capsule/sphere volume).
  EXPECT_NEAR(model_->body(0).mass, 8.91, 0.01);
  EXPECT_NEAR(model_->body(model_->FindBody("right_thigh")).mass, 4.75, 0.01);
  EXPECT_NEAR(model_->body(model_->FindBody("left_lower_arm")).mass, 1.23, 0.01);
  EXPECT_NEAR(model_->total_mass(), 40.8, 0.1);
  for (const Body& b : model_->bodies()) {
    EXPECT_GT(b.principal_inertia.minCoeff(), 0.0) << b.name;
    EXPECT_NEAR(b.principal_rot.determinant(), 1.0, 1e-9) << b.name;
    const Eigen::Matrix3d back =
        b.principal_rot * b.principal_inertia.asDiagonal() * b.principal_rot.transpose();
    EXPECT_LT((back - b.inertia).norm(), 1e-9) << b.name;
  }
}

TEST_F(HumanoidModelTest, StandingPoseTorsoAboveLowestFootPoint) {
  const std::vector<double> q(21, 0.0);
  const FkResult fk = ForwardKinematics(*model_, Eigen::Vector3d(0.3, -0.2, 1.4),
                                        Eigen::Quaterniond::Identity(), q.data());
  const double lowest = LowestGeomZ(*model_, fk);
  EXPECT_NEAR(1.4 - lowest, 1.285, 0.002);
  EXPECT_NEAR(model_->standing_root_height(), 1.285, 0.002);
  // The lowest points are the feet: foot frames sit one capsule radius (0.027 m) above it.
  for (int f : model_->foot_bodies()) {
    EXPECT_NEAR(fk.body_world[f].translation().z() - lowest, 0.027, 0.002);
  }
}

TEST_F(HumanoidModelTest, KneeFlexionMovesFootBackAndUp) {
  std::vector<double> q(21, 0.0);
  const int knee = model_->FindJoint("right_knee");
  q[knee] = -M_PI / 2;  // knees flex with negative angles
  const FkResult fk = ForwardKinematics(*model_, Eigen::Vector3d::Zero(),
                                        Eigen::Quaterniond::Identity(), q.data());
  const Eigen::Vector3d knee_anchor = fk.joint_anchor_world[knee];
  const Eigen::Vector3d foot = fk.body_world[model_->FindBody("right_foot")].translation();
  // Flexed 90 deg, the shin points backwards (-x) from the knee, level with it.
  EXPECT_LT(foot.x() - knee_anchor.x(), -0.3);
  EXPECT_NEAR(foot.z(), knee_anchor.z(), 0.05);
  // The anchor of a hinge does not move when its own angle changes.
  const std::vector<double> zeros(21, 0.0);
  const FkResult fk0 = ForwardKinematics(*model_, Eigen::Vector3d::Zero(),
                                         Eigen::Quaterniond::Identity(), zeros.data());
  EXPECT_LT((fk0.joint_anchor_world[knee] - knee_anchor).norm(), 1e-12);
}

TEST(HumanoidModelRpy, RoundTrip) {
  const Eigen::Quaterniond q = QuatFromRpy(0.2, -0.4, 2.5);
  const Eigen::Vector3d rpy = RpyFromQuat(q);
  EXPECT_NEAR(rpy[0], 0.2, 1e-12);
  EXPECT_NEAR(rpy[1], -0.4, 1e-12);
  EXPECT_NEAR(rpy[2], 2.5, 1e-12);
  // R = Rz(yaw) Ry(pitch) Rx(roll): a pure yaw turns +x towards +y.
  const Eigen::Vector3d x = QuatFromRpy(0, 0, M_PI / 2) * Eigen::Vector3d::UnitX();
  EXPECT_NEAR(x.y(), 1.0, 1e-12);
}

// Writes a copy of data/humanoid.json with one edit applied to the parsed JSON.
std::string WriteEdited(const std::string& name, void (*edit)(Json&)) {
  Json j = LoadJsonFile(HumanoidModel::DefaultPath());
  edit(j);
  const std::string path = ::testing::TempDir() + name;
  std::ofstream(path) << j.dump();
  return path;
}

void ExpectLoadError(const std::string& path, const std::string& field) {
  try {
    HumanoidModel::Load(path);
    FAIL() << "no error for " << path;
  } catch (const ConfigError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
    EXPECT_NE(msg.find(field), std::string::npos) << msg;
  }
}

TEST(HumanoidModelLoad, MalformedFilesNameFileAndField) {
  ExpectLoadError(WriteEdited("h_unknown.json", [](Json& j) { j["bodies"][2]["colour"] = "red"; }),
                  "bodies[2]: unknown field 'colour'");
  ExpectLoadError(WriteEdited("h_range.json",
                              [](Json& j) { j["bodies"][4]["joints"][0]["range"] = "wide"; }),
                  "bodies[4].joints[0].range");
  ExpectLoadError(WriteEdited("h_radius.json",
                              [](Json& j) { j["bodies"][1]["geoms"][0].erase("radius"); }),
                  "bodies[1].geoms[0]: missing required field 'radius'");
  ExpectLoadError(WriteEdited("h_parent.json", [](Json& j) { j["bodies"][3]["parent"] = "tail"; }),
                  "bodies[3].parent");
  ExpectLoadError(WriteEdited("h_order.json",
                              [](Json& j) { j["observation_order"][5] = "right_wrist"; }),
                  "observation_order[5]");
  ExpectLoadError(WriteEdited("h_power.json",
                              [](Json& j) { j["bodies"][5]["joints"][1]["power"] = -3; }),
                  "bodies[5].joints[1].power");
  const std::string truncated = ::testing::TempDir() + "h_trunc.json";
  std::ofstream(truncated) << "{\"name\": \"x\", \"bodies\": [";
  ExpectLoadError(truncated, "malformed JSON");
}

}  // namespace
}  // namespace perch
