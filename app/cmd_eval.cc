// perch eval, eval-merge, sample-end-poses, train-local, mirror-model, average-models: flags
// parsed into the options of the functions that do the work (eval/, tasks/, learner/local/).
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
#include "eval/eval_command.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/meta_env.h"
#include "hierarchy/meta_eval.h"
#include "hierarchy/meta_expert.h"
#include "learner/local/local_train.h"
#include "learner/model_average.h"
#include "learner/service/checkpoint.h"
#include "policy/policy.h"
#include "tasks/model_source.h"
#include "tasks/registry.h"
#include "tasks/state_bank.h"
#include "tasks/task_env.h"
#include "tasks/task_eval.h"
#include "tasks/walk_eval.h"
#include "viz/filmstrip.h"
#include "viz/transition_matrix.h"

namespace perch {

namespace {

// perch eval: which task and policy, its config overrides and the episodes.
void AddEvalEpisodeFlags(CLI::App* cmd, EvalCommand* o) {
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
                  "JSON file (boxes or mesh), all (every preset, one result each) or a "
                  "directory (every chair file in it, one result each)");
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
  // Robustness (issue 49): the figures are the perturbed episodes'; the same episodes also run
  // unperturbed, and flip_rate is the share whose outcome differs.
  cmd->add_option("--push", o->eval.perturb.push_n,
                  "a horizontal push of F N on the pelvis, random direction, at a random step")
      ->check(CLI::Range(0.0, 10000.0));
  cmd->add_option("--push-seconds", o->eval.perturb.push_s, "--push: its duration [s]")
      ->check(CLI::Range(0.001, 10.0));
  cmd->add_option("--obs-noise", o->eval.perturb.obs_noise,
                  "Gaussian noise of this std on every observation entry (its own units)")
      ->check(CLI::Range(0.0, 100.0));
  cmd->add_option("--act-noise", o->eval.perturb.act_noise,
                  "Gaussian noise of this std on every action entry (actions are in [-1, 1])")
      ->check(CLI::Range(0.0, 100.0));
  cmd->add_flag("--restore", o->eval.perturb.restore,
                "save and restore the simulator's state at a random step");
}

// perch eval: what it writes besides its figures (filmstrip, recording, JSON).
void AddEvalOutputFlags(CLI::App* cmd, EvalCommand* o) {
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
}

// perch eval --task sit_chair: trials, records, hand-over banks and the lookahead.
void AddMetaEvalFlags(CLI::App* cmd, EvalCommand* o) {
  cmd->add_option("--trials", o->trials,
                  "sit_chair (the meta controller): number of trials (default: --episodes)")
      ->check(CLI::Range(1, 10000000));
  cmd->add_flag("--planner", o->planner,
                "sit_chair: the scripted planner of the config's sit_chair.meta.planner decides "
                "instead of a meta policy (hierarchy/meta_expert.h); needs --config, no --model");
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
  cmd->add_option("--lookahead-delays-s", o->lookahead.lookahead_delays_s,
                  "sit_chair with a meta policy: at each of its switches also simulate the switch "
                  "delayed by each of these times to the episode's end and take the best "
                  "(hierarchy/meta_lookahead.h; the planner's lookahead is in its config) [s]")
      ->check(CLI::Range(0.001, 3.0));
  cmd->add_flag("--lookahead-sides", o->lookahead.lookahead_sides,
                "sit_chair with a meta policy: at each of its switches into a turn also simulate "
                "the other turn (hierarchy/meta_lookahead.h)");
  cmd->add_option("--lookahead-straight-s", o->lookahead.lookahead_straight_s,
                  "sit_chair with a meta policy: at its first step also simulate the walker "
                  "walking straight on for each of these times before the policy steers [s]")
      ->check(CLI::Range(0.001, 3.0));
  cmd->add_option("--lookahead-detour-deg", o->lookahead.lookahead_detour_deg,
                  "sit_chair with a meta policy and --lookahead-straight-s: each start also with "
                  "the walker heading this far off its facing (+ left), e.g. round the chair [deg]")
      ->check(CLI::Range(-180.0, 180.0));
  cmd->add_option("--lookahead-rank", o->lookahead.lookahead_rank,
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
}

// perch eval --task chain: the scripted chain, its planned hand-over and its policies.
void AddChainFlags(CLI::App* cmd, ChainFlags* chain) {
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
                "starts; hierarchy/chain_plan.h)");
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
}

void RegisterSampleEndPoses(CLI::App& root) {
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
}

void RegisterTrainLocal(CLI::App& root) {
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
}

void RegisterMirrorModel(CLI::App& root) {
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
}

void RegisterAverageModels(CLI::App& root) {
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

void RegisterEvalMerge(CLI::App& root) {
  struct MergeOpts : EvalMergeOptions {
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
    const Json result = MergeEvalRecords(*mg);
    if (mg->json) {
      std::cout << result.dump() << "\n";
    } else {
      const int hi = result["first_trial"].get<int>() + result["trials"].get<int>() - 1;
      std::cout << "sit_chair zone " << result["zone"] << ", trials " << result["first_trial"]
                << " .. " << hi << ": success_rate " << result["success_rate"] << " "
                << result["success_ci95"].dump() << ", min_dist " << result["min_dist_mean_m"]
                << " +- " << result["min_dist_std_m"] << " m\n";
    }
  });
}

}  // namespace

void RegisterEvalCommands(CLI::App& root, CLI::App& /*bench*/) {
  auto o = std::make_shared<EvalCommand>();
  o->cfg.target_turn_prob = 0.0;  // eval measures the paper's targets, not a training curriculum
  CLI::App* cmd =
      root.add_subcommand("eval", "Evaluate a trained subtask policy over seeded episodes");
  AddEvalEpisodeFlags(cmd, o.get());
  AddEvalOutputFlags(cmd, o.get());
  AddMetaEvalFlags(cmd, o.get());
  AddChainFlags(cmd, &o->chain);  // o lives as long as the callback that holds it
  cmd->callback([o]() { RunEvalCommand(*o); });

  RegisterSampleEndPoses(root);
  RegisterTrainLocal(root);
  RegisterMirrorModel(root);
  RegisterAverageModels(root);
  RegisterEvalMerge(root);
}

}  // namespace perch
