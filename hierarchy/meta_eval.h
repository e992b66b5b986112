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
#include "envs/pose_frame.h"
#include "hierarchy/chain_plan.h"
#include "tasks/perturbation.h"
#include "tasks/task_env.h"

namespace perch {

struct MetaPlan;

// One trial's outcome, all the aggregates need: `perch eval --records` saves one per line, so a
// long evaluation resumes where it stopped and shards run apart merge into the result one run
// would give (AggregateMeta).
struct MetaTrialRecord {
  int trial = -1;
  bool success = false;
  bool fell = false;
  double min_dist_m = 0.0;     // minimum pelvis - seat target distance [m]
  double time_to_sit_s = 0.0;  // 0 when it failed [s]
  // At success (MetaEpisode): horizontal distance [m], height above the seat target [m], yaw
  // error [rad].
  double pos_err_m = 0.0, height_m = 0.0, yaw_err_rad = 0.0;
  double spawn_theta = 0.0;        // [rad]
  std::vector<int> sequence;       // SubtaskId of each run
  std::vector<float> begin_value;  // [run] the subtask's critic when it began
  // With a lookahead (hierarchy/meta_lookahead.h): its work and what it predicted.
  bool has_lookahead = false;
  int la_points = 0, la_rollouts = 0, la_changed = 0;
  bool la_predicted_any = false;
  bool la_rules_success = false;  // the decider alone (from the first look ahead on) succeeded
  bool la_as_predicted = false;   // the outcome is the one the last look ahead predicted
  bool la_not_worse = false;      // ... and not worse than the decider alone
  // The program that ran it (PerchVersion(): its commit). Records written before stop 42 have
  // none (""). A resumed evaluation can span builds; the header cannot see a code change, so
  // each trial says which build ran it and AggregateMeta counts them ("builds").
  std::string build;
  // With MetaEvalOptions::record_routes: the meta observation at the start [obs_dim] and the
  // outcome of each start route the lookahead tried (LookaheadPlanner::Stats::routes), for
  // learning the start route (docs/journal/meta.md "Stop 42"). Empty otherwise.
  struct Route {
    int straight_steps = 0;  // [meta steps]; 0: the policy's own start
    double detour_deg = 0;   // [deg] off the facing; NaN: straight ahead
    bool success = false, fell = false;
    int success_step = -1;
    double min_dist_m = 0;
  };
  std::vector<float> start_obs;
  std::vector<Route> routes;
  // With MetaEvalOptions::perturb: the same trial's outcome without the perturbations (0 / 1;
  // -1: not a perturbed evaluation).
  int unperturbed_success = -1;

