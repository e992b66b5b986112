// `perch bench ppo`: PPO update throughput of the subtask network on one core.
// `perch ppo toy`: trains PPO in process on a toy task (point_mass or choice_target) and reports
// the learning curve; the quick end-to-end check of the learner.
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "app/commands.h"
#include "common/file_util.h"
#include "common/json_util.h"
#include "common/proto/model.pb.h"
#include "common/stop_signal.h"
#include "learner/ppo.h"
#include "learner/toy_envs.h"
#include "policy/dense_kernels.h"
#include "policy/policy.h"
#include "policy/rollout.h"

namespace perch {
namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

struct BenchOptions {
  int obs_dim = 57;
  int batch = 8192;
  int minibatches = 32;
  int repeats = 10;
  int threads = 1;
  int epochs = 1;
  uint64_t seed = 0;
  bool blocks = false;   // time all one-thread updates, then all N-thread ones (not alternating)
  bool ceiling = false;  // also time N one-thread learners at once: what N cores give here
  bool json = false;
};

// One timed PPO epoch per Update call; with --threads N > 1 a one-thread learner is timed in the
// same run, alternating epoch by epoch, and the JSON gives the ratio (machines here are noisy).
void RunBench(const BenchOptions& o) {
  if (o.obs_dim <= 0 || o.batch <= 0 || o.minibatches <= 0 || o.repeats <= 0 || o.threads <= 0 ||
      o.epochs <= 0) {
    throw ConfigError(
        "bench ppo: --obs-dim, --batch, --minibatches, --repeats, --threads and --epochs must be "
        "> 0");
  }
  Eigen::setNbThreads(1);
  const PolicyConfig pc = PolicyConfig::Subtask(o.obs_dim);
  PpoConfig cfg = PpoConfig::Subtask();
  cfg.steps_per_update = o.batch;
  cfg.num_minibatches = o.minibatches;
  cfg.num_epochs = o.epochs;  // one timed Update call: the batch's preparation, then the epochs
  PpoConfig cfg_n = cfg;
  cfg_n.threads = o.threads;
  PpoLearner learner(pc, cfg, o.seed);
  PpoLearner learner_n(pc, cfg_n, o.seed);

  // A batch with realistic log-probs: actions sampled by the policy on random observations.
  PolicyRunner runner(pc, cfg.obs_norm);
  runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(), 0);
  runner.set_update_obs_stats(false);
  Rng rng(o.seed + 1);
  Rollout r(pc.obs_dim, pc.action_size());
  r.Reserve(o.batch);
  std::vector<float> raw(pc.obs_dim), norm(pc.obs_dim), act(pc.action_size());
  const auto t_act0 = Clock::now();
  for (int t = 0; t < o.batch; ++t) {
    for (float& x : raw) x = static_cast<float>(rng.Normal());
    const PolicyRunner::Output out = runner.Act(raw.data(), rng, false, norm.data(), act.data());
    const bool trunc = (t + 1) % 1000 == 0;
    r.Add(norm.data(), act.data(), out.log_prob, out.value, static_cast<float>(rng.Normal()), false,
          trunc, trunc || t + 1 == o.batch ? out.value : 0.0f);
  }
  const double act_s = Seconds(t_act0, Clock::now());
  r.obs_stats_delta = RunningMeanStd(pc.obs_dim, 0.0);
  const std::vector<Rollout> batch{r};

