// The immutable humanoid description (bodies, geoms, joints) loaded from data/humanoid.json, and
// its forward kinematics. Pure C++/Eigen: no Bullet here, so mocap and analysis code can use it.
//
// Conventions (the authors' MJCF humanoid, notes 1.2-1.3):
//  * A body's frame is placed at `offset` / `orientation` in its parent's frame; its joints then
//    apply in file order, each a rotation about `axis` through `anchor` (both in the body frame):
//      T_world(body) = T_world(parent) * T(offset, orientation) * prod_k [T(a_k) R(u_k, q_k)
//      T(-a_k)].
//  * Joints are indexed in observation order (0..20, notes 1.3); action_to_joint maps an action
//    index to a joint index (the ankle x/y pairs are swapped, notes 1.4).
//  * Angles in radians (the file holds degrees), lengths in metres, masses in kg.
#pragma once

#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace perch {

struct Geom {
  enum class Type { kCapsule, kSphere };
  Type type = Type::kSphere;
  Eigen::Vector3d from = Eigen::Vector3d::Zero();  // capsule segment start; sphere centre [m]
  Eigen::Vector3d to = Eigen::Vector3d::Zero();    // capsule segment end; = from for a sphere [m]
  double radius = 0.0;                             // [m]
};

struct Joint {
  std::string name;
  int body = -1;                                     // index of the body this hinge moves
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();   // unit, in the body frame
  Eigen::Vector3d anchor = Eigen::Vector3d::Zero();  // in the body frame [m]
  double lower = 0.0, upper = 0.0;                   // range [rad]
  double power = 0.0;                                // the authors' motor power (unitless)
  double max_torque = 0.0;                           // = power_to_torque * power [N m]
  double kp = 0.0;                                   // PD stiffness [N m / rad]
  double kd = 0.0;                                   // PD damping [N m s / rad]
  int action_index = -1;                             // where this joint's command sits in actions

  double mid() const { return 0.5 * (lower + upper); }
  // q_n = 2 (q - mid) / (hi - lo): in [-1, 1] inside the limits (notes 1.5).
  double Normalize(double q) const { return 2.0 * (q - mid()) / (upper - lower); }
};

struct Body {
  std::string name;
  int parent = -1;                                                  // -1 for the root (torso)
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();                 // in the parent frame [m]
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  // relative to the parent
  std::vector<Geom> geoms;                                          // in the body frame
  std::vector<int> joints;                            // joint indices, in application (file) order
  double mass = 0.0;                                  // [kg]
  Eigen::Vector3d com = Eigen::Vector3d::Zero();      // centre of mass, body frame [m]
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Zero();  // about the com, body frame [kg m^2]
  // Principal axes: inertia = principal_rot * diag(principal_inertia) * principal_rot^T.
  Eigen::Matrix3d principal_rot = Eigen::Matrix3d::Identity();  // det +1
  Eigen::Vector3d principal_inertia = Eigen::Vector3d::Zero();  // [kg m^2]
};

class HumanoidModel {
 public:
  static constexpr int kNumJoints = 21;

  // Reads a humanoid file; throws ConfigError "FILE: field: problem" on any malformed input.
  static HumanoidModel Load(const std::string& path);
  // data/humanoid.json of this source tree.
  static std::string DefaultPath();

  const std::string& name() const { return name_; }
  const std::vector<Body>& bodies() const { return bodies_; }
  const std::vector<Joint>& joints() const { return joints_; }  // observation order
  const Body& body(int i) const { return bodies_[i]; }
  const Joint& joint(int i) const { return joints_[i]; }
  int num_bodies() const { return static_cast<int>(bodies_.size()); }
  int num_joints() const { return static_cast<int>(joints_.size()); }
  // action_to_joint()[a] = joint (observation) index commanded by action component a.
  const std::vector<int>& action_to_joint() const { return action_to_joint_; }

  int FindBody(const std::string& name) const;   // -1 if absent
  int FindJoint(const std::string& name) const;  // -1 if absent
  int root_body() const { return 0; }
  int pelvis_body() const { return pelvis_body_; }
  const std::vector<int>& foot_bodies() const { return foot_bodies_; }  // [right, left]

  double total_mass() const { return total_mass_; }  // [kg], bodies only (helpers excluded)
  double helper_link_mass() const { return helper_link_mass_; }  // per helper link [kg]
  // Torso origin height above the lowest geom point with all joint angles 0 (upright, straight
  // legs, flat feet): 1.285 m for the authors' model.
  double standing_root_height() const { return standing_root_height_; }
  double density() const { return density_; }

 private:
  std::string name_;
  std::vector<Body> bodies_;
  std::vector<Joint> joints_;
  std::vector<int> action_to_joint_;
  int pelvis_body_ = -1;
  std::vector<int> foot_bodies_;
  double total_mass_ = 0.0;
  double helper_link_mass_ = 0.0;
  double standing_root_height_ = 0.0;
  double density_ = 1000.0;
};

struct FkResult {
  std::vector<Eigen::Isometry3d> body_world;        // [num_bodies] world pose of each body frame
  std::vector<Eigen::Vector3d> joint_anchor_world;  // [num_joints] world anchor, obs order [m]
};

// World transforms of every body and world anchor of every joint, for a root (torso body frame)
// pose and joint angles q[num_joints] in observation order [rad].
FkResult ForwardKinematics(const HumanoidModel& model, const Eigen::Vector3d& root_pos,
                           const Eigen::Quaterniond& root_quat, const double* q);

// Lowest world z of any geom surface, for a given FK result [m].
double LowestGeomZ(const HumanoidModel& model, const FkResult& fk);

// The authors' Euler convention R = Rz(yaw) Ry(pitch) Rx(roll) (notes 1.5, 7.2).
Eigen::Quaterniond QuatFromRpy(double roll, double pitch, double yaw);
Eigen::Vector3d RpyFromQuat(const Eigen::Quaterniond& q);  // (roll, pitch, yaw)

// Rotation taking +z onto the unit vector d (capsule frames).
Eigen::Quaterniond RotationZTo(const Eigen::Vector3d& d);

// Mass [kg], centre of mass and inertia about it (both in the geom's frame) of one solid geom of
// the given density [kg/m^3]. Capsule = cylinder + two hemispheres (as Bullet's MJCF importer).
void GeomMassProperties(const Geom& g, double density, double* mass, Eigen::Vector3d* com,
                        Eigen::Matrix3d* inertia);

// For each joint, its mirror counterpart and the sign of the mapping q' = sign * q (from the
// joint axes: a reflection maps a rotation about u by q to one about -M u by q).
void MirrorJointMap(const HumanoidModel& model, std::vector<int>* counterpart,
                    std::vector<double>* sign);

// The reflection y -> -y (the humanoid's sagittal plane), shared by states and reference poses:
// a position or linear velocity flips y; a rotation or angular velocity (axial) flips x and z.
inline Eigen::Vector3d MirrorPolar(const Eigen::Vector3d& v) { return {v.x(), -v.y(), v.z()}; }
inline Eigen::Vector3d MirrorAxial(const Eigen::Vector3d& w) { return {-w.x(), w.y(), -w.z()}; }
inline Eigen::Quaterniond MirrorRotation(const Eigen::Quaterniond& q) {
  return Eigen::Quaterniond(q.w(), -q.x(), q.y(), -q.z());
}

}  // namespace perch