  Json ToJson() const;
  // ConfigError naming `where` and the field when a field is missing or of the wrong type.
  static MetaTrialRecord FromJson(const Json& j, const std::string& where);
};

struct MetaEvalOptions {
  int trials = 100;
  // Trials first_trial .. first_trial + trials - 1 (trial i always uses seed (seed, i)): shards
  // of one evaluation on several machines (`perch eval --first-trial`, `perch eval-merge`).
  int first_trial = 0;
  uint64_t seed = 0;
  // false: the meta's most likely class and mean target, the subtasks' mean actions; true: all
  // sampled (the authors' released visualisation).
  bool stochastic = false;
  int threads = 1;
  std::function<void(int done, int successes)> progress;  // called from the threads, serialised
  // When set, the scripted planner (hierarchy/meta_expert.h) decides instead of the meta policy.
  std::shared_ptr<const MetaPlan> planner;
  // When set: the state at every hand-over to starts_subtask (the sit unless changed), in trial
  // order (`episode` = the trial), for training that subtask on them (`perch eval
  // --save-sit-starts`); failed_sit_starts: only those of the trials that failed.
  std::vector<proto::BankState>* sit_starts = nullptr;
  std::vector<proto::BankState>* failed_sit_starts = nullptr;
  // Whose hand-overs those are (a SubtaskId; `perch eval --hand-overs-to`): the sit by default,
  // a turn to train the turn on the states the meta hands it, the walk for its hand-backs (the
  // episode's first run, from the spawn, is never a hand-over).
  int starts_subtask = 2;  // kSit (hierarchy/hierarchy.h)
  // A meta policy with lookahead (hierarchy/meta_lookahead.h; `perch eval --lookahead-*`): only the
  // lookahead_* fields count (delays at each of its switches, the other turn at each switch into
  // a turn, straight-on walking at the start, the rank). None set: the policy alone. (The
  // planner's lookahead is its config's.)
  PlannerConfig policy_lookahead;
  // Each record also holds the start observation and every start route's outcome
  // (MetaTrialRecord::routes; needs a lookahead with straight-on starts).
  bool record_routes = false;
  // Trials already run (from a records file): not run again, but in the result. Each must lie in
  // this evaluation's trials, once.
  std::vector<MetaTrialRecord> done;
  // Called with each trial's record as it finishes (from the threads, serialised).
  std::function<void(const MetaTrialRecord&)> on_record;
  // Perturbations (issue 49; perch eval --push, --obs-noise, --act-noise, --restore): each trial
  // runs first without them (the span its outcome was decided in, to its success or else its
  // end, is the horizon their moments are drawn in, as a subtask's judged span is), then with them;
  // the record is the perturbed run's, with the unperturbed outcome beside it, and the result gains
  // flip_rate (MetaEnv::SetPerturbation).
  Perturbation perturb;
};

// The control-step frames of one trial, labelled with the acting subtask.
struct MetaTrialFrames {
  int trial = -1;
  bool success = false;
  std::vector<PoseFrame> frames;
};

// What makes two evaluations' trials the same trials: task, zone, chair, seed, stochastic, the
// decider (the meta model's and every frozen subtask's SHA-256, or the planner's config), the
// lookahead, the env config and the start banks' SHA-256. Saved as a records file's header; a
// resume or merge refuses records made under another.
Json MetaEvalHeader(const TaskEnvConfig& config, const proto::ModelWeights& meta,
                    const std::vector<FrozenPolicyData>& frozen, const MetaEvalOptions& options);

// The result of the trials `records` (any order; each trial once) run under `header`: the JSON
// EvaluateMeta returns, but for `threads` (and what the caller adds).
Json AggregateMeta(const Json& header, std::vector<MetaTrialRecord> records);

// `perch eval --records`: JSON lines, a header ({"perch_meta_eval_records": 1, "header": H}) then
// one MetaTrialRecord per line in the order the trials finished.
struct MetaRecordsFile {
  Json header;
  std::vector<MetaTrialRecord> records;
  bool torn_tail = false;     // the last line was cut short (a killed run) and is left out
  size_t complete_bytes = 0;  // the bytes up to the end of the last complete line
};
// ConfigError naming the file and line: no header, a malformed line other than the last, a trial
// twice.
MetaRecordsFile ReadMetaRecords(const std::string& path);
MetaRecordsFile ParseMetaRecords(const std::string& text, const std::string& path);
std::string MetaRecordsHeaderLine(const Json& header);

// The records file of one running evaluation. Open() locks the file (a second evaluation on it is
// refused while this one runs), writes the header into a new (or empty) file, or reads an
// existing one: its header must equal `header` but for "about" (else ConfigError naming the first
// field that differs, with both values; a file of a header and no trial takes the new header),
// its trials must lie in `o`'s, and a last line cut short
// by a killed run is cut off in place. Its trials go into o->done; o->on_record then appends each
// new trial (one line, flushed). Nothing recorded is removed or rewritten. Keep the writer alive
// until the evaluation returns.
class MetaRecordsWriter {
 public:
  struct Opened {
    int resumed = 0;         // trials already in the file
    bool torn_tail = false;  // a cut-short last line was dropped
  };
  MetaRecordsWriter() = default;
  MetaRecordsWriter(const MetaRecordsWriter&) = delete;
  MetaRecordsWriter& operator=(const MetaRecordsWriter&) = delete;
  ~MetaRecordsWriter();
  Opened Open(const std::string& path, const Json& header, MetaEvalOptions* o);

 private:
  void Append(const std::string& line);
  int fd_ = -1;
  std::string path_;
};
// The first key whose value differs between two headers ("" when equal), for the refusal; "about"
// (the model's and bank's paths, which differ between machines) is not compared. A file's header
// is read with its env config filled in with this build's defaults (ParseMetaRecords), so a
// config field added later does not refuse older records while it keeps its default.
std::string FirstHeaderDifference(const Json& a, const Json& b);

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

}  // namespace perch
