// Weight averaging of policies from one run (Polyak / SWA style, Izmailov et al. 2018; for deep RL
// Nikishin et al. 2018): late PPO snapshots at a small learning rate lie in one basin and differ
// by update noise, so their mean can act better than any one of them.
#pragma once

#include <vector>

namespace perch {

namespace proto {
class ModelWeights;
}

// Elementwise mean of params [num_params]; observation statistics pooled as one population of the
// snapshots (mean of means; var = mean of (var + mean^2) - pooled mean^2; count = mean count).
// version = the newest snapshot's. Throws ConfigError naming the first snapshot (by index) whose
// shape, normalization settings or sizes differ from snapshot 0, or when `models` is empty.
proto::ModelWeights AverageModels(const std::vector<proto::ModelWeights>& models);

}  // namespace perch
