// PPO's hyperparameters, as an experiment config's "ppo" section holds them: the learner trains
// with them (learner/ppo.h); actors read the observation normaliser's settings from them. Shared
// by both roles, so they live here and not with the training code.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "common/json_util.h"
#include "policy/normalizer.h"

namespace perch {

// Every value is a config field. Defaults: paper Table 2 (subtasks) and notes §8.1.
struct PpoConfig {
  int steps_per_update = 8192;  // nsteps: samples per update (the learner waits for this many)
  int num_minibatches = 32;     // minibatch = 256
  int num_epochs = 4;
  float learning_rate = 1e-4f;  // constant unless lr_schedule says otherwise
  // Piecewise-constant learning rate by the run's samples (ours, issue 48): from each entry's
  // samples on, its rate; before the first entry, learning_rate. Empty: constant. Expresses in one
  // config what walk stage 2 once took five resumed stretches to do (docs/ppo.md).
  std::vector<std::pair<int64_t, float>> lr_schedule;
  float gamma = 0.99f;
  float gae_lambda = 0.95f;
  float clip_range = 0.2f;
  float value_coef = 0.5f;
  bool clip_value = true;  // authors' value clipping, same range as the policy
  float value_clip_range = 0.2f;
  float entropy_coef = 0.0f;
  float max_grad_norm = 0.5f;  // global L2 norm; <= 0 disables
  float adam_beta1 = 0.9f;
  float adam_beta2 = 0.999f;
  float adam_eps = 1e-5f;
  bool normalize_advantages = true;  // per minibatch, (A - mean) / (std + 1e-8)
  float advantage_eps = 1e-8f;
  // DEVELOPERS.md: bootstrap on truncation. The authors treated the time limit as terminal (false).
  bool bootstrap_on_truncation = true;
  // Threads of the PPO update (ours, issue 20): each minibatch's gradient is split across them.
  // A count gives the same result every run; counts differ only in floating-point summation order.
  int threads = 1;
  // Off-policy correction for segments that acted with older weights than the learner's (policy
  // lag >= 1; ours, issue 20): V-trace's truncated importance weights (Espeholt et al. 2018) on
  // the advantages and value targets, rho_t = min(vtrace_rho_clip, pi/mu), c_t = min(vtrace_c_clip,
  // pi/mu), with the learner's current value network; PPO's ratio is then taken against the
  // learner's policy at the start of the update. Segments of the current version are unchanged
  // (plain GAE). Off: lagged segments are trained on as if on-policy (Baselines PPO2).
  bool vtrace = false;
  float vtrace_rho_clip = 1.0f;
  float vtrace_c_clip = 1.0f;
  NormalizerConfig obs_norm;
  RewardScalingConfig reward_scaling;

  static PpoConfig Subtask();  // 8192 / 32 / 4 / 1e-4
  static PpoConfig Meta();     // 64 / 8 / 2 / 1e-4
};
const FieldTable<PpoConfig>& PpoConfigFields();
Json ToJson(const PpoConfig& c);
// The learning rate after `samples` samples of the run (lr_schedule, else learning_rate).
float LearningRateAt(const PpoConfig& c, int64_t samples);
PpoConfig PpoConfigFromJson(const Json& j, const std::string& ctx);  // strict

}  // namespace perch
