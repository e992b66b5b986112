// perch eval: evaluates a trained subtask policy (walk) over seeded episodes, optionally drawing a
// filmstrip; perch train-local: bounded in-process PPO on a task env (no cluster), for comparisons.
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "app/commands.h"
#include "envs/chair.h"
#include "learner/model_average.h"
#include "learner/service/checkpoint.h"
#include "tasks/local_train.h"
#include "tasks/task_env.h"
#include "tasks/walk_eval.h"
#include "viz/filmstrip.h"

namespace perch {
namespace {

// Command-line overrides of a task config; empty / negative: keep the file's value.
struct ConfigOverrides {
  std::string task = "walk";
  std::string config_path;  // empty: the task's defaults
  std::string stage, variant, action_mode;
  std::string start;  // "fixed" or "reference"
  double target_turn_prob = -1.0;
};

// Task config: the file's when given, else the task's defaults; then the command-line overrides.
TaskEnvConfig ResolveConfig(const ConfigOverrides& o) {
  const std::string& task = o.task;
  const std::string& config_path = o.config_path;
  TaskEnvConfig c =
      config_path.empty() ? TaskEnvConfig::Defaults(task) : TaskEnvConfig::Load(config_path);
  if (c.env.task != task) {
    throw ConfigError(config_path + ": task is \"" + c.env.task + "\", --task says \"" + task +
                      "\"");
  }
  Json j = c.ToJson();
  if (!o.stage.empty()) j["walk"]["stage"] = o.stage;
  if (!o.variant.empty()) {
    // The preset replaces the reward fields, so drop them before re-reading.
    Json& w = j["walk"];
    for (const char* k :
         {"similarity", "root_vel_weight", "root_vel_alpha", "target_weight", "target_k"}) {
      w.erase(k);
    }
    w["reward_variant"] = o.variant;
  }
  if (!o.action_mode.empty()) j["action_mode"] = o.action_mode;
  if (o.start == "reference") j["walk"]["reference_state_init"] = true;
  if (o.start == "fixed") j["walk"]["reference_state_init"] = false;
  if (o.target_turn_prob >= 0) j["walk"]["target_turn_prob"] = o.target_turn_prob;
  return TaskEnvConfig::FromJson(j, config_path.empty() ? "--task " + task : config_path);
}

}  // namespace

void RegisterEvalCommands(CLI::App& root, CLI::App& /*bench*/) {
  struct EvalOpts {
    ConfigOverrides cfg;
    std::string model, filmstrip;
    WalkEvalOptions eval;
    int frames = 6;
    int panel_px = 220;
    bool fixed_window = false;
    bool json = false;
  };
  auto o = std::make_shared<EvalOpts>();
  o->cfg.target_turn_prob = 0.0;  // eval measures the paper's targets, not a training curriculum
  CLI::App* cmd =
      root.add_subcommand("eval", "Evaluate a trained subtask policy over seeded episodes");
  cmd->add_option("--task", o->cfg.task, "task to evaluate")->check(CLI::IsMember({"walk"}));
  cmd->add_option("--model", o->model,
                  "policy file: serialized perch.proto.ModelWeights or LearnerState, or a PERCHCKP "
                  "cluster checkpoint")
      ->required();
  cmd->add_option("--config", o->cfg.config_path,
                  "task env config JSON, or an experiment / run config.json (its env section); "
                  "default: the task's defaults");
  cmd->add_option("--start", o->cfg.start,
                  "episode start override: fixed (the config's initial pose) or reference (a "
                  "random phase of the reference motion, the stage-1 training distribution)")
      ->check(CLI::IsMember({"fixed", "reference"}));
  cmd->add_option("--stage", o->cfg.stage, "walk stage override")
      ->check(CLI::IsMember({"forward", "target"}));
  cmd->add_option("--reward-variant", o->cfg.variant, "reward preset override")
      ->check(CLI::IsMember({"paper", "authors"}));
  cmd->add_option("--action-mode", o->cfg.action_mode, "action mode override")
      ->check(CLI::IsMember({"torque", "pd"}));
  cmd->add_option("--target-turn-prob", o->cfg.target_turn_prob,
                  "share of wide-angle target draws (walk.target_turn_prob); default 0: the "
                  "paper's targets, whatever curriculum the run's config trained with")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--episodes", o->eval.episodes, "number of episodes")
      ->check(CLI::Range(1, 1000000));
  cmd->add_option("--seed", o->eval.seed, "episode seed (episode e uses (seed, e))");
  cmd->add_flag("--stochastic", o->eval.stochastic,
                "sample actions instead of the Gaussian's mean");
  cmd->add_option("--no-fall-seconds", o->eval.no_fall_s, "no-fall window [s]")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--filmstrip", o->filmstrip, "draw episode 0 as a PNG filmstrip here");
  cmd->add_option("--frames", o->frames, "filmstrip frames")->check(CLI::Range(1, 64));
  cmd->add_option("--panel-px", o->panel_px, "filmstrip panel size [px]")
      ->check(CLI::Range(64, 1024));
  cmd->add_flag("--fixed-window", o->fixed_window,
                "one world window for all panels (default: each panel follows the humanoid)");
  cmd->add_flag("--json", o->json, "print one JSON object on stdout");
  cmd->callback([o]() {
    const TaskEnvConfig config = ResolveConfig(o->cfg);
    const proto::ModelWeights weights = LoadModelFile(o->model);
    WalkEvalRecording rec;
    std::cerr << "eval: " << o->model << " (version " << weights.version() << "), "
              << o->eval.episodes << " episodes, seed " << o->eval.seed << "\n";
    Json result = EvaluateWalk(config, weights, o->eval, o->filmstrip.empty() ? nullptr : &rec);
    result["model"] = o->model;
    result["config"] = config.ToJson();
    if (!o->filmstrip.empty()) {
      std::unique_ptr<Chair> chair;
      const std::string chair_path = config.env.ChairPath();
      if (!chair_path.empty()) chair = std::make_unique<Chair>(Chair::Load(chair_path));
      const HumanoidModel model = HumanoidModel::Load(config.env.HumanoidPath());
      FilmstripOptions fo;
      fo.panel_px = o->panel_px;
      fo.follow = !o->fixed_window;
      fo.targets = rec.targets;
      const Canvas c = RenderFilmstrip(model, chair.get(), config.env.chair_placement.Transform(),
                                       PickFrames(rec.frames, o->frames), fo);
      c.SavePng(o->filmstrip);
      result["filmstrip"] = o->filmstrip;
      std::cerr << "eval: filmstrip of episode 0 (" << rec.frames.size() << " frames) -> "
                << o->filmstrip << "\n";
    }
    if (o->json) {
      std::cout << result.dump() << "\n";
    } else {
      std::cout << "episodes " << result["episodes"] << ", no_fall_rate " << result["no_fall_rate"]
                << ", mean_imitation_reward " << result["mean_imitation_reward"]
                << ", mean_forward_speed_mps " << result["mean_forward_speed_mps"] << "\n";
    }
  });

  struct TrainOpts {
    ConfigOverrides cfg;
    LocalTrainOptions train;
    int steps_per_update = 0;
    bool json = false;
  };
  auto t = std::make_shared<TrainOpts>();
  CLI::App* tr = root.add_subcommand(
      "train-local", "Bounded in-process PPO on a task env (no cluster): weights + learning curve");
  tr->add_option("--task", t->cfg.task, "task")->check(CLI::IsMember({"walk", "stand"}));
  tr->add_option("--config", t->cfg.config_path,
                 "task env config JSON (default: the task's defaults)");
  tr->add_option("--stage", t->cfg.stage, "walk stage override")
      ->check(CLI::IsMember({"forward", "target"}));
  tr->add_option("--reward-variant", t->cfg.variant, "reward preset override")
      ->check(CLI::IsMember({"paper", "authors"}));
  tr->add_option("--action-mode", t->cfg.action_mode, "action mode override")
      ->check(CLI::IsMember({"torque", "pd"}));
  tr->add_option("--samples", t->train.samples, "env steps in total")->check(CLI::PositiveNumber);
  tr->add_option("--steps-per-update", t->steps_per_update, "PPO nsteps (default 8192)")
      ->check(CLI::Range(64, 1 << 20));
  tr->add_option("--seed", t->train.seed, "seed");
  tr->add_option("--out", t->train.out_dir, "output directory")->required();
  tr->add_flag("--json", t->json, "print one JSON summary on stdout");
  tr->callback([t]() {
    TaskEnvConfig config;
    if (t->cfg.task == "walk") {
      config = ResolveConfig(t->cfg);
    } else {
      config = t->cfg.config_path.empty() ? TaskEnvConfig::Defaults(t->cfg.task)
                                          : TaskEnvConfig::Load(t->cfg.config_path);
    }
    if (t->steps_per_update > 0) t->train.ppo.steps_per_update = t->steps_per_update;
    const Json summary = TrainLocal(config, t->train, [](const Json& row) {
      std::cerr << "train-local: " << row.dump() << "\n";
    });
    if (t->json) {
      std::cout << summary.dump() << "\n";
    } else {
      std::cout << "wrote " << summary["weights"] << " and " << summary["curve"] << "\n";
    }
  });
  struct AverageOpts {
    std::vector<std::string> models;
    std::string out;
    bool json = false;
  };
  auto a = std::make_shared<AverageOpts>();
  CLI::App* av = root.add_subcommand(
      "average-models",
      "Average the weights of policy snapshots of one run (Polyak/SWA) into one ModelWeights file");
  av->add_option("models", a->models, "policy files (ModelWeights, LearnerState or checkpoint)")
      ->required()
      ->expected(2, 1 << 16);
  av->add_option("--out", a->out, "output ModelWeights file (must not exist)")->required();
  av->add_flag("--json", a->json, "print one JSON summary on stdout");
  av->callback([a]() {
    // Never replace a saved model: a typo in --out must not cost a result.
    if (std::filesystem::exists(a->out)) throw ConfigError(a->out + ": exists; not overwritten");
    std::vector<proto::ModelWeights> ws;
    Json versions = Json::array();
    for (const std::string& m : a->models) {
      ws.push_back(LoadModelFile(m));
      versions.push_back(ws.back().version());
    }
    const proto::ModelWeights avg = AverageModels(ws);
    WriteFileAtomic(a->out, avg.SerializeAsString());
    Json summary = {{"out", a->out},
                    {"models", a->models},
                    {"versions", versions},
                    {"version", avg.version()},
                    {"num_params", avg.params_size()}};
    if (a->json) {
      std::cout << summary.dump() << "\n";
    } else {
      std::cout << "wrote " << a->out << " (mean of " << ws.size() << " models)\n";
    }
  });
}

}  // namespace perch
