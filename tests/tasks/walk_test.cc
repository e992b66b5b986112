#include "tasks/walk.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "tasks/task_env.h"

namespace perch {
namespace {

constexpr int kN = HumanoidModel::kNumJoints;

// An env that owns its walk task; the raw pointer lets tests call the hooks directly.
struct WalkEnv {
  std::unique_ptr<HumanoidChairEnv> env;
  WalkTask* task = nullptr;
  std::vector<float> obs;
};

WalkEnv MakeWalk(const TaskEnvConfig& c) {
  const double dt = c.env.physics.physics_dt * c.env.physics.substeps;
  auto t = std::make_unique<WalkTask>(c.walk, dt);
  WalkEnv w;
  w.task = t.get();
  w.env = std::make_unique<HumanoidChairEnv>(c.env, std::move(t));
  w.obs.resize(w.env->spec().obs_dim);
  return w;
}

TaskEnvConfig Walk(const std::string& stage = "forward", const std::string& variant = "paper") {
  TaskEnvConfig c = TaskEnvConfig::Defaults("walk");
  Json j = c.ToJson();
  j["walk"] = Json{{"stage", stage}, {"reward_variant", variant}};
  return TaskEnvConfig::FromJson(j, "test");
}

// Puts the humanoid exactly into the reference's state at episode step k.
void SetToReference(WalkEnv& w, int k) {
  EnvState s = w.env->GetState();
  s.world.humanoid = w.task->ReferenceState(k);
  s.step = k;
  w.env->SetState(s);
}

TEST(WalkConfig, PresetsAndOverrides) {
  const WalkTaskConfig paper = WalkTaskConfig::FromJson(Json::object(), "cfg");
  EXPECT_EQ(paper.similarity.alpha_vel, 10.0);
  EXPECT_EQ(paper.root_vel_weight, 0.5);
  EXPECT_EQ(paper.target_weight, 0.1);
  EXPECT_EQ(paper.min_root_z, 0.78);
  EXPECT_EQ(paper.max_episode_steps, 1000);
  EXPECT_FALSE(paper.similarity.finite_difference_velocities);
  const WalkTaskConfig authors = WalkTaskConfig::FromJson(
      Json{{"reward_variant", "authors"}, {"similarity", {{"w_pose", 0.6}}}}, "cfg");
  EXPECT_EQ(authors.similarity.alpha_vel, 0.01);  // from the preset, kept beside the override
  EXPECT_EQ(authors.similarity.w_pose, 0.6);
  EXPECT_TRUE(authors.similarity.finite_difference_velocities);
  EXPECT_EQ(authors.root_vel_weight, 0.1);
  EXPECT_EQ(authors.target_weight, 0.5);
  // Round trip keeps every resolved value.
  const WalkTaskConfig back = WalkTaskConfig::FromJson(authors.ToJson(), "cfg");
  EXPECT_EQ(back.ToJson(), authors.ToJson());
  EXPECT_THROW(WalkTaskConfig::FromJson(Json{{"reward_varient", "paper"}}, "cfg"), ConfigError);
  EXPECT_THROW(WalkTaskConfig::FromJson(Json{{"reward_variant", "mine"}}, "cfg"), ConfigError);
  EXPECT_THROW(WalkTaskConfig::FromJson(Json{{"stage", 2}}, "cfg"), ConfigError);
  try {
    TaskEnvConfig::FromJson(Json{{"task", "walk"}, {"walk", {{"min_root_zz", 1.0}}}}, "f.json");
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("f.json.walk"), std::string::npos) << e.what();
  }
}

// Azimuth of the walk target from the root, relative to the torso's heading as DrawTarget takes it
// (x axis projected on the ground) [rad].
double TargetAngleFromHeading(const HumanoidChairEnv& env) {
  const HumanoidState& s = env.humanoid_state();
  const Eigen::Vector2d rel = env.walk_target() - s.root_pos.head<2>();
  const Eigen::Vector2d heading = (s.root_quat * Eigen::Vector3d::UnitX()).head<2>();
  return AngleDiff(std::atan2(rel.y(), rel.x()), std::atan2(heading.y(), heading.x()));
}

// The training curriculum (target_turn_prob): off by default; on, a share of the draws lands beside
// or behind the walker, never beyond the turn angle; bad values are refused by name.
TEST(WalkTask, TurnCurriculumDrawsWideTargetsOnlyWhenOn) {
  EXPECT_EQ(WalkTaskConfig::FromJson(Json::object(), "cfg").target_turn_prob, 0.0);
  for (const Json& bad : {Json{{"target_turn_prob", 1.5}}, Json{{"target_turn_prob", -0.1}},
                          Json{{"target_turn_max_angle_deg", 200.0}}}) {
    try {
      WalkTaskConfig::FromJson(bad, "cfg");
      FAIL() << bad.dump();
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(bad.begin().key()), std::string::npos) << e.what();
    }
  }
  const auto angles = [](double prob) {
    TaskEnvConfig c = Walk("target");
    c.walk.target_turn_prob = prob;
    c.walk.target_turn_max_angle_deg = 150.0;
    WalkEnv w = MakeWalk(c);
    w.env->Seed(5);
    w.env->Reset(w.obs.data());
    Rng rng(7);
    std::vector<double> out;
    for (int i = 0; i < 400; ++i) {
      // Reached every time: a fresh draw per call.
      w.env->SetWalkTarget(w.env->BodyXyz().head<2>());
      w.task->BeforeObservation(*w.env, rng);
      out.push_back(std::abs(TargetAngleFromHeading(*w.env)) * 180 / M_PI);
    }
    return out;
  };
  const std::vector<double> off = angles(0.0), half = angles(0.5);
  EXPECT_LE(*std::max_element(off.begin(), off.end()), 45.0 + 1e-6);
  EXPECT_LE(*std::max_element(half.begin(), half.end()), 150.0 + 1e-6);
  const auto wide = std::count_if(half.begin(), half.end(), [](double a) { return a > 45.0; });
  // Half the draws use U(-150, 150): 70% of those exceed 45 deg, so about 140 of 400.
  EXPECT_GT(wide, 90);
  EXPECT_LT(wide, 190);
}

