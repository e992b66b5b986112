#include "bench/env_bench.h"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <iostream>
#include <vector>

#include "envs/chair.h"
#include "envs/humanoid_env.h"

namespace perch {
namespace {

// CPU time of this thread [s]: the benchmark measures one core even on a shared machine.
double ThreadSeconds() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}
double WallSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace

Json RunEnvBench(EnvConfig cfg, const EnvBenchOptions& a) {
  if (cfg.chair == "none")
    cfg.chair = "authors";  // the benchmark is defined in contact with a chair
  if (a.steps < 1 || a.repeats < 1)
    throw ConfigError("bench env: --steps and --repeats must be >= 1");
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
  if (!env.PelvisSeatContact())
    throw std::runtime_error("bench env: the humanoid did not settle on the seat");
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
    state_diff = std::max(
        state_diff,
        (raw.GetState().humanoid.root_pos - env.GetState().world.humanoid.root_pos).norm());
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
                 {"timing",
                  "per 100-step chunk the best of repeats, thread CPU time (one core); "
                  "*_wall: wall clock"},
                 {"pelvis_seat_contact_fraction", static_cast<double>(contact_steps) / total_steps},
                 {"contact_points_at_end", points},
                 {"raw_env_final_root_distance_m", state_diff},
                 {"steps", timed_steps},
                 {"repeats", a.repeats},
                 {"solver_iterations", cfg.physics.solver_iterations},
                 {"chair", cfg.chair}};
  return out;
}

}  // namespace perch
