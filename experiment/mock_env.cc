#include "experiment/mock_env.h"

#include <algorithm>
#include <cmath>

namespace perch {

const FieldTable<MockEnvConfig>& MockEnvConfigFields() {
  static const FieldTable<MockEnvConfig> t =
      FieldTable<MockEnvConfig>()
          .Add("act_dim", &MockEnvConfig::act_dim, "action size (the goal's too)",
               Satisfies<int>([](const int& v) { return v >= 1; }, "must be >= 1"))
          .Add("noise_dims", &MockEnvConfig::noise_dims, "observation entries of pure noise",
               Satisfies<int>([](const int& v) { return v >= 0; }, "must be >= 0"))
          .Add("episode_steps", &MockEnvConfig::episode_steps, "time limit [steps]",
               Satisfies<int>([](const int& v) { return v >= 1; }, "must be >= 1"))
          .Add("fail_distance", &MockEnvConfig::fail_distance,
               "terminate when the action is this far from the goal")
          .Add("reward_scale", &MockEnvConfig::reward_scale, "reward multiplier")
          .Add("work_iterations", &MockEnvConfig::work_iterations,
               "busy work per step (a stand-in for physics cost in transport benchmarks)",
               Satisfies<int>([](const int& v) { return v >= 0; }, "must be >= 0"));
  return t;
}

Json ToJson(const MockEnvConfig& c) { return MockEnvConfigFields().Write(c); }

MockEnvConfig MockEnvConfigFromJson(const Json& j, const std::string& ctx) {
  return MockEnvConfigFields().Read(j, ctx);
}

MockEnv::MockEnv(const MockEnvConfig& config) : config_(config), goal_(config.act_dim) {
  spec_.name = "mock";
  spec_.act_dim = config.act_dim;
  // Observation: goal [act_dim], previous clipped action [act_dim], noise [noise_dims].
  spec_.obs_dim = 2 * config.act_dim + config.noise_dims;
  spec_.obs_low.assign(spec_.obs_dim, -5.0f);
  spec_.obs_high.assign(spec_.obs_dim, 5.0f);
  spec_.act_low.assign(spec_.act_dim, -1.0f);
  spec_.act_high.assign(spec_.act_dim, 1.0f);
  spec_.obs_slices = {{"goal", 0, config.act_dim},
                      {"last_action", config.act_dim, config.act_dim},
                      {"noise", 2 * config.act_dim, config.noise_dims}};
  spec_.max_episode_steps = config.episode_steps;
}

void MockEnv::Observe(const float* last_action, float* obs) {
  const int a = config_.act_dim;
  for (int i = 0; i < a; ++i) {
    obs[i] = goal_[i];
    obs[a + i] = last_action ? last_action[i] : 0.0f;
  }
  for (int i = 0; i < config_.noise_dims; ++i) obs[2 * a + i] = static_cast<float>(rng_.Normal());
}

void MockEnv::Reset(float* obs) {
  for (float& g : goal_) g = static_cast<float>(rng_.Uniform(-1.0, 1.0));
  t_ = 0;
  Observe(nullptr, obs);
}

StepResult MockEnv::Step(const float* action, float* obs) {
  StepResult r;
  std::vector<float> clipped(config_.act_dim);
  double err2 = 0.0;
  bool finite = true;
  for (int i = 0; i < config_.act_dim; ++i) {
    finite = finite && std::isfinite(action[i]);
    clipped[i] = std::clamp(action[i], -1.0f, 1.0f);
    const double d = action[i] - goal_[i];  // unclipped: far-off actions "fall"
    err2 += d * d;
  }
  // Emulated physics cost; volatile so that the loop is not optimised away.
  volatile double sink = 0.0;
  for (int k = 0; k < config_.work_iterations; ++k) sink = sink + std::sqrt(k + 1.0);
  double clip_err2 = 0.0;
  for (int i = 0; i < config_.act_dim; ++i) {
    const double d = clipped[i] - goal_[i];
    clip_err2 += d * d;
  }
  ++t_;
  r.reward = static_cast<float>(config_.reward_scale * (1.0 - clip_err2 / config_.act_dim));
  r.invalid = !finite;
  r.terminated = !finite || std::sqrt(err2) > config_.fail_distance;
  r.truncated = !r.terminated && t_ >= config_.episode_steps;
  Observe(clipped.data(), obs);
  return r;
}

}  // namespace perch
