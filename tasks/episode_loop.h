// The one episode loop of every evaluation: a subtask's `perch eval --task T` (tasks/task_eval.h,
// tasks/walk_eval.h), the chain of subtasks and the meta controller's trials (hierarchy/). It
// seeds, resets, acts, steps and ends an episode on any Env; what an evaluation does around it
// (its policy or planner, its metrics, its recorder) is an EpisodeDriver.
#pragma once

#include <cstdint>

#include "common/env.h"
#include "common/rng.h"

namespace perch {

// Episode e of an evaluation with seed `seed` depends only on (seed, e): s = seed * 1000003 + e,
// the env is seeded with 2 s and the actions' noise with 2 s + 1, so any episode can be rerun
// alone (and a sharded evaluation's trial i is the same trial in every shard).
struct EpisodeSeeds {
  uint64_t env = 0;
  uint64_t actions = 0;
};
EpisodeSeeds EvalEpisodeSeeds(uint64_t seed, int episode);

// What one evaluation does in each episode of the loop.
class EpisodeDriver {
 public:
  virtual ~EpisodeDriver() = default;
  // After the episode's Reset: `obs` is its first observation, `env_seed` the env's seed.
  virtual void Begin(int episode, uint64_t env_seed, const float* obs) {}
  // Writes the action for `obs`; false ends the episode before this step (neither a fall nor a
  // time limit: e.g. the chain's rules have no subtask left to run).
  virtual bool Act(const float* obs, Rng& rng, float* action) = 0;
  // After each step; `steps` counts it.
  virtual void Stepped(const StepResult& r, int steps) {}
};

struct EpisodeLimits {
  int max_steps = 0;                // steps at most
  bool stop_at_truncation = false;  // also end at the env's time limit (StepResult::truncated)
};

struct EpisodeEnd {
  int steps = 0;      // control steps taken
  bool fell = false;  // ended by termination (StepResult::terminated), never by truncation
};

// Runs episode `episode` of an evaluation with seed `seed` on `env`, driven by `driver`.
EpisodeEnd RunEpisode(Env* env, int episode, uint64_t seed, const EpisodeLimits& limits,
                      EpisodeDriver* driver);

}  // namespace perch
