#include "tasks/imitation.h"

#include <cmath>
#include <stdexcept>

namespace perch {

SimilarityRewardConfig SimilarityRewardConfig::FromJson(const Json& j, const std::string& ctx) {
  return FromJson(j, ctx, SimilarityRewardConfig());
}

const FieldTable<SimilarityRewardConfig>& SimilarityRewardConfigFields() {
  using C = SimilarityRewardConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("w_pose", &C::w_pose, "omega^p: pose term weight")
          .Add("w_vel", &C::w_vel, "omega^v: joint velocity term weight")
          .Add("alpha_pose", &C::alpha_pose, "alpha^p [1/rad^2]")
          .Add("alpha_vel", &C::alpha_vel, "alpha^v [s^2/rad^2] (authors' code: 0.01)")
          .Add("finite_difference_velocities", &C::finite_difference_velocities,
               "the clip's joint velocities by finite differences (authors)");
  return t;
}

SimilarityRewardConfig SimilarityRewardConfig::FromJson(const Json& j, const std::string& ctx,
                                                        const SimilarityRewardConfig& base) {
  return SimilarityRewardConfigFields().Read(j, ctx, base);
}

Json SimilarityRewardConfig::ToJson() const { return SimilarityRewardConfigFields().Write(*this); }

double AngleDiff(double a, double b) {
  double d = std::fmod(a - b + M_PI, 2.0 * M_PI);
  if (d < 0) d += 2.0 * M_PI;
  return d - M_PI;
}

double PoseReward(const double* q, const double* q_ref, int n, double alpha_pose) {
  double s = 0.0;
  for (int j = 0; j < n; ++j) {
    const double d = AngleDiff(q[j], q_ref[j]);
    s += d * d;
  }
  return std::exp(-alpha_pose * s);
}

double JointVelocityReward(const double* qdot, const double* qdot_ref, int n, double alpha_vel) {
  double s = 0.0;
  for (int j = 0; j < n; ++j) {
    const double d = qdot[j] - qdot_ref[j];
    s += d * d;
  }
  return std::exp(-alpha_vel * s);
}

double SimilarityReward(const SimilarityRewardConfig& c, const double* q, const double* q_ref,
                        const double* qdot, const double* qdot_ref, int n) {
  return c.w_pose * PoseReward(q, q_ref, n, c.alpha_pose) +
         c.w_vel * JointVelocityReward(qdot, qdot_ref, n, c.alpha_vel);
}

SimilarityTerms SimilarityTermsAt(const SimilarityRewardConfig& c, const double* q,
                                  const double* q_prev, const double* qdot, const double* q_ref,
                                  const double* q_ref_prev, const double* qdot_ref, int n,
                                  double dt) {
  // Stack buffers, not vectors: this runs every control step of every imitation task.
  constexpr int kMaxJoints = 64;
  double fd_qdot[kMaxJoints], fd_qdot_ref[kMaxJoints];
  if (c.finite_difference_velocities) {
    if (n > kMaxJoints) throw std::invalid_argument("SimilarityTermsAt: more than 64 joints");
    for (int j = 0; j < n; ++j) {
      fd_qdot[j] = (q[j] - q_prev[j]) / dt;
      fd_qdot_ref[j] = (q_ref[j] - q_ref_prev[j]) / dt;
    }
    qdot = fd_qdot;
    qdot_ref = fd_qdot_ref;
  }
  SimilarityTerms t;
  t.pose = PoseReward(q, q_ref, n, c.alpha_pose);
  t.joint_vel = JointVelocityReward(qdot, qdot_ref, n, c.alpha_vel);
  t.total = c.w_pose * t.pose + c.w_vel * t.joint_vel;
  return t;
}

double RootVelocityReward(const double* v, const double* v_ref, double w, double alpha) {
  double s = 0.0;
  for (int i = 0; i < 3; ++i) s += (v[i] - v_ref[i]) * (v[i] - v_ref[i]);
  return w * std::exp(-alpha * s);
}

double TargetProgressReward(double d_now, double d_next, double dt, double w, double k) {
  const double v = (d_next - d_now) / dt;
  return w / (1.0 + std::exp(k * v));
}

double RootRotationReward(const double* rpy, const double* rpy_ref, double w, double alpha) {
  double s = 0.0;
  for (int i = 0; i < 3; ++i) {
    const double d = AngleDiff(rpy[i], rpy_ref[i]);
    s += d * d;
  }
  return w * std::exp(-alpha * s);
}

double ApproachReward(double d_now, double d_next, double dt, double w) {
  return w * (-(d_next - d_now) / dt);
}

}  // namespace perch