  const bool compare = o.threads > 1;
  learner.Update(batch);  // warm-up: buffers reach their size, threads start
  if (compare) learner_n.Update(batch);
  std::vector<double> times, times_n;
  for (int i = 0; i < o.repeats; ++i) {
    auto t0 = Clock::now();
    learner.Update(batch);
    times.push_back(Seconds(t0, Clock::now()));
    if (!compare || o.blocks) continue;
    t0 = Clock::now();
    learner_n.Update(batch);
    times_n.push_back(Seconds(t0, Clock::now()));
  }
  // The machine's own ceiling: N independent one-thread updates at once, against one alone. A VM's
  // cores may share a physical core, caches or a power budget; N threads cannot beat this.
  std::vector<double> times_conc;
  std::vector<PpoLearner> copies;
  if (compare && o.ceiling) {
    copies.assign(o.threads - 1, learner);
    for (PpoLearner& c : copies) c.Update(batch);
  }
  for (int i = 0; compare && o.ceiling && i < o.repeats; ++i) {
    const auto t0 = Clock::now();
    std::vector<std::thread> others;
    for (PpoLearner& c : copies) others.emplace_back([&c, &batch] { c.Update(batch); });
    learner.Update(batch);
    for (std::thread& t : others) t.join();
    times_conc.push_back(Seconds(t0, Clock::now()));
  }
  for (int i = 0; compare && o.blocks && i < o.repeats; ++i) {
    const auto t0 = Clock::now();
    learner_n.Update(batch);
    times_n.push_back(Seconds(t0, Clock::now()));
  }
  const double med = Median(times);
  const double best = *std::min_element(times.begin(), times.end());
  Json j{{"bench", "ppo"},
         // Per epoch of one sample pass (an update with --epochs E counts E passes).
         {"samples_per_s", o.batch * o.epochs / med},
         {"samples_per_s_best", o.batch * o.epochs / best},
         {"epoch_ms_median", 1e3 * med / o.epochs},
         {"epoch_ms_min", 1e3 * best / o.epochs},
         {"update_ms_median", 1e3 * med},
         {"batch", o.batch},
         {"minibatch", o.batch / o.minibatches},
         {"repeats", o.repeats},
         {"epochs", o.epochs},
         {"obs_dim", pc.obs_dim},
         {"act_dim", pc.act_dim},
         {"hidden", pc.policy_net.hidden},
         {"activation", "tanh"},
         {"num_params", learner.model().num_params()},
         {"threads", 1},
         {"act_steps_per_s", o.batch / act_s},
         {"eigen_simd", Eigen::SimdInstructionSetsInUse()},
         {"dense_kernels", ActiveDenseKernels().name},
         {"impl", "eigen"}};
  if (compare) {
    const double med_n = Median(times_n);
    j["threads_n"] = o.threads;
    j["samples_per_s_threads_n"] = o.batch * o.epochs / med_n;
    j["epoch_ms_median_threads_n"] = 1e3 * med_n / o.epochs;
    j["update_ms_median_threads_n"] = 1e3 * med_n;
    // Per repeat, one thread's time over N threads' (adjacent epochs share the machine's load).
    std::vector<double> ratios;
    for (size_t i = 0; i < times.size(); ++i) ratios.push_back(times[i] / times_n[i]);
    j["speedup_threads_n"] = Median(ratios);
    std::vector<double> ms1, msn;
    for (double t : times) ms1.push_back(1e3 * t);
    for (double t : times_n) msn.push_back(1e3 * t);
    j["update_ms_runs"] = ms1;
    j["update_ms_runs_threads_n"] = msn;
    j["speedup_threads_n_min"] = *std::min_element(ratios.begin(), ratios.end());
    j["speedup_threads_n_max"] = *std::max_element(ratios.begin(), ratios.end());
    if (!times_conc.empty()) {
      // N updates' worth of work in the time N concurrent one-thread learners took, over one alone.
      j["ceiling_threads_n"] = o.threads * med / Median(times_conc);
      j["speedup_of_ceiling"] =
          j["speedup_threads_n"].get<double>() / j["ceiling_threads_n"].get<double>();
    }
  }
  if (o.json) {
    std::cout << j.dump() << std::endl;
  } else {
    std::cout << "PPO epoch on " << o.batch << " samples (obs " << pc.obs_dim << ", act "
              << pc.act_dim << ", 2x64 tanh, " << ActiveDenseKernels().name
              << " kernels): " << j["samples_per_s"].get<double>() << " samples/s (median of "
              << o.repeats << "), actor step " << j["act_steps_per_s"].get<double>()
              << " steps/s\n";
    if (compare) {
      std::cout << o.threads << " threads: " << j["samples_per_s_threads_n"].get<double>()
                << " samples/s, " << j["speedup_threads_n"].get<double>() << "x one thread\n";
    }
  }
}

struct ToyOptions {
  std::string task = "point_mass";
  std::string config_path;  // optional {"policy": {...}, "ppo": {...}}
  std::string out_dir;      // optional: resolved config + final learner state
  int updates = 0;          // 0: the task's default
  uint64_t seed = 0;
  bool json = false;
};

// The toy tasks' defaults: small batches so that they solve in seconds.
PpoConfig ToyPpoConfig(const std::string& task) {
  PpoConfig c;
  if (task == "point_mass") {
    c.steps_per_update = 2048;
    c.num_minibatches = 32;
    c.num_epochs = 10;
    c.learning_rate = 3e-4f;
  } else {
    c.steps_per_update = 512;
    c.num_minibatches = 8;
    c.num_epochs = 4;
    c.learning_rate = 1e-3f;
    c.gamma = 0.0f;  // one-step episodes
  }
  return c;
}

