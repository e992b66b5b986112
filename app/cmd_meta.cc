// perch meta-clone: the scripted planner cloned into a meta policy
// (learner/local/meta_clone_stage.h).
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <memory>
#include <thread>

#include "app/commands.h"
#include "common/file_util.h"
#include "common/json_util.h"
#include "learner/local/meta_clone_stage.h"
#include "learner/service/checkpoint.h"

namespace perch {

void RegisterMetaCommands(CLI::App& root, CLI::App& /*bench*/) {
  struct Opts {
    MetaCloneStageOptions stage;
    std::string out;
    bool json = false;
  };
  auto o = std::make_shared<Opts>();
  o->stage.clone.threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  CLI::App* cmd = root.add_subcommand(
      "meta-clone",
      "Clone the scripted planner (env.sit_chair.meta.planner) into a meta policy: a start for "
      "PPO (cluster.init_from)");
  cmd->add_option("--config", o->stage.config, "the sit_chair meta experiment config")->required();
  cmd->add_option("--set", o->stage.sets, "override one config field (section.field=JSON)");
  cmd->add_option("--out", o->out,
                  "output checkpoint (must not exist): the clone, its config and the frozen "
                  "subtasks, as a run's checkpoint (perch eval --model, cluster.init_from)")
      ->required();
  cmd->add_option("--episodes", o->stage.clone.episodes, "planner episodes per round")
      ->check(CLI::Range(1, 1000000));
  cmd->add_option("--rounds", o->stage.clone.rounds, "rounds (> 1: DAgger rounds after the first)")
      ->check(CLI::Range(1, 100));
  cmd->add_option("--switch-weight", o->stage.clone.switch_weight,
                  "weight of the meta steps whose label hands over to another subtask, against 1 "
                  "for the others")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 1000.0));
  cmd->add_option("--beta", o->stage.clone.dagger_beta,
                  "DAgger rounds: the planner acts with this probability per meta step")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--epochs", o->stage.clone.epochs, "passes over the data per round")
      ->check(CLI::Range(1, 10000));
  cmd->add_option("--minibatch", o->stage.clone.minibatch, "samples per Adam step")
      ->check(CLI::Range(1, 1 << 20));
  cmd->add_option("--lr", o->stage.clone.learning_rate, "Adam learning rate")
      ->check(CLI::Range(1e-7, 1.0));
  cmd->add_option("--target-log-std", o->stage.clone.target_log_std,
                  "the walk target head's log-std after fitting (PPO's exploration)")
      ->check(CLI::Range(-5.0, 1.0));
  cmd->add_option("--seed", o->stage.clone.seed, "episodes and shuffling");
  cmd->add_option("--threads", o->stage.clone.threads, "collection threads")
      ->check(CLI::Range(1, 256));
  cmd->add_option("--init-from", o->stage.init_from,
                  "a curriculum stage: start from this meta policy (the previous stage's "
                  "checkpoint); round 1 is then a DAgger round driven by it");
  cmd->add_flag("--stage", o->stage.from_config_init,
                "a curriculum stage: start from the config's cluster.init_from (the previous "
                "stage's checkpoint), as --init-from does");
  cmd->add_flag("--json", o->json, "print one JSON summary on stdout");
  cmd->callback([o]() {
    // Never replace a saved model: a typo in --out must not cost a result.
    if (std::filesystem::exists(o->out)) throw ConfigError(o->out + ": exists; not overwritten");
    const MetaCloneStage stage = RunMetaCloneStage(o->stage);
    WriteFileAtomic(o->out, FrameCheckpoint(stage.checkpoint));
    Json summary = stage.summary;
    summary["out"] = o->out;
    WriteFileAtomic(o->out + ".json", summary.dump(2) + "\n");
    if (o->json) {
      std::cout << summary.dump() << "\n";
    } else {
      std::cout << "wrote " << o->out << " (summary " << o->out << ".json)\n";
    }
  });
}

}  // namespace perch
