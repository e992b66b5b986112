// Initialisation (orthogonal, gains sqrt 2 / 0.01 / 1.0, log-std 0), the actor-side runner
// (agrees with the batched evaluation, samples from the stated distribution, accumulates the
// observation statistics it ships), and fixed vs trained sigma.
#include "policy/policy.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "common/proto/model.pb.h"
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

namespace perch {
namespace {

// A narrow model with every parameter and statistic away from its init, so that a widening that
// dropped or misplaced any block would change the outputs.
proto::ModelWeights PerturbedNarrow() {
  PpoLearner learner(PolicyConfig::Subtask(52), PpoConfig::Subtask(), 3);
  proto::ModelWeights w;
  learner.ExportWeights(&w);
  Rng rng(17);
  for (int k = 0; k < w.params_size(); ++k) w.set_params(k, static_cast<float>(rng.Normal(0, 0.3)));
  for (int d = 0; d < 52; ++d) {
    w.mutable_obs_stats()->set_mean(d, rng.Normal(0, 1));
    w.mutable_obs_stats()->set_var(d, 0.5 + rng.Uniform());
  }
  w.mutable_obs_stats()->set_count(1e6);
  return w;
}

TEST(WidenTest, WiderNetworkActsAndValuesAsTheNarrowOne) {
  const proto::ModelWeights narrow = PerturbedNarrow();
  PolicyConfig wide = PolicyConfig::Subtask(52);
  wide.policy_net.hidden = {96, 128};
  wide.value_net.hidden = {80, 64};
  const proto::ModelWeights w = WidenModelWeights(narrow, wide, 5, "test");
  const ActorCritic big(wide, 0);
  ASSERT_EQ(w.params_size(), big.num_params());
  EXPECT_EQ(w.shape().policy_hidden(1), 128);
  EXPECT_EQ(w.obs_stats().SerializeAsString(), narrow.obs_stats().SerializeAsString());

  PolicyRunner a(PolicyConfigFromShape(narrow.shape(), "narrow"), NormalizerConfig());
  PolicyRunner b(wide, NormalizerConfig());
  a.LoadWeights(narrow);
  b.LoadWeights(w);
  a.set_update_obs_stats(false);
  b.set_update_obs_stats(false);
  Rng rng(9), ra(1), rb(1);
  std::vector<float> obs(52), act_a(21), act_b(21);
  for (int trial = 0; trial < 20; ++trial) {
    for (float& x : obs) x = static_cast<float>(rng.Normal(0, 2));
    const auto oa = a.Act(obs.data(), ra, true, nullptr, act_a.data());
    const auto ob = b.Act(obs.data(), rb, true, nullptr, act_b.data());
    EXPECT_NEAR(oa.value, ob.value, 1e-4f * (1 + std::abs(oa.value)));
    EXPECT_NEAR(oa.log_prob, ob.log_prob, 1e-3f);
    for (int k = 0; k < 21; ++k) EXPECT_NEAR(act_a[k], act_b[k], 1e-4f) << k;
  }
  // The extra units are live (initialised incoming weights), so they can learn.
  Eigen::Map<const MatrixXf> w0(w.params().data(), 96, 52);
  EXPECT_GT(w0.bottomRows(32).norm(), 1.0f);
}

TEST(WidenTest, RefusesAnythingButWiderHiddenLayers) {
  const proto::ModelWeights narrow = PerturbedNarrow();
  auto refused = [&](const PolicyConfig& c, const std::string& what) {
    try {
      WidenModelWeights(narrow, c, 0, "init");
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      return true;
    }
    return false;
  };
  PolicyConfig c = PolicyConfig::Subtask(52);
  c.policy_net.hidden = {32, 64};
  EXPECT_TRUE(refused(c, "cannot widen a 52-64-64-21"));
  c.policy_net.hidden = {64, 64, 64};
  EXPECT_TRUE(refused(c, "cannot widen"));
  c = PolicyConfig::Subtask(52);
  c.value_net.activation = Activation::kRelu;
  EXPECT_TRUE(refused(c, "cannot widen"));
  EXPECT_TRUE(refused(PolicyConfig::Subtask(57), "more than hidden widths"));
  // The same widths are a valid (identity) widening.
  EXPECT_EQ(WidenModelWeights(narrow, PolicyConfig::Subtask(52), 0, "same").SerializeAsString(),
            narrow.SerializeAsString());
}

// Freezing sigma for a fine-tune: every log-std becomes the run's init_log_std, nothing else
// moves; freeing it again keeps the values as the start. The result loads into the new network.
TEST(ConvertStdModeTest, FixedTakesTheRunsSigmaTrainedKeepsTheSources) {
  const proto::ModelWeights src = PerturbedNarrow();
  PolicyConfig fixed = PolicyConfig::Subtask(52);
  fixed.std_mode = StdMode::kFixed;
  fixed.init_log_std = -2.3f;
  const proto::ModelWeights w = ConvertStdMode(src, fixed, "freeze");
  const ActorCritic net(fixed, 0);
  ASSERT_EQ(w.params_size(), src.params_size());
  EXPECT_EQ(w.shape().std_mode(), "fixed");
  int changed = 0;
  for (int k = 0; k < w.params_size(); ++k) {
    const bool is_log_std = k >= net.log_std_offset() && k < net.log_std_offset() + 21;
    if (is_log_std) {
      EXPECT_FLOAT_EQ(w.params(k), -2.3f) << k;
    } else {
      EXPECT_EQ(w.params(k), src.params(k)) << k;
    }
    changed += w.params(k) != src.params(k);
  }
  EXPECT_EQ(changed, 21);
  PpoLearner learner(fixed, PpoConfig::Subtask(), 0);
  EXPECT_NO_THROW(learner.ImportWeights(w, "freeze"));
  EXPECT_THROW(learner.ImportWeights(src, "unconverted"), ConfigError);

  const proto::ModelWeights back = ConvertStdMode(w, PolicyConfig::Subtask(52), "free");
  EXPECT_EQ(back.shape().std_mode(), "trained");
  for (int k = 0; k < w.params_size(); ++k) EXPECT_EQ(back.params(k), w.params(k)) << k;
}

}  // namespace
}  // namespace perch

