// Start-state banks (issue 14, notes 4.5): complete restorable episode states (the env's EnvState
// and the task's memory) sampled from a trained policy, with their provenance, in a versioned
// Protobuf file framed like a checkpoint:
//   "PERCHBNK" (8 bytes) | format u32 LE | payload length u64 LE | CRC-32 of payload u32 LE |
//   payload
// A truncated or corrupt file, another format version, or another joint layout is refused with a
// ConfigError naming the file and the reason.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/file_util.h"  // FileSha256, Sha256Hex (used with banks)
#include "common/proto/bank.pb.h"
#include "common/proto/model.pb.h"
#include "envs/humanoid_env.h"
#include "tasks/task_env.h"

namespace perch {

constexpr uint32_t kStateBankFormat = 1;

// Reads and checks a bank; `model` (may be null) must have the bank's joint layout.
proto::StateBank ReadStateBank(const std::string& path, const HumanoidModel* model);
// Writes atomically; refuses to replace an existing file unless overwrite.
void WriteStateBank(const std::string& path, const proto::StateBank& bank, bool overwrite);

// A bank's header (format, task, the model's joint layout, seed, sampling mode, resolved env
// config); the sampler fills in its own fields (steps, survive, count, states).
proto::StateBank NewStateBank(const std::string& task, const HumanoidModel& model, uint64_t seed,
                              bool stochastic, const Json& env_config);

// Hand-overs an evaluation collected (a chain's to sit, or the meta env's to any subtask) as a
// bank for that subtask's start.banks: `states` (moved out) under a header of the run's `task`,
// config, model path(s), seed and sampling mode, written as WriteStateBank does.
void WriteHandOverBank(const std::string& file, const std::string& task,
                       const TaskEnvConfig& config, const std::string& model_path, uint64_t seed,
                       bool stochastic, int episodes_run, std::vector<proto::BankState>& states,
                       bool overwrite);

// The env's state and its task's memory, and back (the inverse restores the episode exactly).
proto::BankState CaptureState(const HumanoidChairEnv& env);
EnvState EnvStateOf(const proto::BankState& b);
HumanoidState HumanoidStateOf(const proto::BankState& b);

struct SampleEndPosesOptions {
  int steps = 60;  // N: keep the state after exactly N control steps ...
  int survive =
      60;  // K: ... of episodes that survive N + K steps (authors: walk 60/60, turns 80/60)
  int count = 1000;  // C
  uint64_t seed = 0;
  bool stochastic = true;  // the authors sample actions
  int workers = 1;         // threads, each with its own env and policy
  // Called about once a second and at the end: states collected, episodes run.
  std::function<void(int collected, int64_t episodes)> progress;
};

// Runs the policy in the task's evaluation env until `count` episodes survived; deterministic for
// a seed whatever the number of workers (the states are those of the first `count` surviving
// episodes by episode index; episode e uses the env seed of perch eval's episode e).
proto::StateBank SampleEndPoses(const TaskEnvConfig& config, const proto::ModelWeights& weights,
                                const SampleEndPosesOptions& options);

// A loaded bank shared by the envs of one process (immutable).
struct StartBank {
  std::vector<proto::BankState> states;
  std::string path;
};
// Loads every path (their union); ConfigError naming a bad file. Cached per path list.
std::shared_ptr<const StartBank> LoadStartBanks(const std::vector<std::string>& paths,
                                                const HumanoidModel& model);

}  // namespace perch
