// PpoLearner::Update mechanics: minibatch/epoch counts for any batch size, the global gradient
// clip is applied, the first minibatch starts at ratio 1, and the obs statistics are merged.
#include "learner/ppo.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "policy/policy.h"

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

// ppo.threads (issue 20): each minibatch is split into one part per thread, which differs from one
// thread only in the summation order of the parts' gradients; any count gives the same bits every
// run.
TEST(PpoUpdateTest, ThreadsMatchOneThread) {
  auto run = [](int threads, UpdateStats* st) {
    PpoConfig cfg;
    cfg.num_minibatches = 4;  // 150-sample minibatches: parts of 75 or 50
    cfg.num_epochs = 2;
    cfg.threads = threads;
    PpoLearner learner(PolicyConfig::Subtask(9), cfg, 5);
    *st = learner.Update({Acted(learner, 350, 2), Acted(learner, 250, 3)});
    return VectorXf(learner.model().params());
  };
  UpdateStats s1, s2, s2b, s3, s4, s4b, s6;
  const VectorXf p1 = run(1, &s1), p2 = run(2, &s2), p2b = run(2, &s2b), p3 = run(3, &s3),
                 p4 = run(4, &s4), p4b = run(4, &s4b), p6 = run(6, &s6);
  const VectorXf p0 = PpoLearner(PolicyConfig::Subtask(9), PpoConfig(), 5).model().params();
  // Minibatches split into parts: the update moved the weights by far more than the split (the
  // summation order of the parts' gradients) changes them.
  const float moved = (p1 - p0).cwiseAbs().maxCoeff();
  EXPECT_GT(moved, 1e-4f);
  EXPECT_FALSE(p2 == p1);  // the split path did run
  for (const VectorXf* p : {&p2, &p3, &p4, &p6}) {
    EXPECT_LT((*p - p1).cwiseAbs().maxCoeff(), 1e-3f * moved);
  }
  // A thread count gives the same bits every run.
  EXPECT_TRUE(p2 == p2b) << (p2 - p2b).cwiseAbs().maxCoeff();
  EXPECT_TRUE(p4 == p4b) << (p4 - p4b).cwiseAbs().maxCoeff();
  EXPECT_EQ(s2.policy_loss, s2b.policy_loss);
  EXPECT_EQ(s4.policy_loss, s4b.policy_loss);
  for (const UpdateStats* s : {&s2, &s3, &s4, &s6}) {
    EXPECT_NEAR(s->policy_loss, s1.policy_loss, 1e-4f * (1 + std::abs(s1.policy_loss)));
    EXPECT_NEAR(s->value_loss, s1.value_loss, 1e-4f * (1 + s1.value_loss));
    EXPECT_NEAR(s->entropy, s1.entropy, 1e-4f * (1 + std::abs(s1.entropy)));
    EXPECT_NEAR(s->approx_kl, s1.approx_kl, 1e-5f + 1e-3f * s1.approx_kl);
    EXPECT_NEAR(s->clip_fraction, s1.clip_fraction, 0.01f);
    EXPECT_NEAR(s->grad_norm, s1.grad_norm, 1e-4f * s1.grad_norm);
    EXPECT_EQ(s->num_minibatch_steps, s1.num_minibatch_steps);
  }
}

// The walker's sizes (52-d observation, 256-sample minibatches split in two 128-column parts).
TEST(PpoUpdateTest, TwoThreadsAtTheWalkersSizeMatchOneThread) {
  auto run = [](int threads) {
    PpoConfig cfg;
    cfg.num_minibatches = 4;
    cfg.num_epochs = 2;
    cfg.threads = threads;
    PpoLearner learner(PolicyConfig::Subtask(52), cfg, 11);
    learner.Update({Acted(learner, 700, 4), Acted(learner, 324, 5)});
    return VectorXf(learner.model().params());
  };
  const VectorXf p0 = PpoLearner(PolicyConfig::Subtask(52), PpoConfig(), 11).model().params();
  const VectorXf p1 = run(1), p2 = run(2), p2b = run(2);
  EXPECT_TRUE(p2 == p2b) << (p2 - p2b).cwiseAbs().maxCoeff();
  const float moved = (p1 - p0).cwiseAbs().maxCoeff();
  EXPECT_LT((p2 - p1).cwiseAbs().maxCoeff(), 1e-3f * moved);
}

