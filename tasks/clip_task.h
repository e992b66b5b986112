// The imitation-task base of the non-looping subtasks (turns, sit; paper Sec. 4, notes 3-4): a
// clip placed per episode by a horizontal transform (yaw about z, then a translation), followed
// one frame per control step and held at its last frame once it ends, the similarity reward
// (Eq. 2-3) against it, and the per-episode memory (placement, start time, previous pose for
// finite differences) as one struct that can be saved and restored with the env state.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <memory>
#include <optional>
#include <string>

#include "common/field_table.h"
#include "common/json_util.h"
#include "envs/humanoid_env.h"
#include "motion/reference_motion.h"
#include "tasks/bank_start.h"
#include "tasks/imitation.h"
#include "tasks/state_bank.h"

namespace perch {

// The authors' energy term (notes 3.1): c = -w_speed mean_i |a_i qdot_n,i| - w_action mean_i a_i^2
// with a the unclipped action and qdot_n the normalised joint speed (ours pairs each action with
// its own joint; the authors' ankle pairs are crossed, notes 9.1). c <= 0.
struct EnergyCostConfig {
  double speed_weight = 7.0;    // 3.5 x Roboschool's 2.0
  double action_weight = 0.35;  // 3.5 x Roboschool's 0.1
  static EnergyCostConfig FromJson(const Json& j, const std::string& ctx);
  Json ToJson() const;
};
const FieldTable<EnergyCostConfig>& EnergyCostConfigFields();
double EnergyCost(const EnergyCostConfig& c, const HumanoidChairEnv& env, const float* action);

// The reference placed in the world for one episode: p_world = R_z(yaw) p_clip + offset, plus
// (sit on a seat of another height) a vertical shift that grows with the root's descent:
// z += descent_dz x clamp((z_top - z) / (z_top - z_bottom), 0, 1), so a standing frame stays on
// the floor and the seated one lands on the seat.
struct ClipPlacement {
  double yaw = 0.0;                                  // [rad]
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();  // [m]
  double descent_dz = 0.0;                           // [m]
  double z_top = 0.0, z_bottom = 0.0;                // clip root heights of the descent [m]
  MotionPose Apply(const MotionPose& p) const;
};

// The bank start of one episode (any task with a BankStartConfig): false when it starts otherwise
// (no bank, or the coin said so); else a uniform bank state with its yaw set to `yaw` (nullopt:
// its own) and its root moved to `xy` (height, joints and velocities as sampled; velocities
// rotated with the yaw), or, with c.keep_pose, where it was relative to its chair. Loads the
// banks into *cache at the first call.
bool DrawBankStart(const BankStartConfig& c, const HumanoidChairEnv& env, Rng& rng,
                   std::optional<double> yaw, const Eigen::Vector2d& xy,
                   std::shared_ptr<const StartBank>* cache, HumanoidState* s);

class ClipTask : public Task {
 public:
  // Per-episode memory; with the env's EnvState it continues an episode from any point.
  struct Memory {
    ClipPlacement placement;
    double t0 = 0.0;  // reference time at step 0 [s]
    std::array<double, HumanoidModel::kNumJoints> prev_q{};
    Eigen::Vector3d prev_root = Eigen::Vector3d::Zero();
    double prev_distance = 0.0;  // the goal term's distance at the previous step [m]
  };

  ClipTask(const std::string& motion_path, double control_dt);
  const ReferenceMotion& motion() const { return motion_; }
  double control_dt() const { return dt_; }
  // Reference at episode step k in the world (held at the last frame after the clip ends).
  MotionPose ReferenceAt(int step) const;
  // The first step at which the reference has reached its last frame.
  int ClipEndStep() const;
  bool ClipEnded(int step) const { return step >= ClipEndStep(); }
  const Memory& GetMemory() const { return m_; }
  void SetMemory(const Memory& m) { m_ = m; }
  Json SaveMemory() const override;
  void LoadMemory(const Json& memory) override;
  double start_time() const { return m_.t0; }
  bool started_from_bank() const { return from_bank_; }  // this episode

 protected:
  // The env state of the reference at time t0 under `placement` (joint speeds zeroed if asked).
  HumanoidState StartState(const ClipPlacement& placement, double t0, bool zero_joint_speeds);
  // Similarity terms at step k against ReferenceAt(k) (velocities by finite differences when
  // c.finite_difference_velocities, notes 3.1). Uses the memory's previous pose.
  using Similarity = SimilarityTerms;
  Similarity ComputeSimilarity(const SimilarityRewardConfig& c, const HumanoidChairEnv& env,
                               int step) const;
  // Root velocity (world) by finite difference or from the simulator, and the reference's.
  void RootVelocities(bool finite_difference, const HumanoidChairEnv& env, int step,
                      Eigen::Vector3d* v, Eigen::Vector3d* v_ref) const;
  void RememberPose(const HumanoidChairEnv& env);  // end of every step and at reset
  // Joint angles += U(-rad, rad), kept inside the joint limits (evaluation: distinct trials).
  static void PerturbJoints(double rad, const HumanoidChairEnv& env, Rng& rng, HumanoidState* s);
  // DrawBankStart with this task's bank cache; false: the episode starts from the clip.
  bool BankStart(const BankStartConfig& c, const HumanoidChairEnv& env, Rng& rng, double yaw,
                 const Eigen::Vector2d& xy, HumanoidState* s);

  ReferenceMotion motion_;
  double dt_;
  Memory m_;
  std::shared_ptr<const StartBank> bank_;
  bool from_bank_ = false;
};

}  // namespace perch
