// A training curriculum for the walk task (ours; off by default): part of the episodes start
// from a state recorded shortly before one of the env's own recent falls, so the rare situations
// that end in falls (a sharp turn after a passed target, a stumble after a re-draw) are practised
// more often than they occur. The recorded state is the whole episode state (physics, foot
// flags, walk target, countdown, reference phase, observation), so the restarted episode
// continues exactly as the original did at that point, with a fresh time limit.
#pragma once

#include <memory>
#include <vector>

#include "common/env.h"
#include "common/rng.h"
#include "envs/humanoid_env.h"
#include "tasks/walk.h"

namespace perch {

class FallRestartEnv : public Env {
 public:
  // `env` must run `task` (the walk task it was built with). Uses config.fall_restart_*.
  FallRestartEnv(std::unique_ptr<HumanoidChairEnv> env, WalkTask* task,
                 const WalkTaskConfig& config);

  const EnvSpec& spec() const override { return env_->spec(); }
  void Seed(uint64_t seed) override;
  void Reset(float* obs) override;
  StepResult Step(const float* action, float* obs) override;

  const HumanoidChairEnv& env() const { return *env_; }
  int pool_size() const { return static_cast<int>(pool_.size()); }
  int64_t falls_recorded() const { return falls_recorded_; }
  int64_t restarts() const { return restarts_; }

 private:
  struct Snapshot {
    EnvState env;            // in the pool: step rebased to 0
    WalkTask::Memory task;   // in the pool: t0 shifted by the rebased steps
    std::vector<float> obs;  // [obs_dim] the observation the policy saw at that point
  };
  void Record(const float* obs, Snapshot* s) const;

  std::unique_ptr<HumanoidChairEnv> env_;
  WalkTask* task_;
  double prob_;
  int lead_steps_;
  int pool_cap_;
  Rng rng_;
  std::vector<Snapshot> recent_;  // ring of the last lead_steps_ states of this episode
  int recent_next_ = 0;
  int recent_count_ = 0;
  std::vector<Snapshot> pool_;  // states lead_steps_ before a fall, oldest replaced
  int pool_next_ = 0;
  int64_t falls_recorded_ = 0;
  int64_t restarts_ = 0;
};

}  // namespace perch
