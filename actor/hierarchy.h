// The actor's per-env stepping loop, with the paper's hierarchy (§3, §5; notes §4.7): a meta
// policy decides every `meta_period` control steps (30 steps = 0.495 s, about 2 Hz) which subtask
// runs and where the walk target is; the chosen subtask policy acts every control step (60 Hz);
// the env runs its physics at 240 Hz inside Step(). With the hierarchy off, the trained subtask
// policy acts directly (single-task training, what is used now).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "common/env.h"
#include "common/rng.h"
#include "learner/policy.h"
#include "learner/rollout.h"

namespace perch {

// Implemented by an env that can run under the meta controller (the full sit task).
class HierarchyEnv {
 public:
  virtual ~HierarchyEnv() = default;
  virtual int num_subtasks() const = 0;
  // Observation of subtask k (its own layout, k in meta choice order: 0 left turn, 1 right turn,
  // 2 sit, 3 walk), for the current state.
  virtual int subtask_obs_dim(int k) const = 0;
  virtual void SubtaskObservation(int k, float* obs) = 0;
  // The meta action's target (theta rad, dist m), relative to the current heading.
  virtual void SetWalkTarget(float theta, float dist) = 0;
};

// Steps one env for a segment. Single-task: T control steps of `trained` (RolloutCollector).
// Meta (trained->model().config().kind == kMeta): T meta steps; each applies the meta action and
// then meta_period control steps of the frozen subtask policy it chose; the reward of a meta step
// is the sum of the env's non-NaN rewards over it.
class HierarchicalCollector {
 public:
  HierarchicalCollector(Env* env, uint64_t stream_id, int meta_period);

  // subtasks[k]: frozen policy of subtask k (meta mode only; may be empty otherwise).
  void Collect(PolicyRunner* trained, const std::vector<PolicyRunner*>& subtasks, Rng& rng,
               int steps, Rollout* out, EpisodeStats* stats);
  uint64_t control_steps() const { return control_steps_; }
  uint64_t meta_decisions() const { return meta_decisions_; }

 private:
  void CollectMeta(PolicyRunner* meta, const std::vector<PolicyRunner*>& subtasks, Rng& rng,
                   int steps, Rollout* out, EpisodeStats* stats);
  Env* env_;
  HierarchyEnv* henv_;  // env_ as HierarchyEnv, or null
  uint64_t stream_id_;
  int meta_period_;
  RolloutCollector single_;
  uint64_t control_steps_ = 0;
  uint64_t meta_decisions_ = 0;
  // Meta-mode episode state.
  bool need_reset_ = true;
  double episode_return_ = 0.0;
  int episode_length_ = 0;
  std::vector<float> obs_, next_obs_, norm_obs_, meta_action_, sub_obs_, sub_norm_, sub_action_;
};

}  // namespace perch
