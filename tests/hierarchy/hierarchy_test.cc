#include "hierarchy/hierarchy.h"

#include <gtest/gtest.h>

#include "learner/ppo.h"
#include "policy/policy.h"
#include "tests/support/untrained.h"

namespace perch {
namespace {

std::array<proto::ModelWeights, kNumSubtasks> UntrainedSet() {
  std::array<proto::ModelWeights, kNumSubtasks> m;
  for (int id = 0; id < kNumSubtasks; ++id) {
    m[id] = Untrained(id == kWalk ? 52 : id == kSit ? 57 : 50, id + 1);
  }
  return m;
}

TaskEnvConfig SitChair(int zone) {
  return TaskEnvConfig::FromJson({{"task", "sit_chair"}, {"spawn", {{"zone", zone}}}}, "t");
}

TEST(Hierarchy, EveryLayoutOfOneEnvAgreesWithWhatTheEnvWrote) {
  auto env = MakeTaskHumanoidEnv(SitChair(1));
  std::vector<float> obs(57), other(57), act(21, 0.1f);
  env->Seed(3);
  env->Reset(obs.data());
  for (int k = 0; k < 5; ++k) env->Step(act.data(), obs.data());
  env->WriteObservation(ObsLayout::kProprioChair, other.data());
  for (int i = 0; i < 57; ++i) EXPECT_EQ(other[i], obs[i]) << i;  // the env's own layout
  env->WriteObservation(ObsLayout::kProprioGoal, other.data());
  for (int i = 0; i < 50; ++i) EXPECT_EQ(other[i], obs[i]) << i;  // shared proprioception
  // The goal feature points at the walk target.
  const Eigen::Vector2d to = env->walk_target() - env->BodyXyz().head<2>();
  const double psi = std::atan2(to.y(), to.x()) - env->RootRpy().z();
  EXPECT_NEAR(other[50], std::sin(psi), 1e-5);
  EXPECT_NEAR(other[51], std::cos(psi), 1e-5);
}

TEST(Hierarchy, SpawnsWalkingInTheZoneFacingItsCentre) {
  for (int zone : {1, 3}) {
    auto env = MakeTaskHumanoidEnv(SitChair(zone));
    const auto& task = dynamic_cast<const SitChairTask&>(env->task());
    std::vector<float> obs(57);
    for (int seed = 0; seed < 5; ++seed) {
      env->Seed(seed);
      env->Reset(obs.data());
      const double theta = task.spawn_theta();
      const auto& r = zone == 1 ? env->config().spawn.zone1_deg : env->config().spawn.zone3_deg;
      EXPECT_GE(std::abs(theta) * 180 / M_PI, r[0] - 1e-9);
      EXPECT_LE(std::abs(theta) * 180 / M_PI, r[1] + 1e-9);
      const SpawnCircle circle = ZoneCircle(env->config().spawn, zone);
      const Eigen::Vector2d c(circle.center_x, circle.center_y);
      const Eigen::Vector2d p = env->humanoid_state().root_pos.head<2>();
      EXPECT_NEAR((p - c).norm(), circle.radius, 1e-6);
      const double to_centre = std::atan2(c.y() - p.y(), c.x() - p.x());
      EXPECT_NEAR(AngleDiff(env->RootRpy().z(), to_centre), 0.0, 1e-6);
      EXPECT_GT(env->humanoid_state().root_lin_vel.norm(), 0.3);  // mid-stride, walking
    }
  }
}

TEST(Hierarchy, TerminationHeightFollowsTheActiveSubtask) {
  // The walking start (root about 1.2 m) is above 0.78 m; a sit threshold set above it ends the
  // episode only while sit is the active subtask.
  auto env = MakeTaskHumanoidEnv(TaskEnvConfig::FromJson(
      {{"task", "sit_chair"}, {"spawn", {{"zone", 1}}}, {"sit_chair", {{"sit_min_root_z", 1.5}}}},
      "t"));
  auto& task = const_cast<SitChairTask&>(dynamic_cast<const SitChairTask&>(env->task()));
  std::vector<float> obs(57), zero(21, 0.0f);
  for (int active : {kWalk, kSit}) {
    env->Seed(1);
    env->Reset(obs.data());
    task.set_active(active);
    EXPECT_EQ(env->Step(zero.data(), obs.data()).terminated, active == kSit) << active;
  }
  EXPECT_EQ(SitChairTaskConfig().min_root_z, 0.78);
  EXPECT_EQ(SitChairTaskConfig().sit_min_root_z, 0.54);
}

// The hierarchy's success is judged in one place, the task's step (the chain and the meta env read
// StepResult::success): once, at the step the seated contact has lasted success_contact_s; its
// counters can be saved and restored (MetaEnvState carries them for the lookahead).
TEST(Hierarchy, SuccessIsTheTasksOnceAfterTheSeatedContactTime) {
  auto env = MakeTaskHumanoidEnv(TaskEnvConfig::FromJson(
      {{"task", "sit_chair"},
       {"spawn", {{"zone", 1}}},
       {"sit_chair", {{"success_contact_s", 1.0}, {"max_episode_steps", 200}}}},
      "t"));
  auto& task = const_cast<SitChairTask&>(dynamic_cast<const SitChairTask&>(env->task()));
  EXPECT_TRUE(env->spec().has_success);
  std::vector<float> obs(env->spec().obs_dim), zero(21, 0.0f);
  env->Seed(4);
  env->Reset(obs.data());
  env->ResetToState(SeatedPose(env->model(), *env->chair(), env->config().chair_placement, 0.005),
                    obs.data());
  task.set_active(kSit);
  const int need = 60;  // 1 s at 60 Hz
  int run = 0, want = -1, got = -1, count = 0;
  SitChairTask::Seated before_success;
  for (int k = 1; k <= 150; ++k) {
    if (k == need - 5) before_success = task.seated();
    const StepResult r = env->Step(zero.data(), obs.data());
    run = env->PelvisSeatContact() ? run + 1 : 0;
    if (want < 0 && run >= need) want = k;
    EXPECT_EQ(task.seated().run, run);
    if (r.success) {
      ++count;
      got = k;
    }
  }
  ASSERT_GT(want, 0) << "the seated body stays on the seat for 1 s";
  EXPECT_EQ(got, want);
  EXPECT_EQ(count, 1);
  EXPECT_TRUE(task.seated().succeeded);
  // Restored to before the success, the success comes again; a new episode starts from nothing.
  task.set_seated(before_success);
  EXPECT_FALSE(task.seated().succeeded);
  env->Reset(obs.data());
  EXPECT_EQ(task.seated().run, 0);
  EXPECT_FALSE(task.seated().succeeded);
}

TEST(Hierarchy, SubtaskPoliciesRefuseAModelOfAnotherObservationByName) {
  auto models = UntrainedSet();
  models[kSit] = Untrained(52, 9);
  try {
    SubtaskPolicies p(models, {"a.bin", "b.bin", "sit.bin", "w.bin"});
    ADD_FAILURE() << "accepted";
  } catch (const ConfigError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("sit policy sit.bin"), std::string::npos) << m;
    EXPECT_NE(m.find("57"), std::string::npos) << m;
  }
}

// A sit trained with observe_chair_shape (82 inputs) is run on the 57-d state plus the chair's
// height grid; a 57-input sit keeps the paper's state.
TEST(Hierarchy, ASitThatSeesTheChairsShapeIsGivenItsHeightGrid) {
  auto models = UntrainedSet();
  EXPECT_EQ(SubtaskPolicies(models, {"l", "r", "s", "w"}).Layout(kSit), ObsLayout::kProprioChair);
  models[kSit] = Untrained(82, 9);
  SubtaskPolicies p(models, {"l", "r", "s", "w"});
  EXPECT_EQ(p.Layout(kSit), ObsLayout::kProprioChairShape);
  auto env = MakeTaskHumanoidEnv(SitChair(1));
  std::vector<float> obs(57), shape_obs(82), a(21), b(21);
  env->Seed(4);
  env->Reset(obs.data());
  Rng r1(2), r2(2);
  p.Act(kSit, *env, r1, true, a.data());
  PolicyRunner direct(PolicyConfigFromShape(models[kSit].shape(), "s"), NormalizerConfig());
  direct.LoadWeights(models[kSit]);
  direct.set_update_obs_stats(false);
  env->WriteObservation(ObsLayout::kProprioChairShape, shape_obs.data());
  direct.Act(shape_obs.data(), r2, true, nullptr, b.data());
  for (int i = 0; i < 21; ++i) EXPECT_EQ(a[i], b[i]) << i;
  // The grid is what the policy saw: another grid gives another action.
  for (int k = 0; k < kChairGridDim; ++k) shape_obs[kObsShape + k] += 0.5f;
  Rng r3(2);
  direct.Act(shape_obs.data(), r3, true, nullptr, b.data());
  int differ = 0;
  for (int i = 0; i < 21; ++i) differ += a[i] != b[i];
  EXPECT_GT(differ, 0);
}

TEST(Hierarchy, ScriptedChainIsReproducibleAndUntrainedSubtasksNeverSit) {
  ChainOptions o;
  o.episodes = 2;
  o.seed = 5;
  std::vector<PoseFrame> frames;
  const auto models = UntrainedSet();
  const std::array<std::string, kNumSubtasks> names = {"l", "r", "s", "w"};
  const Json a = EvaluateChain(SitChair(1), models, names, {}, o, &frames);
  const Json b = EvaluateChain(SitChair(1), models, names, {}, o, nullptr);
  EXPECT_EQ(a.dump(), b.dump());
  EXPECT_EQ(a["success_rate"].get<double>(), 0.0);
  EXPECT_GT(a["min_dist_mean_m"].get<double>(), 0.3);
  ASSERT_FALSE(frames.empty());
  EXPECT_EQ(frames.front().label, "walk");
}

TEST(Hierarchy, ChainSitStartsAreTheStatesAtTheSwitchToSit) {
  ChainOptions o;
  o.episodes = 3;
  o.seed = 2;
  o.reach_m = 5.0;  // turn at once
  o.turn_s = 0.1;   // then sit after 6 control steps, before the untrained subtasks fall
  o.side = "left";
  o.stop_at_sit = true;
  std::vector<proto::BankState> starts;
  o.sit_starts = &starts;
  std::vector<PoseFrame> frames;
  const auto models = UntrainedSet();
  const std::array<std::string, kNumSubtasks> names = {"l", "r", "s", "w"};
  const Json j = EvaluateChain(SitChair(1), models, names, {}, o, &frames);
  EXPECT_EQ(j["reached_sit"].get<int>(), 3);
  EXPECT_EQ(j["left_turns"].get<int>(), 3);
  EXPECT_EQ(j["fall_rate"].get<double>(), 0.0);  // ended at the switch, not by a fall
  ASSERT_EQ(starts.size(), 3u);
  for (size_t e = 0; e < starts.size(); ++e) {
    EXPECT_TRUE(starts[e].has_chair());
    EXPECT_EQ(starts[e].episode(), e);
    EXPECT_EQ(starts[e].step(), 6) << e;  // the turn from step 0, 6 steps (0.1 s) to the switch
  }
  // Episode 0 stopped at the switch: its frames are walk and left turn only.
  for (const PoseFrame& f : frames) EXPECT_NE(f.label, "sit");
  EXPECT_EQ(frames.back().label, "turn_left");
}

Json HeadingTurnExperiment(const std::string& task, double lookahead) {
  return Json{{"env",
               {{"task", task},
                {"chair", "none"},
                {task, {{"heading_goal", true}, {"heading_lookahead_s", lookahead}}}}}};
}

TEST(Hierarchy, HeadingGoalTurnsReadTheirClipFromTheSavedConfig) {
  // A 52-input turn with its saved config observes the walk layout; its goal follows the clip's
  // yaw change since the turn began, from the humanoid's yaw at that moment.
  const auto h = TurnHeadingSource::FromSavedConfig(HeadingTurnExperiment("turn_left", 0.0), "t");
  ASSERT_NE(h, nullptr);
  EXPECT_NEAR(h->GoalYaw(0.7, 0.0), 0.7, 1e-12);
  const double end = h->GoalYaw(0.7, 10.0) - 0.7;  // held at the last frame
  EXPECT_NEAR(end * 180.0 / M_PI, 180.0, 8.0) << "the left clip turns about half round";
  const auto r = TurnHeadingSource::FromSavedConfig(HeadingTurnExperiment("turn_right", 0.3), "t");
  ASSERT_NE(r, nullptr);
  EXPECT_LT(r->GoalYaw(0.0, 10.0), -2.9);
  // The look-ahead reads further along: 0.3 s ahead at t equals no look-ahead at t + 0.3.
  const auto r0 = TurnHeadingSource::FromSavedConfig(HeadingTurnExperiment("turn_right", 0.0), "t");
  EXPECT_NEAR(r->GoalYaw(0.2, 1.0), r0->GoalYaw(0.2, 1.3), 1e-9);
  // A paper turn (no heading goal) or another task has none.
  EXPECT_EQ(TurnHeadingSource::FromSavedConfig(
                Json{{"env", {{"task", "turn_left"}, {"chair", "none"}}}}, "t"),
            nullptr);
  EXPECT_EQ(TurnHeadingSource::FromSavedConfig(Json(), "t"), nullptr);

  auto models = UntrainedSet();
  models[kLeftTurn] = Untrained(52, 11);
  std::array<Json, kNumSubtasks> saved;
  saved[kLeftTurn] = HeadingTurnExperiment("turn_left", 0.3);
  SubtaskPolicies p(models, {"l.bin", "r.bin", "s.bin", "w.bin"}, saved);
  EXPECT_TRUE(p.heading_goal(kLeftTurn));
  EXPECT_FALSE(p.heading_goal(kRightTurn));
  EXPECT_EQ(p.Layout(kLeftTurn), ObsLayout::kProprioGoal);
  EXPECT_EQ(p.Layout(kRightTurn), ObsLayout::kProprio);
  // Without the saved config a 52-input turn is refused, and the message says why.
  try {
    SubtaskPolicies q(models, {"l.bin", "r.bin", "s.bin", "w.bin"});
    ADD_FAILURE() << "accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("heading_goal"), std::string::npos) << e.what();
  }
  // The chain runs with it, reproducibly.
  ChainOptions o;
  o.episodes = 1;
  o.seed = 2;
  const std::array<std::string, kNumSubtasks> names = {"l", "r", "s", "w"};
  EXPECT_EQ(EvaluateChain(SitChair(1), models, names, saved, o, nullptr).dump(),
            EvaluateChain(SitChair(1), models, names, saved, o, nullptr).dump());
}

}  // namespace
}  // namespace perch