TEST(WalkTask, StartsAtTheReferenceFirstFrameAtTheOrigin) {
  WalkEnv w = MakeWalk(Walk());
  w.env->Reset(w.obs.data());
  const HumanoidState& s = w.env->humanoid_state();
  const MotionPose f0 = w.task->motion().At(0.0);
  EXPECT_NEAR(s.root_pos.x(), 0.0, 1e-6);  // Bullet stores floats
  EXPECT_NEAR(s.root_pos.y(), 0.0, 1e-6);
  EXPECT_NEAR(s.root_pos.z(), f0.root_pos.z(), 1e-6);
  EXPECT_NEAR(s.root_quat.angularDistance(f0.root_rot), 0.0, 1e-6);
  for (int j = 0; j < kN; ++j) {
    EXPECT_NEAR(s.q[j], f0.q[j], 1e-6) << j;
    EXPECT_NEAR(s.qd[j], f0.qdot[j], 1e-6) << j;
  }
  EXPECT_NEAR((s.root_lin_vel - f0.root_vel).norm(), 0.0, 1e-6);
  // Facing +x: the torso's x axis points along +x on the ground.
  EXPECT_GT((s.root_quat * Eigen::Vector3d::UnitX()).x(), 0.95);
  EXPECT_EQ(w.task->start_time(), 0.0);
}

