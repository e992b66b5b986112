// The subtask reward terms of the paper (Eq. 2-7), as pure functions of plain arrays, with their
// weights and sharpness coefficients in typed config (paper defaults; the authors' code variant is
// a preset, notes 3.3).
#pragma once

#include <string>

#include "common/field_table.h"
#include "common/json_util.h"

namespace perch {

// Similarity reward r^S = w_pose r^p + w_vel r^v (paper Eq. 2-3).
struct SimilarityRewardConfig {
  double w_pose = 0.5;      // omega^p
  double w_vel = 0.05;      // omega^v
  double alpha_pose = 1.0;  // alpha^p [1/rad^2]
  double alpha_vel = 10.0;  // alpha^v [s^2/rad^2]; the authors' code uses 0.01 (notes 3.3)
  // Authors: both joint velocities are finite differences over one control step (notes 3.1);
  // false uses the simulator's joint velocities and the reference's stored ones.
  bool finite_difference_velocities = false;

  static SimilarityRewardConfig FromJson(const Json& j, const std::string& ctx);
  // Fields absent from j keep base's values (a preset).
  static SimilarityRewardConfig FromJson(const Json& j, const std::string& ctx,
                                         const SimilarityRewardConfig& base);
  Json ToJson() const;
};
const FieldTable<SimilarityRewardConfig>& SimilarityRewardConfigFields();

// d(a, b): the angular difference wrapped into [-pi, pi) [rad].
double AngleDiff(double a, double b);

// r^p = exp(-alpha_pose sum_j d(q_j, qhat_j)^2) over n joints.
double PoseReward(const double* q, const double* q_ref, int n, double alpha_pose);
// r^v = exp(-alpha_vel sum_j (qdot_j - qdothat_j)^2).
double JointVelocityReward(const double* qdot, const double* qdot_ref, int n, double alpha_vel);
// r^S (Eq. 2).
double SimilarityReward(const SimilarityRewardConfig& c, const double* q, const double* q_ref,
                        const double* qdot, const double* qdot_ref, int n);

// The terms of r^S at one control step, for n joints.
struct SimilarityTerms {
  double pose = 0.0;       // r^p
  double joint_vel = 0.0;  // r^v
  double total = 0.0;      // r^S
};
// The joint velocities compared are the simulator's and the reference's stored ones (qdot,
// qdot_ref), or with c.finite_difference_velocities (the authors', notes 3.1) each pose's change
// since the previous control step over dt [s] (q_prev, q_ref_prev); only the pair used is read.
// Every imitation task computes r^S here, so all of them read the config alike.
SimilarityTerms SimilarityTermsAt(const SimilarityRewardConfig& c, const double* q,
                                  const double* q_prev, const double* qdot, const double* q_ref,
                                  const double* q_ref_prev, const double* qdot_ref, int n,
                                  double dt);

// Eq. 4 (stage-1 walk): w exp(-alpha |v - vhat|^2) with v the 3-D root velocity [m/s].
double RootVelocityReward(const double* v, const double* v_ref, double w, double alpha);
// Eq. 5 (stage-2 walk): w / (1 + exp(k V)), V = (D_next - D_now) / dt: the rate of change of
// the horizontal distance to the target [m/s] (negative when approaching).
double TargetProgressReward(double d_now, double d_next, double dt, double w, double k);
// Eq. 6 (turn): w exp(-alpha sum_i d(theta_i, thetahat_i)^2) over (roll, pitch, yaw).
double RootRotationReward(const double* rpy, const double* rpy_ref, double w, double alpha);
// Eq. 7 (sit) and the meta shaping term of Eq. 8: w (-(D_next - D_now) / dt).
double ApproachReward(double d_now, double d_next, double dt, double w);

}  // namespace perch
