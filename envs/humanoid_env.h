// The humanoid-chair environment: a perch::Env over the Bullet World, with the authors'
// observations (notes 2), the two action modes, spawn zones, invalid-state detection and a
// pluggable task (reward, termination, time limit). The actor sees only perch::Env (MakeEnv).
#pragma once

#include <array>
#include <memory>
#include <optional>
#include <vector>

#include "common/env.h"
#include "common/rng.h"
#include "envs/chair.h"
#include "envs/env_config.h"
#include "envs/humanoid_model.h"
#include "envs/humanoid_world.h"
#include "envs/pd_controller.h"

namespace perch {

class HumanoidChairEnv;

// Task hook: tasks/ adds walk (and later turn / sit / meta) as further subclasses. A task's own
// memory (reference phase, previous distances) is not part of EnvState.
struct TaskStep {
  float reward = 0.0f;
  bool terminated = false;  // e.g. fell
  bool success = false;     // the task's success test passed at this step (once per episode)
};

class Task {
 public:
  virtual ~Task() = default;
  virtual const char* name() const = 0;
  virtual int max_episode_steps() const = 0;
  // Whether OnStep ever reports success (training metrics count it; docs/subtasks.md).
  virtual bool has_success() const { return false; }
  // Chooses the episode's initial state (world frame), e.g. a reference frame (reference state
  // initialisation); returning false keeps the env's spawn (config.spawn, config.init).
  virtual bool InitialState(const HumanoidChairEnv& env, Rng& rng, HumanoidState* s) {
    return false;
  }
  // After the initial state is in place, before the first observation (may set the walk target).
  virtual void OnReset(HumanoidChairEnv& env, Rng& rng) {}
  // After the physics of each step, before its observation is written (notes 4.6: the walk
  // target is re-drawn there). Not called on an invalid step.
  virtual void BeforeObservation(HumanoidChairEnv& env, Rng& rng) {}
  // After the physics of one control step; `action` is the raw (unclipped) policy action.
  virtual TaskStep OnStep(const HumanoidChairEnv& env, const float* action) = 0;
  // The task's per-episode memory as JSON, and back (start-state banks): with the env's EnvState
  // it continues an episode from a saved point. Tasks without memory keep the defaults.
  // The last step's named reward terms (recordings, diagnostics); tasks without terms: {}.
  virtual Json LastRewardTerms() const { return Json::object(); }
  virtual Json SaveMemory() const { return Json::object(); }
  virtual void LoadMemory(const Json& memory) {}
};

std::unique_ptr<Task> MakeTask(const EnvConfig& config);

// The env's left/right symmetry on observations of `layout` and actions (EnvSpec::mirror), from
// the model's mirrored joints (MirrorJointMap), their limits and their motor strengths.
MirrorMap BuildMirrorMap(const HumanoidModel& model, ObsLayout layout, ActionMode mode);
// The mirror image (world y -> -y) of a humanoid state: left and right joints swapped.
HumanoidState MirrorHumanoidState(const HumanoidState& s, const HumanoidModel& model);

// Everything an episode depends on: the physical state plus the env's own memory.
struct EnvState {
  WorldState world;
  std::array<bool, 2> foot_flags{};  // the lagged foot-contact flags
  // The flags the last observation showed (GetState fills them in; a bank's state has none and
  // keeps the env's own).
  std::optional<std::array<bool, 2>> shown_flags;
  int step = 0;
  Eigen::Vector2d walk_target = Eigen::Vector2d::Zero();  // world [m]
};

class HumanoidChairEnv : public Env {
 public:
  static constexpr int kProprioDim = 50;

  explicit HumanoidChairEnv(const EnvConfig& config);
  // With a task built elsewhere (tasks/ MakeTaskEnv); null: MakeTask(config).
  HumanoidChairEnv(const EnvConfig& config, std::unique_ptr<Task> task);
  ~HumanoidChairEnv() override;

  const EnvSpec& spec() const override { return spec_; }
  void Seed(uint64_t seed) override { rng_.Seed(seed); }
  // Samples a spawn (config.spawn) for the initial pose (config.init).
  void Reset(float* obs) override;
  StepResult Step(const float* action, float* obs) override;

  // Starts an episode from any state (e.g. a recorded pose), world frame.
  void ResetToState(const HumanoidState& s, float* obs);
  // Starts an episode from the authors' 51-column qpos row (notes 1.6 / 7.2).
  void ResetFromQpos(const double* qpos51, float* obs);
  EnvState GetState() const;
  void SetState(const EnvState& s);  // continues exactly as from the saved point

  // The current observation in any layout (the configured one is what Reset / Step wrote): the
  // hierarchy runs subtask policies that observe differently on one env. Valid after Reset / Step.
  void WriteObservation(ObsLayout layout, float* obs) const;

