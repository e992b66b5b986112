// A cheap perch::Env for testing the transport and the training loop (NOT a deliverable env).
// Each episode draws a target point g in [-1, 1]^act_dim; the observation holds g and the previous
// action; the reward is reward_scale * (1 - |a_clipped - g|^2 / act_dim) per step. A policy that
// learns to output g from the observation gets return -> episode_steps * reward_scale. An episode
// is terminated (a "fall") when the action is further than fail_distance from g, otherwise
// truncated at episode_steps.
#pragma once

#include <cstdint>
#include <string>

#include "common/env.h"
#include "common/field_table.h"
#include "common/json_util.h"
#include "common/rng.h"

namespace perch {

struct MockEnvConfig {
  int act_dim = 2;
  int noise_dims = 2;          // extra observation entries of pure noise
  int episode_steps = 64;      // truncation limit
  float fail_distance = 2.5f;  // |a - g| above this terminates
  float reward_scale = 1.0f;
  int work_iterations = 0;  // busy-loop per step, to emulate an expensive env in benchmarks
};
// The mock_env section's fields, each written once (common/field_table.h).
const FieldTable<MockEnvConfig>& MockEnvConfigFields();
Json ToJson(const MockEnvConfig& c);
MockEnvConfig MockEnvConfigFromJson(const Json& j, const std::string& ctx);

class MockEnv : public Env {
 public:
  explicit MockEnv(const MockEnvConfig& config);
  const EnvSpec& spec() const override { return spec_; }
  void Seed(uint64_t seed) override { rng_.Seed(seed); }
  void Reset(float* obs) override;
  StepResult Step(const float* action, float* obs) override;

 private:
  void Observe(const float* last_action, float* obs);
  MockEnvConfig config_;
  EnvSpec spec_;
  Rng rng_;
  std::vector<float> goal_;  // [act_dim]
  int t_ = 0;
};

}  // namespace perch
