// `perch bench ppo`: PPO update throughput of the subtask network on one core, and with
// --threads N the speedup of N threads over one measured in the same run.
#pragma once

#include <cstdint>

#include "common/json_util.h"

namespace perch {

struct PpoBenchOptions {
  int obs_dim = 57;
  int batch = 8192;
  int minibatches = 32;
  int repeats = 10;
  int threads = 1;
  int epochs = 1;
  uint64_t seed = 0;
  bool blocks = false;   // time all one-thread updates, then all N-thread ones (not alternating)
  bool ceiling = false;  // also time N one-thread learners at once: what N cores give here
};

// One timed PPO epoch per Update call; with threads > 1 a one-thread learner is timed in the same
// run, alternating epoch by epoch, and the JSON gives the ratio (machines here are noisy).
// ConfigError when a size is not positive.
Json RunPpoBench(const PpoBenchOptions& o);

}  // namespace perch
