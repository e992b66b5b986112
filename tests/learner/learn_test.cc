// PPO learns: a continuous-control task (point mass to a random target) reaches the return of a
// tuned PD controller, and the meta head learns both the discrete choice and the walk target.
// Fixed seeds, bounded step counts (a few seconds in Release).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <vector>

#include "learner/ppo.h"
#include "learner/toy_envs.h"
#include "policy/policy.h"
#include "policy/rollout.h"

namespace perch {
namespace {

// Mean undiscounted return of `episodes` episodes of `policy` (raw obs -> action) on a fresh
// PointMassEnv seeded with `seed`.
double EvalPointMass(const std::function<void(const float*, float*)>& policy, uint64_t seed,
                     int episodes) {
  PointMassEnv env;
  env.Seed(seed);
  std::vector<float> obs(6), act(2);
  double total = 0;
  for (int e = 0; e < episodes; ++e) {
    env.Reset(obs.data());
    for (;;) {
      policy(obs.data(), act.data());
      const StepResult r = env.Step(act.data(), obs.data());
      total += r.reward;
      if (r.terminated || r.truncated) break;
    }
  }
  return total / episodes;
}

PpoConfig PointMassPpo() {
  PpoConfig c;
  c.steps_per_update = 2048;
  c.num_minibatches = 32;
  c.num_epochs = 10;
  c.learning_rate = 1e-3f;
  return c;
}

// Trains for `updates` updates; returns the learner.
PpoLearner TrainPointMass(uint64_t seed, int updates, const PpoConfig& cfg) {
  PolicyConfig pc = PolicyConfig::Subtask(6);
  pc.act_dim = 2;
  PpoLearner learner(pc, cfg, seed);
  PolicyRunner runner(pc, cfg.obs_norm);
  PointMassEnv env;
  env.Seed(seed);
  RolloutCollector collector(&env, 0);
  Rng rng(seed + 1);
  std::vector<Rollout> batch(1);
  for (int u = 0; u < updates; ++u) {
    runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(),
                      learner.num_updates());
    collector.Collect(&runner, rng, cfg.steps_per_update, &batch[0], nullptr);
    learner.Update(batch);
  }
  return learner;
}

TEST(LearnTest, PointMassReachesPdControllerReturn) {
  const int kEvalEpisodes = 200;
  const uint64_t kEvalSeed = 12345;
  // Baselines on the same evaluation episodes: doing nothing, and the best of a grid of PD gains.
  const double zero =
      EvalPointMass([](const float*, float* a) { a[0] = a[1] = 0; }, kEvalSeed, kEvalEpisodes);
  double pd = -1e9;
  for (float kp : {1.f, 2.f, 4.f, 8.f, 16.f}) {
    for (float kd : {0.5f, 1.f, 2.f, 4.f}) {
      pd = std::max(pd, EvalPointMass(
                            [&](const float* o, float* a) {
                              for (int i = 0; i < 2; ++i) {
                                a[i] =
                                    std::clamp(kp * (o[4 + i] - o[i]) - kd * o[2 + i], -1.f, 1.f);
                              }
                            },
                            kEvalSeed, kEvalEpisodes));
    }
  }
  ASSERT_GT(pd, zero + 10.0);  // the task is not trivial

  const PpoConfig cfg = PointMassPpo();
  PpoLearner learner = TrainPointMass(/*seed=*/1, /*updates=*/40, cfg);
  PolicyRunner runner(learner.model().config(), cfg.obs_norm);
  runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(), 0);
  runner.set_update_obs_stats(false);
  Rng rng(0);
  const double trained = EvalPointMass(
      [&](const float* o, float* a) { runner.Act(o, rng, /*deterministic=*/true, nullptr, a); },
      kEvalSeed, kEvalEpisodes);
  PpoLearner untrained = TrainPointMass(1, 0, cfg);
  PolicyRunner runner0(untrained.model().config(), cfg.obs_norm);
  runner0.SetWeights(untrained.model().params(), untrained.obs_normalizer().stats(), 0);
  const double before =
      EvalPointMass([&](const float* o, float* a) { runner0.Act(o, rng, true, nullptr, a); },
                    kEvalSeed, kEvalEpisodes);
  RecordProperty("zero_return", std::to_string(zero));
  RecordProperty("pd_return", std::to_string(pd));
  RecordProperty("trained_return", std::to_string(trained));
  std::printf("point mass: zero %.2f, untrained %.2f, best PD %.2f, PPO %.2f\n", zero, before, pd,
              trained);
  // Solved: at least 90% of the best PD controller's gain over doing nothing.
  EXPECT_GT(trained, zero + 0.9 * (pd - zero));
  EXPECT_LT(before, zero + 0.5 * (pd - zero));
}

