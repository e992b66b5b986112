// perch meta-clone: the scripted planner cloned into a meta policy (learner/local/meta_clone.h).
#include <chrono>
#include <filesystem>
#include <iostream>
#include <memory>
#include <thread>

#include "app/commands.h"
#include "common/file_util.h"
#include "common/json_util.h"
#include "common/paths.h"
#include "experiment/experiment.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/meta_expert.h"
#include "learner/local/meta_clone.h"
#include "learner/service/checkpoint.h"
#include "protocol/wire.h"
#include "tasks/model_source.h"
#include "tasks/task_env.h"

namespace perch {

void RegisterMetaCommands(CLI::App& root, CLI::App& /*bench*/) {
  struct Opts {
    std::string config, out, init_from;
    std::vector<std::string> sets;
    CloneOptions clone;
    bool json = false, stage = false;
  };
  auto o = std::make_shared<Opts>();
  o->clone.threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  CLI::App* cmd = root.add_subcommand(
      "meta-clone",
      "Clone the scripted planner (env.sit_chair.meta.planner) into a meta policy: a start for "
      "PPO (cluster.init_from)");
  cmd->add_option("--config", o->config, "the sit_chair meta experiment config")->required();
  cmd->add_option("--set", o->sets, "override one config field (section.field=JSON)");
  cmd->add_option("--out", o->out,
                  "output checkpoint (must not exist): the clone, its config and the frozen "
                  "subtasks, as a run's checkpoint (perch eval --model, cluster.init_from)")
      ->required();
  cmd->add_option("--episodes", o->clone.episodes, "planner episodes per round")
      ->check(CLI::Range(1, 1000000));
  cmd->add_option("--rounds", o->clone.rounds, "rounds (> 1: DAgger rounds after the first)")
      ->check(CLI::Range(1, 100));
  cmd->add_option("--switch-weight", o->clone.switch_weight,
                  "weight of the meta steps whose label hands over to another subtask, against 1 "
                  "for the others")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 1000.0));
  cmd->add_option("--beta", o->clone.dagger_beta,
                  "DAgger rounds: the planner acts with this probability per meta step")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--epochs", o->clone.epochs, "passes over the data per round")
      ->check(CLI::Range(1, 10000));
  cmd->add_option("--minibatch", o->clone.minibatch, "samples per Adam step")
      ->check(CLI::Range(1, 1 << 20));
  cmd->add_option("--lr", o->clone.learning_rate, "Adam learning rate")
      ->check(CLI::Range(1e-7, 1.0));
  cmd->add_option("--target-log-std", o->clone.target_log_std,
                  "the walk target head's log-std after fitting (PPO's exploration)")
      ->check(CLI::Range(-5.0, 1.0));
  cmd->add_option("--seed", o->clone.seed, "episodes and shuffling");
  cmd->add_option("--threads", o->clone.threads, "collection threads")->check(CLI::Range(1, 256));
  cmd->add_option("--init-from", o->init_from,
                  "a curriculum stage: start from this meta policy (the previous stage's "
                  "checkpoint); round 1 is then a DAgger round driven by it");
  cmd->add_flag("--stage", o->stage,
                "a curriculum stage: start from the config's cluster.init_from (the previous "
                "stage's checkpoint), as --init-from does");
  cmd->add_flag("--json", o->json, "print one JSON summary on stdout");
  cmd->callback([o]() {
    // Never replace a saved model: a typo in --out must not cost a result.
    if (std::filesystem::exists(o->out)) throw ConfigError(o->out + ": exists; not overwritten");
    const ExperimentConfig c = LoadExperimentConfig(o->config, o->sets);
    const TaskEnvConfig config = TaskEnvConfig::FromJson(c.env, o->config + ": env");
    if (config.env.task != "sit_chair") {
      throw ConfigError(o->config + ": env.task is \"" + config.env.task +
                        "\"; meta-clone needs sit_chair");
    }
    if (o->stage) {
      if (!o->init_from.empty()) throw ConfigError("meta-clone: --stage or --init-from, not both");
      if (c.cluster.init_from.empty()) {
        throw ConfigError(o->config + ": --stage needs cluster.init_from (the previous stage)");
      }
      o->init_from = ResolveProjectPath(c.cluster.init_from);
    }
    if (!o->init_from.empty()) o->clone.init = LoadModelFile(o->init_from);
    const std::vector<FrozenPolicyData> frozen = ExperimentFrozenPolicies(c);
    const PolicyConfig pc = ResolvePolicyConfig(c, MakeExperimentEnv(c)->spec());
    if (o->clone.init) {
      // Refuse a start of another shape now, not after the planner's calibration.
      try {
        CheckCloneInit(pc, c.ppo.obs_norm, *o->clone.init);
      } catch (const ConfigError& e) {
        throw ConfigError(o->init_from + ": does not fit the config's meta network: " + e.what());
      }
    }
    const auto t0 = std::chrono::steady_clock::now();
    std::cerr << "meta-clone: measuring the turns for the planner\n";
    auto plan = std::make_shared<const MetaPlan>(
        BuildMetaPlan(config, frozen, config.Section<SitChairTaskConfig>().meta.planner));
    o->clone.progress = [](const std::string& line) { std::cerr << line << "\n"; };
    const CloneResult r = CloneMeta(config, frozen, pc, c.ppo.obs_norm, plan, o->clone);
    // A checkpoint like a run's at update 0, so that eval finds the config and the subtasks in
    // it and a PPO run starts from it.
    proto::Checkpoint ck;
    ck.set_wire_version(proto::WIRE_VERSION_CURRENT);
    proto::TaskPolicy* tp = ck.mutable_weights()->add_policies();
    tp->set_task(proto::TASK_META);
    *tp->mutable_model() = r.weights;
    for (const FrozenPolicyData& f : frozen) {
      *ck.mutable_weights()->add_policies() = FrozenPolicyToProto(f);
    }
    *ck.mutable_trainer()->mutable_model() = r.weights;
    ck.set_resolved_config_json(ToJson(c).dump());
    ck.set_compat_key(CompatKey(c, pc));
    ck.set_seed(c.seed);
    WriteFileAtomic(o->out, FrameCheckpoint(ck));
    Json summary = r.summary;
    summary["out"] = o->out;
    // The stage's cost (issue 15 asks for meta steps, samples and wall time per stage).
    summary["wall_s"] =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    summary["config"] = ToJson(c);
    // Which curriculum stage this is: the zone it was cloned on and the stage it started from.
    summary["stage"] = Json{{"zone", config.env.spawn.zone},
                            {"init_from", o->init_from.empty() ? Json() : Json(o->init_from)}};
    WriteFileAtomic(o->out + ".json", summary.dump(2) + "\n");
    if (o->json) {
      std::cout << summary.dump() << "\n";
    } else {
      std::cout << "wrote " << o->out << " (summary " << o->out << ".json)\n";
    }
  });
}

}  // namespace perch
