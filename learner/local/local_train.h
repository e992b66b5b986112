// In-process PPO on a task env (no cluster): a bounded number of samples, for quick comparisons
// (torque vs pd, paper vs authors rewards). Writes into out_dir:
//   config.json     resolved env/task/PPO config and seed
//   curve.csv       one row per PPO update (learning curve)
//   learner_state.bin  serialized perch.proto.LearnerState (resumable state, what perch eval reads)
//   weights.bin     serialized perch.proto.ModelWeights
// Files are written atomically (temporary + rename); nothing else in out_dir is touched.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "common/json_util.h"
#include "learner/ppo.h"
#include "tasks/task_env.h"

namespace perch {

struct LocalTrainOptions {
  int64_t samples = 8192 * 4;  // env steps in total (rounded up to whole updates)
  uint64_t seed = 0;
  std::string out_dir;
  PpoConfig ppo = PpoConfig::Subtask();
};

// Returns a summary (updates, samples, last rows); `progress` gets each curve row.
Json TrainLocal(const TaskEnvConfig& config, const LocalTrainOptions& options,
                const std::function<void(const Json&)>& progress);

}  // namespace perch
