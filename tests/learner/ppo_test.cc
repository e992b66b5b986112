// PpoLearner::Update mechanics: minibatch/epoch counts for any batch size, the global gradient
// clip is applied, the first minibatch starts at ratio 1, and the obs statistics are merged.
#include "learner/ppo.h"

#include <gtest/gtest.h>

#include <vector>

#include "learner/policy.h"

namespace perch {
namespace {

Rollout Acted(const PpoLearner& learner, int steps, uint64_t seed) {
  const PolicyConfig& c = learner.model().config();
  PolicyRunner runner(c, learner.config().obs_norm);
  runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(), 0);
  Rng rng(seed);
  Rollout r(c.obs_dim, c.action_size());
  std::vector<float> raw(c.obs_dim), norm(c.obs_dim), a(c.action_size());
  for (int t = 0; t < steps; ++t) {
    for (float& x : raw) x = static_cast<float>(rng.Normal(2.0, 3.0));
    const auto o = runner.Act(raw.data(), rng, false, norm.data(), a.data());
    r.Add(norm.data(), a.data(), o.log_prob, o.value, static_cast<float>(rng.Normal(1.0, 1.0)),
          false, false, t + 1 == steps ? o.value : 0.0f);
  }
  r.obs_stats_delta = runner.obs_stats_delta();
  return r;
}

TEST(PpoUpdateTest, CountsMinibatchStepsForAnyBatchSize) {
  PpoConfig cfg;
  cfg.num_minibatches = 32;
  cfg.num_epochs = 3;
  PpoLearner learner(PolicyConfig::Subtask(7), cfg, 1);
  const UpdateStats st = learner.Update({Acted(learner, 60, 2), Acted(learner, 43, 3)});
  EXPECT_EQ(st.num_samples, 103);
  EXPECT_EQ(st.num_minibatch_steps, 3 * 32);
  EXPECT_EQ(learner.optimizer().step(), 3 * 32);
  EXPECT_EQ(learner.num_samples(), 103);
  EXPECT_EQ(learner.num_updates(), 1);
  // Both deltas merged into the master statistics (prior 1e-4 + 103 observations).
  EXPECT_NEAR(learner.obs_normalizer().stats().count(), 103 + 1e-4, 1e-9);
  EXPECT_NEAR(learner.obs_normalizer().stats().mean()[0], 2.0, 0.9);
}

TEST(PpoUpdateTest, FirstMinibatchStartsAtRatioOne) {
  PpoConfig cfg;
  cfg.num_minibatches = 1;
  cfg.num_epochs = 1;
  PpoLearner learner(PolicyConfig::Subtask(7), cfg, 1);
  const UpdateStats st = learner.Update({Acted(learner, 64, 2)});
  // One minibatch, evaluated before its own step: the learner reproduces the actor's log-probs.
  EXPECT_LT(st.approx_kl, 1e-9);
  EXPECT_EQ(st.clip_fraction, 0.0f);
}

TEST(PpoUpdateTest, GlobalGradientClipIsApplied) {
  // Adam is nearly invariant to the gradient's scale, except when the clipped gradient falls far
  // below eps: a clip at 1e-9 must all but freeze the weights, no clip must move them.
  VectorXf moved[2];
  for (int i = 0; i < 2; ++i) {
    PpoConfig cfg;
    cfg.num_minibatches = 2;
    cfg.num_epochs = 1;
    cfg.learning_rate = 1e-3f;
    cfg.max_grad_norm = i == 0 ? 1e-9f : 0.0f;  // 0 disables
    PpoLearner learner(PolicyConfig::Subtask(7), cfg, 1);
    const VectorXf before = learner.model().params();
    const UpdateStats st = learner.Update({Acted(learner, 64, 2)});
    EXPECT_GT(st.grad_norm, 1e-3f);  // reported before clipping
    moved[i] = learner.model().params() - before;
  }
  EXPECT_LT(moved[0].cwiseAbs().maxCoeff(), 1e-6f);
  EXPECT_GT(moved[1].cwiseAbs().maxCoeff(), 1e-4f);
}

}  // namespace
}  // namespace perch
