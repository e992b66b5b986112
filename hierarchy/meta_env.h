// The hierarchy as an env (paper Sec. 5; notes 4.7): one Step() of MetaEnv is one meta decision.
// The action is the hybrid meta action [switch class, theta rad, dist m]; the env sets the walk
// target, then runs `meta.period` control steps (60 Hz) of the chosen frozen subtask policy on
// the sit_chair humanoid env (240 Hz physics inside), and returns the meta reward (Eq. 8) of that
// meta step. The actor loop sees a plain Env: it knows nothing about subtasks or humanoids.
//
// The frozen subtask policies arrive through FrozenPolicyEnv: the learner ships them with the
// weights (actors on a cluster read no files); local tools load them from the files the config
// names (LoadFrozenPolicies).
#pragma once

#include <array>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/env.h"
#include "common/rng.h"
#include "envs/humanoid_env.h"
#include "hierarchy/hierarchy.h"
#include "tasks/perturbation.h"
#include "tasks/task_env.h"

namespace perch {

// What happened in the current (or last) episode, for evaluation.
struct MetaEpisode {
  std::vector<int> sequence;  // SubtaskId of each run of one subtask, in order
  // [run] that subtask's own critic when it began (SubtaskPolicies::Value; the walker's with the
  // target its meta step set).
  std::vector<float> begin_value;
  double min_dist_m = 0.0;  // minimum pelvis - seat target distance [m]
  int success_step = -1;    // control step at which 3 s of seated contact completed
  bool fell = false;        // early termination
  int control_steps = 0;
  double spawn_theta = 0.0;  // azimuth of the spawn around the zone centre [rad]
  // At success: pelvis horizontal distance to the seat target [m], the pelvis's height above it
  // [m] (the pelvis capsule's radius, 0.09 m, keeps it well above the seat surface) and root yaw
  // error to the chair's facing direction [rad].
  double seated_pos_err_m = 0.0;
  double seated_height_m = 0.0;
  double seated_yaw_err_rad = 0.0;
};

// A meta episode's complete state (the humanoid env's, its task's memory, the subtasks' clocks
// and the meta env's own): restored into a MetaEnv with the same config and frozen policies it
// continues exactly as the env that saved it would after restoring it too
// (hierarchy/meta_lookahead.h).
struct MetaEnvState {
  EnvState env;
  Json task_memory;
  SubtaskPolicies::Clocks clocks;
  Rng rng;
  int active = 0, order_pos = 0;
  bool begun = false;
  int active_steps = 0;
  SitChairTask::Seated seated;  // the task's success counters
  int blend_from = 0, blend_left = 0;
  double prev_dist = 0.0;  // [m]
  MetaEpisode episode;
};

class MetaEnv : public Env, public FrozenPolicyEnv {
 public:
  // config.env.task must be sit_chair; its section's `meta` says which subtasks run.
  explicit MetaEnv(const TaskEnvConfig& config);
  ~MetaEnv() override;

  const EnvSpec& spec() const override { return spec_; }
  void Seed(uint64_t seed) override;
  void Reset(float* obs) override;
  StepResult Step(const float* action, float* obs) override;

  std::vector<std::string> frozen_policy_names() const override;
  bool has_frozen_policies() const override { return policies_ != nullptr; }
  void SetFrozenPolicies(const std::vector<FrozenPolicyData>& policies) override;

  const HumanoidChairEnv& humanoid() const { return *env_; }
  const MetaConfig& meta() const { return meta_; }
  const MetaEpisode& episode() const { return episode_; }
  int active() const { return active_; }  // SubtaskId acting now
  // Subtask `id`'s own critic on the current state, as if it began now (SubtaskPolicies::Value).
  float SubtaskValue(int id) const;
  // The acting subtask's critic on the current state, on its own clock.
  float ActiveValue() const;
  // Save / restore the episode (needs the frozen policies). Restoring rebuilds the physics world
  // (Bullet's contact caches start empty), so two envs restored from one state step identically,
  // but not bit-identically to the env that saved it had it gone on without a restore.
  MetaEnvState SaveState() const;
  // The observation Step last wrote, written again for the current state (after a restore).
  void Observe(float* obs) const { WriteObservation(obs); }
  void RestoreState(const MetaEnvState& s);
  // Called after every control step (recordings, filmstrips): the env, its step result and the
  // acting subtask.
  std::function<void(const HumanoidChairEnv&, const StepResult&, int active)> on_control_step;
  // Called when a subtask (re)starts, before its first action (start-state banks of hand-overs).
  std::function<void(const HumanoidChairEnv&, int sub)> on_subtask_begin;
  // An evaluation's perturbations (perch eval --task sit_chair --push, --obs-noise, --act-noise,
  // --restore; issue 49), from the next Reset on: each episode gets its push and restore at
  // control steps drawn uniformly in [0, horizon_steps), the noises on what the meta and the
  // subtasks see and on the subtasks' actions, all from an RNG of their own seeded with the
  // episode, so its other draws are the unperturbed episode's. A push is applied step by step
  // from here, so it lasts across the lookahead's restores. Perturbation(): none.
  void SetPerturbation(const Perturbation& p, int horizon_steps);

 private:
  void WriteObservation(float* obs) const;
  void Perturb();                // before a control step: the push and the restore
  void AddObsNoise(float* obs);  // the meta's observation
  Perturbation perturb_;
  int perturb_horizon_ = 1;  // [control steps]
  Rng perturb_rng_;
  int push_step_ = -1, restore_step_ = -1;                // this episode's [control step]; -1: none
  int push_left_ = 0;                                     // control steps the push still lasts
  Eigen::Vector3d push_force_ = Eigen::Vector3d::Zero();  // [N], world frame
  TaskEnvConfig config_;
  SitChairTaskConfig task_config_;
  MetaConfig meta_;
  std::vector<int> choice_ids_;  // SubtaskId per switch class
  std::unique_ptr<HumanoidChairEnv> env_;
  SitChairTask* task_ = nullptr;  // owned by env_
  std::unique_ptr<SubtaskPolicies> policies_;
  EnvSpec spec_;
  Rng rng_;  // the subtasks' action noise
  std::vector<float> inner_obs_, action_, blend_action_;
  int blend_from_ = 0;  // meta.blend_steps: the subtask faded out, for blend_left_ more steps
  int blend_left_ = 0;
  int active_ = kWalk;
  int order_pos_ = 0;  // fixed_order: index in choices of the running subtask
  bool begun_ = false;
  int active_steps_ = 0;    // control steps the active subtask has run
  double prev_dist_ = 0.0;  // pelvis - seat distance at the previous meta-step end [m]
  MetaEpisode episode_;
};

// The frozen subtask policies the config's sit_chair.meta names (only the chosen ones), read
// from their files and checked against the layouts they must observe (ConfigError naming the
// subtask and the file otherwise).
std::vector<FrozenPolicyData> LoadFrozenPolicies(const TaskEnvConfig& config);

}  // namespace perch
