#include "actor/hierarchy.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "actor/mock_env.h"

namespace perch {
namespace {

// The mock env under a meta controller: records which subtask observations were asked for, the
// walk targets set, and returns the meta reward only at the end of each meta period (NaN
// otherwise, as the authors' meta env).
class MockHierarchyEnv : public MockEnv, public HierarchyEnv {
 public:
  MockHierarchyEnv(const MockEnvConfig& c, int period) : MockEnv(c), period_(period) {}
  int num_subtasks() const override { return 4; }
  int subtask_obs_dim(int k) const override { return spec().obs_dim; }
  void SubtaskObservation(int k, float* obs) override {
    subtask_calls.push_back(k);
    for (int i = 0; i < spec().obs_dim; ++i) obs[i] = 0.1f * (i + k);
  }
  void SetWalkTarget(float theta, float dist) override { targets.push_back({theta, dist}); }
  StepResult Step(const float* action, float* obs) override {
    StepResult r = MockEnv::Step(action, obs);
    ++t_;
    if (t_ % period_ != 0) {
      r.reward = std::nanf("");
    } else {
      meta_rewards.push_back(r.reward);
    }
    return r;
  }
  std::vector<int> subtask_calls;
  std::vector<std::pair<float, float>> targets;
  std::vector<float> meta_rewards;

 private:
  int period_;
  int t_ = 0;
};

TEST(HierarchyTest, MetaDecidesEveryPeriodAndRunsTheChosenSubtask) {
  constexpr int kPeriod = 30, kMetaSteps = 6;
  MockEnvConfig mc;
  mc.episode_steps = 100000;
  mc.fail_distance = 1e9f;  // no falls: every meta step lasts the full period
  MockHierarchyEnv env(mc, kPeriod);
  env.Seed(3);
  const int obs_dim = env.spec().obs_dim;
  NormalizerConfig nc;
  PolicyRunner meta(PolicyConfig::Meta(obs_dim), nc);
  PolicyConfig sc;
  sc.obs_dim = obs_dim;
  sc.act_dim = env.spec().act_dim;
  std::vector<PolicyRunner> subs(4, PolicyRunner(sc, nc));
  std::vector<PolicyRunner*> sub_ptrs;
  for (auto& s : subs) sub_ptrs.push_back(&s);

  HierarchicalCollector collector(&env, 7, kPeriod);
  Rng rng(11);
  Rollout out;
  EpisodeStats stats;
  collector.Collect(&meta, sub_ptrs, rng, kMetaSteps, &out, &stats);

  EXPECT_EQ(collector.meta_decisions(), static_cast<uint64_t>(kMetaSteps));
  EXPECT_EQ(collector.control_steps(), static_cast<uint64_t>(kMetaSteps * kPeriod));
  ASSERT_EQ(out.size(), kMetaSteps);  // one PPO sample per meta step
  EXPECT_EQ(out.action_size, 3);      // [choice, theta, dist]
  EXPECT_EQ(env.targets.size(), static_cast<size_t>(kMetaSteps));
  ASSERT_EQ(env.subtask_calls.size(), static_cast<size_t>(kMetaSteps * kPeriod));
  for (int m = 0; m < kMetaSteps; ++m) {
    const float choice = out.actions[m * 3];
    ASSERT_EQ(choice, std::floor(choice));
    ASSERT_GE(choice, 0);
    ASSERT_LT(choice, 4);
    EXPECT_FLOAT_EQ(env.targets[m].first, out.actions[m * 3 + 1]);
    EXPECT_FLOAT_EQ(env.targets[m].second, out.actions[m * 3 + 2]);
    // The chosen subtask acted for the whole period.
    for (int k = 0; k < kPeriod; ++k) {
      ASSERT_EQ(env.subtask_calls[m * kPeriod + k], static_cast<int>(choice)) << m << " " << k;
    }
    // The meta reward: the one non-NaN reward of the period.
    EXPECT_FLOAT_EQ(out.rewards[m], env.meta_rewards[m]);
  }
  EXPECT_EQ(out.stream_id, 7u);
  EXPECT_FALSE(out.truncated.back());
  EXPECT_TRUE(std::isfinite(out.bootstrap_values.back()));
}

TEST(HierarchyTest, SingleTaskStepsControlStepsDirectly) {
  MockEnvConfig mc;
  MockEnv env(mc);
  env.Seed(1);
  PolicyConfig pc;
  pc.obs_dim = env.spec().obs_dim;
  pc.act_dim = env.spec().act_dim;
  PolicyRunner runner(pc, NormalizerConfig{});
  HierarchicalCollector collector(&env, 1, 30);
  Rng rng(2);
  Rollout out;
  EpisodeStats stats;
  collector.Collect(&runner, {}, rng, 100, &out, &stats);
  EXPECT_EQ(out.size(), 100);
  EXPECT_EQ(collector.control_steps(), 100u);
  EXPECT_EQ(collector.meta_decisions(), 0u);
  EXPECT_EQ(out.action_size, env.spec().act_dim);
}

TEST(HierarchyTest, MetaOnAPlainEnvIsAConfigError) {
  MockEnv env(MockEnvConfig{});
  PolicyRunner meta(PolicyConfig::Meta(env.spec().obs_dim), NormalizerConfig{});
  HierarchicalCollector collector(&env, 1, 30);
  Rng rng(2);
  Rollout out;
  EXPECT_THROW(collector.Collect(&meta, {}, rng, 2, &out, nullptr), ConfigError);
}

}  // namespace
}  // namespace perch
