// Evaluation of the meta controller on the main task (paper Sec. 7, Tables 3 and 6, Fig. 7):
// `perch eval --task sit_chair --zone Z --trials N`. Trials are spread over threads; trial i
// uses seed (seed, i) whatever the thread count, so the result is deterministic for a seed.
// Definitions: docs/meta.md.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "common/env.h"
#include "common/json_util.h"
#include "common/proto/bank.pb.h"
#include "common/proto/model.pb.h"
#include "tasks/chain_plan.h"
#include "tasks/task_env.h"
#include "viz/filmstrip.h"

namespace perch {

struct MetaPlan;

struct MetaEvalOptions {
  int trials = 100;
  uint64_t seed = 0;
  // false: the meta's most likely class and mean target, the subtasks' mean actions; true: all
  // sampled (the authors' released visualisation).
  bool stochastic = false;
  int threads = 1;
  std::function<void(int done, int successes)> progress;  // called from the threads, serialised
  // When set, the scripted planner (tasks/meta_expert.h) decides instead of the meta policy.
  std::shared_ptr<const MetaPlan> planner;
  // When set: the state at every hand-over to starts_subtask (the sit unless changed), in trial
  // order (`episode` = the trial), for training that subtask on them (`perch eval
  // --save-sit-starts`); failed_sit_starts: only those of the trials that failed.
  std::vector<proto::BankState>* sit_starts = nullptr;
  std::vector<proto::BankState>* failed_sit_starts = nullptr;
  // Whose hand-overs those are (a SubtaskId; `perch eval --hand-overs-to`): the sit by default,
  // a turn to train the turn on the states the meta hands it, the walk for its hand-backs (the
  // episode's first run, from the spawn, is never a hand-over).
  int starts_subtask = 2;  // kSit (tasks/hierarchy.h)
  // A meta policy with lookahead (tasks/meta_lookahead.h; `perch eval --lookahead-*`): only the
  // lookahead_* fields count (delays at each of its switches, the other turn at each switch into
  // a turn, straight-on walking at the start, the rank). None set: the policy alone. (The
  // planner's lookahead is its config's.)
  PlannerConfig policy_lookahead;
};

// The control-step frames of one trial, labelled with the acting subtask.
struct MetaTrialFrames {
  int trial = -1;
  bool success = false;
  std::vector<PoseFrame> frames;
};

// JSON: trials, seed, zone, success_rate, success_ci95, min_dist_mean_m, min_dist_std_m,
// fall_rate, seated_position_error_cm_mean, seated_orientation_error_deg_mean, time_to_sit_s_mean,
// transitions (per start side: counts from -> to, with "start" as the first row), sequences (the
// most frequent subtask sequences). first_success / first_failure (when given) get the frames of
// the first successful and the first failed trial.
Json EvaluateMeta(const TaskEnvConfig& config, const proto::ModelWeights& meta,
                  const std::vector<FrozenPolicyData>& frozen, const MetaEvalOptions& options,
                  MetaTrialFrames* first_success = nullptr,
                  MetaTrialFrames* first_failure = nullptr);

// The chance that a positive (second = true) scores higher than a negative, ties counted half
// (the area under the ROC curve); 0.5 when either group is empty.
double RankAuc(std::vector<std::pair<float, bool>> scored);

// Fig. 7: the `transitions` of an EvaluateMeta result as a PNG, one matrix per start side; rows
// are where a run of one subtask came from (start or a subtask), columns what followed (a subtask
// or the episode's end); cells shaded by the row's share, labelled with the count.
void SaveTransitionMatrixPng(const Json& result, const std::string& path);

}  // namespace perch
