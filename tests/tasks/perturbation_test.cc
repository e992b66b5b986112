// tasks/perturbation.h: the evaluation's perturbations (issue 49) and the flip rate.
#include "tasks/perturbation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <string>
#include <vector>

#include "tasks/model_source.h"
#include "tasks/registry.h"
#include "tasks/task_env.h"
#include "tasks/task_eval.h"

namespace perch {
namespace {

// Steps both envs with zero actions and returns the root heights [m] per step.
std::vector<double> Heights(Env* stepped, const HumanoidChairEnv& env, int steps, uint64_t seed) {
  std::vector<float> obs(env.spec().obs_dim), zero(env.spec().act_dim, 0.0f);
  stepped->Seed(seed);
  stepped->Reset(obs.data());
  std::vector<double> z;
  for (int k = 0; k < steps; ++k) {
    stepped->Step(zero.data(), obs.data());
    z.push_back(env.humanoid_state().root_pos.z());
  }
  return z;
}

TEST(Perturbation, WithoutPerturbationsTheEpisodeIsTheBareEnvs) {
  auto env = MakeTaskHumanoidEnv(TaskEnvConfig::Defaults("sit"));
  PerturbedEnv plain(env.get(), Perturbation(), 30);
  const std::vector<double> a = Heights(env.get(), *env, 30, 5);
  EXPECT_EQ(Heights(&plain, *env, 30, 5), a);
  EXPECT_EQ(plain.push_step(), -1);
  EXPECT_EQ(plain.restore_step(), -1);
  // Action noise changes the episode, reproducibly for its seed.
  Perturbation noisy;
  noisy.act_noise = 0.3;
  PerturbedEnv n(env.get(), noisy, 30);
  const std::vector<double> b = Heights(&n, *env, 30, 5);
  EXPECT_NE(b, a);
  EXPECT_EQ(Heights(&n, *env, 30, 5), b);
}

TEST(Perturbation, APushActsForItsDurationFromARandomStepInsideTheEpisode) {
  auto env = MakeTaskHumanoidEnv(TaskEnvConfig::Defaults("sit"));
  Perturbation p;
  p.push_n = 50.0;
  p.push_s = 0.1;  // 6 control steps at 60 Hz
  PerturbedEnv e(env.get(), p, 40);
  std::vector<float> obs(env->spec().obs_dim), zero(env->spec().act_dim, 0.0f);
  std::vector<int> push_steps;
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    e.Seed(seed);
    e.Reset(obs.data());
    ASSERT_GE(e.push_step(), 0);
    ASSERT_LT(e.push_step(), 40);
    push_steps.push_back(e.push_step());
    int pushed = 0, first = -1;
    for (int k = 0; k < 50; ++k) {
      e.Step(zero.data(), obs.data());
      const Eigen::Vector3d f = env->push_force();
      if (f.norm() > 0) {
        if (first < 0) first = k;
        ++pushed;
        EXPECT_NEAR(f.norm(), 50.0, 1e-9);
        EXPECT_EQ(f.z(), 0.0);  // horizontal
      }
    }
    EXPECT_EQ(first, e.push_step());
    EXPECT_EQ(pushed, 6);
    EXPECT_EQ(env->pushes(), 1);
  }
  // The moment is drawn per episode.
  EXPECT_GT(std::set<int>(push_steps.begin(), push_steps.end()).size(), 1u);
}

TEST(Perturbation, FlipRateCountsTheEpisodesWhoseOutcomeDiffers) {
  const Json j = FlipRate({true, true, false, false}, {true, false, true, false});
  EXPECT_EQ(j["flips"], 2);
  EXPECT_DOUBLE_EQ(j["flip_rate"].get<double>(), 0.5);
  EXPECT_LT(j["flip_ci95"][0].get<double>(), 0.5);
  EXPECT_GT(j["flip_ci95"][1].get<double>(), 0.5);
  EXPECT_THROW(FlipRate({true}, {true, false}), std::logic_error);
}

// An evaluation with a perturbation reports the same episodes unperturbed, and their success rate
// is what a plain evaluation gives: the outcome is judged the same way (the task's success).
TEST(Perturbation, TheUnperturbedRunIsThePlainEvaluation) {
  const std::string path = std::string(PERCH_SOURCE_DIR) + "/models/turn_left/policy.bin";
  const proto::ModelWeights w = LoadModelFile(path);
  const TaskEnvConfig c = TaskEnvConfig::FromJson(SavedConfig(path)["env"], "turn_left");
  EvalOptions o;
  o.episodes = 12;
  o.seed = 3;
  o.stochastic = true;  // some failures, so that outcomes can flip
  const TaskDef& def = GetTask("turn_left", "t");
  const Json plain = def.evaluate(c, w, o, nullptr);
  o.perturb.push_n = 200.0;
  const Json pushed = def.evaluate(c, w, o, nullptr);
  EXPECT_EQ(pushed["unperturbed_success_rate"], plain["success_rate"]);
  EXPECT_EQ(pushed["perturbation"]["push_n"], 200.0);
  const double flip = pushed["flip_rate"].get<double>();
  // At least the change in the success rate flipped.
  EXPECT_GE(flip + 1e-12,
            std::abs(pushed["success_rate"].get<double>() - plain["success_rate"].get<double>()));
  EXPECT_FALSE(plain.contains("flip_rate"));
}

}  // namespace
}  // namespace perch

namespace perch {
namespace {

// The walk's outcome is staying up for the no-fall window, and its perturbations fall inside it:
// the unperturbed run is the plain evaluation, and a hard push flips some episodes.
TEST(Perturbation, WalkPushesLandInsideTheNoFallWindow) {
  const std::string dir = std::string(PERCH_SOURCE_DIR) + "/models/";
  const proto::ModelWeights w =
      LoadModelFile(dir + "walk_stage2_fallrestart/checkpoints/ckpt-0000013900.bin");
  TaskEnvConfig c =
      TaskEnvConfig::FromJson(LoadJsonFile(dir + "walk_stage2/config.json")["env"], "walk_stage2");
  EvalOptions o;
  o.episodes = 6;
  o.seed = 0;
  o.no_fall_s = 2.0;  // shorter than the task's time limit
  const TaskDef& def = GetTask("walk", "t");
  const Json plain = def.evaluate(c, w, o, nullptr);
  o.perturb.push_n = 400.0;
  o.perturb.push_s = 0.2;
  const Json pushed = def.evaluate(c, w, o, nullptr);
  EXPECT_EQ(pushed["unperturbed_success_rate"], plain["no_fall_rate"]);
  EXPECT_GT(pushed["flips"].get<int>(), 0);
}

}  // namespace
}  // namespace perch
