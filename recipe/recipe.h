// A training recipe (issue 48): the stages from an empty directory to a delivered hierarchy, each
// naming its kind, its config, its inputs (earlier stages' outputs, by name), its stop rule and
// how its delivered checkpoint is chosen. This header is the file format and the pure logic on it
// (validation, dependencies, scaling, fingerprints, the state file); recipe/runner.h runs it.
// Format and semantics: docs/recipe.md.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "common/field_table.h"
#include "common/json_util.h"

namespace perch {

// How a train stage's delivered checkpoint is chosen: each of the run's newest `last_k`
// checkpoints (with `milestones`, also every milestone checkpoint the run kept: each
// cluster.milestone_every updates, so the whole run is searched, not only its end) is evaluated
// (perch eval, `episodes` episodes on the selection seed), the best by `metric` wins (ties: the
// newer). last_k 0: the newest checkpoint, no evaluation. With `include_init` the policy the run
// started from (cluster.init_from) competes as the oldest candidate, "init": a fine-tune that does
// not beat its input on the selection seed delivers its input.
struct StageSelect {
  int last_k = 0;
  bool milestones = false;
  bool include_init = false;
  int episodes = 100;                   // scaled by --scale (floor: min_episodes)
  uint64_t seed = 1;                    // the selection seed; reports use another (docs/recipe.md)
  std::string metric = "success_rate";  // a top-level number of perch eval's JSON
  bool lower_is_better = false;         // e.g. "fall_rate"
  std::vector<std::string> args;        // more perch eval flags (e.g. --task walk)
};

// The checkpoints a selection evaluates, oldest first, from a run's checkpoint files (sorted by
// update; the run keeps its milestones and its newest keep_last): the newest last_k (at least
// one), and with milestones every file.
std::vector<std::string> SelectionCandidates(const std::vector<std::string>& checkpoints,
                                             const StageSelect& select);

// One stage. Strings in `sets` and `args` may hold references "${STAGE.OUTPUT}" (an earlier
// stage's output file), "${out.OUTPUT}" (this stage's own output file) and "${dir}" (this stage's
// directory); the stages a stage reads from are its dependencies.
struct RecipeStage {
  std::string name;
  std::string kind;     // train, sample, mirror, clone, eval, run
  std::string command;  // the perch subcommand (kinds other than train; default per kind)
  std::string doc;
  std::string config;             // a config file (base); "" for stages that take none
  std::vector<std::string> sets;  // --set overrides of the config (section.field=VALUE)
  std::vector<std::string> args;  // further flags of the command
  // A toy run (--scale < 1) trains nothing, so where an untrained policy cannot produce the
  // stage's output at all (end poses that survive 60 steps, hand-overs that reach the chair),
  // these give one of the same shape: toy_args replace args, toy_set is added to set.
  std::vector<std::string> toy_args;
  bool has_toy_args = false;
  std::vector<std::string> toy_sets;
  // Flags whose value is a count of episodes, trials or states: multiplied by --scale, with
  // floor `min_count` (a toy run still sees a few episodes).
  std::map<std::string, int64_t> counts;
  int64_t min_count = 3;
  // Stop rule of a train stage: a sample budget, and optionally a success rate over the newest
  // `target_window` judged episodes that ends it earlier.
  int64_t max_samples = 0;
  double target_success = 0.0;
  int target_window = 0;  // 0: the config's cluster.target_window
  int actors = 0;         // 0: the runner's --actors
  StageSelect select;
  // Output name -> file name inside the stage's directory (defaults per kind: docs/recipe.md).
  std::map<std::string, std::string> outputs;
  // Outputs the command may rightly leave unwritten (a planner that never fails writes no bank of
  // failed hand-overs): the stage is done without them, and a list in a later stage's `set` that
  // names one drops it.
  std::vector<std::string> optional_outputs;
  // Figures copied from the stage's JSON result (eval: perch eval --json; clone: its summary).
  std::vector<std::string> figures;
  double est_wall_s = 0.0;  // full-scale wall time on 2 cores, for the recipe's ETA
  // An eval stage of --trials (perch eval --task sit_chair) runs as this many shards of
  // consecutive trials (--first-trial, --records), which `perch recipe worker` processes on other
  // machines may take, merged by perch eval-merge. The merged result is the one an unsharded run
  // gives, so it is not in the fingerprint (as actors).
  int shards = 1;
  std::vector<std::string> deps;  // derived from the references, in stage order
};

// A stage's and its select's fields, each written once (common/field_table.h): reading (unknown
// keys refused, ranges checked; the rules across fields are StageFromJson's), writing, and
// `perch recipe fields`.
const FieldTable<StageSelect>& StageSelectFields();
const FieldTable<RecipeStage>& RecipeStageFields();
// The format's fields as `perch recipe fields` prints them: one line each (name, default, rule,
// doc; select's under "select."), or the tables as JSON.
std::string RecipeFieldsText(bool json);

// Shard k of `trials` split `shards` ways: its first trial and count; empty shards left out.
struct TrialShard {
  int index = 0;
  int64_t first = 0, count = 0;
};
std::vector<TrialShard> TrialShards(int64_t trials, int shards);

struct Recipe {
  std::string path;  // the file it was read from
  std::string name;
  std::string doc;
  std::vector<RecipeStage> stages;
  int Index(const std::string& stage) const;  // -1 when absent
};

// Reads and checks a recipe file: unknown keys, unknown kinds, duplicate names, references to
// unknown stages or outputs or to later stages (the order is the run order) are ConfigErrors
// naming the file, the stage and the field.
Recipe LoadRecipe(const std::string& path);
Recipe RecipeFromJson(const Json& j, const std::string& ctx);

// Every "${A.B}" reference in `s`, as (A, B) pairs.
std::vector<std::pair<std::string, std::string>> FindRefs(const std::string& s);
// `s` with every reference replaced through `lookup(A, B)`.
std::string SubstituteRefs(
    const std::string& s,
    const std::function<std::string(const std::string&, const std::string&)>& lookup);

// Options that change what stages do, and so their fingerprints.
struct RecipeRunOptions {
  double scale = 1.0;             // --scale F (0 < F <= 1)
  std::vector<std::string> sets;  // --set applied to every stage's config
  int actors = 2;
};

// A count scaled: max(round(n * scale), floor), never above n.
int64_t ScaledCount(int64_t n, double scale, int64_t floor);

// The stage as it will run: counts, budgets and selection episodes scaled, global sets appended.
RecipeStage ScaledStage(const RecipeStage& s, const RecipeRunOptions& o);

// The stage's outputs with kind defaults filled in (train/mirror/clone: policy -> policy.bin;
// sample: bank -> bank.bin; eval: result -> eval.json; clone also summary).
std::map<std::string, std::string> StageOutputs(const RecipeStage& s);
// The perch subcommand a stage runs ("train" for train stages).
std::string StageCommand(const RecipeStage& s);

// What makes a stage's result what it is: its definition as it will run (references kept as
// names), its composed config, and the SHA-256 of every input file. A stage whose fingerprint
// differs from the one recorded must run again, and so must every stage after it that reads it.
std::string StageFingerprint(const RecipeStage& scaled, const Json& composed_config,
                             const std::map<std::string, std::string>& input_sha256);

// The state file (D/recipe-state.json): one record per stage.
struct StageRecord {
  std::string state = "pending";  // pending, running, done, failed
  std::string fingerprint;
  int64_t samples = 0;
  double wall_s = 0.0;  // over all attempts
  int attempts = 0;
  std::map<std::string, std::string> outputs;        // name -> path relative to D
  std::map<std::string, std::string> output_sha256;  // name -> SHA-256
  Json figures = Json::object();
  std::string error;  // the last failure: what and the log's last lines
  std::string started_at, finished_at;
  // Unix time the running attempt began (0 when none runs), so that status shows a running
  // stage's wall time while it runs.
  double attempt_started_unix = 0.0;
};

struct RecipeState {
  std::string recipe_path;
  std::string recipe_name;
  double scale = 1.0;
  std::map<std::string, StageRecord> stages;
};

Json ToJson(const StageRecord& r);
StageRecord StageRecordFromJson(const Json& j, const std::string& ctx);
Json ToJson(const RecipeState& s);
RecipeState RecipeStateFromJson(const Json& j, const std::string& ctx);
std::string StatePath(const std::string& dir);
// An absent file is an empty state; a corrupt one a ConfigError (never silently reset).
RecipeState LoadRecipeState(const std::string& dir);
void SaveRecipeState(const std::string& dir, const RecipeState& s);

// The stages that read `name`, directly or through other stages, in the recipe's order.
std::vector<std::string> StagesReading(const Recipe& r, const std::string& name);

// --extend: whether the composed config `next` continues a training run made under `prev` that
// has trained `samples` samples: continuing it trains what a fresh start under `next` would
// have (up to the run's own randomness). Only the budget (cluster.max_samples, at least `samples`)
// and the learning rate after `samples` (ppo.learning_rate with ppo.lr_schedule: equal at every
// sample count below `samples`) may differ. Returns "" when it continues, else what differs.
std::string ExtensionMismatch(const Json& prev, const Json& next, int64_t samples);

// Stages to be redone: those whose recorded fingerprint differs from `fingerprints` (done,
// running or failed ones with a record), and every later stage that depends on one of them,
// transitively. In stage order.
std::vector<std::string> InvalidatedStages(const Recipe& r, const RecipeState& s,
                                           const std::map<std::string, std::string>& fingerprints);

}  // namespace perch