TEST(LearnTest, MetaHeadLearnsChoiceAndTarget) {
  ChoiceTargetConfig tc;
  ChoiceTargetEnv env(tc);
  env.Seed(3);
  const PolicyConfig pc = PolicyConfig::Meta(env.spec().obs_dim);
  PpoConfig cfg;
  cfg.steps_per_update = 512;
  cfg.num_minibatches = 8;
  cfg.num_epochs = 4;
  cfg.learning_rate = 1e-3f;
  cfg.gamma = 0.0f;  // one-step episodes
  PpoLearner learner(pc, cfg, 3);
  PolicyRunner runner(pc, cfg.obs_norm);
  RolloutCollector collector(&env, 0);
  Rng rng(4);
  std::vector<Rollout> batch(1);
  for (int u = 0; u < 40; ++u) {
    runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(), u);
    collector.Collect(&runner, rng, cfg.steps_per_update, &batch[0], nullptr);
    learner.Update(batch);
  }
  runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(), 0);
  runner.set_update_obs_stats(false);
  ChoiceTargetEnv eval(tc);
  eval.Seed(99);
  std::vector<float> obs(env.spec().obs_dim), act(3);
  eval.Reset(obs.data());
  int correct = 0, walks = 0;
  double target_err = 0;
  const int kTrials = 1000;
  for (int i = 0; i < kTrials; ++i) {
    const int context = eval.context();
    const float gx = eval.goal()[0], gy = eval.goal()[1];
    runner.Act(obs.data(), rng, /*deterministic=*/true, nullptr, act.data());
    const int choice = static_cast<int>(act[0]);
    correct += choice == context;
    if (context == tc.target_choice) {
      ++walks;
      target_err += std::hypot(act[1] - gx, act[2] - gy);
    }
    eval.Step(act.data(), obs.data());
  }
  ASSERT_GT(walks, 100);
  target_err /= walks;
  std::printf("choice accuracy %.3f, walk target error %.3f m\n",
              static_cast<double>(correct) / kTrials, target_err);
  EXPECT_GT(correct, 0.97 * kTrials);
  // Goals are U(-1, 1)^2: predicting their mean would be off by ~0.77 m on average.
  EXPECT_LT(target_err, 0.15);
}

TEST(LearnTest, SameSeedSameWeightsDifferentSeedDifferent) {
  PpoConfig cfg = PointMassPpo();
  cfg.steps_per_update = 512;
  cfg.num_minibatches = 8;
  cfg.num_epochs = 2;
  const PpoLearner a = TrainPointMass(5, 3, cfg);
  const PpoLearner b = TrainPointMass(5, 3, cfg);
  const PpoLearner c = TrainPointMass(6, 3, cfg);
  const PpoLearner init = TrainPointMass(5, 0, cfg);
  EXPECT_EQ(a.model().params(), b.model().params());
  EXPECT_EQ(a.obs_normalizer().stats().mean(), b.obs_normalizer().stats().mean());
  EXPECT_NE(a.model().params(), c.model().params());
  EXPECT_GT((a.model().params() - init.model().params()).norm(), 1e-3f);
}

}  // namespace
}  // namespace perch