  // Queries for tasks, metrics and tests (valid after Reset / Step).
  const HumanoidModel& model() const { return model_; }
  const Task& task() const { return *task_; }
  const EnvConfig& config() const { return config_; }
  const World& world() const { return *world_; }
  const HumanoidState& humanoid_state() const { return state_; }
  Eigen::Vector3d RootRpy() const { return rpy_; }
  Eigen::Vector3d BodyPosition(int body) const { return body_pos_[body]; }  // world [m]
  Eigen::Vector3d PelvisPosition() const { return body_pos_[model_.pelvis_body()]; }
  // Pelvis touches the chair AND pelvis z < the contact height (notes 5; seat_contact_relative).
  bool PelvisSeatContact() const;
  double SeatContactMaxPelvisZ() const;  // [m]
  // This episode's chair (env.chair, or a random one under chair_random); null without a chair.
  const Chair* chair() const { return chair_.get(); }
  double PelvisSeatDistance() const;                      // 3-D distance pelvis - seat target [m]
  const Contacts& contacts() const { return contacts_; }  // current (not lagged)
  Eigen::Vector3d SeatTargetWorld() const { return world_->SeatTargetWorld(); }
  // Mean x, y of the non-root bodies; z of the torso (authors' body_xyz, notes 1.5).
  Eigen::Vector3d BodyXyz() const;
  void SetWalkTarget(const Eigen::Vector2d& world_xy) { walk_target_ = world_xy; }
  Eigen::Vector2d walk_target() const { return walk_target_; }
  int episode_step() const { return step_; }
  // The random push (env.push) on the pelvis now [N], world frame; zero between pushes.
  const Eigen::Vector3d& push_force() const { return world_->root_force(); }
  int pushes() const { return pushes_; }  // pushes started this episode
  // A push of `force_n` [N] (world frame) on the pelvis for the next `steps` control steps
  // (perch eval --push; env.push draws its own).
  void StartPush(const Eigen::Vector3d& force_n, int steps);
  // Torques [N m] (observation order) last applied, for diagnostics.
  const std::array<double, HumanoidModel::kNumJoints>& last_torques() const { return tau_; }
  const PdController& pd() const { return *pd_; }
  // PD action that holds joint angles q (observation order): a = q_n in action order.
  void HoldPoseAction(const double* q, float* action) const;
  // The initial pose before spawning (standing, or the configured qpos row), chair frame.
  const HumanoidState& init_pose() const { return init_pose_; }

 private:
  void BuildSpec();
  void AfterPhysics();  // reads state, contacts, body positions
  void WriteObs(float* obs);
  bool StateInvalid() const;
  void ComputePdTorques(const float* clipped_action);
  void UpdatePush();       // env.push: ends, starts or keeps the pelvis push before a control step
  void UpdateChairGrid();  // after chair_ changed

  EnvConfig config_;
  HumanoidModel model_;
  std::unique_ptr<Chair> chair_;       // this episode's
  std::unique_ptr<Chair> base_chair_;  // env.chair, when chair_random replaces it
  std::vector<Chair> file_chairs_;     // chair_random.files, loaded at the first draw
  // The chair's height grid (proprio_chair_shape), chair frame, relative to the seat target [m].
  // Those of the base and file chairs are kept: a mesh chair's grid costs a pass over its
  // triangles per point, too much for every reset.
  std::array<float, kChairGridDim> chair_grid_{};
  std::array<float, kChairGridDim> base_chair_grid_{};
  std::vector<std::array<float, kChairGridDim>> file_chair_grids_;
  std::unique_ptr<World> world_;
  std::unique_ptr<Task> task_;
  EnvSpec spec_;
  Rng rng_;
  HumanoidState init_pose_;

  // Per-step state (refreshed by AfterPhysics).
  HumanoidState state_;
  Eigen::Vector3d rpy_ = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> body_pos_;
  Contacts contacts_;
  std::array<bool, 2> foot_flags_{};
  std::array<bool, 2> shown_flags_{};  // the flags in the last observation written
  int step_ = 0;
  int push_steps_left_ = 0;  // control steps the current push still lasts
  int pushes_ = 0;
  Eigen::Vector2d walk_target_ = Eigen::Vector2d::Zero();
  std::array<double, HumanoidModel::kNumJoints> tau_{};
  std::array<float, HumanoidModel::kNumJoints> action_clipped_{};
  std::unique_ptr<PdController> pd_;
};

// The factory the actor uses.
std::unique_ptr<Env> MakeEnv(const EnvConfig& config);

// A seated pose on the chair (hips and knees at 90 deg, pelvis `clearance` above the seat top,
// facing away from the backrest), world frame; for benchmarks and tests.
HumanoidState SeatedPose(const HumanoidModel& model, const Chair& chair,
                         const ChairPlacement& placement, double clearance);
// All joint angles 0, clipped into the limits; torso upright with the feet `clearance` above z=0.
HumanoidState StandingPose(const HumanoidModel& model, double clearance);

}  // namespace perch
