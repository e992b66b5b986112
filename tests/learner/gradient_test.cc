// Finite-difference checks of every analytic gradient: MLP layers (tanh, relu), the Gaussian and
// meta heads (log-prob, entropy), the value net, and each PPO loss term.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>
#include <tuple>
#include <vector>

#include "learner/ppo.h"
#include "policy/mlp.h"
#include "policy/policy.h"

namespace perch {
namespace {

MatrixXf RandomMatrix(int rows, int cols, Rng& rng, double scale = 1.0) {
  MatrixXf m(rows, cols);
  for (int j = 0; j < cols; ++j)
    for (int i = 0; i < rows; ++i) m(i, j) = static_cast<float>(rng.Normal() * scale);
  return m;
}

VectorXf RandomVector(int n, Rng& rng, double scale = 1.0) {
  return RandomMatrix(n, 1, rng, scale).col(0);
}

// Central differences of f at params, checked against `analytic` on `num_checks` random
// coordinates plus every coordinate in `always`. Returns how many checked entries were non-zero.
int CheckGradient(const std::function<double(const VectorXf&)>& f, VectorXf params,
                  const VectorXf& analytic, Rng& rng, int num_checks,
                  const std::vector<int>& always = {}, double h = 1e-2) {
  EXPECT_EQ(params.size(), analytic.size());
  std::vector<int> coords = always;
  for (int i = 0; i < num_checks; ++i) {
    coords.push_back(static_cast<int>(rng.UniformInt(params.size())));
  }
  const double scale = std::max(1e-3, static_cast<double>(analytic.cwiseAbs().maxCoeff()));
  int nonzero = 0;
  for (int c : coords) {
    const float orig = params[c];
    params[c] = orig + static_cast<float>(h);
    const double fp = f(params);
    params[c] = orig - static_cast<float>(h);
    const double fm = f(params);
    params[c] = orig;
    const double fd = (fp - fm) / (2 * h);
    EXPECT_NEAR(fd, analytic[c], 3e-3 * scale + 3e-3 * std::abs(fd)) << "coordinate " << c;
    if (std::abs(analytic[c]) > 1e-6) ++nonzero;
  }
  return nonzero;
}

std::vector<int> Range(int begin, int end) {
  std::vector<int> v;
  for (int i = begin; i < end; ++i) v.push_back(i);
  return v;
}

class MlpGradientTest : public ::testing::TestWithParam<Activation> {};

TEST_P(MlpGradientTest, ParamsAndInputMatchFiniteDifferences) {
  Rng rng(7);
  MlpConfig cfg;
  cfg.hidden = {16, 12};
  cfg.activation = GetParam();
  const Mlp mlp(5, cfg, 3);
  VectorXf params(mlp.num_params());
  mlp.Init(params.data(), rng, 1.41421356f, 1.0f);
  params += RandomVector(mlp.num_params(), rng, 0.1);  // non-zero biases
  const MatrixXf x = RandomMatrix(5, 7, rng);
  const MatrixXf weight = RandomMatrix(3, 7, rng);  // L = sum(weight .* out)
  MlpCache cache;
  auto loss = [&](const VectorXf& p) {
    MlpCache c;
    mlp.Forward(p.data(), x, &c);
    return (c.out().cast<double>().array() * weight.cast<double>().array()).sum();
  };
  mlp.Forward(params.data(), x, &cache);
  VectorXf grad = VectorXf::Zero(mlp.num_params());
  MatrixXf grad_in(5, 7);
  mlp.Backward(params.data(), weight, &cache, grad.data(), &grad_in);
  const double h = GetParam() == Activation::kRelu ? 1e-3 : 1e-2;
  // Every parameter of every layer: the net is small.
  EXPECT_GT(CheckGradient(loss, params, grad, rng, 0, Range(0, mlp.num_params()), h), 100);

  // Input gradient.
  auto loss_x = [&](const VectorXf& xv) {
    MlpCache c;
    mlp.Forward(params.data(), Eigen::Map<const MatrixXf>(xv.data(), 5, 7), &c);
    return (c.out().cast<double>().array() * weight.cast<double>().array()).sum();
  };
  const VectorXf xv = Eigen::Map<const VectorXf>(x.data(), x.size());
  const VectorXf gx = Eigen::Map<const VectorXf>(grad_in.data(), grad_in.size());
  EXPECT_GT(CheckGradient(loss_x, xv, gx, rng, 0, Range(0, 35), h), 30);

  // Backward accumulates: a second call doubles the parameter gradient.
  VectorXf grad2 = grad;
  mlp.Forward(params.data(), x, &cache);
  mlp.Backward(params.data(), weight, &cache, grad2.data());
  EXPECT_LT((grad2 - 2 * grad).norm(), 1e-4 * grad.norm());
}

TEST_P(MlpGradientTest, ForwardOneMatchesBatchedForward) {
  Rng rng(3);
  MlpConfig cfg;
  cfg.hidden = {64, 32};
  cfg.activation = GetParam();
  const Mlp mlp(57, cfg, 21);
  VectorXf params(mlp.num_params());
  mlp.Init(params.data(), rng, 1.41421356f, 1.0f);
  const MatrixXf x = RandomMatrix(57, 4, rng);
  MlpCache cache;
  mlp.Forward(params.data(), x, &cache);
  std::vector<float> out(21), scratch(2 * mlp.max_width());
  for (int b = 0; b < 4; ++b) {
    mlp.ForwardOne(params.data(), x.col(b).data(), out.data(), scratch.data());
    for (int i = 0; i < 21; ++i) EXPECT_NEAR(out[i], cache.out()(i, b), 1e-5);
  }
}

INSTANTIATE_TEST_SUITE_P(Activations, MlpGradientTest,
                         ::testing::Values(Activation::kTanh, Activation::kRelu),
                         [](const auto& info) { return ActivationName(info.param); });

// A small actor-critic with random (non-init) parameters so every gradient is sizeable.
struct Fixture {
  ActorCritic model;
  VectorXf params;
  MatrixXf obs, actions;
};

Fixture MakeFixture(PolicyKind kind, int batch, uint64_t seed) {
  Rng rng(seed);
  PolicyConfig cfg = kind == PolicyKind::kMeta ? PolicyConfig::Meta(9) : PolicyConfig::Subtask(9);
  cfg.act_dim = kind == PolicyKind::kMeta ? 2 : 4;
  cfg.policy_net.hidden = {8, 6};
  cfg.value_net.hidden = {7, 5};
  Fixture f{ActorCritic(cfg, seed), {}, {}, {}};
  f.params = f.model.params() + RandomVector(f.model.num_params(), rng, 0.3);
  f.obs = RandomMatrix(9, batch, rng);
  f.actions = RandomMatrix(cfg.action_size(), batch, rng);
  if (kind == PolicyKind::kMeta) {
    // Every choice appears, walk (3) included, so the gate is exercised both ways.
    for (int b = 0; b < batch; ++b) f.actions(0, b) = static_cast<float>(b % cfg.num_choices);
  }
  return f;
}

class HeadGradientTest : public ::testing::TestWithParam<PolicyKind> {};

TEST_P(HeadGradientTest, LogProbEntropyValueMatchFiniteDifferences) {
  const Fixture f = MakeFixture(GetParam(), 12, 11);
  Rng rng(5);
  const int b = 12;
  // One check per term, then all together.
  for (int term = 0; term < 4; ++term) {
    VectorXf cl = RandomVector(b, rng), ce = RandomVector(b, rng), cv = RandomVector(b, rng);
    if (term != 0 && term != 3) cl.setZero();
    if (term != 1 && term != 3) ce.setZero();
    if (term != 2 && term != 3) cv.setZero();
    auto loss = [&](const VectorXf& p) {
      PolicyEvalCache c;
      f.model.Evaluate(p.data(), f.obs, f.actions, &c);
      return c.log_prob.cast<double>().dot(cl.cast<double>()) +
             c.entropy.cast<double>().dot(ce.cast<double>()) +
             c.value.cast<double>().dot(cv.cast<double>());
    };
    PolicyEvalCache cache;
    f.model.Evaluate(f.params.data(), f.obs, f.actions, &cache);
    VectorXf grad = VectorXf::Zero(f.model.num_params());
    f.model.Backward(f.params.data(), cl, ce, cv, &cache, grad.data());
    SCOPED_TRACE("term " + std::to_string(term));
    // The Gaussian entropy depends on log-std only (state-independent sigma).
    const int min_nonzero = (term == 1 && GetParam() == PolicyKind::kGaussian) ? 4 : 10;
    EXPECT_GE(CheckGradient(loss, f.params, grad, rng, 0, Range(0, f.model.num_params())),
              min_nonzero);
  }
}

std::string KindName(PolicyKind k) { return k == PolicyKind::kMeta ? "meta" : "gaussian"; }

INSTANTIATE_TEST_SUITE_P(Kinds, HeadGradientTest,
                         ::testing::Values(PolicyKind::kGaussian, PolicyKind::kMeta),
                         [](const auto& info) { return KindName(info.param); });

TEST(HeadTest, MetaTargetCountsOnlyForTheTargetChoice) {
  Fixture f = MakeFixture(PolicyKind::kMeta, 8, 2);
  PolicyEvalCache a, b;
  f.model.Evaluate(f.params.data(), f.obs, f.actions, &a);
  MatrixXf moved = f.actions;
  moved.bottomRows(2).array() += 0.7f;  // move every target
  f.model.Evaluate(f.params.data(), f.obs, moved, &b);
  for (int k = 0; k < 8; ++k) {
    if (static_cast<int>(f.actions(0, k)) == f.model.config().target_choice) {
      EXPECT_GT(std::abs(a.log_prob[k] - b.log_prob[k]), 1e-4) << k;
    } else {
      EXPECT_EQ(a.log_prob[k], b.log_prob[k]) << k;
    }
  }
}

TEST(HeadTest, GaussianLogProbMatchesDensity) {
  const Fixture f = MakeFixture(PolicyKind::kGaussian, 3, 4);
  PolicyEvalCache c;
  f.model.Evaluate(f.params.data(), f.obs, f.actions, &c);
  const int k = f.model.act_dim();
  const float* log_std = f.params.data() + f.model.log_std_offset();
  for (int b = 0; b < 3; ++b) {
    double lp = 0;
    for (int i = 0; i < k; ++i) {
      const double s = std::exp(log_std[i]);
      const double d = f.actions(i, b) - c.pi.out()(i, b);
      lp += std::log(std::exp(-0.5 * d * d / (s * s)) / (s * std::sqrt(2 * M_PI)));
    }
    EXPECT_NEAR(c.log_prob[b], lp, 1e-4 * std::max(1.0, std::abs(lp)));
  }
}

// PPO loss terms, each isolated by the coefficients, plus the sum.
class LossGradientTest : public ::testing::TestWithParam<std::tuple<PolicyKind, bool>> {};

TEST_P(LossGradientTest, EachTermMatchesFiniteDifferences) {
  const auto [kind, clip_value] = GetParam();
  const int b = 24;
  const Fixture f = MakeFixture(kind, b, 21);
  Rng rng(9);
  PolicyEvalCache cache;
  f.model.Evaluate(f.params.data(), f.obs, f.actions, &cache);
  // Old log-probs / values offset so that some samples sit well inside and some well outside the
  // clip ranges (away from the kinks, where finite differences are meaningless).
  const float offsets[3] = {-0.6f, 0.0f, 0.6f};
  VectorXf old_logp(b), old_value(b);
  for (int k = 0; k < b; ++k) {
    old_logp[k] = cache.log_prob[k] + offsets[k % 3];
    old_value[k] = cache.value[k] + 0.5f * offsets[(k / 3) % 3];
  }
  const VectorXf adv = RandomVector(b, rng), ret = RandomVector(b, rng);
  const VectorXf zero_adv = VectorXf::Zero(b);

  struct Case {
    const char* name;
    float value_coef, entropy_coef;
    bool use_adv;
  };
  const Case cases[] = {{"policy", 0.0f, 0.0f, true},
                        {"value", 1.0f, 0.0f, false},
                        {"entropy", 0.0f, 1.0f, false},
                        {"all", 0.5f, 0.1f, true}};
  for (const Case& cs : cases) {
    SCOPED_TRACE(cs.name);
    PpoConfig cfg;
    cfg.clip_value = clip_value;
    cfg.value_coef = cs.value_coef;
    cfg.entropy_coef = cs.entropy_coef;
    const VectorXf& a = cs.use_adv ? adv : zero_adv;
    PpoLossWorkspace ws;
    auto loss = [&](const VectorXf& p) {
      PpoLossWorkspace w;
      return PpoLoss(f.model, p.data(), cfg, f.obs, f.actions, old_logp, old_value, a, ret, &w,
                     nullptr)
          .total;
    };
    VectorXf grad = VectorXf::Zero(f.model.num_params());
    const PpoLossTerms t = PpoLoss(f.model, f.params.data(), cfg, f.obs, f.actions, old_logp,
                                   old_value, a, ret, &ws, grad.data());
    const bool gauss_entropy = kind == PolicyKind::kGaussian && std::string(cs.name) == "entropy";
    EXPECT_GE(CheckGradient(loss, f.params, grad, rng, 0, Range(0, f.model.num_params())),
              gauss_entropy ? f.model.act_dim() : 10);
    if (std::string(cs.name) == "policy") {
      EXPECT_GT(t.clip_fraction, 0.3);  // the offsets put 2/3 outside the range
      EXPECT_LT(t.clip_fraction, 0.9);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(KindsAndValueClip, LossGradientTest,
                         ::testing::Combine(::testing::Values(PolicyKind::kGaussian,
                                                              PolicyKind::kMeta),
                                            ::testing::Bool()),
                         [](const auto& info) {
                           return KindName(std::get<0>(info.param)) +
                                  (std::get<1>(info.param) ? "_value_clip" : "_no_value_clip");
                         });

TEST(LossTest, ClippedSamplesGetNoPolicyGradient) {
  // A single sample with ratio far above 1 + clip and a positive advantage: the clipped term is
  // the max, so the surrogate is flat there.
  Fixture f = MakeFixture(PolicyKind::kGaussian, 1, 8);
  PolicyEvalCache cache;
  f.model.Evaluate(f.params.data(), f.obs, f.actions, &cache);
  VectorXf old_logp(1), old_value(1), adv(1), ret(1);
  old_logp[0] = cache.log_prob[0] - 1.0f;  // ratio e
  old_value[0] = cache.value[0];
  adv[0] = 1.0f;
  ret[0] = cache.value[0];
  PpoConfig cfg;
  cfg.value_coef = 0.0f;
  PpoLossWorkspace ws;
  VectorXf grad = VectorXf::Zero(f.model.num_params());
  const PpoLossTerms t = PpoLoss(f.model, f.params.data(), cfg, f.obs, f.actions, old_logp,
                                 old_value, adv, ret, &ws, grad.data());
  EXPECT_NEAR(t.policy_loss, -(1.0 + cfg.clip_range), 1e-5);
  EXPECT_EQ(grad.norm(), 0.0f);
  // With a negative advantage the unclipped term is the max and the gradient is back.
  adv[0] = -1.0f;
  grad.setZero();
  PpoLoss(f.model, f.params.data(), cfg, f.obs, f.actions, old_logp, old_value, adv, ret, &ws,
          grad.data());
  EXPECT_GT(grad.norm(), 1e-3f);
}

}  // namespace
}  // namespace perch
