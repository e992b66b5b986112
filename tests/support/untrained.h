// Test helper: the weights of a freshly initialised subtask policy (a learner's, untrained) of
// obs_dim inputs, for tests that need a model of the right shape but no skill.
#pragma once

#include <cstdint>

#include "common/proto/model.pb.h"
#include "learner/ppo.h"

namespace perch {

inline proto::ModelWeights Untrained(int obs_dim, uint64_t seed) {
  PpoLearner learner(PolicyConfig::Subtask(obs_dim), PpoConfig::Subtask(), seed);
  proto::ModelWeights w;
  learner.ExportWeights(&w);
  return w;
}

}  // namespace perch
