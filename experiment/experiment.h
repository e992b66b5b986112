// An experiment config file (configs/*.json), read once in main and passed down:
//   { "seed": 0, "env_backend": "bullet" | "mock", "env": {...}, "mock_env": {...},
//     "policy": {...}, "ppo": {...}, "cluster": {...} }
// "env" is the envs/ EnvConfig (bullet backend), "mock_env" the transport fixture's (mock
// backend), "policy" the network (obs_dim/act_dim come from the env spec), "ppo" the PPO core's
// PpoConfig, "cluster" ClusterConfig. Every section is optional and defaults to the paper's values.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/env.h"
#include "common/json_util.h"
#include "experiment/mock_env.h"
#include "policy/policy.h"
#include "protocol/cluster_config.h"
#include "protocol/ppo_config.h"

namespace perch {

struct ExperimentConfig {
  uint64_t seed = 0;  // authors: seed 0 for every run (notes §8.2)
  std::string env_backend = "bullet";
  Json env = Json::object();  // validated by the envs/ parser
  MockEnvConfig mock_env;
  Json policy = Json::object();  // PolicyConfig without the dims (filled from the env spec)
  PpoConfig ppo;
  ClusterConfig cluster;
  std::string source;  // file it was read from, for messages
};

// Strict: unknown field or wrong type -> ConfigError naming the file and field. Also builds one
// env to check the env section and the policy dims. The file may name a `base` config, and each
// `sets` entry ("ppo.learning_rate=3e-5", the --set flag) overrides one field
// (common/config_file.h).
ExperimentConfig LoadExperimentConfig(const std::string& path,
                                      const std::vector<std::string>& sets = {});
ExperimentConfig ExperimentConfigFromJson(const Json& j, const std::string& ctx);
// Resolved config (all defaults filled in), saved into run dirs and checkpoints.
Json ToJson(const ExperimentConfig& c);

// The env of the experiment (a fresh instance; each actor env calls this).
std::unique_ptr<Env> MakeExperimentEnv(const ExperimentConfig& c);

// The policy of the trained task, dims from the env spec. ConfigError when "policy" sets dims
// that disagree with the env.
PolicyConfig ResolvePolicyConfig(const ExperimentConfig& c, const EnvSpec& spec);

// The frozen policies the trained task runs inside its env (meta: the subtasks named in
// env.sit_chair.meta, read from their files and checked); empty for other tasks. The learner
// ships them to the actors.
std::vector<FrozenPolicyData> ExperimentFrozenPolicies(const ExperimentConfig& c);

// The sections' field tables (common/field_table.h): {"env": [...], "ppo": [...], "cluster":
// [...]}, each row {name, default or fields, doc, rule}. `perch config --fields` prints them.
Json ConfigFieldTables();
// `perch config --fields SECTION [--json]`: one section's table (or "all"), as aligned text
// ("section.field  default  rule  doc", nested fields dotted) or JSON. ConfigError for an
// unknown section.
std::string ConfigFieldsText(const std::string& section, bool json);

// What must match between a checkpoint and the config resuming from it: task, dims, network.
std::string CompatKey(const ExperimentConfig& c, const PolicyConfig& policy);

}  // namespace perch
