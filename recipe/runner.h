// perch recipe run / status (issue 48): runs a recipe's stages as child `perch` processes in a
// directory D, records each stage's state, outputs (with SHA-256) and figures in
// D/recipe-state.json, and resumes where it stopped. docs/recipe.md.
#pragma once

#include <atomic>
#include <string>

#include "common/json_util.h"
#include "recipe/recipe.h"

namespace perch {

struct RecipeRunFlags {
  std::string recipe;  // the recipe file
  std::string dir;     // D
  RecipeRunOptions options;
  std::string from, until;  // run only these stages (inclusive); earlier ones must be done
  std::string force_from;   // accept: this stage and every later one that ran are redone
  // Accept a training stage's larger budget (and learning rates past what it trained): it
  // continues from its newest checkpoint; the stages that read it are redone.
  std::string extend;
  // Take the stages (up to --until) another directory of the same recipe finished with the same
  // definition and inputs (the same fingerprint: a second seed's directory, a variant's): their
  // files are copied in, their records kept (figures.adopted_from), and they do not run here.
  std::string adopt_from;
  int parallel = 1;          // independent stages run side by side
  double progress_s = 10.0;  // console progress period
  std::string exe;           // the perch program (default: this one)
  // A cluster (k8s/recipe.yaml): each training stage runs `perch learner` on these addresses
  // (actors elsewhere follow it without files: `perch actor` without --config) plus
  // options.actors local actors of the same kind; keys from PERCH_KEYS_DIR.
  bool cluster = false;
  bool check = false;  // validate the recipe and D's state, print the plan, run nothing
  std::string bind = "0.0.0.0";
  int rollout_port = 5555, weights_port = 5556, metrics_port = 9100;
  std::atomic<bool>* stop = nullptr;  // set by a signal: stop children, keep what is saved
  // Sharded eval stages: 1, the runner takes shards itself as well; 0, only `perch recipe
  // worker` processes do (on other machines sharing D).
  int local_shards = 1;
};

// `perch recipe worker --dir D`: takes the shards of D's sharded eval stages while they run
// (a shard claimed by a file in the stage's shards/, touched while it runs; a stale claim is
// taken over), runs each with its perch eval, and exits after exit_when_idle_s with nothing to
// do (0: never). Returns 0, or 130 when stopped.
struct RecipeWorkerFlags {
  std::string dir;
  double exit_when_idle_s = 0.0;
  std::string exe;  // the perch program (default: this one)
  std::atomic<bool>* stop = nullptr;
};
int RunRecipeWorker(const RecipeWorkerFlags& f);

// Returns the exit code: 0 all stages in range done, 1 a stage failed (named on stderr with its
// log's last lines), 130 stopped by a signal. ConfigError for a bad recipe, a changed stage
// config without --force-from, or outputs that changed on disk.
int RunRecipe(const RecipeRunFlags& f);

// The status of D: {"name", "dir", "runner_alive", "stages": [{name, kind, state, samples,
// wall_s, outputs, figures, chosen, error}], "total_samples", "total_wall_s"}. A running stage
// shows its live sample count.
Json RecipeStatus(const std::string& dir);
std::string RecipeStatusText(const Json& status);

}  // namespace perch
