// perch env demo: the stand task held by a PD hold-pose controller (scripts/train.sh uses it
// until the cluster exists). perch bench env: env vs bare-Bullet control steps per second with
// the humanoid seated on the chair.
#include <time.h>

#include <chrono>
#include <iostream>
#include <memory>

#include "app/commands.h"
#include "bench/env_bench.h"
#include "common/json_util.h"
#include "envs/humanoid_env.h"

namespace perch {
namespace {

struct EnvArgs {
  std::string config;  // env config JSON (EnvConfig); empty: defaults
  double seconds = 10.0;
  uint64_t seed = 0;
  int steps = 1000;  // bench: control steps per timed run
  int repeats = 10;  // bench: interleaved runs, best kept
  std::string save_config;
  bool json = false;
};

EnvConfig LoadEnvConfig(const EnvArgs& a) {
  return a.config.empty() ? EnvConfig{} : EnvConfig::Load(a.config);
}

void RunDemo(const EnvArgs& a) {
  EnvConfig cfg = LoadEnvConfig(a);
  cfg.action_mode = ActionMode::kPd;  // the hold-pose controller commands target angles
  if (!a.save_config.empty()) SaveJsonFileAtomic(a.save_config, cfg.ToJson());
  HumanoidChairEnv env(cfg);
  env.Seed(a.seed);
  std::vector<float> obs(env.spec().obs_dim), act(env.spec().act_dim);
  env.Reset(obs.data());
  const int steps = static_cast<int>(a.seconds / env.spec().control_dt + 0.5);
  const int per_second = static_cast<int>(1.0 / env.spec().control_dt + 0.5);
  env.HoldPoseAction(env.humanoid_state().q.data(), act.data());
  double ret = 0.0;
  int episodes = 1, falls = 0, invalid = 0;
  for (int t = 1; t <= steps; ++t) {
    const StepResult r = env.Step(act.data(), obs.data());
    ret += r.reward;
    if (t % per_second == 0 || t == steps) {
      std::cerr << "env demo: t=" << t * env.spec().control_dt
                << " s  torso z=" << env.humanoid_state().root_pos.z() << " m  return=" << ret
                << "\n";
    }
    if (r.terminated || r.truncated) {
      falls += r.terminated && !r.invalid;
      invalid += r.invalid;
      if (t == steps) break;
      ++episodes;
      env.Reset(obs.data());
      env.HoldPoseAction(env.humanoid_state().q.data(), act.data());
    }
  }
  const double z = env.humanoid_state().root_pos.z();
  if (a.json) {
    std::cout << Json{{"seconds", steps * env.spec().control_dt},
                      {"control_steps", steps},
                      {"final_root_height_m", z},
                      {"return", ret},
                      {"episodes", episodes},
                      {"falls", falls},
                      {"invalid", invalid},
                      {"seed", a.seed},
                      {"config", cfg.ToJson()}}
                     .dump()
              << "\n";
  } else {
    std::cout << "final root height: " << z << " m (" << falls << " falls, " << invalid
              << " invalid, return " << ret << ")\n";
  }
}

}  // namespace

void RegisterEnvCommands(CLI::App& root, CLI::App& bench) {
  auto args = std::make_shared<EnvArgs>();
  CLI::App* env = root.add_subcommand("env", "The humanoid-chair environment");
  env->require_subcommand(1);
  CLI::App* demo = env->add_subcommand("demo", "Stand task under a PD hold-pose controller");
  demo->add_option("--config", args->config, "env config JSON (defaults: the paper's values)");
  demo->add_option("--seconds", args->seconds, "simulated seconds");
  demo->add_option("--seed", args->seed, "seed");
  demo->add_option("--save-config", args->save_config, "write the resolved env config here");
  demo->add_flag("--json", args->json, "print one JSON object");
  demo->callback([args] { RunDemo(*args); });

  CLI::App* b =
      bench.add_subcommand("env", "Env vs bare Bullet control steps/s, seated on the chair");
  b->add_option("--config", args->config, "env config JSON");
  b->add_option("--steps", args->steps, "control steps per timed run");
  b->add_option("--repeats", args->repeats, "interleaved runs (best kept)");
  b->add_flag("--json", args->json, "print one JSON object");
  b->callback([args] {
    EnvBenchOptions o;
    o.steps = args->steps;
    o.repeats = args->repeats;
    const Json out = RunEnvBench(LoadEnvConfig(*args), o);
    std::cout << (args->json ? out.dump() : out.dump(2)) << "\n";
  });
}

}  // namespace perch