TEST(PpoUpdateTest, PartsOfAMinibatchAddUpToTheWhole) {
  PpoConfig cfg;
  PpoLearner learner(PolicyConfig::Subtask(9), cfg, 5);
  const Rollout r = Acted(learner, 40, 2);
  const ActorCritic& m = learner.model();
  const MatrixXf obs = Eigen::Map<const MatrixXf>(r.obs.data(), 9, 40);
  const MatrixXf act = Eigen::Map<const MatrixXf>(r.actions.data(), m.action_size(), 40);
  const VectorXf logp = Eigen::Map<const VectorXf>(r.log_probs.data(), 40).array() - 0.1f;
  const VectorXf val = Eigen::Map<const VectorXf>(r.values.data(), 40);
  VectorXf adv(40), ret(40);
  Rng rng(3);
  for (int k = 0; k < 40; ++k) {
    adv[k] = static_cast<float>(rng.Normal());
    ret[k] = static_cast<float>(rng.Normal());
  }
  PpoLossWorkspace ws;
  VectorXf whole = VectorXf::Zero(m.num_params()), parts = VectorXf::Zero(m.num_params());
  const PpoLossTerms tw =
      PpoLoss(m, m.params().data(), cfg, obs, act, logp, val, adv, ret, &ws, whole.data());
  PpoLossTerms tp;
  for (auto [lo, n] : {std::pair{0, 13}, std::pair{13, 27}}) {
    const PpoLossTerms t = PpoLoss(m, m.params().data(), cfg, obs.middleCols(lo, n),
                                   act.middleCols(lo, n), logp.segment(lo, n), val.segment(lo, n),
                                   adv.segment(lo, n), ret.segment(lo, n), &ws, parts.data(), 40);
    tp.total += t.total;
    tp.entropy += t.entropy;
    tp.value_loss += t.value_loss;
  }
  EXPECT_NEAR(tp.total, tw.total, 1e-5 * (1 + std::abs(tw.total)));
  EXPECT_NEAR(tp.entropy, tw.entropy, 1e-5 * (1 + std::abs(tw.entropy)));
  EXPECT_NEAR(tp.value_loss, tw.value_loss, 1e-5 * (1 + tw.value_loss));
  EXPECT_GT(whole.norm(), 0.0f);
  EXPECT_LT((parts - whole).norm(), 1e-4f * whole.norm());
}

