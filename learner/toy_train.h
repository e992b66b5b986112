// `perch ppo toy`: PPO trained in process on a toy task (point_mass or choice_target), the quick
// end-to-end check of the learner: its learning curve and a final deterministic evaluation.
#pragma once

#include <cstdint>
#include <string>

#include "common/json_util.h"
#include "protocol/ppo_config.h"

namespace perch {

struct ToyTrainOptions {
  std::string task = "point_mass";
  std::string config_path;  // optional {"policy": {...}, "ppo": {...}}
  std::string out_dir;      // optional: resolved config + final learner state
  int updates = 0;          // 0: the task's default
  uint64_t seed = 0;
};

// The toy tasks' defaults: small batches so that they solve in seconds.
PpoConfig ToyPpoConfig(const std::string& task);

// Trains on a toy task; JSON: the resolved config, per-update stats ("curve"), the final
// deterministic return and its episode count. With out_dir: config.json and learner_state.pb.
// ConfigError on an unknown task or a bad config file.
Json TrainToy(const ToyTrainOptions& o);

}  // namespace perch
