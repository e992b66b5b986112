// The main task and the hierarchy's lower level on one humanoid env (paper Sec. 3, 5; notes 4.7):
//  * SitChairTask ("sit_chair"): spawn in a zone around the chair from a walking pose, Eq. 8
//    reward per control step, termination at root < 0.78 m (< 0.54 m while sit is active), the
//    authors' 990-step episode. The env task of the meta controller and of the scripted chain.
//  * SubtaskPolicies: the four frozen subtask policies, each with its own frozen normaliser, run
//    on their own observation layouts of the same env (walk 52, turns 50 or 52, sit 57).
//  * The scripted chain (issue 14): walk to a point in front of the seat, turn to the side that
//    faces away from the chair, sit; no meta policy. The floor the meta controller must beat.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "common/json_util.h"
#include "common/proto/model.pb.h"
#include "common/subtasks.h"
#include "envs/humanoid_env.h"
#include "envs/pose_frame.h"
#include "hierarchy/chain_plan.h"
#include "policy/policy.h"
#include "tasks/clip_task.h"
#include "tasks/recording.h"
#include "tasks/task_env.h"

namespace perch {

// SubtaskId, SubtaskName, SubtaskIdOf: the subtasks' one table, common/subtasks.h.

// The meta controller's view of the hierarchy (paper Sec. 5; notes 4.7): which subtasks its switch
// chooses from, which frozen checkpoints run them, and how often it decides.
struct MetaConfig {
  // The switch's classes in order (authors: alphabetical keys, 0 left turn .. 3 walk). The
  // walk-only pre-training uses {"walk"}; the one-turn baselines (Table 3) drop a turn. Must
  // contain walk (the target head belongs to it).
  std::vector<std::string> choices{"turn_left", "turn_right", "sit", "walk"};
  int period = 30;                 // control steps per meta decision (0.495 s, about 2 Hz)
  bool subtask_stochastic = true;  // subtasks sample their actions (authors, notes 9.7)
  // The fixed-order baselines (paper Table 3): `choices` is the order the subtasks run in, and the
  // meta can only keep the running one or trigger the next (choosing any other class keeps it).
  bool fixed_order = false;
  // Ours (default off: the paper's 57-d sit state): the meta also observes which subtask acts
  // (one-hot over the four, SubtaskId order) and how long it has acted (s / active_time_scale_s,
  // clipped to 2), since a turn's or a sit's progress is not visible in one posture.
  bool observe_active = false;
  double active_time_scale_s = 3.0;
  // Ours (2026-12-05, default off): the meta also observes the subtasks' own critics on the
  // current state, each as if it began now (SubtaskId order; 0 for a subtask not among the
  // choices), and the acting subtask's on its own clock: 5 inputs after the others. They tell
  // which hand-over a subtask expects to survive (docs/meta.md "The subtasks' critics").
  bool observe_values = false;
  // Ours (2026-12-06, default 0: the paper switches at once): for this many control steps after a
  // switch the humanoid gets a cross-fade of the previous subtask's action and the new one's (the
  // new one's weight k / (blend_steps + 1) at the k-th step), since a sit's outcome is decided in
  // its first control steps (docs/journal/meta.md "Stop 43").
  int blend_steps = 0;
  // The scripted planner that teaches this meta (perch meta-clone) and its evaluation row
  // (perch eval --planner); hierarchy/meta_expert.h.
  PlannerConfig planner;
  // Frozen subtask checkpoints by SubtaskId (the fine-tuned ones, as the authors' chain).
  std::array<std::string, 4> subtasks{"models/turn_left_from_walk/policy.bin",
                                      "models/turn_right_from_walk/policy.bin",
                                      "models/sit_from_turn/policy.bin",
                                      "models/walk_stage2_fallrestart/checkpoints/"
                                      "ckpt-0000013900.bin"};

  static MetaConfig FromJson(const Json& j, const std::string& ctx);
  Json ToJson() const;
  int obs_dim() const;                  // 57 (+5 observe_active) (+5 observe_values)
  int target_choice() const;            // index of walk in choices
  std::vector<int> choice_ids() const;  // SubtaskId per class
};

struct SitChairTaskConfig {
  // Eq. 8: `support_reward` while the pelvis is on the seat, else approach_weight x (-V_sit).
  // Paper 1.0; the authors' code 5.0 (notes 3.3).
  double support_reward = 1.0;
  double approach_weight = 0.5;
  // Ours (default 0, the paper has none): subtracted on the meta step that ends in a fall, so
  // walking into the chair is not free.
  double fall_penalty = 0.0;
  double min_root_z = 0.78;      // [m]
  double sit_min_root_z = 0.54;  // while the sit subtask is active [m]
  int max_episode_steps = 990;   // 33 meta steps of 30 control steps (notes 4.1)
  // The start pose: a random state of these banks (walking mid-stride), its yaw turned to face
  // the spawn zone's centre, placed at the spawn (env.spawn). Empty: the env's init pose.
  BankStartConfig start{{"data/banks/walk_end_poses.bin"}, 1.0};
  double success_contact_s = 3.0;  // paper Sec. 7
  MetaConfig meta;

