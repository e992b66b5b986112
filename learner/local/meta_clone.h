// Behaviour cloning of the scripted planner into a meta policy (ours; issue 15): `perch
// meta-clone`. The planner (hierarchy/meta_expert.h) drives MetaEnv for some episodes; every meta
// step's observation and the planner's hybrid action [class, theta, dist] are kept; the meta
// network (the config's, as PPO trains it) is fitted by maximising the log-likelihood of those
// actions (cross-entropy on the switch, Gaussian on the target) with Adam, and the observation
// statistics are those of the collected observations. The result starts PPO (cluster.init_from)
// where a working sequence of subtasks already is: the Zone 1 meta runs never found one by
// exploration from Eq. 8 (docs/meta.md).
//
// DAgger rounds (Ross et al. 2011): after the first fit, episodes are driven by the cloned policy
// with probability 1 - beta per meta step while the planner still labels every step, so the data
// cover the states the clone itself reaches.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include "common/env.h"
#include "common/json_util.h"
#include "common/proto/model.pb.h"
#include "hierarchy/meta_expert.h"
#include "policy/policy.h"
#include "tasks/task_env.h"

namespace perch {

struct CloneOptions {
  int episodes = 300;        // per round
  int rounds = 1;            // 1: plain cloning; > 1: DAgger rounds after the first
  double dagger_beta = 0.5;  // later rounds: the planner acts with this probability per step
  // Weight in the fit of the meta steps whose label changes the acting subtask (a hand-over),
  // against 1 for the others (ours, 2026-12-05): they are 1-2% of the steps at 30 Hz, yet each
  // decides a trial.
  double switch_weight = 1.0;
  int epochs = 40;  // passes over the data per round
  int minibatch = 256;
  float learning_rate = 1e-3f;
  // The target head's log-std after fitting [log m / log rad]: PPO's exploration (the fit
  // itself drives it down to the planner's spread).
  float target_log_std = -1.0f;
  uint64_t seed = 0;
  int threads = 1;
  // A curriculum stage (ours; issue 15): start from this meta policy (the previous stage's), so
  // that round 1 is already a DAgger round driven by it and the fit continues from its weights.
  // Empty: a fresh network and plain cloning in round 1.
  std::optional<proto::ModelWeights> init;
  std::function<void(const std::string&)> progress;  // one line per round / epoch block
};

struct CloneResult {
  proto::ModelWeights weights;
  Json summary;  // samples, per round: planner success, accuracy of the switch, target error
};

// Throws ConfigError "meta-clone --init-from: ..." unless `init` loads as the meta policy `pc`
// (shape, parameter count, finite weights).
void CheckCloneInit(const PolicyConfig& pc, const NormalizerConfig& norm,
                    const proto::ModelWeights& init);

// pc: the meta policy as the experiment config resolves it (kind meta, the config's inputs and
// choices). frozen: the subtasks (as the learner ships them).
CloneResult CloneMeta(const TaskEnvConfig& config, const std::vector<FrozenPolicyData>& frozen,
                      const PolicyConfig& pc, const NormalizerConfig& norm,
                      std::shared_ptr<const MetaPlan> plan, const CloneOptions& o);

}  // namespace perch
