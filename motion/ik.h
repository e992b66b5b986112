// Damped-least-squares Jacobian IK for a floating-base articulated model: solves for the root
// position, root orientation and hinge angles whose key points best match target positions.
// The model is abstract (key points from a forward-kinematics callback) so the solver is tested on
// a synthetic skeleton with a known answer and used on the humanoid for retargeting.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

namespace perch {

struct IkPose {
  Eigen::Vector3d root_pos = Eigen::Vector3d::Zero();            // [m]
  Eigen::Quaterniond root_rot = Eigen::Quaterniond::Identity();  // root body to world
  Eigen::VectorXd q;                                             // [num_joints] hinge angles [rad]
};

class IkModel {
 public:
  virtual ~IkModel() = default;
  virtual int num_joints() const = 0;
  virtual int num_points() const = 0;
  virtual double lower(int joint) const = 0;  // [rad]
  virtual double upper(int joint) const = 0;  // [rad]
  // World positions of the key points, [3, num_points] [m].
  virtual void KeyPoints(const IkPose& pose, Eigen::Matrix3Xd* points) const = 0;
};

struct IkOptions {
  double damping = 0.01;           // lambda of (J^T W J + lambda^2 I) [m]; keeps steps bounded
  int max_iters = 100;             // per solve
  double min_improvement = 1e-12;  // stop when the weighted squared error drops by less [m^2]
  double fd_step = 1e-6;           // central finite-difference step for the Jacobian [m or rad]
  double max_step = 0.5;           // cap on |delta| per iteration, against overshoot [m or rad]
};

struct IkResult {
  IkPose pose;
  double weighted_sq_err = 0.0;  // sum_k w_k |x_k - target_k|^2 [m^2]
  int iterations = 0;
};

// Starts from `init` (warm start), iterates DLS steps, clamps hinge angles to the model's limits
// after every step. `weights` [num_points] (>= 0) weigh each key point's error.
IkResult SolveIk(const IkModel& model, const Eigen::Matrix3Xd& targets,
                 const Eigen::VectorXd& weights, const IkPose& init, const IkOptions& opt);

}  // namespace perch
