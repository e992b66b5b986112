// Initialisation (orthogonal, gains sqrt 2 / 0.01 / 1.0, log-std 0), the actor-side runner
// (agrees with the batched evaluation, samples from the stated distribution, accumulates the
// observation statistics it ships), and fixed vs trained sigma.
#include "learner/policy.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "learner/ppo.h"

namespace perch {
namespace {

TEST(InitTest, OrthogonalWithTheAuthorsGains) {
  const ActorCritic m(PolicyConfig::Subtask(57), 0);
  const float* p = m.params().data();
  // Policy layer 0: W [64 x 57], columns orthonormal times sqrt 2.
  Eigen::Map<const MatrixXf> w0(p, 64, 57);
  EXPECT_LT((w0.transpose() * w0 - 2.0f * MatrixXf::Identity(57, 57)).cwiseAbs().maxCoeff(), 1e-4);
  Eigen::Map<const VectorXf> b0(p + 64 * 57, 64);
  EXPECT_EQ(b0.norm(), 0.0f);
  // Policy output: W [21 x 64] after the two hidden layers, rows orthonormal times 0.01.
  const int out_off = 64 * 57 + 64 + 64 * 64 + 64;
  Eigen::Map<const MatrixXf> wo(p + out_off, 21, 64);
  EXPECT_LT((wo * wo.transpose() - 1e-4f * MatrixXf::Identity(21, 21)).cwiseAbs().maxCoeff(), 1e-7);
  // log-std starts at 0.
  EXPECT_EQ(m.params().segment(m.log_std_offset(), 21).cwiseAbs().maxCoeff(), 0.0f);
  // Value output [1 x 64] has norm 1.
  Eigen::Map<const VectorXf> wv(p + m.num_params() - 65, 64);
  EXPECT_NEAR(wv.norm(), 1.0f, 1e-5);
  EXPECT_EQ(m.num_params(), (57 * 64 + 64 + 64 * 64 + 64 + 64 * 21 + 21) + 21 +
                                (57 * 64 + 64 + 64 * 64 + 64 + 64 + 1));
  // Seeded: same seed same weights, other seed other weights.
  EXPECT_EQ(ActorCritic(PolicyConfig::Subtask(57), 0).params(), m.params());
  EXPECT_NE(ActorCritic(PolicyConfig::Subtask(57), 1).params(), m.params());
}

TEST(InitTest, MetaHeadsAreSeparatelyOrthogonal) {
  const PolicyConfig c = PolicyConfig::Meta(57);
  const ActorCritic m(c, 0);
  EXPECT_EQ(m.head_dim(), 6);
  EXPECT_EQ(m.action_size(), 3);
  const int out_off = 64 * 57 + 64 + 64 * 64 + 64;
  Eigen::Map<const MatrixXf> wo(m.params().data() + out_off, 6, 64);
  // Each head's rows are orthonormal (times 0.01) on their own.
  const MatrixXf logits = wo.topRows(4), mean = wo.bottomRows(2);
  EXPECT_LT((logits * logits.transpose() - 1e-4f * MatrixXf::Identity(4, 4)).cwiseAbs().maxCoeff(),
            1e-7);
  EXPECT_LT((mean * mean.transpose() - 1e-4f * MatrixXf::Identity(2, 2)).cwiseAbs().maxCoeff(),
            1e-7);
}

PolicyRunner RandomRunner(const PolicyConfig& c, uint64_t seed) {
  ActorCritic m(c, seed);
  Rng rng(seed);
  VectorXf p = m.params();
  for (int i = 0; i < p.size(); ++i) p[i] += static_cast<float>(0.2 * rng.Normal());
  PolicyRunner r(c, NormalizerConfig());
  RunningMeanStd stats(c.obs_dim);
  r.SetWeights(p, stats, 0);
  return r;
}

class RunnerTest : public ::testing::TestWithParam<PolicyKind> {};

TEST_P(RunnerTest, ActAgreesWithBatchedEvaluate) {
  const PolicyConfig c =
      GetParam() == PolicyKind::kMeta ? PolicyConfig::Meta(57) : PolicyConfig::Subtask(52);
  PolicyRunner runner = RandomRunner(c, 3);
  Rng rng(1);
  const int n = 16;
  MatrixXf obs(c.obs_dim, n), act(c.action_size(), n);
  std::vector<float> logp(n), value(n), raw(c.obs_dim);
  for (int b = 0; b < n; ++b) {
    for (float& x : raw) x = static_cast<float>(rng.Normal(1.0, 2.0));
    const auto out = runner.Act(raw.data(), rng, false, obs.col(b).data(), act.col(b).data());
    logp[b] = out.log_prob;
    value[b] = out.value;
    EXPECT_FLOAT_EQ(runner.Value(raw.data()), out.value);  // same stats after the update
  }
  PolicyEvalCache cache;
  runner.model().Evaluate(runner.model().params().data(), obs, act, &cache);
  for (int b = 0; b < n; ++b) {
    EXPECT_NEAR(cache.log_prob[b], logp[b], 1e-4 * (1 + std::abs(logp[b]))) << b;
    EXPECT_NEAR(cache.value[b], value[b], 1e-5 * (1 + std::abs(value[b]))) << b;
  }
  // The delta holds exactly the raw observations seen.
  EXPECT_DOUBLE_EQ(runner.obs_stats_delta().count(), n);
  EXPECT_NEAR(runner.normalizer().stats().count(), n + 1e-4, 1e-9);
  runner.ClearObsStatsDelta();
  EXPECT_EQ(runner.obs_stats_delta().count(), 0.0);
}

INSTANTIATE_TEST_SUITE_P(Kinds, RunnerTest,
                         ::testing::Values(PolicyKind::kGaussian, PolicyKind::kMeta),
                         [](const auto& info) {
                           return std::string(info.param == PolicyKind::kMeta ? "meta"
                                                                              : "gaussian");
                         });

TEST(RunnerTest, GaussianSamplesHaveTheStatedMeanAndSigma) {
  PolicyConfig c = PolicyConfig::Subtask(5);
  c.act_dim = 3;
  c.init_log_std = -0.5f;
  PolicyRunner runner = RandomRunner(c, 4);
  runner.set_update_obs_stats(false);
  const std::vector<float> raw = {0.1f, -0.2f, 0.3f, 0.0f, 1.0f};
  std::vector<float> mean(3), a(3);
  Rng rng(2);
  runner.Act(raw.data(), rng, /*deterministic=*/true, nullptr, mean.data());
  const float* log_std = runner.model().params().data() + runner.model().log_std_offset();
  const int n = 20000;
  std::vector<double> s1(3, 0), s2(3, 0);
  for (int i = 0; i < n; ++i) {
    runner.Act(raw.data(), rng, false, nullptr, a.data());
    for (int j = 0; j < 3; ++j) {
      s1[j] += a[j];
      s2[j] += (a[j] - mean[j]) * (a[j] - mean[j]);
    }
  }
  for (int j = 0; j < 3; ++j) {
    const double sigma = std::exp(log_std[j]);
    EXPECT_NEAR(s1[j] / n, mean[j], 4 * sigma / std::sqrt(n)) << j;
    EXPECT_NEAR(std::sqrt(s2[j] / n), sigma, 0.02 * sigma) << j;
  }
}

TEST(RunnerTest, MetaChoicesFollowTheSoftmax) {
  PolicyRunner runner = RandomRunner(PolicyConfig::Meta(6), 5);
  runner.set_update_obs_stats(false);
  const std::vector<float> raw = {0.5f, -1.0f, 0.2f, 0.0f, 0.3f, -0.7f};
  // Probabilities from the batched head.
  MatrixXf obs(6, 1), act = MatrixXf::Zero(3, 1);
  runner.normalizer().Normalize(raw.data(), obs.data());
  PolicyEvalCache cache;
  runner.model().Evaluate(runner.model().params().data(), obs, act, &cache);
  Rng rng(3);
  std::vector<int> counts(4, 0);
  std::vector<float> a(3);
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    runner.Act(raw.data(), rng, false, nullptr, a.data());
    counts[static_cast<int>(a[0])]++;
  }
  for (int j = 0; j < 4; ++j) {
    const double p = cache.probs(j, 0);
    EXPECT_NEAR(counts[j] / static_cast<double>(n), p, 4 * std::sqrt(p * (1 - p) / n) + 1e-3) << j;
  }
}

TEST(StdModeTest, FixedSigmaNeverMovesTrainedSigmaDoes) {
  for (StdMode mode : {StdMode::kFixed, StdMode::kTrained}) {
    PolicyConfig c = PolicyConfig::Subtask(4);
    c.act_dim = 2;
    c.std_mode = mode;
    c.init_log_std = -0.3f;
    PpoConfig cfg;
    cfg.num_minibatches = 4;
    cfg.num_epochs = 2;
    cfg.entropy_coef = 0.1f;  // a steady push on log-std
    PpoLearner learner(c, cfg, 1);
    PolicyRunner runner(c, cfg.obs_norm);
    runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(), 0);
    Rng rng(2);
    Rollout r(4, 2);
    std::vector<float> raw(4), norm(4), a(2);
    for (int t = 0; t < 64; ++t) {
      for (float& x : raw) x = static_cast<float>(rng.Normal());
      const auto o = runner.Act(raw.data(), rng, false, norm.data(), a.data());
      r.Add(norm.data(), a.data(), o.log_prob, o.value, static_cast<float>(rng.Normal()), false,
            false, 0.0f);
    }
    learner.Update({r});
    const VectorXf ls = learner.model().params().segment(learner.model().log_std_offset(), 2);
    if (mode == StdMode::kFixed) {
      EXPECT_EQ(ls, VectorXf::Constant(2, -0.3f));
    } else {
      EXPECT_GT((ls - VectorXf::Constant(2, -0.3f)).norm(), 1e-5f);
    }
  }
}

}  // namespace
}  // namespace perch