// Trains on a toy task; returns per-update stats and the final deterministic evaluation.
Json RunToy(const ToyOptions& o) {
  std::unique_ptr<Env> env, eval_env;
  PolicyConfig pc;
  if (o.task == "point_mass") {
    env = std::make_unique<PointMassEnv>();
    eval_env = std::make_unique<PointMassEnv>();
    pc = PolicyConfig::Subtask(6);
    pc.act_dim = 2;
  } else if (o.task == "choice_target") {
    env = std::make_unique<ChoiceTargetEnv>();
    eval_env = std::make_unique<ChoiceTargetEnv>();
    pc = PolicyConfig::Meta(6);
  } else {
    throw ConfigError("ppo toy: --task must be point_mass or choice_target, got '" + o.task + "'");
  }
  PpoConfig cfg = ToyPpoConfig(o.task);
  if (!o.config_path.empty()) {
    const Json j = LoadJsonFile(o.config_path);
    CheckKnownKeys(j, {"policy", "ppo"}, o.config_path);
    if (j.contains("policy")) {
      Json merged = ToJson(pc);
      merged.update(j["policy"]);
      pc = PolicyConfigFromJson(merged, o.config_path + ".policy");
    }
    if (j.contains("ppo")) {
      Json merged = ToJson(cfg);
      merged.update(j["ppo"]);
      cfg = PpoConfigFromJson(merged, o.config_path + ".ppo");
    }
  }
  const int updates = o.updates > 0 ? o.updates : (o.task == "point_mass" ? 40 : 30);
  const Json resolved{{"task", o.task},
                      {"seed", o.seed},
                      {"updates", updates},
                      {"policy", ToJson(pc)},
                      {"ppo", ToJson(cfg)}};
  if (!o.out_dir.empty()) {
    std::filesystem::create_directories(o.out_dir);
    SaveJsonFileAtomic(o.out_dir + "/config.json", resolved);
  }
  env->Seed(o.seed);
  eval_env->Seed(o.seed + 1000);
  PpoLearner learner(pc, cfg, o.seed);
  PolicyRunner runner(pc, cfg.obs_norm);
  RolloutCollector collector(env.get(), 0);
  Rng rng(o.seed + 7);
  std::vector<Rollout> batch(1);
  Json curve = Json::array();
  for (int u = 0; u < updates; ++u) {
    runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(),
                      learner.num_updates());
    EpisodeStats es;
    collector.Collect(&runner, rng, cfg.steps_per_update, &batch[0], &es);
    const UpdateStats st = learner.Update(batch);
    double mean_ret = 0;
    for (double x : es.returns) mean_ret += x;
    if (!es.returns.empty()) mean_ret /= es.returns.size();
    Json row = ToJson(st);
    row["update"] = u + 1;
    row["episode_return"] = mean_ret;
    curve.push_back(row);
    spdlog::info("update {}/{}: return {:.3f} kl {:.4f} clip {:.3f} ev {:.2f}", u + 1, updates,
                 mean_ret, st.approx_kl, st.clip_fraction, st.explained_variance);
  }
  // Deterministic evaluation on fresh episodes.
  runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(),
                    learner.num_updates());
  runner.set_update_obs_stats(false);
  RolloutCollector eval(eval_env.get(), 1);
  eval.set_deterministic(true);
  Rollout ro;
  EpisodeStats es;
  eval.Collect(&runner, rng, cfg.steps_per_update, &ro, &es);
  double mean_ret = 0;
  for (double x : es.returns) mean_ret += x;
  if (!es.returns.empty()) mean_ret /= es.returns.size();
  if (!o.out_dir.empty()) {
    proto::LearnerState state;
    learner.ExportState(&state);
    std::string bytes;
    state.SerializeToString(&bytes);
    WriteFileAtomic(o.out_dir + "/learner_state.pb", bytes);
  }
  return Json{{"config", resolved},
              {"curve", curve},
              {"final_deterministic_return", mean_ret},
              {"episodes", es.returns.size()}};
}

}  // namespace

void RegisterLearnerCommands(CLI::App& root, CLI::App& bench) {
  auto bo = std::make_shared<BenchOptions>();
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
  b->add_flag("--json", bo->json, "print one JSON object");
  b->callback([bo] {
    LogToStderr("ppo");
    RunBench(*bo);
  });

  CLI::App* ppo = root.add_subcommand("ppo", "PPO learner tools");
  ppo->require_subcommand(1);
  auto to = std::make_shared<ToyOptions>();
  CLI::App* toy = ppo->add_subcommand("toy", "Train PPO in process on a toy task");
  toy->add_option("--task", to->task, "point_mass or choice_target");
  toy->add_option("--config", to->config_path, "JSON {\"policy\": {...}, \"ppo\": {...}}");
  toy->add_option("--out", to->out_dir, "directory for config.json and learner_state.pb");
  toy->add_option("--updates", to->updates, "PPO updates (default per task)");
  toy->add_option("--seed", to->seed, "seed");
  toy->add_flag("--json", to->json, "print one JSON object");
  toy->callback([to] {
    LogToStderr("ppo");
    const Json j = RunToy(*to);
    if (to->json) {
      std::cout << j.dump() << std::endl;
    } else {
      std::cout << "final deterministic return " << j["final_deterministic_return"].get<double>()
                << "\n";
    }
  });
}

}  // namespace perch