namespace perch {
namespace {

// A policy with non-trivial weights and observation statistics (drawn from rng), so that a wrong
// column, row or offset in a mapping shows.
proto::ModelWeights RandomizedWeights(const PolicyConfig& pc, const PpoConfig& ppo, uint64_t seed,
                                      double count, Rng& rng) {
  PpoLearner learner(pc, ppo, seed);
  proto::ModelWeights w;
  learner.ExportWeights(&w);
  for (int i = 0; i < w.params_size(); ++i) w.set_params(i, static_cast<float>(rng.Normal() * 0.3));
  proto::RunningStats* st = w.mutable_obs_stats();
  st->set_count(count);
  st->clear_mean();
  st->clear_var();
  for (int i = 0; i < pc.obs_dim; ++i) {
    st->add_mean(rng.Uniform(-1.0, 1.0));
    st->add_var(rng.Uniform(0.5, 2.0));
  }
  return w;
}

// Walk (52 inputs: proprioceptive + goal) -> turn (50): the mapped network acts and values as the
// source does when the dropped inputs sit at their running mean.
TEST(DropTrailingInputs, ActsAsTheSourceWithTheDroppedInputsAtTheirMean) {
  Rng rng(5);
  const proto::ModelWeights w =
      RandomizedWeights(PolicyConfig::Subtask(52), PpoConfig::Subtask(), 11, 100.0, rng);
  const proto::RunningStats* st = &w.obs_stats();
  const proto::ModelWeights small = DropTrailingInputs(w, 50, "test");
  EXPECT_EQ(small.shape().obs_dim(), 50);
  EXPECT_EQ(small.obs_stats().mean_size(), 50);
  PolicyRunner big_r(PolicyConfigFromShape(w.shape(), "w"), NormalizerConfig());
  PolicyRunner small_r(PolicyConfigFromShape(small.shape(), "s"), NormalizerConfig());
  big_r.LoadWeights(w);
  small_r.LoadWeights(small);
  big_r.set_update_obs_stats(false);
  small_r.set_update_obs_stats(false);
  for (int trial = 0; trial < 5; ++trial) {
    std::vector<float> x(52), a(21), b(21);
    for (int i = 0; i < 50; ++i) x[i] = static_cast<float>(rng.Normal());
    x[50] = static_cast<float>(st->mean(50));
    x[51] = static_cast<float>(st->mean(51));
    const auto ob = big_r.Act(x.data(), rng, true, nullptr, a.data());
    const auto os = small_r.Act(x.data(), rng, true, nullptr, b.data());
    for (int i = 0; i < 21; ++i) EXPECT_NEAR(a[i], b[i], 1e-4) << i;
    EXPECT_NEAR(ob.value, os.value, 1e-4);
    // Away from the mean the dropped inputs matter for the source only.
    x[50] += 3.0f;
    big_r.Act(x.data(), rng, true, nullptr, a.data());
    double diff = 0;
    for (int i = 0; i < 21; ++i) diff += std::abs(a[i] - b[i]);
    EXPECT_GT(diff, 1e-3);
  }
  EXPECT_THROW(DropTrailingInputs(w, 52, "t"), ConfigError);
  EXPECT_THROW(DropTrailingInputs(w, 60, "t"), ConfigError);
}

// `wide` (more inputs) acts and values as `w` on observations of its size, whatever the extra
// inputs hold: `k` action entries compared, mean actions, 5 random observations.
void ExpectSameActionsAndValues(const proto::ModelWeights& w, const proto::ModelWeights& wide,
                                int k, Rng& rng) {
  PolicyRunner src(PolicyConfigFromShape(w.shape(), "w"), NormalizerConfig());
  PolicyRunner dst(PolicyConfigFromShape(wide.shape(), "d"), NormalizerConfig());
  src.LoadWeights(w);
  dst.LoadWeights(wide);
  src.set_update_obs_stats(false);
  dst.set_update_obs_stats(false);
  const int n = wide.shape().obs_dim();
  for (int trial = 0; trial < 5; ++trial) {
    std::vector<float> x(n), a(k), b(k);
    for (float& v : x) v = static_cast<float>(rng.Normal() * 2.0);
    const auto os = src.Act(x.data(), rng, true, nullptr, a.data());
    const auto od = dst.Act(x.data(), rng, true, nullptr, b.data());
    for (int i = 0; i < k; ++i) EXPECT_NEAR(a[i], b[i], 1e-5) << i;
    EXPECT_NEAR(os.value, od.value, 1e-5);
  }
}

// The meta that observes its active subtask (57 + 5 inputs) starts from one that did not (57): the
// same actions and value whatever the new inputs hold, until training moves their weights.
TEST(AppendZeroInputs, ActsAsTheSourceWhateverTheNewInputsHold) {
  Rng rng(8);
  const proto::ModelWeights w =
      RandomizedWeights(PolicyConfig::Meta(57), PpoConfig::Meta(), 13, 50.0, rng);
  const proto::ModelWeights wide = AppendZeroInputs(w, 62, "test");
  EXPECT_EQ(wide.shape().obs_dim(), 62);
  ASSERT_EQ(wide.obs_stats().mean_size(), 62);
  EXPECT_EQ(wide.obs_stats().mean(60), 0.0);
  EXPECT_EQ(wide.obs_stats().var(60), 1.0);
  EXPECT_EQ(wide.shape().num_choices(), w.shape().num_choices());
  // A meta's action: the switch class, then act_dim continuous values.
  ExpectSameActionsAndValues(w, wide, 1 + PolicyConfigFromShape(w.shape(), "w").act_dim, rng);
  EXPECT_THROW(AppendZeroInputs(w, 57, "t"), ConfigError);
  EXPECT_THROW(AppendZeroInputs(w, 40, "t"), ConfigError);
}

// The sit that observes the chair's shape (57 + 25 inputs) starts from a trained 57-input sit:
// the same torques and value whatever the grid holds.
TEST(AppendZeroInputs, AGaussianSubtaskActsAsTheSourceWhateverTheNewInputsHold) {
  Rng rng(9);
  const proto::ModelWeights w =
      RandomizedWeights(PolicyConfig::Subtask(57), PpoConfig::Subtask(), 14, 50.0, rng);
  const proto::ModelWeights wide = AppendZeroInputs(w, 82, "test");
  EXPECT_EQ(wide.shape().obs_dim(), 82);
  EXPECT_EQ(wide.shape().kind(), "gaussian");
  ExpectSameActionsAndValues(w, wide, PolicyConfigFromShape(w.shape(), "w").act_dim, rng);
}

}  // namespace
}  // namespace perch

