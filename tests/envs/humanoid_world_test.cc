#include "envs/humanoid_world.h"

#include <cmath>

#include <gtest/gtest.h>

#include "common/rng.h"

namespace perch {
namespace {

class WorldTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    model_ = new HumanoidModel(HumanoidModel::Load(HumanoidModel::DefaultPath()));
    chair_ = new Chair(Chair::Load(Chair::PresetPath("authors")));
  }
  static void TearDownTestSuite() {
    delete model_;
    delete chair_;
  }
  static HumanoidModel* model_;
  static Chair* chair_;
};
HumanoidModel* WorldTest::model_ = nullptr;
Chair* WorldTest::chair_ = nullptr;

// Bullet's articulated body, built from helper links and principal frames, must place every body
// where our MJCF-style forward kinematics does.
TEST_F(WorldTest, BulletBodyPosesMatchForwardKinematics) {
  World world(*model_, nullptr, ChairPlacement{}, PhysicsConfig{});
  Rng rng(7);
  for (int trial = 0; trial < 5; ++trial) {
    HumanoidState s;
    s.root_pos = Eigen::Vector3d(rng.Uniform(-1, 1), rng.Uniform(-1, 1), 2.0);
    s.root_quat = QuatFromRpy(rng.Uniform(-0.5, 0.5), rng.Uniform(-0.5, 0.5), rng.Uniform(-3, 3));
    for (int j = 0; j < model_->num_joints(); ++j) {
      s.q[j] = rng.Uniform(model_->joint(j).lower, model_->joint(j).upper);
    }
    world.SetState(s);
    const FkResult fk = ForwardKinematics(*model_, s.root_pos, s.root_quat, s.q.data());
    for (int b = 0; b < model_->num_bodies(); ++b) {
      const Eigen::Isometry3d bullet = world.BodyPose(b);
      EXPECT_LT((bullet.translation() - fk.body_world[b].translation()).norm(), 1e-4)
          << model_->body(b).name;
      EXPECT_LT((bullet.rotation() - fk.body_world[b].rotation()).norm(), 1e-4)
          << model_->body(b).name;
    }
    double q[21], qd[21];
    world.ReadJoints(q, qd);
    for (int j = 0; j < 21; ++j) EXPECT_NEAR(q[j], s.q[j], 1e-5);
    const WorldState back = world.GetState();
    EXPECT_LT((back.humanoid.root_pos - s.root_pos).norm(), 1e-5);
    EXPECT_LT(back.humanoid.root_quat.angularDistance(s.root_quat), 1e-5);
  }
}

TEST_F(WorldTest, PositiveTorqueTurnsJointPositive) {
  World world(*model_, nullptr, ChairPlacement{}, PhysicsConfig{});
  HumanoidState s;
  s.root_pos = Eigen::Vector3d(0, 0, 3.0);  // in the air, no contacts
  s.q[model_->FindJoint("right_elbow")] = -0.5;
  world.SetState(s);
  double tau[21] = {0};
  tau[model_->FindJoint("right_elbow")] = 5.0;
  world.SetJointTorques(tau);
  for (int i = 0; i < 10; ++i) world.StepPhysics();
  double q[21], qd[21];
  world.ReadJoints(q, qd);
  EXPECT_GT(qd[model_->FindJoint("right_elbow")], 0.5);
  EXPECT_GT(q[model_->FindJoint("right_elbow")], -0.5);
}

TEST_F(WorldTest, QposRowRoundTrip) {
  double row[51];
  for (int i = 0; i < 51; ++i) row[i] = 0.01 * i - 0.2;
  const HumanoidState s = StateFromQpos(row);
  EXPECT_DOUBLE_EQ(s.q[3], row[6]);
  EXPECT_DOUBLE_EQ(s.qd[3], row[7]);
  EXPECT_DOUBLE_EQ(s.root_pos.z(), row[44]);
  EXPECT_DOUBLE_EQ(s.root_lin_vel.x(), row[48]);
  double back[51];
  QposFromState(s, back);
  for (int i = 0; i < 51; ++i) EXPECT_NEAR(back[i], row[i], 1e-12) << i;
}

}  // namespace
}  // namespace perch
