// perch env demo: the stand task held by a PD hold-pose controller (scripts/train.sh uses it
// until the cluster exists). perch bench env: env vs bare-Bullet control steps per second with
// the humanoid seated on the chair.
#include <time.h>

#include <chrono>
#include <iostream>
#include <memory>

#include "app/commands.h"
#include "common/json_util.h"
#include "envs/humanoid_env.h"

namespace perch {
namespace {

struct EnvArgs {
  std::string config;  // env config JSON (EnvConfig); empty: defaults
  double seconds = 10.0;
  uint64_t seed = 0;
  int steps = 1000;    // bench: control steps per timed run
  int repeats = 10;    // bench: interleaved runs, best kept
  std::string save_config;
  bool json = false;
};

EnvConfig LoadEnvConfig(const EnvArgs& a) {
  return a.config.empty() ? EnvConfig{} : EnvConfig::Load(a.config);
}

// CPU time of this thread [s]: the benchmark measures one core even on a shared machine.
double ThreadSeconds() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}
double WallSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
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
      std::cerr << "env demo: t=" << t * env.spec().control_dt << " s  torso z="
                << env.humanoid_state().root_pos.z() << " m  return=" << ret << "\n";
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

void RunBench(const EnvArgs& a) {
  EnvConfig cfg = LoadEnvConfig(a);
  if (cfg.chair == "none") cfg.chair = "authors";  // the benchmark is defined in contact with a chair
  if (a.steps < 1 || a.repeats < 1) throw ConfigError("bench env: --steps and --repeats must be >= 1");
  // The humanoid sits on the chair, held by the pd action mode's hold-pose action, so it stays in
  // contact for the whole run (constant torques would let it slump off the seat).
  cfg.action_mode = ActionMode::kPd;
  HumanoidChairEnv env(cfg);
  std::vector<float> obs(env.spec().obs_dim), act(env.spec().act_dim);
  const Chair chair = Chair::Load(cfg.ChairPath());
  const HumanoidState seated = SeatedPose(env.model(), chair, cfg.chair_placement, 0.01);
  env.ResetToState(seated, obs.data());
  env.HoldPoseAction(seated.q.data(), act.data());
  for (int t = 0; t < 120; ++t) env.Step(act.data(), obs.data());  // settle onto the seat
  if (!env.PelvisSeatContact()) throw std::runtime_error("bench env: the humanoid did not settle on the seat");
  const EnvState start = env.GetState();

  // Both loops run the same physics from the same states with the same PD law every physics
  // step: the raw loop is bare Bullet (read joints, PD, add torques, step); the env adds its own
  // work (action clipping, state read-back, body poses, contacts, observation, checks, task).
  // The run is cut into chunks, each started from a recorded state; every chunk is timed
  // `repeats` times per loop, alternating the order, and its fastest time kept: on a shared
  // machine this filters out the other jobs' interruptions.
  const int chunk = std::min(a.steps, 100);
  const int chunks = (a.steps + chunk - 1) / chunk;
  std::vector<EnvState> chunk_start;
  env.SetState(start);
  for (int k = 0; k < chunks; ++k) {
    chunk_start.push_back(env.GetState());
    for (int t = 0; t < chunk; ++t) env.Step(act.data(), obs.data());
  }
  World raw(env.model(), &chair, cfg.chair_placement, cfg.physics);
  double env_cpu = 0, raw_cpu = 0, env_wall = 0, raw_wall = 0, state_diff = 0;
  int contact_steps = 0, total_steps = 0;
  for (int k = 0; k < chunks; ++k) {
    double best_env = 1e9, best_raw = 1e9, best_env_wall = 1e9, best_raw_wall = 1e9;
    auto time_raw = [&] {
      raw.SetState(chunk_start[k].world);
      const double c0 = ThreadSeconds(), w0 = WallSeconds();
      raw.RawControlStepsPd(chunk, env.pd(), act.data());
      best_raw = std::min(best_raw, ThreadSeconds() - c0);
      best_raw_wall = std::min(best_raw_wall, WallSeconds() - w0);
    };
    auto time_env = [&] {
      env.SetState(chunk_start[k]);
      int contact = 0;
      const double c0 = ThreadSeconds(), w0 = WallSeconds();
      for (int t = 0; t < chunk; ++t) {
        env.Step(act.data(), obs.data());
        contact += env.PelvisSeatContact();
      }
      best_env = std::min(best_env, ThreadSeconds() - c0);
      best_env_wall = std::min(best_env_wall, WallSeconds() - w0);
      contact_steps += contact;
      total_steps += chunk;
    };
    for (int rep = 0; rep < a.repeats; ++rep) {
      if (rep % 2 == 0) {
        time_raw();
        time_env();
      } else {
        time_env();
        time_raw();
      }
    }
    env_cpu += best_env;
    raw_cpu += best_raw;
    env_wall += best_env_wall;
    raw_wall += best_raw_wall;
    // Same physics in both loops: their states agree at the end of every chunk.
    state_diff = std::max(state_diff, (raw.GetState().humanoid.root_pos -
                                       env.GetState().world.humanoid.root_pos).norm());
    std::cerr << "bench env: chunk " << k + 1 << "/" << chunks << " done\n";
  }
  const int timed_steps = chunks * chunk;
  int self_points = 0;
  const int points = env.world().NumContactPoints(&self_points);
  const double env_rate = timed_steps / env_cpu, raw_rate = timed_steps / raw_cpu;
  const Json out{{"env_ctrl_steps_per_s", env_rate},
                 {"raw_ctrl_steps_per_s", raw_rate},
                 {"env_over_raw", env_rate / raw_rate},
                 {"env_physics_steps_per_s", env_rate * cfg.physics.substeps},
                 {"raw_physics_steps_per_s", raw_rate * cfg.physics.substeps},
                 {"env_ctrl_steps_per_s_wall", timed_steps / env_wall},
                 {"raw_ctrl_steps_per_s_wall", timed_steps / raw_wall},
                 {"timing", "per 100-step chunk the best of repeats, thread CPU time (one core); "
                            "*_wall: wall clock"},
                 {"pelvis_seat_contact_fraction", static_cast<double>(contact_steps) / total_steps},
                 {"contact_points_at_end", points},
                 {"raw_env_final_root_distance_m", state_diff},
                 {"steps", timed_steps},
                 {"repeats", a.repeats},
                 {"solver_iterations", cfg.physics.solver_iterations},
                 {"chair", cfg.chair}};
  if (a.json) {
    std::cout << out.dump() << "\n";
  } else {
    std::cout << out.dump(2) << "\n";
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

  CLI::App* b = bench.add_subcommand("env", "Env vs bare Bullet control steps/s, seated on the chair");
  b->add_option("--config", args->config, "env config JSON");
  b->add_option("--steps", args->steps, "control steps per timed run");
  b->add_option("--repeats", args->repeats, "interleaved runs (best kept)");
  b->add_flag("--json", args->json, "print one JSON object");
  b->callback([args] { RunBench(*args); });
}

}  // namespace perch
