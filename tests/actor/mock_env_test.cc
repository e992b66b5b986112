#include "experiment/mock_env.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace perch {
namespace {

TEST(MockEnvTest, SameSeedSameEpisodes) {
  MockEnvConfig c;
  MockEnv a(c), b(c);
  a.Seed(5);
  b.Seed(5);
  std::vector<float> oa(a.spec().obs_dim), ob(b.spec().obs_dim);
  a.Reset(oa.data());
  b.Reset(ob.data());
  EXPECT_EQ(oa, ob);
  MockEnv d(c);
  d.Seed(6);
  std::vector<float> od(d.spec().obs_dim);
  d.Reset(od.data());
  EXPECT_NE(oa, od);
}

TEST(MockEnvTest, RewardIsHighestAtTheGoalAndTruncatesAtTheLimit) {
  MockEnvConfig c;
  c.episode_steps = 5;
  MockEnv env(c);
  env.Seed(1);
  std::vector<float> obs(env.spec().obs_dim);
  env.Reset(obs.data());
  const std::vector<float> goal(obs.begin(), obs.begin() + c.act_dim);
  StepResult r;
  for (int t = 0; t < 5; ++t) {
    r = env.Step(goal.data(), obs.data());
    EXPECT_FLOAT_EQ(r.reward, c.reward_scale);
    EXPECT_FALSE(r.terminated);
    EXPECT_EQ(r.truncated, t == 4);
  }
  env.Reset(obs.data());
  std::vector<float> off(obs.begin(), obs.begin() + c.act_dim);
  off[0] += 0.5f;
  EXPECT_LT(env.Step(off.data(), obs.data()).reward, c.reward_scale);
}

TEST(MockEnvTest, FarActionsTerminateAndNaNIsInvalid) {
  MockEnvConfig c;
  MockEnv env(c);
  env.Seed(2);
  std::vector<float> obs(env.spec().obs_dim);
  env.Reset(obs.data());
  std::vector<float> far(c.act_dim, 10.0f);
  const StepResult r = env.Step(far.data(), obs.data());
  EXPECT_TRUE(r.terminated);
  EXPECT_FALSE(r.truncated);
  env.Reset(obs.data());
  std::vector<float> nan(c.act_dim, std::nanf(""));
  const StepResult n = env.Step(nan.data(), obs.data());
  EXPECT_TRUE(n.invalid);
  EXPECT_TRUE(n.terminated);
}

TEST(MockEnvTest, ConfigIsStrict) {
  EXPECT_THROW(MockEnvConfigFromJson({{"act_dims", 2}}, "m"), ConfigError);
  EXPECT_THROW(MockEnvConfigFromJson({{"act_dim", 0}}, "m"), ConfigError);
  const MockEnvConfig c = MockEnvConfigFromJson({{"act_dim", 4}}, "m");
  EXPECT_EQ(MockEnv(c).spec().obs_dim, 2 * 4 + c.noise_dims);
}

}  // namespace
}  // namespace perch
