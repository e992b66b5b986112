// Small tasks that prove the learner learns, fast enough for unit tests and for quick end-to-end
// checks of the cluster. They are test tasks, not the product: the product envs live in envs/.
#pragma once

#include <cstdint>

#include "common/env.h"
#include "common/rng.h"

namespace perch {

// A 2-D point mass pushed by a force to a random target (continuous control, 2-d action).
// obs [6] = position (2, m), velocity (2, m/s), target (2, m); action [2] = force, clipped to
// [-1, 1] and scaled by max_accel. Reward per step:
// max_reward * (1 - |position - target| / reward_scale).
// Leaving the arena (|x| or |y| > arena) terminates; the time limit truncates.
struct PointMassConfig {
  float dt = 0.1f;            // s per step
  float max_accel = 2.0f;     // m/s^2 at |action| = 1
  float damping = 0.9f;       // velocity kept per step
  float start_range = 1.0f;   // positions and targets ~ U(-start_range, start_range)
  float arena = 2.0f;         // m
  float max_reward = 1.0f;    // per step, at the target
  float reward_scale = 2.0f;  // m: reward falls by max_reward per reward_scale of distance
  int max_episode_steps = 50;
};

class PointMassEnv : public Env {
 public:
  explicit PointMassEnv(const PointMassConfig& config = PointMassConfig());
  const EnvSpec& spec() const override { return spec_; }
  void Seed(uint64_t seed) override { rng_.Seed(seed); }
  void Reset(float* obs) override;
  StepResult Step(const float* action, float* obs) override;

 private:
  void Observe(float* obs) const;
  PointMassConfig config_;
  EnvSpec spec_;
  Rng rng_;
  float pos_[2] = {0, 0}, vel_[2] = {0, 0}, target_[2] = {0, 0};
  int t_ = 0;
};

// A one-step task for the meta head (paper §5): a one-hot context (num_choices) says which choice
// is right; a goal point (2, U(-1, 1)) says where the target should go. Action [1 + 2] = (choice,
// target). Reward: 0 for a wrong choice; right_choice_reward for a right choice other than
// target_choice; for a right target_choice: target_base_reward + target_bonus_reward *
// exp(-|target - goal|^2 / target_width^2). Every step terminates.
struct ChoiceTargetConfig {
  int num_choices = 4;
  int target_choice = 3;
  float target_width = 0.5f;  // m
  float right_choice_reward = 1.0f;
  float target_base_reward = 0.5f;   // a right walk choice always beats a wrong choice
  float target_bonus_reward = 0.5f;  // for hitting the goal
};

class ChoiceTargetEnv : public Env {
 public:
  explicit ChoiceTargetEnv(const ChoiceTargetConfig& config = ChoiceTargetConfig());
  const EnvSpec& spec() const override { return spec_; }
  void Seed(uint64_t seed) override { rng_.Seed(seed); }
  void Reset(float* obs) override;
  StepResult Step(const float* action, float* obs) override;
  int context() const { return context_; }
  const float* goal() const { return goal_; }

 private:
  void Draw(float* obs);
  ChoiceTargetConfig config_;
  EnvSpec spec_;
  Rng rng_;
  int context_ = 0;
  float goal_[2] = {0, 0};
};

}  // namespace perch