  static SitChairTaskConfig FromJson(const Json& j, const std::string& ctx);
  Json ToJson() const;
};

// The sit_chair section's and the meta's fields, each written once (common/field_table.h).
const FieldTable<MetaConfig>& MetaConfigFields();
const FieldTable<SitChairTaskConfig>& SitChairTaskConfigFields();

class SitChairTask : public Task {
 public:
  explicit SitChairTask(const SitChairTaskConfig& c, double control_dt);
  const char* name() const override { return "sit_chair"; }
  int max_episode_steps() const override { return c_.max_episode_steps; }
  bool InitialState(const HumanoidChairEnv& env, Rng& rng, HumanoidState* s) override;
  void OnReset(HumanoidChairEnv& env, Rng& rng) override;
  TaskStep OnStep(const HumanoidChairEnv& env, const float* action) override;
  bool has_success() const override { return true; }
  Json SaveMemory() const override;
  void LoadMemory(const Json& j) override;

  // The hierarchy's success rule, judged here only (StepResult::success, once per episode): the
  // pelvis on the seat for success_contact_s without a break. Its counters travel in MetaEnvState
  // rather than in SaveMemory, so the hand-over banks written from this task stay as they were.
  struct Seated {
    int run = 0;  // control steps of continuous seated contact
    bool succeeded = false;
  };
  const Seated& seated() const { return seated_; }
  void set_seated(const Seated& s) { seated_ = s; }

  // The subtask acting now (the termination height depends on it).
  void set_active(int subtask) { active_ = subtask; }
  int active() const { return active_; }
  const SitChairTaskConfig& config() const { return c_; }
  double spawn_theta() const { return spawn_theta_; }  // azimuth of this episode's spawn [rad]

 private:
  SitChairTaskConfig c_;
  double dt_;
  std::shared_ptr<const StartBank> bank_;
  int active_ = kWalk;
  double prev_distance_ = 0.0;
  double spawn_theta_ = 0.0;
  Seated seated_;
};

// A turn trained with `heading_goal` (docs/subtasks.md) observes the reference heading: in the
// hierarchy it is the turn clip's yaw change since the turn began, added to the humanoid's yaw
// at that moment, read heading_lookahead_s ahead.
struct TurnHeadingSource {
  std::vector<double> clip_yaw;  // [frame] unwrapped root yaw of the clip [rad]
  double frame_time = 0.0;       // [s]
  double lookahead_s = 0.0;      // [s]
  // Goal yaw [rad] t seconds after the turn began with the humanoid at yaw0.
  double GoalYaw(double yaw0, double t) const;
  // From a turn model's saved experiment config; null when the turn has no heading goal.
  static std::unique_ptr<TurnHeadingSource> FromSavedConfig(const Json& experiment,
                                                            const std::string& ctx);
};

// Four frozen subtask policies over one env.
class SubtaskPolicies {
 public:
  // models in SubtaskId order; each must observe its layout (ConfigError naming the subtask and
  // the file otherwise). saved_configs (the experiment config saved with each model, may be null
  // JSON) tell a heading-goal turn (52 inputs) from the paper's (50).
  // needed: which subtasks get a runner (the others' models are not read; Act on them throws).
  SubtaskPolicies(const std::array<proto::ModelWeights, kNumSubtasks>& models,
                  const std::array<std::string, kNumSubtasks>& names_for_errors,
                  const std::array<Json, kNumSubtasks>& saved_configs = {},
                  const std::array<bool, kNumSubtasks>& needed = {true, true, true, true});
  // Subtask `id` becomes active now (a heading-goal turn starts its clip clock).
  void Begin(int id, const HumanoidChairEnv& env);
  // The action of subtask `id` on the env's current state (its own observation and normaliser).
  // With `obs_noise` (an evaluation's perturbation, perch eval --obs-noise), Gaussian noise of
  // obs_noise->first std drawn from *obs_noise->second on every entry of what the policy sees.
  void Act(int id, const HumanoidChairEnv& env, Rng& rng, bool deterministic, float* action,
           const std::pair<double, Rng*>* obs_noise = nullptr);
  // Subtask `id`'s own critic on the env's current state, as if it began now (a heading-goal
  // turn's clock at 0): how well its training expects it to do from here, in its value units.
  float Value(int id, const HumanoidChairEnv& env);
  // The same for the subtask running since its Begin (a heading-goal turn's clock then).
  float RunningValue(int id, const HumanoidChairEnv& env);
  // The layout subtask `id` observes (with this set of models).
  ObsLayout Layout(int id) const;
  bool heading_goal(int id) const { return heading_[id] != nullptr; }
  bool has(int id) const { return runners_[id] != nullptr; }
  // The subtasks' clocks (Begin's control step and yaw): the only state the policies keep
  // between steps, saved and restored with an episode (MetaEnv::SaveState).
  struct Clocks {
    std::array<int, kNumSubtasks> begin_step{};
    std::array<double, kNumSubtasks> begin_yaw{};  // [rad]
  };
  Clocks clocks() const { return {begin_step_, begin_yaw_}; }
  void set_clocks(const Clocks& c) {
    begin_step_ = c.begin_step;
    begin_yaw_ = c.begin_yaw;
  }

