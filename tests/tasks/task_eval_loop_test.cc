// tasks/task_eval.h's RunEvalEpisodes: the one episode loop of every task's evaluation.
#include <gtest/gtest.h>

#include <vector>

#include "learner/ppo.h"
#include "tasks/task_eval.h"
#include "tests/support/untrained.h"

namespace perch {
namespace {

// Records what the loop hands a task: per episode its steps, whether it fell, and the valid
// steps it was shown.
class CountingObserver : public EpisodeObserver {
 public:
  void Begin(const HumanoidChairEnv&) override { observed_.push_back(0); }
  void Observe(const HumanoidChairEnv&, const StepResult&, int steps) override {
    ++observed_.back();
    last_step_ = steps;
  }
  bool End(const HumanoidChairEnv&, int episode, int steps, bool fell) override {
    episodes_.push_back(episode);
    steps_.push_back(steps);
    fell_.push_back(fell);
    return !fell;
  }
  std::vector<int> episodes_, steps_, observed_;
  std::vector<bool> fell_;
  int last_step_ = 0;
};

TEST(EvalLoop, EpisodesAreSeededByIndexAndEndAtFallOrLimit) {
  TaskEnvConfig c = TaskEnvConfig::Defaults("walk");
  c.walk.max_episode_steps = 20;
  std::unique_ptr<HumanoidChairEnv> env = MakeTaskHumanoidEnv(c);
  PolicyRunner policy = MakeEvalPolicy(Untrained(env->spec().obs_dim, 2), env->spec(), "walk");
  EvalOptions o;
  o.episodes = 3;
  o.seed = 5;
  EpisodeLoop loop;
  loop.max_steps = 35;
  loop.stop_at_truncation = true;
  CountingObserver a;
  EvalRecording rec;
  const EpisodeTotals t = RunEvalEpisodes(env.get(), &policy, o, loop, &a, &rec);
  ASSERT_EQ(a.episodes_, (std::vector<int>{0, 1, 2}));
  int64_t steps = 0;
  int falls = 0;
  for (size_t e = 0; e < 3; ++e) {
    // At the task's limit (20) unless it fell first; never past it when asked to stop there.
    EXPECT_LE(a.steps_[e], 20);
    if (!a.fell_[e]) {
      EXPECT_EQ(a.steps_[e], 20);
    }
    EXPECT_EQ(a.observed_[e], a.steps_[e]);  // every step valid here
    steps += a.steps_[e];
    falls += a.fell_[e];
  }
  EXPECT_EQ(t.steps, steps);
  EXPECT_EQ(t.falls, falls);
  EXPECT_EQ(static_cast<int>(t.fall_episodes.size()), falls);
  EXPECT_EQ(t.invalid, 0);
  // Episode 0's poses: the start and one per step.
  EXPECT_EQ(static_cast<int>(rec.frames.size()), a.steps_[0] + 1);
  EXPECT_TRUE(rec.targets.empty());

  // Past the task's limit when the metric needs longer episodes (stop_at_truncation off).
  loop.stop_at_truncation = false;
  CountingObserver b;
  RunEvalEpisodes(env.get(), &policy, o, loop, &b, nullptr);
  for (size_t e = 0; e < 3; ++e) {
    if (!b.fell_[e]) {
      EXPECT_EQ(b.steps_[e], 35);
    }
    // The same episode up to the limit: seeded by (seed, e) alone.
    if (a.fell_[e]) {
      EXPECT_TRUE(b.fell_[e]);
      EXPECT_EQ(b.steps_[e], a.steps_[e]);
    }
  }
  // Sampled actions: the same seed again gives the same episodes, another seed others.
  o.stochastic = true;
  CountingObserver c2;
  const EpisodeTotals again = RunEvalEpisodes(env.get(), &policy, o, loop, &c2, nullptr);
  EXPECT_EQ(again.sum_return,
            RunEvalEpisodes(env.get(), &policy, o, loop, &c2, nullptr).sum_return);
  o.seed = 6;
  CountingObserver d;
  const EpisodeTotals other = RunEvalEpisodes(env.get(), &policy, o, loop, &d, nullptr);
  EXPECT_NE(other.sum_return, again.sum_return);
}

TEST(EvalLoop, APolicyOfAnotherShapeIsRefusedNamingTheTask) {
  const TaskEnvConfig c = TaskEnvConfig::Defaults("walk");
  std::unique_ptr<HumanoidChairEnv> env = MakeTaskHumanoidEnv(c);
  try {
    MakeEvalPolicy(Untrained(env->spec().obs_dim + 5, 1), env->spec(), "walk");
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("does not fit the walk env"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace perch
