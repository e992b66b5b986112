// The walk subtask (paper Sec. 4, issue 6): imitation of the looping walk clip with the similarity
// reward (Eq. 2-3) plus a goal term, early termination when the root falls below a height, and a
// time limit. Two stages:
//   forward: Eq. 4, root linear velocity matched to the reference's;
//   target:  Eq. 5, progress towards a 2-D target re-drawn in front of the humanoid every 2.5 s or
//            when reached (notes 4.4); the env's goal feature points at it.
// The episode starts from the reference (root, joints, velocities) with its root moved to x, y = 0;
// the reference trajectory is shifted by the same offset for the whole episode.
#pragma once

#include <Eigen/Core>
#include <array>
#include <memory>
#include <string>

#include "common/field_table.h"
#include "common/json_util.h"
#include "envs/humanoid_env.h"
#include "motion/reference_motion.h"
#include "tasks/bank_start.h"
#include "tasks/imitation.h"

namespace perch {

// The env state (world frame) of a reference pose: root pose and velocities, joint angles and
// velocities. Used to start episodes from, or track, a reference motion.
HumanoidState HumanoidStateFromPose(const MotionPose& p);

enum class WalkStage { kForward, kTarget };

struct WalkTaskConfig {
  // A preset applied first; explicit fields in the same JSON object override it.
  //   "paper":   alpha_vel 10, simulator velocities, Eq. 4 0.5 exp(-10 |dv|^2), Eq. 5 weight 0.1;
  //   "authors": alpha_vel 0.01, finite differences, Eq. 4 0.1 exp(-1 |dv|^2), Eq. 5 weight 0.5
  //              (notes 3.2-3.3; alpha 1 is the authors' value for the normal-speed walk clip).
  std::string reward_variant = "paper";
  std::string motion_file = "data/motions/walk.json";
  WalkStage stage = WalkStage::kForward;
  SimilarityRewardConfig similarity;
  double root_vel_weight = 0.5;  // Eq. 4 weight
  double root_vel_alpha = 10.0;  // Eq. 4 sharpness [s^2/m^2]
  double target_weight = 0.1;    // Eq. 5 weight
  double target_k = 10.0;        // Eq. 5 sigmoid slope [s/m]
  double min_root_z = 0.78;      // early termination: root (torso) z below this [m]
  int max_episode_steps = 1000;  // time limit (authors: 1000 control steps)
  // Reference state initialisation: start at a uniformly random phase of the cycle. Off by
  // default: the authors start every walk episode at a fixed frame (notes 4.3).
  bool reference_state_init = false;
  // Walk targets (stage "target", notes 4.4).
  double target_redraw_s = 2.5;    // countdown before a new target [s]
  double target_reach_m = 0.2;     // horizontal body_xyz-target distance counted as reached [m]
  double target_min_dist_m = 1.0;  // dist ~ U(min, max) [m]
  double target_max_dist_m = 5.0;
  double target_max_angle_deg = 45.0;  // theta ~ U(-max, max) from the heading [deg]
  // Training curriculum (ours, not the paper's; 0 = off = the paper): with this probability a draw
  // uses U(-turn_max, turn_max) instead, so targets beside and behind (which the walker meets
  // after passing a target at > target_reach_m) are practised. `perch eval` turns it off.
  double target_turn_prob = 0.0;
  double target_turn_max_angle_deg = 180.0;  // [deg]
  // Training curriculum (ours, not the paper's; 0 = off = the paper): with this probability an
  // episode starts from the state recorded fall_restart_lead_s before one of the env's recent
  // falls (FallRestartEnv: pose, target, countdown and reference phase), so the situations that
  // end in falls are practised more often than they occur. `perch eval` never uses it.
  double fall_restart_prob = 0.0;
  double fall_restart_lead_s = 1.5;  // how long before the fall [s]
  int fall_restart_pool = 64;        // falls kept per env, the oldest replaced
  // Training starts from a start-state bank (ours; default: none = the paper): with start.prob an
  // episode starts from a bank state (its own yaw, root over the origin), e.g. the meta's
  // hand-backs to the walker after an aborted turn (perch eval --task sit_chair --hand-overs-to
  // walk). The reference phase is the clip's nearest pose. `perch eval` turns it off unless
  // --start end-poses.
  BankStartConfig start;
  // Stage "forward": the goal feature points at this fixed world point (Roboschool's default) [m].
  std::array<double, 2> forward_target{1000.0, 0.0};

