#include "envs/humanoid_world.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "common/rng.h"
#include "envs/humanoid_env.h"

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

// A rollout with contacts, falls and self-collision: random full torques from standing, one
// draw per control step. Returns the state after every control step.
std::vector<WorldState> Rollout(World& world, const HumanoidModel& model, int steps, uint64_t seed,
                                int* max_manifolds = nullptr) {
  world.SetState(StandingPose(model, 0.002));
  Rng rng(seed);
  std::vector<WorldState> out;
  double tau[HumanoidModel::kNumJoints];
  for (int t = 0; t < steps; ++t) {
    for (int j = 0; j < model.num_joints(); ++j)
      tau[j] = model.joint(j).max_torque * rng.Uniform(-1, 1);
    world.SetJointTorques(tau);
    for (int s = 0; s < 4; ++s) world.StepPhysics();
    if (max_manifolds) *max_manifolds = std::max(*max_manifolds, world.NumManifolds());
    out.push_back(world.GetState());
  }
  return out;
}

void ExpectSameStates(const std::vector<WorldState>& a, const std::vector<WorldState>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t t = 0; t < a.size(); ++t) {
    const HumanoidState& x = a[t].humanoid;
    const HumanoidState& y = b[t].humanoid;
    ASSERT_EQ(x.root_pos, y.root_pos) << "step " << t;
    ASSERT_EQ(x.root_quat.coeffs(), y.root_quat.coeffs()) << "step " << t;
    ASSERT_EQ(x.root_lin_vel, y.root_lin_vel) << "step " << t;
    ASSERT_EQ(x.q, y.q) << "step " << t;
    ASSERT_EQ(x.qd, y.qd) << "step " << t;
  }
}

// The pools only decide where Bullet's manifolds and algorithms live (past the pool: the heap), so
// the trajectory is bit-identical for Bullet's default 4096, our 64, and 1 (every manifold but
// one from the heap).
TEST_F(WorldTest, CollisionPoolSizeChangesNoTrajectory) {
  std::vector<std::vector<WorldState>> runs;
  int max_manifolds = 0;
  for (int pool : {4096, 64, 1}) {
    PhysicsConfig c;
    c.collision_pool_size = pool;
    World world(*model_, nullptr, ChairPlacement{}, c);
    runs.push_back(Rollout(world, *model_, 150, 11, &max_manifolds));
  }
  EXPECT_GT(max_manifolds, 1);  // the size-1 pool overflowed
  // The humanoid fell and moved: the comparison covers contact-rich motion.
  EXPECT_LT(runs[0].back().humanoid.root_pos.z(), 0.5);
  ExpectSameStates(runs[0], runs[1]);
  ExpectSameStates(runs[0], runs[2]);
}

// The finite floor relies on this: a body within contact range of the plane always overlaps the
// slab, so collision detection finds exactly the plane's contacts, while bodies away from the
// floor are no longer paired with it.
TEST_F(WorldTest, FiniteFloorFindsThePlanesContactsAndPairsOnlyNearBodies) {
  PhysicsConfig infinite_cfg;
  infinite_cfg.floor_half_extent = 0.0;
  World infinite(*model_, nullptr, ChairPlacement{}, infinite_cfg);
  World slab(*model_, nullptr, ChairPlacement{}, PhysicsConfig{});
  Rng rng(3);
  int floor_points = 0;
  for (int trial = 0; trial < 200; ++trial) {
    HumanoidState s;
    s.root_pos =
        Eigen::Vector3d(rng.Uniform(-50, 50), rng.Uniform(-50, 50), rng.Uniform(0.05, 1.3));
    s.root_quat = QuatFromRpy(rng.Uniform(-3, 3), rng.Uniform(-1.5, 1.5), rng.Uniform(-3, 3));
    for (int j = 0; j < model_->num_joints(); ++j) {
      s.q[j] = rng.Uniform(model_->joint(j).lower, model_->joint(j).upper);
    }
    infinite.SetState(s);
    slab.SetState(s);
    int self_a = 0, self_b = 0;
    const int points_a = infinite.NumContactPoints(&self_a);
    const int points_b = slab.NumContactPoints(&self_b);
    ASSERT_EQ(points_a, points_b) << "trial " << trial;
    ASSERT_EQ(self_a, self_b) << "trial " << trial;
    floor_points += points_a - self_a;
    const Contacts ca = infinite.ReadContacts(), cb = slab.ReadContacts();
    ASSERT_EQ(ca.foot_floor[0], cb.foot_floor[0]) << "trial " << trial;
    ASSERT_EQ(ca.foot_floor[1], cb.foot_floor[1]) << "trial " << trial;
    int floor_a = 0, floor_b = 0;
    infinite.NumManifolds(&floor_a);
    slab.NumManifolds(&floor_b);
    ASSERT_GE(floor_a, model_->num_bodies());  // every body (each compound child), every step
    ASSERT_LE(floor_b, floor_a);
  }
  EXPECT_GT(floor_points, 100);  // the poses did touch the floor
  // Standing: only the feet are paired with the floor.
  slab.SetState(StandingPose(*model_, 0.002));
  infinite.SetState(StandingPose(*model_, 0.002));
  int slab_pairs = 0, infinite_pairs = 0;
  slab.NumManifolds(&slab_pairs);
  infinite.NumManifolds(&infinite_pairs);
  EXPECT_GE(slab_pairs, 2);
  EXPECT_LT(3 * slab_pairs, infinite_pairs) << slab_pairs << " vs " << infinite_pairs;
  EXPECT_TRUE(slab.ReadContacts().foot_floor[0]);
  EXPECT_TRUE(slab.ReadContacts().foot_floor[1]);
}

