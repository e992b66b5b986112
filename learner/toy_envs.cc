#include "learner/toy_envs.h"

#include <algorithm>
#include <cmath>

namespace perch {

PointMassEnv::PointMassEnv(const PointMassConfig& config) : config_(config) {
  spec_.name = "point_mass";
  spec_.obs_dim = 6;
  spec_.act_dim = 2;
  spec_.obs_low.assign(6, -config.arena);
  spec_.obs_high.assign(6, config.arena);
  spec_.act_low.assign(2, -1.0f);
  spec_.act_high.assign(2, 1.0f);
  spec_.obs_slices = {{"position", 0, 2}, {"velocity", 2, 2}, {"target", 4, 2}};
  spec_.control_dt = config.dt;
  spec_.max_episode_steps = config.max_episode_steps;
}

void PointMassEnv::Observe(float* obs) const {
  obs[0] = pos_[0];
  obs[1] = pos_[1];
  obs[2] = vel_[0];
  obs[3] = vel_[1];
  obs[4] = target_[0];
  obs[5] = target_[1];
}

void PointMassEnv::Reset(float* obs) {
  const double r = config_.start_range;
  for (int i = 0; i < 2; ++i) {
    pos_[i] = static_cast<float>(rng_.Uniform(-r, r));
    target_[i] = static_cast<float>(rng_.Uniform(-r, r));
    vel_[i] = 0.0f;
  }
  t_ = 0;
  Observe(obs);
}

StepResult PointMassEnv::Step(const float* action, float* obs) {
  StepResult res;
  for (int i = 0; i < 2; ++i) {
    const float a = std::clamp(action[i], -1.0f, 1.0f);
    vel_[i] = config_.damping * vel_[i] + config_.max_accel * config_.dt * a;
    pos_[i] += config_.dt * vel_[i];
  }
  ++t_;
  const float dx = pos_[0] - target_[0], dy = pos_[1] - target_[1];
  res.reward = config_.max_reward * (1.0f - std::sqrt(dx * dx + dy * dy) / config_.reward_scale);
  res.terminated = std::abs(pos_[0]) > config_.arena || std::abs(pos_[1]) > config_.arena;
  res.truncated = !res.terminated && t_ >= config_.max_episode_steps;
  Observe(obs);
  return res;
}

ChoiceTargetEnv::ChoiceTargetEnv(const ChoiceTargetConfig& config) : config_(config) {
  spec_.name = "choice_target";
  spec_.obs_dim = config.num_choices + 2;
  spec_.act_dim = 3;
  spec_.obs_low.assign(spec_.obs_dim, -1.0f);
  spec_.obs_high.assign(spec_.obs_dim, 1.0f);
  spec_.act_low = {0.0f, -1e3f, -1e3f};
  spec_.act_high = {static_cast<float>(config.num_choices - 1), 1e3f, 1e3f};
  spec_.obs_slices = {{"context", 0, config.num_choices}, {"goal", config.num_choices, 2}};
  spec_.max_episode_steps = 1;
}

void ChoiceTargetEnv::Draw(float* obs) {
  context_ = static_cast<int>(rng_.UniformInt(config_.num_choices));
  goal_[0] = static_cast<float>(rng_.Uniform(-1.0, 1.0));
  goal_[1] = static_cast<float>(rng_.Uniform(-1.0, 1.0));
  for (int i = 0; i < config_.num_choices; ++i) obs[i] = i == context_ ? 1.0f : 0.0f;
  obs[config_.num_choices] = goal_[0];
  obs[config_.num_choices + 1] = goal_[1];
}

void ChoiceTargetEnv::Reset(float* obs) { Draw(obs); }

StepResult ChoiceTargetEnv::Step(const float* action, float* obs) {
  StepResult res;
  const int choice = static_cast<int>(std::lround(action[0]));
  if (choice == context_) {
    if (choice == config_.target_choice) {
      const float dx = action[1] - goal_[0], dy = action[2] - goal_[1];
      const float w2 = config_.target_width * config_.target_width;
      res.reward = config_.target_base_reward +
                   config_.target_bonus_reward * std::exp(-(dx * dx + dy * dy) / w2);
    } else {
      res.reward = config_.right_choice_reward;
    }
  }
  res.terminated = true;
  Draw(obs);  // the next episode's first observation (ignored after termination)
  return res;
}

}  // namespace perch