TEST(PpoConfigTest, ThreadsOutOfRangeAreRefusedByName) {
  for (int bad : {0, -1, 257}) {
    try {
      PpoConfigFromJson(Json{{"threads", bad}}, "ppo");
      FAIL() << bad;
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("ppo.threads"), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(PpoConfigFromJson(Json{{"threads", 4}}, "ppo").threads, 4);
}

// V-trace (issue 20): twin learners, one with ppo.vtrace, fed the same batches.
struct VtraceTwins {
  PpoLearner off, on;
  static PpoConfig Cfg(bool vtrace) {
    PpoConfig cfg;
    cfg.num_minibatches = 4;
    cfg.num_epochs = 2;
    cfg.vtrace = vtrace;
    return cfg;
  }
  VtraceTwins()
      : off(PolicyConfig::Subtask(7), Cfg(false), 3), on(PolicyConfig::Subtask(7), Cfg(true), 3) {}
};

TEST(PpoVtraceTest, SegmentsOfTheCurrentVersionAreUntouched) {
  VtraceTwins tw;
  const std::vector<Rollout> batch = {Acted(tw.off, 200, 2), Acted(tw.off, 100, 3)};
  const UpdateStats a = tw.off.Update(batch), b = tw.on.Update(batch);
  EXPECT_TRUE(tw.off.model().params() == tw.on.model().params());
  EXPECT_EQ(a.policy_loss, b.policy_loss);
  EXPECT_EQ(b.lagged_samples, 0);
}

TEST(PpoVtraceTest, LaggedSegmentsAreCorrectedByTheirImportanceRatios) {
  VtraceTwins tw;
  const std::vector<Rollout> first = {Acted(tw.off, 200, 2)};
  tw.off.Update(first);
  tw.on.Update(first);
  ASSERT_EQ(tw.on.num_updates(), 1);
  // Acted by the current weights but stamped version 0 (lag 1): pi == mu up to the actor's
  // single-sample arithmetic, so V-trace's ratios are 1 and the update is PPO's.
  Rollout lagged = Acted(tw.on, 256, 4);
  ASSERT_EQ(lagged.policy_version, 0u);
  {
    PpoLearner off = tw.off, on = tw.on;
    const VectorXf p0 = on.model().params();
    const UpdateStats a = off.Update({lagged}), b = on.Update({lagged});
    EXPECT_EQ(a.lagged_samples, 256);
    EXPECT_EQ(b.lagged_samples, 256);
    EXPECT_NEAR(b.vtrace_ratio_mean, 1.0f, 1e-4f);  // (ratios a few ulp above 1 count as clipped)
    const float moved = (off.model().params() - p0).cwiseAbs().maxCoeff();
    EXPECT_GT(moved, 1e-4f);
    EXPECT_LT((on.model().params() - off.model().params()).cwiseAbs().maxCoeff(), 1e-2f * moved);
  }
  // mu twice as likely as pi everywhere: ratio 1/2, every advantage term halved -> a different
  // update; PPO's ratio starts at 1 against the learner's own policy (no clipping at first).
  {
    Rollout half = lagged;
    for (float& lp : half.log_probs) lp += std::log(2.0f);
    PpoLearner off = tw.off, on = tw.on;
    const UpdateStats a = off.Update({half}), b = on.Update({half});
    EXPECT_NEAR(b.vtrace_ratio_mean, 0.5f, 1e-4f);
    EXPECT_EQ(b.vtrace_rho_clipped, 0.0f);
    EXPECT_GT(a.clip_fraction, 0.5f);  // without V-trace, ratios of 1/2 are clipped at once
    EXPECT_LT(b.clip_fraction, a.clip_fraction);
    EXPECT_FALSE(on.model().params() == off.model().params());
  }
  // mu half as likely: ratio 2, truncated to rho_clip 1 everywhere.
  {
    Rollout dbl = lagged;
    for (float& lp : dbl.log_probs) lp -= std::log(2.0f);
    PpoLearner on = tw.on;
    const UpdateStats b = on.Update({dbl});
    EXPECT_NEAR(b.vtrace_ratio_mean, 2.0f, 1e-3f);
    EXPECT_EQ(b.vtrace_rho_clipped, 1.0f);
    for (int i = 0; i < on.model().params().size(); ++i) {
      ASSERT_TRUE(std::isfinite(on.model().params()[i]));
    }
  }
}

TEST(PpoConfigTest, VtraceClipsMustBePositive) {
  for (const char* f : {"vtrace_rho_clip", "vtrace_c_clip"}) {
    try {
      PpoConfigFromJson(Json{{"vtrace", true}, {f, 0.0}}, "ppo");
      FAIL() << f;
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("ppo.") + f), std::string::npos) << e.what();
    }
  }
  const PpoConfig c = PpoConfigFromJson(Json{{"vtrace", true}, {"vtrace_c_clip", 0.5}}, "ppo");
  EXPECT_TRUE(c.vtrace);
  EXPECT_EQ(c.vtrace_c_clip, 0.5f);
  EXPECT_FALSE(PpoConfig().vtrace);  // off by default
}

}  // namespace
}  // namespace perch