// Drops the humanoid onto the seat with zero torques; returns whether the pelvis touched the
// chair in any of `steps` physics steps.
bool DropOnSeat(World& world, const HumanoidModel& model, const Chair& chair, int steps) {
  world.SetState(SeatedPose(model, chair, ChairPlacement{}, 0.05));
  bool pelvis = false;
  for (int i = 0; i < steps; ++i) {
    world.StepPhysics();
    pelvis = pelvis || world.ReadContacts().pelvis_chair;
  }
  return pelvis;
}

// The sit task and its metrics read only contacts with the chair body and the chair's placement,
// so a static chair serves them; the authors' dynamic chair stays selectable.
TEST_F(WorldTest, ChairBodyModes) {
  const double legs_gap = chair_->boxes[0].min.z();  // the legs start 1 mm above the floor
  ASSERT_GT(legs_gap, 0.0);
  PhysicsConfig c;
  EXPECT_EQ(c.chair_body, ChairBody::kStatic);  // the default
  {
    World world(*model_, chair_, ChairPlacement{}, c);
    EXPECT_TRUE(DropOnSeat(world, *model_, *chair_, 120));
    EXPECT_FALSE(world.ChairAwake());
    const ChairState cs = world.GetState().chair;
    EXPECT_LT(cs.pos.norm(), 1e-6);  // never moves
    EXPECT_EQ(cs.lin_vel, Eigen::Vector3d::Zero());
  }
  c.chair_body = ChairBody::kDynamic;
  {
    World world(*model_, chair_, ChairPlacement{}, c);
    HumanoidState away = StandingPose(*model_, 0.002);
    away.root_pos.x() = 3.0;
    world.SetState(away);
    for (int i = 0; i < 60; ++i) world.StepPhysics();
    EXPECT_TRUE(world.ChairAwake());
    // Fell onto the floor (to within Bullet's contact slop).
    EXPECT_LT(world.GetState().chair.pos.z(), -0.5 * legs_gap);
    EXPECT_GT(world.GetState().chair.pos.z(), -3.0 * legs_gap);
    EXPECT_TRUE(DropOnSeat(world, *model_, *chair_, 120));
  }
  c.chair_body = ChairBody::kSleeping;
  {
    World world(*model_, chair_, ChairPlacement{}, c);
    HumanoidState away = StandingPose(*model_, 0.002);
    away.root_pos.x() = 3.0;
    world.SetState(away);
    for (int i = 0; i < 60; ++i) world.StepPhysics();
    EXPECT_FALSE(world.ChairAwake());
    EXPECT_LT(world.GetState().chair.pos.norm(), 1e-6);  // asleep: not even gravity
    EXPECT_TRUE(DropOnSeat(world, *model_, *chair_, 120));
    EXPECT_TRUE(world.ChairAwake());  // woken by the humanoid, then simulated
    EXPECT_LT(world.GetState().chair.pos.z(), -0.5 * legs_gap);
  }
  // A chair file that says "dynamic": false stays static.
  Chair fixed = *chair_;
  fixed.dynamic = false;
  World world(*model_, &fixed, ChairPlacement{}, c);
  EXPECT_TRUE(DropOnSeat(world, *model_, fixed, 120));
  EXPECT_FALSE(world.ChairAwake());
  EXPECT_LT(world.GetState().chair.pos.norm(), 1e-6);
}

TEST_F(WorldTest, PhysicsConfigNamesBadFields) {
  const auto error = [](const Json& j) {
    try {
      PhysicsConfig::FromJson(j, "run.json.physics");
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error({{"chair_body", "wobbly"}}).find("run.json.physics.chair_body"),
            std::string::npos);
  EXPECT_NE(error({{"collision_pool_size", 0}}).find("run.json.physics.collision_pool_size"),
            std::string::npos);
  EXPECT_NE(error({{"floor_half_extent", -1.0}}).find("run.json.physics.floor_half_extent"),
            std::string::npos);
  const PhysicsConfig c = PhysicsConfig::FromJson(
      {{"chair_body", "sleeping"}, {"collision_pool_size", 4096}, {"floor_half_extent", 0.0}}, "x");
  EXPECT_EQ(c.chair_body, ChairBody::kSleeping);
  EXPECT_EQ(c.collision_pool_size, 4096);
  EXPECT_EQ(c.floor_half_extent, 0.0);
  EXPECT_EQ(PhysicsConfig::FromJson(c.ToJson(), "x").ToJson(), c.ToJson());
}

}  // namespace
}  // namespace perch
