// `perch bench ppo`: PPO update throughput (bench/ppo_bench.h).
// `perch ppo toy`: PPO trained in process on a toy task (learner/toy_train.h).
#include <iostream>
#include <memory>

#include "app/commands.h"
#include "bench/ppo_bench.h"
#include "common/json_util.h"
#include "common/stop_signal.h"
#include "learner/toy_train.h"

namespace perch {
namespace {

void PrintPpoBench(const Json& j, const PpoBenchOptions& o, bool json) {
  if (json) {
    std::cout << j.dump() << std::endl;
  } else {
    std::cout << "PPO epoch on " << o.batch << " samples (obs " << j["obs_dim"].get<int>()
              << ", act " << j["act_dim"].get<int>() << ", 2x64 tanh, "
              << j["dense_kernels"].get<std::string>()
              << " kernels): " << j["samples_per_s"].get<double>() << " samples/s (median of "
              << o.repeats << "), actor step " << j["act_steps_per_s"].get<double>()
              << " steps/s\n";
    if (o.threads > 1) {
      std::cout << o.threads << " threads: " << j["samples_per_s_threads_n"].get<double>()
                << " samples/s, " << j["speedup_threads_n"].get<double>() << "x one thread\n";
    }
  }
}

}  // namespace

void RegisterLearnerCommands(CLI::App& root, CLI::App& bench) {
  auto bo = std::make_shared<PpoBenchOptions>();
  auto bench_json = std::make_shared<bool>(false);
  CLI::App* b =
      bench.add_subcommand("ppo", "PPO update throughput (Eigen; one core, or --threads)");
  b->add_option("--obs-dim", bo->obs_dim, "observation size (57 sit/meta, 52 walk/turn)");
  b->add_option("--batch", bo->batch, "samples per update (Table 2: 8192)");
  b->add_option("--minibatches", bo->minibatches, "minibatches per epoch (Table 2: 32)");
  b->add_option("--repeats", bo->repeats, "timed epochs");
  b->add_option("--seed", bo->seed, "seed");
  b->add_option("--epochs", bo->epochs,
                "epochs per timed update (1: the historical one-epoch figure; Table 2: 4)");
  b->add_option("--threads", bo->threads,
                "PPO threads (ppo.threads); > 1 also times one thread and reports the speedup");
  b->add_flag("--blocks", bo->blocks,
              "with --threads: all one-thread updates first, then all N-thread ones (each learner "
              "keeps its caches warm) instead of alternating update by update");
  b->add_flag("--ceiling", bo->ceiling,
              "with --threads N: also time N one-thread learners running at once (the speedup N "
              "cores give on this machine, the ceiling for N threads)");
  b->add_flag("--json", *bench_json, "print one JSON object");
  b->callback([bo, bench_json] {
    LogToStderr("ppo");
    PrintPpoBench(RunPpoBench(*bo), *bo, *bench_json);
  });

  CLI::App* ppo = root.add_subcommand("ppo", "PPO learner tools");
  ppo->require_subcommand(1);
  auto to = std::make_shared<ToyTrainOptions>();
  auto toy_json = std::make_shared<bool>(false);
  CLI::App* toy = ppo->add_subcommand("toy", "Train PPO in process on a toy task");
  toy->add_option("--task", to->task, "point_mass or choice_target");
  toy->add_option("--config", to->config_path, "JSON {\"policy\": {...}, \"ppo\": {...}}");
  toy->add_option("--out", to->out_dir, "directory for config.json and learner_state.pb");
  toy->add_option("--updates", to->updates, "PPO updates (default per task)");
  toy->add_option("--seed", to->seed, "seed");
  toy->add_flag("--json", *toy_json, "print one JSON object");
  toy->callback([to, toy_json] {
    LogToStderr("ppo");
    const Json j = TrainToy(*to);
    if (*toy_json) {
      std::cout << j.dump() << std::endl;
    } else {
      std::cout << "final deterministic return " << j["final_deterministic_return"].get<double>()
                << "\n";
    }
  });
}

}  // namespace perch
