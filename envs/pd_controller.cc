#include "envs/pd_controller.h"

#include <algorithm>

namespace perch {

std::vector<double> EffectiveJointInertia(const HumanoidModel& m, const double* q) {
  const FkResult fk = ForwardKinematics(m, Eigen::Vector3d::Zero(), Eigen::Quaterniond::Identity(), q);
  std::vector<double> out(m.num_joints());
  for (int j = 0; j < m.num_joints(); ++j) {
    const int jb = m.joint(j).body;
    const Eigen::Vector3d u = (fk.body_world[jb].rotation() * m.joint(j).axis).normalized();
    const Eigen::Vector3d p = fk.joint_anchor_world[j];
    double sub = 0.0, rest = 0.0;
    for (int b = 0; b < m.num_bodies(); ++b) {
      bool in_subtree = false;
      for (int a = b; a >= 0 && !in_subtree; a = m.body(a).parent) in_subtree = a == jb;
      const Body& body = m.body(b);
      const Eigen::Matrix3d r = fk.body_world[b].rotation();
      const Eigen::Vector3d c = fk.body_world[b] * body.com;
      const double inertia = u.dot(r * body.inertia * r.transpose() * u) +
                             body.mass * (c - p).cross(u).squaredNorm();
      (in_subtree ? sub : rest) += inertia;
    }
    out[j] = sub * rest / (sub + rest);
  }
  return out;
}

std::vector<double> StandingJointInertia(const HumanoidModel& m) {
  std::vector<double> q(m.num_joints());
  for (int j = 0; j < m.num_joints(); ++j) q[j] = std::clamp(0.0, m.joint(j).lower, m.joint(j).upper);
  return EffectiveJointInertia(m, q.data());
}

PdController::PdController(const HumanoidModel& model, double dt, bool implicit)
    : model_(model), dt_(dt), implicit_(implicit), inertia_(StandingJointInertia(model)) {}

double PdController::Target(int joint, float a) const {
  const Joint& jt = model_.joint(joint);
  return jt.mid() + a * 0.5 * (jt.upper - jt.lower);
}

void PdController::Torques(const float* a, const double* q, const double* qd, double* tau) const {
  for (int i = 0; i < model_.num_joints(); ++i) {
    const int j = model_.action_to_joint()[i];
    const Joint& jt = model_.joint(j);
    const double target = Target(j, a[i]);
    double t = jt.kp * (target - q[j]) - jt.kd * qd[j];
    if (implicit_) {
      // Velocity-implicit PD (backward Euler on this joint alone): stays stable for the light
      // distal links (feet, hands) whose explicit PD would need dt * omega < 2.
      const double h = dt_;
      t = (jt.kp * (target - q[j] - h * qd[j]) - jt.kd * qd[j]) /
          (1.0 + (jt.kp * h * h + jt.kd * h) / inertia_[j]);
    }
    tau[j] = std::clamp(t, -jt.max_torque, jt.max_torque);
  }
}

}  // namespace perch