TEST(WalkTask, ReferenceStateInitDrawsThePhaseFromTheSeed) {
  TaskEnvConfig c = Walk();
  c.walk.reference_state_init = true;
  WalkEnv a = MakeWalk(c), b = MakeWalk(c);
  a.env->Seed(5);
  b.env->Seed(5);
  a.env->Reset(a.obs.data());
  b.env->Reset(b.obs.data());
  EXPECT_EQ(a.task->start_time(), b.task->start_time());
  const double t_first = a.task->start_time();
  a.env->Reset(a.obs.data());
  EXPECT_NE(a.task->start_time(), t_first);
  EXPECT_GE(a.task->start_time(), 0.0);
  EXPECT_LT(a.task->start_time(), a.task->motion().duration());
  // Still at the origin, in the reference's pose at that phase.
  const MotionPose p = a.task->motion().At(a.task->start_time());
  EXPECT_NEAR(a.env->humanoid_state().root_pos.head<2>().norm(), 0.0, 1e-6);
  EXPECT_NEAR(a.env->humanoid_state().q[3], p.q[3], 1e-6);
}

TEST(WalkTask, RewardIsTheFormulaOnEnvAndReferenceStates) {
  for (const char* variant : {"paper", "authors"}) {
    const TaskEnvConfig c = Walk("forward", variant);
    WalkEnv w = MakeWalk(c);
    w.env->Reset(w.obs.data());
    std::vector<float> a(21);
    const double dt = w.env->spec().control_dt;
    for (int k = 1; k <= 3; ++k) {
      const HumanoidState before = w.env->humanoid_state();
      w.env->HoldPoseAction(w.task->ReferenceState(k).q.data(), a.data());
      const StepResult r = w.env->Step(a.data(), w.obs.data());
      ASSERT_FALSE(r.invalid);
      const HumanoidState& s = w.env->humanoid_state();
      const MotionPose ref = w.task->ReferenceAt(k), prev = w.task->ReferenceAt(k - 1);
      const SimilarityRewardConfig& sc = c.walk.similarity;
      const bool fd = sc.finite_difference_velocities;
      double qd[kN], qd_ref[kN];
      for (int j = 0; j < kN; ++j) {
        qd[j] = fd ? (s.q[j] - before.q[j]) / dt : s.qd[j];
        qd_ref[j] = fd ? (ref.q[j] - prev.q[j]) / dt : ref.qdot[j];
      }
      const Eigen::Vector3d v =
          fd ? Eigen::Vector3d((s.root_pos - before.root_pos) / dt) : s.root_lin_vel;
      const Eigen::Vector3d v_ref =
          fd ? Eigen::Vector3d((ref.root_pos - prev.root_pos) / dt) : ref.root_vel;
      const double expected =
          SimilarityReward(sc, s.q.data(), ref.q.data(), qd, qd_ref, kN) +
          RootVelocityReward(v.data(), v_ref.data(), c.walk.root_vel_weight, c.walk.root_vel_alpha);
      EXPECT_NEAR(r.reward, expected, 1e-5) << variant << " step " << k;
      EXPECT_NEAR(w.task->last_terms().similarity,
                  SimilarityReward(sc, s.q.data(), ref.q.data(), qd, qd_ref, kN), 1e-9);
    }
  }
}

TEST(WalkTask, PerfectTrackingEarnsTheMaximum) {
  // Paper variant: simulator velocities, so one step in the reference state suffices.
  {
    const TaskEnvConfig c = Walk("forward", "paper");
    WalkEnv w = MakeWalk(c);
    w.env->Reset(w.obs.data());
    SetToReference(w, 17);
    std::vector<float> a(21, 0.0f);
    w.task->OnStep(*w.env, a.data());
    const SimilarityRewardConfig& sc = c.walk.similarity;
    EXPECT_NEAR(w.task->last_terms().similarity, sc.w_pose + sc.w_vel, 1e-6);
    EXPECT_NEAR(w.task->last_terms().goal, c.walk.root_vel_weight, 1e-6);
    // Any deviation earns less.
    EnvState s = w.env->GetState();
    s.world.humanoid.q[4] += 0.2;
    w.env->SetState(s);
    w.task->OnStep(*w.env, a.data());
    EXPECT_LT(w.task->last_terms().similarity, sc.w_pose + sc.w_vel - 1e-3);
  }
  // Authors' variant: finite differences need the previous step on the reference too.
  {
    const TaskEnvConfig c = Walk("forward", "authors");
    WalkEnv w = MakeWalk(c);
    w.env->Reset(w.obs.data());
    std::vector<float> a(21, 0.0f);
    SetToReference(w, 16);
    w.task->OnStep(*w.env, a.data());
    SetToReference(w, 17);
    w.task->OnStep(*w.env, a.data());
    EXPECT_NEAR(w.task->last_terms().similarity, 0.55, 1e-6);
    EXPECT_NEAR(w.task->last_terms().goal, 0.1, 1e-6);
  }
}

