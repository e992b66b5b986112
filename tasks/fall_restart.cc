#include "tasks/fall_restart.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace perch {

namespace {
// The restart coin and pool draws use their own stream, so the env's episode stream (spawns,
// targets) is the same as without the curriculum up to the first restart.
constexpr uint64_t kRestartSalt = 0x9e3779b97f4a7c15ull;
}  // namespace

FallRestartEnv::FallRestartEnv(std::unique_ptr<HumanoidChairEnv> env, WalkTask* task,
                               const WalkTaskConfig& config)
    : env_(std::move(env)),
      task_(task),
      prob_(config.fall_restart_prob),
      lead_steps_(std::max(
          1, static_cast<int>(std::lround(config.fall_restart_lead_s / task->control_dt())))),
      pool_cap_(config.fall_restart_pool),
      recent_(lead_steps_) {}

void FallRestartEnv::Seed(uint64_t seed) {
  env_->Seed(seed);
  rng_.Seed(seed ^ kRestartSalt);
}

void FallRestartEnv::Record(const float* obs, Snapshot* s) const {
  s->env = env_->GetState();
  s->task = task_->GetMemory();
  s->obs.assign(obs, obs + env_->spec().obs_dim);
}

void FallRestartEnv::Reset(float* obs) {
  recent_count_ = 0;
  recent_next_ = 0;
  if (!pool_.empty() && rng_.Uniform(0.0, 1.0) < prob_) {
    const Snapshot& s = pool_[rng_.UniformInt(pool_.size())];
    env_->SetState(s.env);
    task_->SetMemory(s.task);
    std::copy(s.obs.begin(), s.obs.end(), obs);
    ++restarts_;
  } else {
    env_->Reset(obs);
  }
  Record(obs, &recent_[recent_next_]);
  recent_next_ = (recent_next_ + 1) % static_cast<int>(recent_.size());
  recent_count_ = 1;
}

StepResult FallRestartEnv::Step(const float* action, float* obs) {
  const StepResult r = env_->Step(action, obs);
  const int ring = static_cast<int>(recent_.size());
  if (r.terminated && !r.invalid) {
    // The oldest state in the full ring is lead_steps_ before this fall (which is not recorded).
    if (recent_count_ == ring) {
      Snapshot s = recent_[recent_next_];
      // A fresh time limit from the restart; the reference phase stays where it was.
      s.task.t0 += s.env.step * task_->control_dt();
      s.env.step = 0;
      if (static_cast<int>(pool_.size()) < pool_cap_) {
        pool_.push_back(std::move(s));
      } else {
        pool_[pool_next_] = std::move(s);
        pool_next_ = (pool_next_ + 1) % pool_cap_;
      }
      ++falls_recorded_;
    }
    return r;
  }
  Record(obs, &recent_[recent_next_]);
  recent_next_ = (recent_next_ + 1) % ring;
  recent_count_ = std::min(recent_count_ + 1, ring);
  return r;
}

}  // namespace perch
