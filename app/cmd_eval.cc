// perch eval: evaluates a trained subtask policy (any registered task) over seeded episodes,
// optionally drawing a filmstrip; perch train-local: bounded in-process PPO on a task env (no
// cluster), for comparisons.
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "app/commands.h"
#include "common/paths.h"
#include "envs/chair.h"
#include "learner/model_average.h"
#include "learner/policy.h"
#include "learner/service/checkpoint.h"
#include "tasks/hierarchy.h"
#include "tasks/local_train.h"
#include "tasks/meta_env.h"
#include "tasks/meta_eval.h"
#include "tasks/meta_expert.h"
#include "tasks/model_source.h"
#include "tasks/registry.h"
#include "tasks/state_bank.h"
#include "tasks/task_env.h"
#include "tasks/task_eval.h"
#include "tasks/walk_eval.h"
#include "viz/filmstrip.h"

namespace perch {
namespace {

// Command-line overrides of a task config; empty / negative: keep the file's value.
struct ConfigOverrides {
  std::string task;         // empty: the config's task
  std::string config_path;  // empty: the model's saved config, else the task's defaults
  std::string stage, variant, action_mode, chair;
  std::string start;               // "fixed", "reference" or "end-poses"
  std::vector<std::string> banks;  // --start end-poses: the start-state banks
  std::string bank_ang_vel;        // "keep" / "zero": the bank state's torso angular velocity
  double target_turn_prob = -1.0;
  double start_noise = 0.02;  // turn / sit: start_joint_noise_rad for evaluation [rad]
};

// Whether any of a meta policy's lookahead fields (the --lookahead-* flags) is off its default.
bool SetsLookahead(const PlannerConfig& c) {
  return c.lookahead() || c.lookahead_rank != PlannerConfig().lookahead_rank ||
         !c.lookahead_detour_deg.empty();
}

// `perch eval --lookahead FILE`: a meta policy's lookahead from a JSON object of the
// --lookahead-* flags' fields (as in sit_chair.meta.planner), instead of the flags (`flags`, which
// must then be at their defaults). ConfigError naming the file and the key otherwise.
PlannerConfig LookaheadFromFile(const std::string& path, const PlannerConfig& flags) {
  if (SetsLookahead(flags)) {
    throw ConfigError("--lookahead " + path +
                      ": not with --lookahead-delays-s / --lookahead-sides / "
                      "--lookahead-straight-s / --lookahead-detour-deg / --lookahead-rank (the "
                      "file holds them)");
  }
  const Json j = LoadJsonFile(path);
  if (!j.is_object()) throw ConfigError(path + ": not a JSON object");
  static const std::set<std::string> kKeys = {"lookahead_delays_s", "lookahead_sides",
                                              "lookahead_straight_s", "lookahead_detour_deg",
                                              "lookahead_rank"};
  for (const auto& [k, v] : j.items()) {
    if (kKeys.count(k) == 0) {
      throw ConfigError(path + ": \"" + k +
                        "\" is not a lookahead field (lookahead_delays_s, lookahead_sides, "
                        "lookahead_straight_s, lookahead_detour_deg, lookahead_rank)");
    }
  }
  // The planner config's own checks (types, ranges, at most 8 times, a detour needs its times);
  // with only lookahead keys, every other field keeps its default, as with the flags.
  PlannerConfig file = PlannerConfig::FromJson(j, path);
  if (!file.lookahead()) {
    throw ConfigError(path +
                      ": no lookahead (lookahead_delays_s, lookahead_sides or "
                      "lookahead_straight_s)");
  }
  return file;
}

// Task config: --config's, else the model's saved one, else the task's defaults; then the
// command-line overrides. Warns when --config's task section differs from the saved one.
TaskEnvConfig ResolveConfig(const ConfigOverrides& o, const std::string& model_path) {
  const Json saved = model_path.empty() ? Json() : SavedConfig(model_path);
  auto env_of = [](const Json& j) { return j.is_object() && j.contains("env") ? j["env"] : j; };
  Json j;
  std::string ctx;
  if (!o.config_path.empty()) {
    j = TaskEnvConfig::Load(o.config_path).ToJson();
    ctx = o.config_path;
    if (saved.is_object()) {
      const Json s = TaskEnvConfig::FromJson(env_of(saved), model_path + " (saved)").ToJson();
      const std::string t = s.value("task", "");
      if (s.value("task", "") != j.value("task", "") || (s.contains(t) && s[t] != j[t])) {
        std::cerr << "eval: warning: --config " << o.config_path << " differs from the config "
                  << "saved with " << model_path << " in the task section (\"" << t
                  << "\"); using --config\n";
      }
    }
  } else if (saved.is_object()) {
    j = TaskEnvConfig::FromJson(env_of(saved), model_path + " (saved config)").ToJson();
    ctx = model_path + " (saved config)";
  } else {
    if (o.task.empty()) {
      throw ConfigError("--task: required when neither --config nor the model carries a config");
    }
    j = TaskEnvConfig::Defaults(o.task).ToJson();
    ctx = "--task " + o.task;
  }
  const std::string task = j["task"].get<std::string>();
  if (!o.task.empty() && task != o.task) {
    throw ConfigError(ctx + ": task is \"" + task + "\", --task says \"" + o.task + "\"");
  }
  Json& sec = j[task == "stand" ? "walk" : task];
  if (task == "walk") {
    if (!o.stage.empty()) sec["stage"] = o.stage;
    if (o.start == "reference") sec["reference_state_init"] = true;
    if (o.start == "fixed") sec["reference_state_init"] = false;
    if (o.target_turn_prob >= 0) sec["target_turn_prob"] = o.target_turn_prob;
  } else if (!o.stage.empty() || o.target_turn_prob > 0) {
    throw ConfigError("--stage / --target-turn-prob: only for --task walk");
  }
  if (task == "sit") {
    // Evaluation starts from the clip's first frame (Table 4), unless asked otherwise.
    sec["reference_state_init"] = o.start == "reference";
  }
  if (task == "turn_left" || task == "turn_right" || task == "sit") {
    sec["start_joint_noise_rad"] = o.start_noise;
  }
  if ((task == "turn_left" || task == "turn_right") && o.start != "reference") {
    sec["rsi_prob"] = 0.0;  // evaluation starts turns at frame 0 (Table 4)
  }
  if (o.start == "end-poses") {
    if (o.banks.empty()) throw ConfigError("--start end-poses: needs --bank FILE");
    if (task != "turn_left" && task != "turn_right" && task != "sit" && task != "walk") {
      throw ConfigError("--start end-poses: only for walk, turn_left, turn_right and sit");
    }
    // Keeps the config's other start settings (zero_root_ang_vel).
    if (!sec.contains("start") || !sec["start"].is_object()) sec["start"] = Json::object();
    sec["start"]["banks"] = o.banks;
    sec["start"]["prob"] = 1.0;
    if (!o.bank_ang_vel.empty()) sec["start"]["zero_root_ang_vel"] = o.bank_ang_vel == "zero";
  } else if (!o.banks.empty() || !o.bank_ang_vel.empty()) {
    throw ConfigError("--bank / --bank-ang-vel: only with --start end-poses");
  } else if (task != "stand" && sec.contains("start")) {
    // A fine-tuned policy is evaluated from its clip's first frame unless asked otherwise, as
    // the subtask itself is: without the banks' placement noise (sit applies it to every
    // episode of a run that lists banks), so the retention figure compares like with like.
    sec["start"]["prob"] = 0.0;
    sec["start"]["banks"] = Json::array();
  }
  if (!o.variant.empty()) {
    // The preset replaces the reward fields, so drop them before re-reading.
    for (const char* k : {"similarity", "root_vel_weight", "root_vel_alpha", "target_weight",
                          "target_k", "rot_weight", "rot_alpha", "hold_phase", "approach_weight"}) {
      sec.erase(k);
    }
    sec["reward_variant"] = o.variant;
  }
  if (!o.action_mode.empty()) j["action_mode"] = o.action_mode;
  if (!o.chair.empty() && o.chair != "all") j["chair"] = o.chair;
  // Evaluation measures the chair asked for, not a training distribution of chairs.
  if (j.contains("chair_random")) j["chair_random"]["prob"] = 0.0;
  if (task == "stand") j.erase("walk");
  return TaskEnvConfig::FromJson(j, ctx);
}

// Hand-overs (a chain's to sit, or the meta env's to any subtask) as a start-state bank for that
// subtask's start.banks.
void WriteSitStartBank(const std::string& file, const std::string& task,
                       const TaskEnvConfig& config, const std::string& model_path,
                       const EvalOptions& eval, int episodes_run,
                       std::vector<proto::BankState>& states, bool force) {
  const HumanoidModel model = HumanoidModel::Load(config.env.HumanoidPath());
  proto::StateBank bank = NewStateBank(task, model, eval.seed, eval.stochastic, config.ToJson());
  bank.set_model_path(model_path);
  bank.set_count(static_cast<int>(states.size()));
  bank.set_episodes_run(episodes_run);
  for (proto::BankState& b : states) *bank.add_states() = std::move(b);
  WriteStateBank(file, bank, force);
}

std::vector<std::string> EvalTaskNames() {
  std::vector<std::string> names = TaskNames();
  names.push_back("chain");  // the scripted walk -> turn -> sit chain (tasks/hierarchy.h)
  return names;
}

struct ChainFlags {
  int zone = 1;
  std::array<std::string, kNumSubtasks> models = {
      "models/turn_left/policy.bin", "models/turn_right/policy.bin", "models/sit/policy.bin",
      "models/walk_stage2_fallrestart/checkpoints/ckpt-0000013900.bin"};
  ChainOptions options;
  std::string save_sit_starts;  // --chain-save-sit-starts: a bank of the states at the switch
};

}  // namespace

void RegisterEvalCommands(CLI::App& root, CLI::App& /*bench*/) {
  struct EvalOpts {
    ConfigOverrides cfg;
    std::string model, filmstrip, record;
    int record_episodes = 0;
    bool force = false;
    EvalOptions eval;
    int frames = 6;
    int panel_px = 220;
    bool fixed_window = false;
    bool json = false;
    int trials = 0;
    std::string matrix_png;
    bool planner = false;         // sit_chair: the scripted planner decides (no --model)
    std::string save_sit_starts;  // sit_chair: a bank of the states at every hand-over to sit
    std::string save_failed_sit_starts;        // ... of the trials that failed
    std::string hand_overs_to = "sit";         // sit_chair: whose hand-overs those banks hold
    std::vector<double> lookahead_delays_s;    // sit_chair with a meta policy: its lookahead
    bool lookahead_sides = false;              // ... with the other turn at each turn switch
    std::vector<double> lookahead_straight_s;  // ... with straight-on starts [s]
    std::vector<double> lookahead_detour_deg;  // ... and detours [deg]
    std::string lookahead_rank = "sooner";     // ... and how it ranks two successes
    std::string lookahead_file;  // ... or all of them from a JSON file (configs/lookahead/)
    bool record_routes = false;  // ... and each start route's outcome in the records
    std::string start_bank = "data/banks/walk_end_poses_eval.bin";  // sit_chair: walk starts
    std::string records;  // sit_chair: per-trial records, appended as trials finish (resumes)
    int first_trial = 0;  // sit_chair: a shard's first trial
    int threads = std::max(1u, std::thread::hardware_concurrency());
  };
  auto o = std::make_shared<EvalOpts>();
  o->cfg.target_turn_prob = 0.0;  // eval measures the paper's targets, not a training curriculum
  CLI::App* cmd =
      root.add_subcommand("eval", "Evaluate a trained subtask policy over seeded episodes");
  cmd->add_option("--task", o->cfg.task,
                  "task to evaluate (default: the task of the model's saved config)")
      ->check(CLI::IsMember(EvalTaskNames()));
  cmd->add_option("--model", o->model,
                  "policy: a PERCHCKP cluster checkpoint (carries its config), a run dir (its "
                  "newest checkpoint and config.json), or a ModelWeights / LearnerState file "
                  "(required but for --task chain)");
  cmd->add_option("--config", o->cfg.config_path,
                  "task env config JSON, or an experiment / run config.json (its env section); "
                  "default: the config saved with the model, else the task's defaults");
  cmd->add_option("--chair", o->cfg.chair,
                  "chair override: a preset in data/chairs/ (authors, armchair, ...), a chair "
                  "JSON file, or all (every preset, one result each)");
  cmd->add_option("--start", o->cfg.start,
                  "episode start override: fixed (the config's initial pose / the clip's first "
                  "frame), reference (a random phase of the reference motion) or end-poses "
                  "(states of --bank, e.g. walk end poses for a turn)")
      ->check(CLI::IsMember({"fixed", "reference", "end-poses"}));
  cmd->add_option("--start-noise", o->cfg.start_noise,
                  "turn / sit: joint angles of the start pose += U(-x, x) rad, so episodes are "
                  "distinct trials (0: every mean-action episode is the same)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.5));
  cmd->add_option("--bank", o->cfg.banks,
                  "start-state bank(s) for --start end-poses (perch sample-end-poses); several: "
                  "their union");
  cmd->add_option("--bank-ang-vel", o->cfg.bank_ang_vel,
                  "--start end-poses: the bank state's torso angular velocity, keep (ours) or zero "
                  "(the authors restore into a freshly loaded humanoid); default: the config's")
      ->check(CLI::IsMember({"keep", "zero"}));
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
  cmd->add_option("--no-fall-seconds", o->eval.no_fall_s, "walk: no-fall window [s]")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--filmstrip", o->filmstrip, "draw episode 0 as a PNG filmstrip here");
  cmd->add_option("--frames", o->frames, "filmstrip frames")->check(CLI::Range(1, 64));
  cmd->add_option("--panel-px", o->panel_px, "filmstrip panel size [px]")
      ->check(CLI::Range(64, 1024));
  cmd->add_flag("--fixed-window", o->fixed_window,
                "one world window for all panels (default: each panel follows the humanoid)");
  cmd->add_option("--record", o->record,
                  "write the episodes as a recording (docs/recording.md) for perch view and "
                  "perch export-bvh");
  cmd->add_option("--record-episodes", o->record_episodes,
                  "record only the first K episodes (0: all)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1000000));
  cmd->add_flag(
      "--force", o->force,
      "overwrite an existing --record, --chain-save-sit-starts or --save-sit-starts file");
  cmd->add_flag("--json", o->json, "print one JSON object on stdout");
  cmd->add_option("--trials", o->trials,
                  "sit_chair (the meta controller): number of trials (default: --episodes)")
      ->check(CLI::Range(1, 10000000));
  cmd->add_flag("--planner", o->planner,
                "sit_chair: the scripted planner of the config's sit_chair.meta.planner decides "
                "instead of a meta policy (tasks/meta_expert.h); needs --config, no --model");
  cmd->add_option("--matrix-png", o->matrix_png,
                  "sit_chair: draw the subtask transition matrices (per start side) here");
  cmd->add_option("--records", o->records,
                  "sit_chair: append each trial's outcome to this JSON-lines file as it finishes; "
                  "when it exists (same model, config, seed and flags), its trials are not run "
                  "again: a long evaluation resumes where it stopped (docs/meta.md)");
  cmd->add_option("--first-trial", o->first_trial,
                  "sit_chair: run trials K .. K + --trials - 1 (a shard; trial i is the same "
                  "trial in every shard; perch eval-merge joins shards' --records)")
      ->check(CLI::Range(0, 100000000));
  cmd->add_option("--threads", o->threads, "sit_chair: threads (default: all cores)")
      ->check(CLI::Range(1, 1024));
  cmd->add_option("--save-sit-starts", o->save_sit_starts,
                  "sit_chair: write the full state at every hand-over to sit as a start-state "
                  "bank (with the chair; for sit's start.keep_pose)");
  cmd->add_option("--save-failed-sit-starts", o->save_failed_sit_starts,
                  "sit_chair: the same for the hand-overs of the trials that failed only (listed "
                  "beside the full bank, they weigh the failures twice)");
  cmd->add_option("--hand-overs-to", o->hand_overs_to,
                  "sit_chair: whose hand-overs --save-sit-starts and --save-failed-sit-starts "
                  "write (sit, turn_left, turn_right or walk; a turn's or the walk's bank is for "
                  "its start.banks; the episode's first run is not a hand-over)")
      ->capture_default_str();
  cmd->add_option("--lookahead-delays-s", o->lookahead_delays_s,
                  "sit_chair with a meta policy: at each of its switches also simulate the switch "
                  "delayed by each of these times to the episode's end and take the best "
                  "(tasks/meta_lookahead.h; the planner's lookahead is in its config) [s]")
      ->check(CLI::Range(0.001, 3.0));
  cmd->add_flag("--lookahead-sides", o->lookahead_sides,
                "sit_chair with a meta policy: at each of its switches into a turn also simulate "
                "the other turn (tasks/meta_lookahead.h)");
  cmd->add_option("--lookahead-straight-s", o->lookahead_straight_s,
                  "sit_chair with a meta policy: at its first step also simulate the walker "
                  "walking straight on for each of these times before the policy steers [s]")
      ->check(CLI::Range(0.001, 3.0));
  cmd->add_option("--lookahead-detour-deg", o->lookahead_detour_deg,
                  "sit_chair with a meta policy and --lookahead-straight-s: each start also with "
                  "the walker heading this far off its facing (+ left), e.g. round the chair [deg]")
      ->check(CLI::Range(-180.0, 180.0));
  cmd->add_option("--lookahead-rank", o->lookahead_rank,
                  "sit_chair with a meta policy's lookahead: which of two successful "
                  "outcomes is better, the sooner or the nearer (smaller minimum pelvis - seat "
                  "distance); the planner's is its config's lookahead_rank")
      ->check(CLI::IsMember({"sooner", "nearer"}))
      ->capture_default_str();
  cmd->add_option("--lookahead", o->lookahead_file,
                  "sit_chair with a meta policy: its lookahead from this JSON file, whose keys "
                  "are those of the --lookahead-* flags as in sit_chair.meta.planner "
                  "(lookahead_delays_s, lookahead_sides, lookahead_straight_s, "
                  "lookahead_detour_deg, lookahead_rank), e.g. configs/lookahead/8x3.json; "
                  "instead of the flags");
  cmd->add_flag("--record-routes", o->record_routes,
                "sit_chair with --records and a lookahead with straight-on starts: each record "
                "also holds the start observation and the outcome of every start route tried "
                "(data for learning the start route)");
  cmd->add_option("--start-bank", o->start_bank,
                  "sit_chair: the walk start states (default: the evaluation bank; name the "
                  "training bank when sampling hand-overs to train on)")
      ->capture_default_str();
  auto chain = std::make_shared<ChainFlags>();
  cmd->add_option("--zone", chain->zone,
                  "chain and sit_chair: spawn zone (1 easy, 2 lateral, 3 rear)")
      ->capture_default_str()
      ->check(CLI::Range(1, 3));
  cmd->add_option("--chain-approach-m", chain->options.approach_dist_m,
                  "chain: the walk target's distance in front of the seat [m]")
      ->capture_default_str();
  cmd->add_option("--chain-reach-m", chain->options.reach_m,
                  "chain: walk -> turn when this close to the walk target [m]")
      ->capture_default_str()
      ->check(CLI::Range(0.01, 5.0));
  cmd->add_option("--chain-turn-s", chain->options.turn_s, "chain: turn -> sit after this long [s]")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 10.0));
  cmd->add_option("--chain-sit-yaw-deg", chain->options.sit_yaw_deg,
                  "chain: also turn -> sit once the heading is within this of the chair's facing "
                  "direction (0: time only) [deg]")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 90.0));
  cmd->add_option("--chain-save-sit-starts", chain->save_sit_starts,
                  "chain: write the full state at every switch to sit as a start-state bank "
                  "(with the chair; for sit's start.keep_pose)");
  cmd->add_flag("--chain-stop-at-sit", chain->options.stop_at_sit,
                "chain: end each episode at the switch to sit (sampling sit starts only)");
  cmd->add_flag("--chain-plan", chain->options.plan,
                "chain: the planned hand-over (walk so that the turn ends where the sit's clip "
                "starts; tasks/chain_plan.h)");
  cmd->add_option("--chain-plan-reach-m", chain->options.planner.reach_m,
                  "chain plan: hand over when the predicted turn end is this close [m]")
      ->check(CLI::Range(0.0, 2.0));
  cmd->add_option("--chain-plan-pass-m", chain->options.planner.pass_m,
                  "chain plan: or at the closest approach within this [m]")
      ->check(CLI::Range(0.0, 3.0));
  cmd->add_option("--chain-plan-lookahead-m", chain->options.planner.lookahead_m,
                  "chain plan: the walk target is never nearer than this [m]")
      ->check(CLI::Range(0.0, 5.0));
  cmd->add_option("--chain-plan-aim-m", chain->options.planner.aim_m,
                  "chain plan: aim the turn's end this far from the sit clip's start (along the "
                  "chair's facing, across to its left) [m]");
  cmd->add_option("--chain-plan-approach-deg", chain->options.planner.approach_deg,
                  "chain plan: approach the turn along a line at this angle to the sit's facing "
                  "(90: past the chair's front; < 0: off) [deg]")
      ->check(CLI::Range(-1.0, 90.0));
  cmd->add_option("--chain-plan-regress", chain->options.planner.regress_start_state,
                  "chain plan: predict the turn's path from its start state (true) or use the "
                  "mean path (false)");
  cmd->add_option("--chain-plan-calibration-runs", chain->options.planner.calibration_runs,
                  "chain plan: turn runs measured to learn each turn's path")
      ->check(CLI::Range(1, 1000));
  cmd->add_option("--chain-decision-period", chain->options.decision_period,
                  "chain: switch (and move the walk target) only every this many control steps "
                  "(30: a meta controller's 2 Hz)")
      ->check(CLI::Range(1, 990));
  cmd->add_option("--chain-side", chain->options.side,
                  "chain: which turn (short: the short way round to the chair's facing)")
      ->capture_default_str()
      ->check(CLI::IsMember({"short", "left", "right"}));
  for (int id = 0; id < kNumSubtasks; ++id) {
    const std::string flag = std::string("--") + SubtaskName(id) + "-model";
    std::string dashed = flag;
    std::replace(dashed.begin(), dashed.end(), '_', '-');
    cmd->add_option(dashed, chain->models[id],
                    std::string("chain: the ") + SubtaskName(id) + " policy")
        ->capture_default_str();
  }
  cmd->callback([o, chain]() {
    // --record: checked before the (long) evaluation, written after it.
    std::unique_ptr<EpisodeRecorder> recorder;
    if (!o->record.empty()) {
      if (o->cfg.chair == "all") throw ConfigError("--record: not with --chair all");
      if (!o->force && std::filesystem::exists(o->record)) {
        throw ConfigError("--record " + o->record + ": exists; not overwritten (--force)");
      }
      recorder = std::make_unique<EpisodeRecorder>(o->record_episodes);
      o->eval.recorder = recorder.get();
      chain->options.recorder = recorder.get();
    }
    auto write_recording = [&](const std::string& task, const std::string& model,
                               const Json& config) {
      if (!recorder) return;
      proto::Recording& r = recorder->recording();
      r.set_task(task);
      r.set_model(model);
      r.set_config_json(config.dump());
      r.set_seed(o->eval.seed);
      r.set_stochastic(o->eval.stochastic);
      r.set_perch_version(PerchVersion());
      WriteRecording(o->record, r, o->force);
      std::cerr << "eval: recording of " << r.episodes_size() << " episodes -> " << o->record
                << "\n";
    };
    if (o->cfg.task == "chain") {
      // The scripted chain: four subtask policies on the sit_chair env, no meta policy.
      Json env{{"task", "sit_chair"},
               {"chair", o->cfg.chair.empty() ? "authors" : o->cfg.chair},
               {"spawn", {{"zone", chain->zone}}}};
      if (!o->cfg.config_path.empty()) {
        env = TaskEnvConfig::Load(o->cfg.config_path).ToJson();
        env["spawn"]["zone"] = chain->zone;
      }
      const TaskEnvConfig config = TaskEnvConfig::FromJson(env, "--task chain");
      std::array<proto::ModelWeights, kNumSubtasks> models;
      std::array<std::string, kNumSubtasks> files;
      std::array<Json, kNumSubtasks> saved;
      for (int id = 0; id < kNumSubtasks; ++id) {
        files[id] = ModelFile(ResolveProjectPath(chain->models[id]));
        models[id] = LoadModelFile(files[id]);
        saved[id] = SavedConfig(ResolveProjectPath(chain->models[id]));
      }
      chain->options.episodes = o->eval.episodes;
      chain->options.seed = o->eval.seed;
      chain->options.stochastic = o->eval.stochastic;
      std::vector<proto::BankState> sit_starts;
      if (!chain->save_sit_starts.empty()) {
        // Refuse before the work, as the bank writer would after it.
        if (std::filesystem::exists(chain->save_sit_starts) && !o->force) {
          throw ConfigError("--chain-save-sit-starts " + chain->save_sit_starts +
                            ": exists (--force replaces it)");
        }
        chain->options.sit_starts = &sit_starts;
      }
      std::vector<PoseFrame> frames;
      Json result = EvaluateChain(config, models, files, saved, chain->options,
                                  o->filmstrip.empty() ? nullptr : &frames);
      if (!chain->save_sit_starts.empty()) {
        if (sit_starts.empty())
          throw ConfigError("--chain-save-sit-starts: no episode reached sit");
        const int n = static_cast<int>(sit_starts.size());
        WriteSitStartBank(chain->save_sit_starts, "chain", config,
                          files[kWalk] + "," + files[kLeftTurn] + "," + files[kRightTurn], o->eval,
                          o->eval.episodes, sit_starts, o->force);
        result["sit_starts"] = {{"file", chain->save_sit_starts}, {"states", n}};
      }
      std::string all_models;
      for (const std::string& f : files) all_models += (all_models.empty() ? "" : ",") + f;
      write_recording("chain", all_models, config.ToJson());
      if (!o->filmstrip.empty()) {
        const Chair chair = Chair::Load(config.env.ChairPath());
        const HumanoidModel model = HumanoidModel::Load(config.env.HumanoidPath());
        FilmstripOptions fo;
        fo.panel_px = o->panel_px;
        fo.follow = !o->fixed_window;
        RenderFilmstrip(model, &chair, config.env.chair_placement.Transform(),
                        PickFrames(frames, o->frames), fo)
            .SavePng(o->filmstrip);
        result["filmstrip"] = o->filmstrip;
      }
      if (o->json) {
        std::cout << result.dump() << "\n";
      } else {
        std::cout << "chain zone " << chain->zone << ": success_rate " << result["success_rate"]
                  << " " << result["success_ci95"].dump() << ", min_dist "
                  << result["min_dist_mean_m"] << " +- " << result["min_dist_std_m"] << " m\n";
      }
      return;
    }
    if (o->planner && (!o->model.empty() || o->cfg.config_path.empty())) {
      throw ConfigError("--planner: needs --config (the sit_chair experiment) and no --model");
    }
    if (o->model.empty() && !o->planner) {
      throw ConfigError("--model: required (but for --task chain and --planner)");
    }
    const TaskEnvConfig config = ResolveConfig(o->cfg, o->model);
    if (o->planner && config.env.task != "sit_chair") {
      throw ConfigError("--planner: only for the sit_chair task, the config's is \"" +
                        config.env.task + "\"");
    }
    if (config.env.task == "sit_chair") {
      if (o->cfg.chair == "all" &&
          (!o->filmstrip.empty() || !o->matrix_png.empty() || !o->records.empty())) {
        throw ConfigError(
            "--filmstrip / --matrix-png / --records: not with --chair all (name one chair)");
      }
      // The meta controller on the main task: the authors' zones as defined (whatever spawn the
      // run trained with), walk start states from the evaluation bank (docs/meta.md). The
      // planner is measured on each chair (where the sit's clip starts depends on it).
      auto evaluate_meta = [&](const TaskEnvConfig& on_chair) -> Json {
        // Refused before any work (the planner's calibration, the trials).
        PlannerConfig la;  // a meta policy's lookahead: only its lookahead_* fields count
        la.lookahead_delays_s = o->lookahead_delays_s;
        la.lookahead_sides = o->lookahead_sides;
        la.lookahead_straight_s = o->lookahead_straight_s;
        la.lookahead_rank = o->lookahead_rank;
        la.lookahead_detour_deg = o->lookahead_detour_deg;
        if (!o->lookahead_file.empty()) {
          la = LookaheadFromFile(o->lookahead_file, la);
        }
        const bool look = la.lookahead();
        if (o->planner && SetsLookahead(la)) {
          throw ConfigError(
              "--lookahead / --lookahead-delays-s / --lookahead-sides / --lookahead-straight-s / "
              "--lookahead-detour-deg / --lookahead-rank: for a meta policy; the planner's "
              "lookahead is its config's sit_chair.meta.planner.lookahead_*");
        }
        if (la.lookahead_rank != "sooner" && !look) {
          throw ConfigError(
              "--lookahead-rank: only with a lookahead (--lookahead-delays-s, --lookahead-sides "
              "or --lookahead-straight-s)");
        }
        // The planner config's own checks (at most 8 times, ranges, a detour needs its times).
        PlannerConfig::FromJson(la.ToJson(), "--lookahead-*");
        TaskEnvConfig mc = on_chair;
        mc.env.spawn = SpawnConfig();
        mc.env.spawn.zone = chain->zone;
        mc.MutableSection<SitChairTaskConfig>().start.banks = {o->start_bank};
        const std::string model_file = o->planner ? "" : ModelFile(o->model);
        std::vector<FrozenPolicyData> frozen;
        if (!o->planner) frozen = FrozenPoliciesIn(o->model);
        if (frozen.empty()) frozen = LoadFrozenPolicies(mc);
        MetaEvalOptions mo;
        if (o->planner) {
          mo.planner = std::make_shared<const MetaPlan>(
              BuildMetaPlan(mc, frozen, mc.Section<SitChairTaskConfig>().meta.planner));
        }
        mo.trials = o->trials > 0 ? o->trials : o->eval.episodes;
        mo.seed = o->eval.seed;
        mo.stochastic = o->eval.stochastic;
        mo.threads = o->threads;
        mo.first_trial = o->first_trial;
        mo.policy_lookahead = la;
        if (o->record_routes && (o->records.empty() || la.lookahead_straight_s.empty())) {
          throw ConfigError(
              "--record-routes: needs --records and a lookahead with straight-on starts "
              "(--lookahead-straight-s or lookahead_straight_s in --lookahead)");
        }
        mo.record_routes = o->record_routes;
        const proto::ModelWeights meta_weights =
            o->planner ? proto::ModelWeights() : LoadModelFile(model_file);
        std::vector<proto::BankState> sit_starts, failed_sit_starts;
        // Refuse before the work, as the bank writer would after it.
        for (const std::string* f : {&o->save_sit_starts, &o->save_failed_sit_starts}) {
          if (!f->empty() && std::filesystem::exists(*f) && !o->force) {
            throw ConfigError("--save-" + std::string(f == &o->save_sit_starts ? "" : "failed-") +
                              "sit-starts " + *f + ": exists (--force replaces it)");
          }
        }
        mo.starts_subtask = SubtaskIdOf(o->hand_overs_to);
        if (mo.starts_subtask < 0) {
          throw ConfigError("--hand-overs-to \"" + o->hand_overs_to +
                            "\": not a subtask (sit, turn_left, turn_right, walk)");
        }
        if (!o->save_sit_starts.empty()) mo.sit_starts = &sit_starts;
        if (!o->save_failed_sit_starts.empty()) mo.failed_sit_starts = &failed_sit_starts;
        // The records file: made with its header, or resumed (the same header: the same
        // trials); appended to as trials finish (tasks/meta_eval.h).
        MetaRecordsWriter records;
        int resumed = 0;
        if (!o->records.empty()) {
          Json header = MetaEvalHeader(mc, meta_weights, frozen, mo);
          header["about"] = {{"model", o->planner ? Json("planner") : Json(model_file)},
                             {"start_bank", o->start_bank}};
          const MetaRecordsWriter::Opened r = records.Open(o->records, header, &mo);
          if (r.torn_tail) {
            std::cerr << "eval: " << o->records << ": its last line was cut short (a killed "
                      << "run); that trial runs again\n";
          }
          resumed = r.resumed;
          if (resumed > 0) {
            std::cerr << "eval: " << o->records << ": " << resumed << " of " << mo.trials
                      << " trials already run; resuming\n";
            // The header holds what ran, not the code: say when the file's trials came from
            // another build (the JSON's "builds" counts them).
            int other = 0;
            for (const MetaTrialRecord& t : mo.done) other += t.build != PerchVersion();
            if (other > 0) {
              std::cerr << "eval: " << o->records << ": " << other << " of its trials were run "
                        << "by another build than this " << PerchVersion()
                        << " (\"builds\" in the JSON); a change to the simulation between "
                        << "them would mix two sets of trials\n";
            }
          }
        }
        const auto t0 = std::chrono::steady_clock::now();
        const int every = std::max(1, mo.trials / 20);
        double last_print_s = 0;
        mo.progress = [&](int done, int successes) {
          const double sec =
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          // Every 5% of the trials, and at least once a minute: a 10,000-trial run with the
          // lookahead takes ~1.5 s a trial, so 5% is ~12 min apart.
          if (done % every != 0 && done != mo.trials && sec - last_print_s < 60) return;
          last_print_s = sec;
          std::cerr << "eval: " << done << "/" << mo.trials << " trials, success "
                    << static_cast<double>(successes) / done << " so far, " << static_cast<int>(sec)
                    << " s";
          // The rate of this run's own trials (not those resumed from the records).
          const int ran = done - resumed;
          if (ran > 0 && done < mo.trials) {
            std::cerr << ", " << std::setprecision(3) << sec / ran << " s a trial, about "
                      << static_cast<int>((mo.trials - done) * sec / ran / 60 + 0.5) << " min to go"
                      << std::setprecision(6);
          }
          std::cerr << "\n";
        };
        MetaTrialFrames ok, bad;
        const bool film = !o->filmstrip.empty();
        Json result =
            EvaluateMeta(mc, meta_weights, frozen, mo, film ? &ok : nullptr, film ? &bad : nullptr);
        if (!o->records.empty()) {
          result["records"] = o->records;
          result["resumed_trials"] = resumed;
        }
        result["model"] = o->planner ? Json("planner") : Json(model_file);
        result["start_bank"] = o->start_bank;
        auto write_bank = [&](const std::string& file, std::vector<proto::BankState>& states,
                              const std::string& key) {
          if (file.empty()) return;
          if (states.empty()) {
            std::cerr << "eval: no hand-over to " << o->hand_overs_to << " for " << file
                      << "; not written\n";
            result[key] = {{"file", file}, {"states", 0}};
            return;
          }
          const int n = static_cast<int>(states.size());
          WriteSitStartBank(file, "sit_chair", mc, o->planner ? "planner" : model_file, o->eval,
                            mo.trials, states, o->force);
          result[key] = {{"file", file}, {"states", n}, {"hand_overs_to", o->hand_overs_to}};
        };
        write_bank(o->save_sit_starts, sit_starts, "sit_starts");
        write_bank(o->save_failed_sit_starts, failed_sit_starts, "failed_sit_starts");
        result["wall_s"] =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (film) {
          const Chair chair = Chair::Load(mc.env.ChairPath());
          const HumanoidModel model = HumanoidModel::Load(mc.env.HumanoidPath());
          FilmstripOptions fo;
          fo.panel_px = o->panel_px;
          fo.follow = !o->fixed_window;
          // <name>.png: the first success; <name>_failure.png: the first failure.
          const std::string base = o->filmstrip.substr(0, o->filmstrip.rfind(".png"));
          for (const MetaTrialFrames* t : {&ok, &bad}) {
            if (t->frames.empty()) continue;
            const std::string path = t->success ? base + ".png" : base + "_failure.png";
            RenderFilmstrip(model, &chair, mc.env.chair_placement.Transform(),
                            PickFrames(t->frames, o->frames), fo)
                .SavePng(path);
            result[t->success ? "filmstrip_success" : "filmstrip_failure"] = {{"path", path},
                                                                              {"trial", t->trial}};
          }
        }
        if (!o->matrix_png.empty()) {
          SaveTransitionMatrixPng(result, o->matrix_png);
          result["transition_matrix_png"] = o->matrix_png;
        }
        return result;
      };
      if (o->cfg.chair == "all") {
        // Every preset in data/chairs/, one row each (the many-chairs table).
        Json table = Json::object();
        for (const std::string& preset : Chair::PresetNames()) {
          ConfigOverrides co = o->cfg;
          co.chair = preset;
          std::cerr << "eval: chair " << preset << "\n";
          Json r = evaluate_meta(ResolveConfig(co, o->model));
          r.erase("sequences");
          table[preset] = r;
        }
        Json all{{"task", "sit_chair"},
                 {"model", o->planner ? Json("planner") : Json(ModelFile(o->model))},
                 {"zone", chain->zone},
                 {"per_chair", table}};
        if (o->json) {
          std::cout << all.dump() << "\n";
        } else {
          for (const auto& [name, r] : table.items()) {
            std::cout << "sit_chair zone " << chain->zone << " chair " << name << ": success_rate "
                      << r["success_rate"] << " " << r["success_ci95"].dump() << "\n";
          }
        }
        return;
      }
      const Json result = evaluate_meta(config);
      if (o->json) {
        std::cout << result.dump() << "\n";
      } else {
        std::cout << "sit_chair zone " << chain->zone << ": success_rate " << result["success_rate"]
                  << " " << result["success_ci95"].dump() << ", min_dist "
                  << result["min_dist_mean_m"] << " +- " << result["min_dist_std_m"] << " m, falls "
                  << result["fall_rate"] << "\n";
      }
      return;
    }
    const std::string model_file = ModelFile(o->model);
    const proto::ModelWeights weights = LoadModelFile(model_file);
    EvalRecording rec;
    std::cerr << "eval: " << model_file << " (version " << weights.version() << "), task "
              << config.env.task << ", " << o->eval.episodes << " episodes, seed " << o->eval.seed
              << "\n";
    const TaskDef& def = GetTask(config.env.task, "--task");
    if (!def.evaluate) throw ConfigError("--task " + def.name + ": has no evaluation");
    if (o->cfg.chair == "all") {
      // Every preset in data/chairs/, one row each (the many-chairs table).
      Json table = Json::object();
      for (const std::string& preset : Chair::PresetNames()) {
        ConfigOverrides co = o->cfg;
        co.chair = preset;
        const TaskEnvConfig cc = ResolveConfig(co, o->model);
        std::cerr << "eval: chair " << preset << "\n";
        Json r = def.evaluate(cc, weights, o->eval, nullptr);
        r.erase("fall_times_s");
        r.erase("fall_episodes");
        table[preset] = r;
      }
      Json result{{"model", model_file}, {"task", config.env.task}, {"per_chair", table}};
      if (o->json) {
        std::cout << result.dump() << "\n";
      } else {
        for (const auto& [name, r] : table.items()) {
          std::cout << name << ": success_rate " << r["success_rate"] << " "
                    << r["success_ci95"].dump() << "\n";
        }
      }
      return;
    }
    Json result = def.evaluate(config, weights, o->eval, o->filmstrip.empty() ? nullptr : &rec);
    write_recording(config.env.task, model_file, config.ToJson());
    if (recorder) result["recording"] = o->record;
    result["model"] = model_file;
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
      std::cout << "task " << result["task"] << ", episodes " << result["episodes"]
                << ", success_rate " << result["success_rate"] << " (95% "
                << result["success_ci95"].dump() << "), fall_rate " << result["fall_rate"]
                << ", mean_imitation_reward " << result["mean_imitation_reward"] << "\n";
    }
  });

  struct SampleOpts {
    ConfigOverrides cfg;
    std::string model, out;
    SampleEndPosesOptions sample;
    bool deterministic = false, overwrite = false, json = false;
  };
  auto so = std::make_shared<SampleOpts>();
  so->sample.workers = std::max(1u, std::thread::hardware_concurrency());
  CLI::App* sp = root.add_subcommand(
      "sample-end-poses",
      "Run a trained subtask policy and keep the full state after N steps of every episode that "
      "survives N + K steps: a start-state bank for transition fine-tuning (notes 4.5)");
  sp->add_option("--model", so->model, "policy (checkpoint, run dir or ModelWeights)")->required();
  sp->add_option("--task", so->cfg.task, "task of the policy (default: the model's saved config)")
      ->check(CLI::IsMember(EvalTaskNames()));
  sp->add_option("--config", so->cfg.config_path, "task env config (default: the model's)");
  sp->add_option("--steps", so->sample.steps, "N: control steps before the kept state")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000));
  sp->add_option("--survive", so->sample.survive, "K: further steps the episode must survive")
      ->capture_default_str()
      ->check(CLI::Range(0, 100000));
  sp->add_option("--count", so->sample.count, "C: states to collect")
      ->capture_default_str()
      ->check(CLI::Range(1, 10000000));
  sp->add_option("--seed", so->sample.seed, "episode seed (episode e as perch eval's)")
      ->capture_default_str();
  sp->add_option("--workers", so->sample.workers, "threads (default: all cores)")
      ->check(CLI::Range(1, 1024));
  sp->add_flag("--mean-actions", so->deterministic,
               "the Gaussian's mean instead of sampled actions (the authors sample)");
  sp->add_option("--out", so->out, "bank file to write (refuses to overwrite)")->required();
  sp->add_flag("--overwrite", so->overwrite, "replace an existing --out");
  sp->add_flag("--json", so->json, "print one JSON summary on stdout");
  sp->callback([so]() {
    if (!so->overwrite && std::filesystem::exists(so->out)) {
      throw ConfigError(so->out + ": exists; not overwritten (--overwrite replaces it)");
    }
    ConfigOverrides co = so->cfg;
    TaskEnvConfig config = ResolveConfig(co, so->model);
    const std::string model_file = ModelFile(so->model);
    const proto::ModelWeights weights = LoadModelFile(model_file);
    so->sample.stochastic = !so->deterministic;
    const auto t0 = std::chrono::steady_clock::now();
    so->sample.progress = [&](int collected, int64_t episodes) {
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::cerr << "sample-end-poses: " << collected << "/" << so->sample.count << " states, "
                << episodes << " episodes, " << static_cast<int>(s) << " s\n";
    };
    proto::StateBank bank = SampleEndPoses(config, weights, so->sample);
    bank.set_model_path(model_file);
    bank.set_model_sha256(FileSha256(model_file));
    WriteStateBank(so->out, bank, so->overwrite);
    const double secs =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    Json summary{{"out", so->out},
                 {"task", bank.task()},
                 {"model", model_file},
                 {"model_sha256", bank.model_sha256()},
                 {"states", bank.states_size()},
                 {"episodes_run", bank.episodes_run()},
                 {"survival_rate", static_cast<double>(bank.states_size()) /
                                       std::max<int64_t>(1, bank.episodes_run())},
                 {"steps", bank.steps()},
                 {"survive", bank.survive()},
                 {"seed", bank.seed()},
                 {"stochastic", bank.stochastic()},
                 {"workers", so->sample.workers},
                 {"seconds", secs}};
    if (so->json) {
      std::cout << summary.dump() << "\n";
    } else {
      std::cout << "wrote " << so->out << ": " << bank.states_size() << " states from "
                << bank.episodes_run() << " episodes\n";
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
  t->cfg.task = "walk";
  std::vector<std::string> train_tasks = TaskNames();
  train_tasks.push_back("stand");
  tr->add_option("--task", t->cfg.task, "task")->check(CLI::IsMember(train_tasks));
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
    const TaskEnvConfig config = ResolveConfig(t->cfg, "");
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
  struct MirrorOpts {
    std::string model, config, out;
    bool json = false;
  };
  auto mo = std::make_shared<MirrorOpts>();
  CLI::App* mi = root.add_subcommand("mirror-model",
                                     "A policy for the mirror-image task (turn right from turn "
                                     "left): weights mirrored left/right");
  mi->add_option("--model", mo->model, "policy file of the source task")->required();
  mi->add_option("--config", mo->config, "task config of the target task (its env's mirror map)")
      ->required();
  mi->add_option("--out", mo->out, "output ModelWeights file (must not exist)")->required();
  mi->add_flag("--json", mo->json, "print one JSON summary on stdout");
  mi->callback([mo]() {
    if (std::filesystem::exists(mo->out)) throw ConfigError(mo->out + ": exists; not overwritten");
    ConfigOverrides co;
    co.config_path = mo->config;
    const TaskEnvConfig config = ResolveConfig(co, "");
    const std::unique_ptr<Env> env = MakeTaskEnv(config);
    const proto::ModelWeights w =
        MirrorModelWeights(LoadModelFile(mo->model), env->spec().mirror, mo->model);
    WriteFileAtomic(mo->out, w.SerializeAsString());
    Json summary = {{"out", mo->out},
                    {"model", mo->model},
                    {"config", mo->config},
                    {"env", env->spec().name},
                    {"num_params", w.params_size()}};
    if (mo->json) {
      std::cout << summary.dump() << "\n";
    } else {
      std::cout << "wrote " << mo->out << " (" << mo->model << " mirrored for " << env->spec().name
                << ")\n";
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

  struct MergeOpts {
    std::vector<std::string> files;
    std::string matrix_png;
    int trials = 0;  // only the first N trials (0: all)
    bool so_far = false;  // only the trials up to the first one missing
    bool json = false;
  };
  auto mg = std::make_shared<MergeOpts>();
  CLI::App* me = root.add_subcommand(
      "eval-merge",
      "Join the --records of sit_chair evaluation shards (perch eval --first-trial) into the "
      "result one evaluation of all their trials gives");
  me->add_option("records", mg->files, "records files (perch eval --records)")
      ->required()
      ->expected(1, 1 << 16);
  me->add_option("--matrix-png", mg->matrix_png,
                 "draw the subtask transition matrices (per start side) here");
  me->add_option("--trials", mg->trials,
                 "only the first N trials (from the lowest), e.g. a figure so far from a run that "
                 "is still going (0: all; they must all be there)")
      ->check(CLI::Range(0, 100000000));
  me->add_flag("--so-far", mg->so_far,
               "only the trials from the lowest up to the first one missing: the figure so far "
               "of a run still going (its threads finish trials out of order)")
      ->excludes("--trials");
  me->add_flag("--json", mg->json, "print one JSON object on stdout");
  me->callback([mg]() {
    Json header;
    std::vector<MetaTrialRecord> all;
    std::map<int, std::string> owner;  // trial -> the file that holds it
    for (const std::string& file : mg->files) {
      MetaRecordsFile f = ReadMetaRecords(file);
      if (f.torn_tail) {
        std::cerr << "eval-merge: " << file << ": its last line was cut short; left out\n";
      }
      if (header.is_null()) {
        header = f.header;
      } else if (const std::string d = FirstHeaderDifference(header, f.header); !d.empty()) {
        throw ConfigError(file + ": its trials were run with another \"" + d + "\" than " +
                          mg->files.front() +
                          "'s; shards of one evaluation share model, "
                          "config, seed and flags");
      }
      for (MetaTrialRecord& r : f.records) {
        auto [it, fresh] = owner.emplace(r.trial, file);
        if (!fresh) {
          throw ConfigError(file + ": trial " + std::to_string(r.trial) + " is also in " +
                            it->second + " (overlapping shards)");
        }
        all.push_back(std::move(r));
      }
    }
    if (all.empty()) throw ConfigError("eval-merge: the records hold no trials");
    const int lo = owner.begin()->first;
    if (mg->so_far) {
      int n = 0;
      while (owner.count(lo + n)) ++n;
      mg->trials = n;
    }
    if (mg->trials > 0) {
      all.erase(
          std::remove_if(all.begin(), all.end(),
                         [&](const MetaTrialRecord& r) { return r.trial >= lo + mg->trials; }),
          all.end());
      owner.erase(owner.lower_bound(lo + mg->trials), owner.end());
      if (static_cast<int>(all.size()) < mg->trials) {
        throw ConfigError("eval-merge --trials " + std::to_string(mg->trials) + ": the records " +
                          "hold " + std::to_string(all.size()) + " of trials " +
                          std::to_string(lo) + " .. " + std::to_string(lo + mg->trials - 1));
      }
    }
    // Contiguous trials only: a gap is a shard not run (or not finished).
    const int hi = owner.rbegin()->first;
    if (hi - lo + 1 != static_cast<int>(all.size())) {
      int missing = lo;
      while (owner.count(missing)) ++missing;
      throw ConfigError("eval-merge: trials " + std::to_string(lo) + " .. " + std::to_string(hi) +
                        " lack " + std::to_string(hi - lo + 1 - static_cast<int>(all.size())) +
                        ", the first " + std::to_string(missing) +
                        " (resume that shard: perch eval --records its file)");
    }
    Json result = AggregateMeta(header, std::move(all));
    const Json about = header.value("about", Json::object());
    for (const char* k : {"model", "start_bank"}) {
      if (about.contains(k)) result[k] = about[k];
    }
    result["records"] = mg->files;
    if (!mg->matrix_png.empty()) {
      SaveTransitionMatrixPng(result, mg->matrix_png);
      result["transition_matrix_png"] = mg->matrix_png;
    }
    if (mg->json) {
      std::cout << result.dump() << "\n";
    } else {
      std::cout << "sit_chair zone " << result["zone"] << ", trials " << result["first_trial"]
                << " .. " << hi << ": success_rate " << result["success_rate"] << " "
                << result["success_ci95"].dump() << ", min_dist " << result["min_dist_mean_m"]
                << " +- " << result["min_dist_std_m"] << " m\n";
    }
  });
}

}  // namespace perch