namespace perch {
namespace {

// The walk-only meta (one switch class) starts the full one (four): same walk target, log-std and
// value; only the switch head is new.
TEST(WidenMetaChoices, KeepsTargetHeadAndValueAndStartsTheSwitchAnew) {
  PolicyConfig one = PolicyConfig::Meta(57);
  one.num_choices = 1;
  one.target_choice = 0;
  PpoLearner learner(one, PpoConfig::Meta(), 3);
  proto::ModelWeights w;
  learner.ExportWeights(&w);
  Rng rng(9);
  for (int i = 0; i < w.params_size(); ++i) w.set_params(i, static_cast<float>(rng.Normal() * 0.3));
  const PolicyConfig four = PolicyConfig::Meta(57);
  const proto::ModelWeights wide = WidenMetaChoices(w, four, 1, "test");
  EXPECT_EQ(wide.shape().num_choices(), 4);
  EXPECT_EQ(wide.shape().target_choice(), 3);
  PolicyRunner a(one, NormalizerConfig()), b(four, NormalizerConfig());
  a.LoadWeights(w);
  b.LoadWeights(wide);
  a.set_update_obs_stats(false);
  b.set_update_obs_stats(false);
  for (int trial = 0; trial < 5; ++trial) {
    std::vector<float> x(57), ua(3), ub(3);
    for (float& v : x) v = static_cast<float>(rng.Normal());
    const auto oa = a.Act(x.data(), rng, true, nullptr, ua.data());
    const auto ob = b.Act(x.data(), rng, true, nullptr, ub.data());
    EXPECT_NEAR(ua[1], ub[1], 1e-5);  // theta
    EXPECT_NEAR(ua[2], ub[2], 1e-5);  // dist
    EXPECT_NEAR(oa.value, ob.value, 1e-5);
  }
  // Anything but a meta policy with fewer classes is refused.
  EXPECT_THROW(WidenMetaChoices(wide, four, 1, "t"), ConfigError);
  PpoLearner gauss(PolicyConfig::Subtask(57), PpoConfig::Subtask(), 1);
  proto::ModelWeights g;
  gauss.ExportWeights(&g);
  EXPECT_THROW(WidenMetaChoices(g, four, 1, "t"), ConfigError);
}

}  // namespace
}  // namespace perch