TEST(WalkTask, TerminatesBelowTheHeightAndTruncatesAtTheLimit) {
  TaskEnvConfig c = Walk();
  c.walk.max_episode_steps = 3;
  WalkEnv w = MakeWalk(c);
  w.env->Reset(w.obs.data());
  std::vector<float> a(21, 0.0f);
  for (double z : {c.walk.min_root_z - 0.01, c.walk.min_root_z + 0.01}) {
    EnvState s = w.env->GetState();
    s.world.humanoid.root_pos.z() = z;
    w.env->SetState(s);
    EXPECT_EQ(w.task->OnStep(*w.env, a.data()).terminated, z < c.walk.min_root_z) << z;
  }
  w.env->Reset(w.obs.data());
  EXPECT_EQ(w.env->spec().max_episode_steps, 3);
  for (int k = 1; k <= 3; ++k) {
    w.env->HoldPoseAction(w.task->ReferenceState(k).q.data(), a.data());
    const StepResult r = w.env->Step(a.data(), w.obs.data());
    EXPECT_FALSE(r.terminated) << k;
    EXPECT_EQ(r.truncated, k == 3) << k;
  }
}

double GoalAzimuth(const HumanoidChairEnv& env) {
  const Eigen::Vector2d to = env.walk_target() - env.BodyXyz().head<2>();
  return AngleDiff(std::atan2(to.y(), to.x()), env.RootRpy().z());
}