  // Sets the preset's fields (keeps the others).
  void ApplyVariant(const std::string& variant, const std::string& ctx);
  static WalkTaskConfig FromJson(const Json& j, const std::string& ctx);
  Json ToJson() const;
  std::string MotionPath() const;
};
// Every field of the "walk" section, written once (common/field_table.h).
const FieldTable<WalkTaskConfig>& WalkTaskConfigFields();

// The reward terms of the last step, for metrics and tests.
struct WalkTerms {
  double pose = 0.0;        // r^p (Eq. 3)
  double joint_vel = 0.0;   // r^v (Eq. 3)
  double similarity = 0.0;  // r^S = w_pose r^p + w_vel r^v (Eq. 2)
  double goal = 0.0;        // Eq. 4 (forward) or Eq. 5 (target), weighted
  double total = 0.0;
  bool target_redrawn = false;  // a new target was drawn before this step's observation
  bool target_reached = false;  // ... because the old one was reached
};

class WalkTask : public Task {
 public:
  WalkTask(const WalkTaskConfig& config, double control_dt);
  const char* name() const override { return "walk"; }
  int max_episode_steps() const override { return c_.max_episode_steps; }
  bool InitialState(const HumanoidChairEnv& env, Rng& rng, HumanoidState* s) override;
  void OnReset(HumanoidChairEnv& env, Rng& rng) override;
  void BeforeObservation(HumanoidChairEnv& env, Rng& rng) override;
  TaskStep OnStep(const HumanoidChairEnv& env, const float* action) override;

  const WalkTaskConfig& config() const { return c_; }
  const ReferenceMotion& motion() const { return motion_; }
  // The reference at episode step k, shifted into this episode's frame (world).
  MotionPose ReferenceAt(int step) const;
  // As a HumanoidState (what perfect tracking would be).
  HumanoidState ReferenceState(int step) const;
  double start_time() const { return m_.t0; }            // reference time at step 0 [s]
  bool started_from_bank() const { return from_bank_; }  // this episode
  // The clip time [s] (control steps from 0) whose joint angles are nearest to q (squared sum).
  double NearestPhase(const std::array<double, HumanoidModel::kNumJoints>& q) const;
  const WalkTerms& last_terms() const { return m_.terms; }
  Json LastRewardTerms() const override {
    const WalkTerms& t = m_.terms;
    return Json{{"pose", t.pose},
                {"joint_vel", t.joint_vel},
                {"similarity", t.similarity},
                {"goal", t.goal},
                {"total", t.total}};
  }
  int targets_reached() const { return m_.targets_reached; }  // this episode
  // The current target's distance from the root when it was drawn [m] (target stage).
  double target_drawn_distance_m() const { return m_.target_drawn_dist_m; }
  // Horizontal distance body_xyz -> walk target [m].
  static double TargetDistance(const HumanoidChairEnv& env);

  // What the task carries between steps; with the env's EnvState it continues an episode from
  // any recorded point (FallRestartEnv).
  struct Memory {
    double t0 = 0.0;                                   // reference time at step 0 [s]
    Eigen::Vector3d offset = Eigen::Vector3d::Zero();  // added to the reference's root position [m]
    int countdown = 0;
    double prev_distance = 0.0;
    bool redrawn = false, reached = false;
    int targets_reached = 0;
    double target_drawn_dist_m = 0.0;
    std::array<double, HumanoidModel::kNumJoints> prev_q{};
    Eigen::Vector3d prev_root = Eigen::Vector3d::Zero();
    WalkTerms terms;
  };
  const Memory& GetMemory() const { return m_; }
  void SetMemory(const Memory& m) { m_ = m; }
  Json SaveMemory() const override;
  void LoadMemory(const Json& memory) override;
  double control_dt() const { return dt_; }

 private:
  void DrawTarget(HumanoidChairEnv& env, Rng& rng);

  WalkTaskConfig c_;
  double dt_;
  ReferenceMotion motion_;
  int redraw_steps_ = 150;
  Memory m_;
  std::shared_ptr<const StartBank> bank_;
  bool from_bank_ = false;
};

}  // namespace perch
