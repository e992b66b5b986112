// Where a model comes from: a run dir or a checkpoint file, the experiment config saved with it,
// and the frozen-policy bundle (model, saved config, source) the hierarchy ships to actors.
#pragma once

#include <string>
#include <vector>

#include "common/env.h"
#include "common/json_util.h"
#include "common/proto/model.pb.h"

namespace perch {

// The experiment config saved with a model: a checkpoint's resolved config, or a run dir's
// config.json. Null when the file carries none (a bare ModelWeights).
Json SavedConfig(const std::string& model_path);

// A run dir's newest checkpoint; any other path as given.
std::string ModelFile(const std::string& model_path);

// Reads a policy file: a serialized perch.proto.ModelWeights, a LearnerState (its model), or a
// cluster checkpoint ("PERCHCKP" frame around perch.proto.Checkpoint, learner/service/checkpoint.h:
// its trainer.model). ConfigError naming the file on anything else (corrupt, truncated, empty).
proto::ModelWeights LoadModelFile(const std::string& path);

// A model file (or run dir) as a frozen policy named `name`: its weights, saved config and
// "path (sha256 ...)". ConfigError naming the file when it does not load.
FrozenPolicyData LoadFrozenPolicy(const std::string& name, const std::string& model_path);

// The frozen policies a checkpoint carries (a meta run's subtasks, as it trained with them);
// empty for other files.
std::vector<FrozenPolicyData> FrozenPoliciesIn(const std::string& model_path);

}  // namespace perch