namespace perch {
namespace {

// The mirror-image task's policy acts as M_act(pi(M_obs(o))) and values as V(M_obs(o)), for any
// signed, scaled, shifted permutation of inputs and actions (the normaliser statistics included).
TEST(MirrorModelWeights, ActsAsTheSourceOnTheMirroredObservation) {
  Rng rng(21);
  const proto::ModelWeights w =
      RandomizedWeights(PolicyConfig::Subtask(52), PpoConfig::Subtask(), 17, 100.0, rng);
  auto perm = [&](int n) {
    std::vector<int> p(n);
    for (int i = 0; i < n; ++i) p[i] = i;
    for (int i = n - 1; i > 0; --i) std::swap(p[i], p[rng.UniformInt(i + 1)]);
    return p;
  };
  auto scale = [&](int n) {
    std::vector<float> v(n);
    for (float& x : v)
      x = static_cast<float>((rng.Uniform(0, 1) < 0.5 ? -1 : 1) * rng.Uniform(0.5, 2));
    return v;
  };
  auto offset = [&](int n) {
    std::vector<float> v(n);
    for (float& x : v) x = static_cast<float>(rng.Uniform(-0.5, 0.5));
    return v;
  };
  MirrorMap m;
  m.obs_src = perm(52);
  m.obs_scale = scale(52);
  m.obs_offset = offset(52);
  m.act_src = perm(21);
  m.act_scale = scale(21);
  m.act_offset = offset(21);
  const proto::ModelWeights mw = MirrorModelWeights(w, m, "test");
  PolicyRunner src(PolicyConfigFromShape(w.shape(), "w"), NormalizerConfig());
  PolicyRunner dst(PolicyConfigFromShape(mw.shape(), "m"), NormalizerConfig());
  src.LoadWeights(w);
  dst.LoadWeights(mw);
  src.set_update_obs_stats(false);
  dst.set_update_obs_stats(false);
  for (int trial = 0; trial < 5; ++trial) {
    std::vector<float> o(52), mo(52), a(21), b(21);
    for (float& v : o) v = static_cast<float>(rng.Normal());
    for (int i = 0; i < 52; ++i) mo[i] = m.obs_scale[i] * o[m.obs_src[i]] + m.obs_offset[i];
    const auto os = src.Act(mo.data(), rng, true, nullptr, a.data());
    const auto od = dst.Act(o.data(), rng, true, nullptr, b.data());
    for (int k = 0; k < 21; ++k) {
      EXPECT_NEAR(b[k], m.act_scale[k] * a[m.act_src[k]] + m.act_offset[k], 1e-4) << k;
    }
    EXPECT_NEAR(od.value, os.value, 1e-4);
  }
  // sigma follows its action, scaled.
  const ActorCritic net(PolicyConfigFromShape(w.shape(), "w"), 0);
  for (int k = 0; k < 21; ++k) {
    EXPECT_NEAR(mw.params(net.log_std_offset() + k),
                w.params(net.log_std_offset() + m.act_src[k]) + std::log(std::abs(m.act_scale[k])),
                1e-5);
  }
  // Refused: no map, a source used twice, a zero scale, a meta policy.
  EXPECT_THROW(MirrorModelWeights(w, MirrorMap(), "t"), ConfigError);
  MirrorMap dup = m;
  dup.obs_src[1] = dup.obs_src[0];
  EXPECT_THROW(MirrorModelWeights(w, dup, "t"), ConfigError);
  MirrorMap zero = m;
  zero.act_scale[3] = 0.0f;
  EXPECT_THROW(MirrorModelWeights(w, zero, "t"), ConfigError);
  PpoLearner meta(PolicyConfig::Meta(52), PpoConfig::Meta(), 1);
  proto::ModelWeights mwm;
  meta.ExportWeights(&mwm);
  EXPECT_THROW(MirrorModelWeights(mwm, m, "t"), ConfigError);
}

}  // namespace
}  // namespace perch
