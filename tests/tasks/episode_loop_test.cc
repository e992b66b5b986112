// tasks/episode_loop.h: the one episode loop of every evaluation (subtasks, chain, meta trials).
#include "tasks/episode_loop.h"

#include <gtest/gtest.h>

#include <vector>

namespace perch {
namespace {

// A counting env (no physics: the loop is what is under test). Its observation
// is [step, seed low bits]; it terminates at step `fall_at` (0: never) and truncates at `limit`.
class CountingEnv : public Env {
 public:
  CountingEnv() {
    spec_.obs_dim = 2;
    spec_.act_dim = 1;
    spec_.max_episode_steps = 10;
  }
  const EnvSpec& spec() const override { return spec_; }
  void Seed(uint64_t seed) override { seed_ = seed; }
  void Reset(float* obs) override {
    step_ = 0;
    obs[0] = 0.0f;
    obs[1] = static_cast<float>(seed_ % 1000);
  }
  StepResult Step(const float* action, float* obs) override {
    ++step_;
    actions.push_back(action[0]);
    obs[0] = static_cast<float>(step_);
    obs[1] = static_cast<float>(seed_ % 1000);
    StepResult r;
    r.reward = 1.0f;
    r.terminated = fall_at > 0 && step_ == fall_at;
    r.truncated = !r.terminated && step_ >= spec_.max_episode_steps;
    return r;
  }
  int fall_at = 0;
  std::vector<float> actions;

 private:
  EnvSpec spec_;
  uint64_t seed_ = 0;
  int step_ = 0;
};

// Acts with a number from the loop's action noise; stops when told; records what it saw.
class RecordingDriver : public EpisodeDriver {
 public:
  void Begin(int episode, uint64_t env_seed, const float* obs) override {
    episodes.push_back(episode);
    env_seeds.push_back(env_seed);
    first_obs_step.push_back(obs[0]);
  }
  bool Act(const float* obs, Rng& rng, float* action) override {
    if (stop_at >= 0 && obs[0] >= stop_at) return false;
    action[0] = static_cast<float>(rng.Uniform());
    return true;
  }
  void Stepped(const StepResult&, int steps) override { stepped.push_back(steps); }
  int stop_at = -1;
  std::vector<int> episodes, stepped;
  std::vector<uint64_t> env_seeds;
  std::vector<float> first_obs_step;
};

TEST(EpisodeLoop, SeedsDependOnlyOnTheSeedAndTheEpisode) {
  const EpisodeSeeds a = EvalEpisodeSeeds(3, 7);
  EXPECT_EQ(a.env, 2 * (3 * 1000003ULL + 7));
  EXPECT_EQ(a.actions, a.env + 1);
  EXPECT_NE(EvalEpisodeSeeds(3, 8).env, a.env);
  EXPECT_NE(EvalEpisodeSeeds(4, 7).env, a.env);

  // Episode 7 run alone acts as it does after episodes 0-6: nothing carries over.
  CountingEnv env;
  RecordingDriver d;
  for (int e = 0; e <= 7; ++e) RunEpisode(&env, e, 3, {5, false}, &d);
  const std::vector<float> in_sequence(env.actions.end() - 5, env.actions.end());
  CountingEnv alone;
  RecordingDriver d2;
  RunEpisode(&alone, 7, 3, {5, false}, &d2);
  EXPECT_EQ(alone.actions, in_sequence);
  EXPECT_EQ(d2.env_seeds, std::vector<uint64_t>{a.env});
  EXPECT_EQ(d.episodes, (std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7}));
  EXPECT_EQ(d.first_obs_step, std::vector<float>(8, 0.0f));  // Begin sees the reset's observation
}

TEST(EpisodeLoop, EndsAtAFallAtTheLimitOrWhenTheDriverStops) {
  CountingEnv env;
  RecordingDriver d;
  // The step limit.
  EpisodeEnd end = RunEpisode(&env, 0, 1, {4, false}, &d);
  EXPECT_EQ(end.steps, 4);
  EXPECT_FALSE(end.fell);
  EXPECT_EQ(d.stepped, (std::vector<int>{1, 2, 3, 4}));
  // The env's time limit (10) is no fall; past it only when not asked to stop there.
  end = RunEpisode(&env, 0, 1, {100, true}, &d);
  EXPECT_EQ(end.steps, 10);
  EXPECT_FALSE(end.fell);
  end = RunEpisode(&env, 0, 1, {12, false}, &d);
  EXPECT_EQ(end.steps, 12);
  // A termination is a fall, and ends the episode at once.
  env.fall_at = 3;
  end = RunEpisode(&env, 0, 1, {100, true}, &d);
  EXPECT_EQ(end.steps, 3);
  EXPECT_TRUE(end.fell);
  // The driver stops before a step: no step is taken then.
  env.fall_at = 0;
  d.stop_at = 2;
  d.stepped.clear();
  end = RunEpisode(&env, 0, 1, {100, true}, &d);
  EXPECT_EQ(end.steps, 2);
  EXPECT_FALSE(end.fell);
  EXPECT_EQ(d.stepped, (std::vector<int>{1, 2}));
}

}  // namespace
}  // namespace perch
