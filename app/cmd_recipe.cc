// perch recipe run / status / worker: a training recipe from an empty directory to a delivered
// hierarchy (recipe/runner.h, docs/recipe.md).
#include <atomic>
#include <iostream>
#include <memory>

#include "app/commands.h"
#include "common/stop_signal.h"
#include "recipe/runner.h"

namespace perch {

namespace {

void RegisterRecipeRun(CLI::App* recipe) {
  auto f = std::make_shared<RecipeRunFlags>();
  CLI::App* run = recipe->add_subcommand(
      "run", "Run a recipe's stages in order in --dir; run again to continue after a stop");
  run->add_option("recipe", f->recipe, "the recipe file (recipes/sit_chair.json)")->required();
  run->add_option("--dir", f->dir, "the recipe's directory (state file, stages' outputs)")
      ->required();
  run->add_option("--actors", f->options.actors, "actor processes per training stage");
  run->add_option("--from", f->from, "first stage to run (earlier ones must be done)");
  run->add_option("--until", f->until, "last stage to run");
  run->add_option("--force-from", f->force_from,
                  "redo this stage and the stages that read it, transitively (their files move "
                  "to DIR/superseded/): accepts a changed stage");
  run->add_option("--extend", f->extend,
                  "accept a training stage's larger budget (cluster.max_samples; learning rates "
                  "past the samples it trained may change too): it continues from its newest "
                  "checkpoint, and the stages that read it are redone (files to DIR/superseded/); "
                  "with its budget unchanged, a changed select: its checkpoint is chosen again");
  run->add_option("--adopt-from", f->adopt_from,
                  "take the stages another directory of this recipe finished with the same "
                  "definition and inputs (a second seed's, a variant's): copied in, not run");
  run->add_option("--set", f->options.sets,
                  "override a field of every stage's config: section.field=VALUE (repeatable)");
  run->add_option("--scale", f->options.scale,
                  "multiply every sample budget, episode, trial and state count by F (floors: one "
                  "update, a few episodes); 0.0001 is a toy run");
  run->add_option("--parallel", f->parallel, "independent stages run side by side, at most N");
  run->add_option("--progress-s", f->progress_s, "seconds between progress lines");
  run->add_flag("--cluster", f->cluster,
                "training stages run `perch learner` on --bind:5555/5556 (metrics :9100); actors "
                "elsewhere join each stage with `perch actor --learner-host H` and no config; "
                "--actors local ones join too (k8s/recipe.yaml)");
  run->add_option("--bind", f->bind, "--cluster: the learner's interface");
  run->add_option("--rollout-port", f->rollout_port, "--cluster: rollout port");
  run->add_option("--weights-port", f->weights_port, "--cluster: weights port");
  run->add_option("--metrics-port", f->metrics_port, "--cluster: Prometheus port");
  run->add_option("--local-shards", f->local_shards,
                  "sharded eval stages: 1, this runner runs shards too; 0, only `perch recipe "
                  "worker` processes sharing --dir do")
      ->check(CLI::Range(0, 1));
  run->add_flag("--check-config", f->check,
                "read the recipe and the state, say what would run, and exit (manifest checks)");
  run->callback([f] {
    InstallStopHandlers();
    f->stop = &StopFlag();
    const int code = RunRecipe(*f);
    if (code != 0) std::exit(code);
  });
}

void RegisterRecipeWorker(CLI::App* recipe) {
  auto w = std::make_shared<RecipeWorkerFlags>();
  auto w_check = std::make_shared<bool>(false);
  CLI::App* worker = recipe->add_subcommand(
      "worker",
      "Take the shards of the sharded evaluation stages of a recipe running in --dir (another "
      "machine sharing the directory; k8s/recipe-eval-workers.yaml)");
  worker->add_option("--dir", w->dir, "the recipe's directory (shared)")->required();
  worker
      ->add_option("--exit-when-idle-s", w->exit_when_idle_s,
                   "exit after this many seconds without a shard to run (0: never)")
      ->check(CLI::NonNegativeNumber);
  worker->add_flag("--check-config", *w_check, "check the flags and exit (manifest checks)");
  worker->callback([w, w_check] {
    if (*w_check) {
      std::cerr << "perch recipe worker: OK (--dir " << w->dir << ")\n";
      return;
    }
    InstallStopHandlers();
    w->stop = &StopFlag();
    const int code = RunRecipeWorker(*w);
    if (code != 0) std::exit(code);
  });
}

void RegisterRecipeStatus(CLI::App* recipe) {
  auto dir = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  CLI::App* status = recipe->add_subcommand(
      "status", "Each stage's state, samples, wall time, chosen checkpoint and figures");
  status->add_option("--dir", *dir, "the recipe's directory")->required();
  status->add_flag("--json", *json, "print one JSON object");
  status->callback([dir, json] {
    const Json s = RecipeStatus(*dir);
    if (*json) {
      std::cout << s.dump() << "\n";
    } else {
      std::cout << RecipeStatusText(s);
    }
  });
}

void RegisterRecipeFields(CLI::App* recipe) {
  auto json = std::make_shared<bool>(false);
  CLI::App* fields = recipe->add_subcommand(
      "fields", "A recipe stage's fields: name, default, range, doc (docs/recipe.md)");
  fields->add_flag("--json", *json, "print the table as JSON");
  fields->callback([json] { std::cout << RecipeFieldsText(*json); });
}

}  // namespace

void RegisterRecipeCommands(CLI::App& root, CLI::App& /*bench*/) {
  CLI::App* recipe = root.add_subcommand("recipe", "Training recipes: every stage in one command");
  recipe->require_subcommand(1);
  RegisterRecipeRun(recipe);
  RegisterRecipeWorker(recipe);
  RegisterRecipeStatus(recipe);
  RegisterRecipeFields(recipe);
}

}  // namespace perch
