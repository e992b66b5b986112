// GAE against hand-written recursions: segment-end bootstrap, termination (no bootstrap),
// truncation (bootstrap from the final observation, or not, as the authors).
#include <gtest/gtest.h>

#include <vector>

#include "policy/rollout.h"

namespace perch {
namespace {

constexpr float kGamma = 0.9f;
constexpr float kLambda = 0.8f;

Rollout Make(const std::vector<float>& r, const std::vector<float>& v, const std::vector<int>& term,
             const std::vector<int>& trunc, const std::vector<float>& boot) {
  Rollout ro(1, 1);
  for (size_t t = 0; t < r.size(); ++t) {
    const float o = 0.0f, a = 0.0f;
    ro.Add(&o, &a, 0.0f, v[t], r[t], term[t], trunc[t], boot[t]);
  }
  return ro;
}

struct Out {
  std::vector<float> adv, ret;
};

Out Gae(const Rollout& ro, bool bootstrap_on_truncation = true, float gamma = kGamma,
        float lambda = kLambda) {
  Out o{std::vector<float>(ro.size()), std::vector<float>(ro.size())};
  ComputeGae(ro, nullptr, gamma, lambda, bootstrap_on_truncation, o.adv.data(), o.ret.data());
  return o;
}

const std::vector<float> kR = {1.0f, 0.0f, 2.0f, -1.0f};
const std::vector<float> kV = {0.5f, 0.2f, -0.3f, 0.1f};

TEST(GaeTest, SegmentEndBootstraps) {
  const float boot = 0.7f;
  const Out o = Gae(Make(kR, kV, {0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, boot}));
  const float g = kGamma, gl = kGamma * kLambda;
  const float d3 = kR[3] + g * boot - kV[3];
  const float d2 = kR[2] + g * kV[3] - kV[2];
  const float d1 = kR[1] + g * kV[2] - kV[1];
  const float d0 = kR[0] + g * kV[1] - kV[0];
  const float a3 = d3, a2 = d2 + gl * a3, a1 = d1 + gl * a2, a0 = d0 + gl * a1;
  const float want[4] = {a0, a1, a2, a3};
  for (int t = 0; t < 4; ++t) {
    EXPECT_NEAR(o.adv[t], want[t], 1e-6) << t;
    EXPECT_NEAR(o.ret[t], want[t] + kV[t], 1e-6) << t;
  }
}

TEST(GaeTest, TerminationCutsTheEpisodeWithoutBootstrap) {
  const float boot = 0.7f;
  // Fell after step 1; a new episode runs steps 2-3 and the segment ends mid-episode.
  // bootstrap_values[1] holds garbage: a terminated step must not read it.
  const Out o = Gae(Make(kR, kV, {0, 1, 0, 0}, {0, 0, 0, 0}, {0, 99.0f, 0, boot}));
  const float g = kGamma, gl = kGamma * kLambda;
  const float a1 = kR[1] - kV[1];
  const float a0 = (kR[0] + g * kV[1] - kV[0]) + gl * a1;
  const float a3 = kR[3] + g * boot - kV[3];
  const float a2 = (kR[2] + g * kV[3] - kV[2]) + gl * a3;
  const float want[4] = {a0, a1, a2, a3};
  for (int t = 0; t < 4; ++t) EXPECT_NEAR(o.adv[t], want[t], 1e-6) << t;
}

TEST(GaeTest, TruncationBootstrapsFromTheFinalObservation) {
  const float final_value = -0.4f, boot = 0.7f;
  const Rollout ro = Make(kR, kV, {0, 0, 0, 0}, {0, 1, 0, 0}, {0, final_value, 0, boot});
  const float g = kGamma, gl = kGamma * kLambda;
  const float a1 = kR[1] + g * final_value - kV[1];
  const float a0 = (kR[0] + g * kV[1] - kV[0]) + gl * a1;
  const float a3 = kR[3] + g * boot - kV[3];
  const float a2 = (kR[2] + g * kV[3] - kV[2]) + gl * a3;
  const Out o = Gae(ro);
  const float want[4] = {a0, a1, a2, a3};
  for (int t = 0; t < 4; ++t) EXPECT_NEAR(o.adv[t], want[t], 1e-6) << t;

  // The authors' behaviour: the time limit is treated like a fall.
  const Out a = Gae(ro, /*bootstrap_on_truncation=*/false);
  EXPECT_NEAR(a.adv[1], kR[1] - kV[1], 1e-6);
  EXPECT_NEAR(a.adv[0], (kR[0] + g * kV[1] - kV[0]) + gl * (kR[1] - kV[1]), 1e-6);
  EXPECT_NEAR(a.adv[3], o.adv[3], 1e-7);  // the other episode is unaffected
}

TEST(GaeTest, TerminationOnTheLastStepIgnoresTheBootstrapValue) {
  const Out o = Gae(Make(kR, kV, {0, 0, 0, 1}, {0, 0, 0, 0}, {0, 0, 0, 5.0f}));
  EXPECT_NEAR(o.adv[3], kR[3] - kV[3], 1e-6);
}

TEST(GaeTest, LambdaOneGammaOneIsMonteCarloReturn) {
  const float boot = 0.7f;
  const Out o = Gae(Make(kR, kV, {0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, boot}), true, 1.0f, 1.0f);
  float tail = boot;
  for (int t = 3; t >= 0; --t) {
    tail += kR[t];
    EXPECT_NEAR(o.ret[t], tail, 1e-5) << t;
  }
}

TEST(GaeTest, ScaledRewardsOverrideTheStoredOnes) {
  const Rollout ro = Make(kR, kV, {0, 0, 0, 1}, {0, 0, 0, 0}, {0, 0, 0, 0});
  std::vector<float> doubled(kR);
  for (float& x : doubled) x *= 2;
  std::vector<float> adv(4), ret(4);
  ComputeGae(ro, doubled.data(), kGamma, kLambda, true, adv.data(), ret.data());
  EXPECT_NEAR(adv[3], 2 * kR[3] - kV[3], 1e-6);
}

TEST(RolloutTest, ValidateNamesTheBadField) {
  Rollout ro = Make(kR, kV, {0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, 0});
  ro.log_probs.pop_back();
  try {
    ro.Validate("seg");
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("seg.log_probs"), std::string::npos) << e.what();
  }
  Rollout nan = Make(kR, kV, {0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, 0});
  nan.rewards[2] = std::nanf("");
  EXPECT_THROW(nan.Validate("seg"), ConfigError);
}

// V-trace (issue 20). Its targets from the paper's sum form (Espeholt et al. 2018, Eq. 1):
//   v_s = V_s + sum_{t >= s} gamma^(t-s) (prod_{i=s}^{t-1} lambda c_i) rho_t (r_t + gamma V_{t+1} -
//   V_t)
// against the recursion, on a segment with a termination and a segment-end bootstrap.
TEST(VtraceTest, MatchesTheSumFormOfTheTargets) {
  const std::vector<float> r = {1.0f, 0.0f, 2.0f, -1.0f, 0.5f};
  const std::vector<float> v_old = {9.0f, 9.0f, 9.0f, 9.0f, 9.0f};  // the acting network's
  const std::vector<float> v = {0.5f, 0.2f, -0.3f, 0.1f, 0.4f};     // the learner's
  const std::vector<int> term = {0, 1, 0, 0, 0};
  const float boot = 0.7f;
  const Rollout ro = Make(r, v_old, term, {0, 0, 0, 0, 0}, {0, 0, 0, 0, boot});
  const std::vector<float> rho = {0.3f, 1.0f, 0.8f, 1.0f, 0.6f};
  const std::vector<float> c = {0.5f, 0.9f, 0.2f, 1.0f, 0.7f};
  std::vector<float> adv(5), ret(5);
  ComputeVtrace(ro, nullptr, v.data(), rho.data(), c.data(), kGamma, kLambda, true, adv.data(),
                ret.data());
  // Episode boundaries: steps 0-1 (terminated at 1), steps 2-4 (bootstrapped at 4).
  auto next_v = [&](int t) { return term[t] ? 0.0f : (t == 4 ? boot : v[t + 1]); };
  auto end_of = [&](int s) { return s <= 1 ? 1 : 4; };
  for (int s = 0; s < 5; ++s) {
    double vs = v[s], disc = 1.0;
    for (int t = s; t <= end_of(s); ++t) {
      vs += disc * rho[t] * (r[t] + kGamma * next_v(t) - v[t]);
      disc *= kGamma * kLambda * c[t];
    }
    EXPECT_NEAR(ret[s], vs, 1e-5) << s;
    EXPECT_NEAR(adv[s], vs - v[s], 1e-5) << s;
  }
}

TEST(VtraceTest, RatiosOfOneAndTheSegmentsValuesAreGaeBitForBit) {
  const Rollout ro =
      Make({1.0f, 0.0f, 2.0f, -1.0f}, kV, {0, 0, 1, 0}, {1, 0, 0, 0}, {0.3f, 0, 0, 0.7f});
  const std::vector<float> ones(4, 1.0f);
  std::vector<float> adv(4), ret(4);
  ComputeVtrace(ro, nullptr, ro.values.data(), ones.data(), ones.data(), kGamma, kLambda, true,
                adv.data(), ret.data());
  const Out g = Gae(ro);
  for (int t = 0; t < 4; ++t) {
    EXPECT_EQ(adv[t], g.adv[t]) << t;
    EXPECT_EQ(ret[t], g.ret[t]) << t;
  }
}

}  // namespace
}  // namespace perch