TEST(WalkTask, TargetsAreDrawnInFrontAndRedrawnOnTimeOrWhenReached) {
  const TaskEnvConfig c = Walk("target");
  WalkEnv w = MakeWalk(c);
  Rng rng(11);
  w.env->Seed(3);
  w.env->Reset(w.obs.data());
  const double max_angle = c.walk.target_max_angle_deg * M_PI / 180;
  const auto check_in_front = [&](const char* when) {
    const HumanoidState& s = w.env->humanoid_state();
    const Eigen::Vector2d rel = w.env->walk_target() - s.root_pos.head<2>();
    const Eigen::Vector2d heading = (s.root_quat * Eigen::Vector3d::UnitX()).head<2>();
    EXPECT_GE(rel.norm(), c.walk.target_min_dist_m * heading.norm() - 1e-9) << when;
    EXPECT_LE(rel.norm(), c.walk.target_max_dist_m * heading.norm() + 1e-9) << when;
    EXPECT_LE(std::abs(TargetAngleFromHeading(*w.env)), max_angle + 1e-9) << when;
  };
  check_in_front("reset");
  // The goal feature is (sin, cos) of the target's azimuth from the heading.
  EXPECT_NEAR(w.obs[50], std::sin(GoalAzimuth(*w.env)), 1e-5);
  EXPECT_NEAR(w.obs[51], std::cos(GoalAzimuth(*w.env)), 1e-5);

  // Time: unchanged for redraw_s / dt - 1 observations, new at the next.
  const int steps =
      static_cast<int>(std::lround(c.walk.target_redraw_s / w.env->spec().control_dt));
  EXPECT_EQ(steps, 150);
  const Eigen::Vector2d first = w.env->walk_target();
  for (int k = 1; k < steps; ++k) {
    w.task->BeforeObservation(*w.env, rng);
    ASSERT_EQ(w.env->walk_target(), first) << k;
  }
  w.task->BeforeObservation(*w.env, rng);
  EXPECT_NE(w.env->walk_target(), first);
  EXPECT_EQ(w.task->targets_reached(), 0);
  check_in_front("timer");

  // Reached: within target_reach_m of body_xyz.
  const Eigen::Vector2d near =
      w.env->BodyXyz().head<2>() + Eigen::Vector2d(0.5 * c.walk.target_reach_m, 0.0);
  w.env->SetWalkTarget(near);
  w.task->BeforeObservation(*w.env, rng);
  EXPECT_NE(w.env->walk_target(), near);
  EXPECT_EQ(w.task->targets_reached(), 1);
  check_in_front("reached");

  // Through Step: a re-draw step earns the sigmoid at V = 0, and the feature follows the target.
  WalkEnv v = MakeWalk(c);
  v.env->Reset(v.obs.data());
  std::vector<float> a(21);
  v.env->HoldPoseAction(v.task->ReferenceState(1).q.data(), a.data());
  v.env->SetWalkTarget(v.env->BodyXyz().head<2>());  // reached at the next observation
  v.env->Step(a.data(), v.obs.data());
  EXPECT_TRUE(v.task->last_terms().target_reached);
  EXPECT_NEAR(v.task->last_terms().goal, 0.5 * c.walk.target_weight, 1e-12);
  EXPECT_NEAR(v.obs[50], std::sin(GoalAzimuth(*v.env)), 1e-5);
  EXPECT_NEAR(v.obs[51], std::cos(GoalAzimuth(*v.env)), 1e-5);
  // A normal step: Eq. 5 on the distance change.
  const double d0 = WalkTask::TargetDistance(*v.env);
  v.env->HoldPoseAction(v.task->ReferenceState(2).q.data(), a.data());
  v.env->Step(a.data(), v.obs.data());
  ASSERT_FALSE(v.task->last_terms().target_redrawn);
  EXPECT_NEAR(v.task->last_terms().goal,
              TargetProgressReward(d0, WalkTask::TargetDistance(*v.env), v.env->spec().control_dt,
                                   c.walk.target_weight, c.walk.target_k),
              1e-9);
}

TEST(TaskEnv, BuildsStandAndWalkByName) {
  TaskEnvConfig stand = TaskEnvConfig::Defaults("stand");
  EXPECT_EQ(MakeTaskEnv(stand)->spec().name, "humanoid_chair_stand");
  TaskEnvConfig walk = TaskEnvConfig::Defaults("walk");
  EXPECT_EQ(walk.env.chair, "none");
  std::unique_ptr<Env> env = MakeTaskEnv(walk);
  EXPECT_EQ(env->spec().name, "humanoid_chair_walk");
  EXPECT_EQ(env->spec().obs_dim, 52);
  // envs alone refuses the walk task with a pointer to tasks/.
  EXPECT_THROW(MakeEnv(walk.env), ConfigError);
  EXPECT_THROW(TaskEnvConfig::Defaults("fly"), ConfigError);
  // Same seed, same episode.
  std::unique_ptr<Env> a = MakeTaskEnv(walk), b = MakeTaskEnv(walk);
  std::vector<float> oa(52), ob(52), act(21, 0.1f);
  a->Seed(9);
  b->Seed(9);
  a->Reset(oa.data());
  b->Reset(ob.data());
  for (int k = 0; k < 5; ++k) {
    const StepResult ra = a->Step(act.data(), oa.data()), rb = b->Step(act.data(), ob.data());
    EXPECT_EQ(ra.reward, rb.reward);
  }
  EXPECT_EQ(oa, ob);
}

}  // namespace
}  // namespace perch
