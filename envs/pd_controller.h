// The PD law of the `pd` action mode, shared by the env and the bare-Bullet benchmark loop.
#pragma once

#include <vector>

#include "envs/humanoid_model.h"

namespace perch {

// Effective inertia of each hinge [kg m^2], observation order: the two parts it separates (its
// body's subtree and the rest) as rigid bodies about the hinge axis, combined as the reduced
// inertia I_sub I_rest / (I_sub + I_rest); in the pose q [num_joints] (observation order).
std::vector<double> EffectiveJointInertia(const HumanoidModel& m, const double* q);
// The same in the standing pose (angles 0 clipped into the limits).
std::vector<double> StandingJointInertia(const HumanoidModel& m);

class PdController {
 public:
  // dt: the physics step [s]; implicit: velocity-implicit damping per joint (docs/env.md).
  PdController(const HumanoidModel& model, double dt, bool implicit);

  // Target angle of joint j for action component a in [-1, 1]: mid + a (hi - lo) / 2.
  double Target(int joint, float a) const;
  // tau[num_joints] (observation order) from actions in action order and joint angles q and
  // speeds qd (observation order); clipped to the torque limits.
  void Torques(const float* action, const double* q, const double* qd, double* tau) const;
  const std::vector<double>& effective_inertia() const { return inertia_; }

 private:
  const HumanoidModel& model_;
  double dt_;
  bool implicit_;
  std::vector<double> inertia_;  // [num_joints] effective hinge inertia [kg m^2]
};

}  // namespace perch