 private:
  // obs_ <- subtask id's observation; a heading-goal turn's clock from its Begin (running) or 0.
  void WriteObservation(int id, const HumanoidChairEnv& env, bool running);
  std::array<std::unique_ptr<PolicyRunner>, kNumSubtasks> runners_;
  std::array<std::unique_ptr<TurnHeadingSource>, kNumSubtasks> heading_;
  std::array<int, kNumSubtasks> begin_step_{};
  std::array<double, kNumSubtasks> begin_yaw_{};
  bool sit_sees_shape_ = false;  // the sit policy observes the chair's shape (82 inputs)
  std::vector<float> obs_;
};

struct ChainOptions {
  int episodes = 100;
  uint64_t seed = 0;
  bool stochastic = false;
  double approach_dist_m = 0.6;  // walk target: this far in front of the seat target
  double reach_m = 0.25;         // walk -> turn when body_xyz is this close to the target
  double max_walk_s = 8.0;       // walk -> turn at the latest
  double turn_s = 3.2;           // turn -> sit after this long (the turn clips last 2.9 s)
  // Also turn -> sit as soon as the torso heading is within this of the chair's facing direction
  // (the back to the seat), after turn_min_s of turning; 0: time only.
  double sit_yaw_deg = 0.0;
  double turn_min_s = 0.3;
  std::string side = "short";  // which turn: "short" (the short way round), "left", "right"
  // The planned hand-over (hierarchy/chain_plan.h; ours): walk so that the turn ends where the
  // sit's clip starts, and hand over to the turn when its predicted end is there. The side is
  // chosen once per episode ("short": by the heading at the spawn).
  bool plan = false;
  PlannerConfig planner;  // its rules (sit_yaw_deg and turn_max_s: the chain's own above)
  // Switches (and walk-target updates) only every this many control steps: 30 is what a meta
  // controller at 2 Hz can do; 1 is every control step.
  int decision_period = 1;
  // When set: the full state at every switch to sit (where a sit starts in the chain), for a
  // start-state bank; with stop_at_sit the episode ends there (sampling only).
  std::vector<proto::BankState>* sit_starts = nullptr;
  bool stop_at_sit = false;
  EpisodeRecorder* recorder = nullptr;  // perch eval --record (not owned)
};

// Runs the chain over seeded episodes; JSON: success_rate, success_ci95, min_dist_mean_m,
// min_dist_std_m, fall_rate, turn choices, time to sit, ... Episode 0's frames (labelled with the
// active subtask) go to `frames` when not null.
Json EvaluateChain(const TaskEnvConfig& config,
                   const std::array<proto::ModelWeights, kNumSubtasks>& models,
                   const std::array<std::string, kNumSubtasks>& model_paths,
                   const std::array<Json, kNumSubtasks>& saved_configs, const ChainOptions& o,
                   std::vector<PoseFrame>* frames);

// Adds the hierarchy's task, sit_chair, to the task registry (tasks/registry.h), after the
// built-in subtasks. The tasks' floor knows nothing of the hierarchy, so each program that reads
// configs naming it calls this once at start (perch's main, the tests' main); calling it again
// does nothing.
void RegisterHierarchyTasks();

}  // namespace perch
