// The mutable Bullet world: floor, the humanoid as a btMultiBody (Featherstone) and an optional
// chair. The header is Bullet-free (pimpl) so that tests and the app never include Bullet.
//
// The humanoid: one revolute link per joint. A body with several hinges (abdomen, hips, ankles,
// shoulders) gets low-mass helper links for all but its last hinge, as Bullet's MJCF importer
// does; the last hinge's link carries the body's mass, inertia (principal frame at the com) and
// collision shapes. Self-collision is on except between a link and its ancestors; joint limits
// are btMultiBodyJointLimitConstraints. Actuation is explicit joint torque only.
#pragma once

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "common/field_table.h"
#include "common/json_util.h"
#include "envs/chair.h"
#include "envs/humanoid_model.h"

namespace perch {

class PdController;

enum class ChairBody {
  kStatic,    // fixed; costs nothing (the sit task and its metrics only read contacts with it)
  kDynamic,   // the chair file's mass and inertia, never sleeping (the authors' 1000 kg chair)
  kSleeping,  // as kDynamic, but asleep (not simulated) until a body comes near; sleeps again
              // once left at rest (Bullet's sleeping)
};
// "static", "dynamic", "sleeping" and back; ConfigError naming ctx on another name.
ChairBody ChairBodyFromName(const std::string& name, const std::string& ctx);
std::string ChairBodyName(ChairBody body);

// Depth of the floor's broadphase slab below z = 0 [m]: deeper than anything sinks into it.
constexpr double kFloorSlabDepth = 1.0;

struct PhysicsConfig {
  // The paper's 240 Hz physics / 60 Hz control, matching our retargeted references (1/60 s per
  // frame). The authors ran 0.0165 / 4 s (242.4 / 60.6 Hz, notes 1.1): set 0.004125 for that.
  double physics_dt = 1.0 / 240.0;  // [s]
  int substeps = 4;                 // physics steps per control step
  double gravity = 9.8;             // [m/s^2], along -z
  int solver_iterations = 5;        // PGS iterations (authors: 5; docs/env.md)
  double contact_erp = 0.9;         // Bullet erp2 for contacts (authors: 0.9)
  double floor_friction = 0.8;      // lateral; Bullet multiplies the two bodies' frictions
  double humanoid_friction = 0.5;   // Bullet's MJCF importer default
  double chair_friction = 0.5;      // Bullet's URDF default
  double linear_damping = 0.04;     // btMultiBody defaults, as in the authors' sim [1/s]
  double angular_damping = 0.04;
  // Bullet clamps every joint speed to this [rad/s] (btMultiBody's default, as in the authors'
  // sim).
  double max_joint_speed = 100.0;
  // A manifold point counts as contact when its signed distance is below this [m].
  double contact_distance = 0.02;
  // A joint's limit constraint is in the world only within limit_margin + 2 |qdot| dt of a limit
  // [rad]. Bullet makes a limit row only at or past the limit, so this saves the per-constraint
  // overhead and changes no physics (docs/env.md).
  double limit_margin = 0.05;
  // Passive joint damping, applied implicitly (docs/env.md "Stability under random actions"):
  // c_j = joint_damping + max_torque_j / damping_speed, i.e. full torque alone cannot spin a
  // joint faster than damping_speed. joint_damping 0 and damping_speed 0: none (the authors').
  double joint_damping = 0.0;   // [N m s/rad], every joint
  double damping_speed = 15.0;  // [rad/s]; 0: off
  // Rotational inertia of each helper link (isotropic) [kg m^2]. The authors' importer: about
  // 4e-8 (a 1 g point), which lets the ankles and hips reach Bullet's speed clamp within one
  // control step; 1e-2 is about twice the foot's inertia about the ankle (docs/env.md).
  double helper_link_inertia = 1e-2;
  // The floor is the plane z = 0; for the broadphase it is a slab this wide in x and y [m] (half
  // width) and kFloorSlabDepth deep, so only bodies near the floor are paired with it. Contacts
  // are the plane's either way. 0: Bullet's infinite bounds, which pair every body with the floor
  // at every step (before issue 19; docs/env.md "Floor").
  double floor_half_extent = 1000.0;
  // Entries in each of Bullet's contact-manifold and collision-algorithm pools. The world is
  // rebuilt at every reset, and Bullet's default of 4096 makes that 4x dearer; past the pool
  // Bullet takes memory from the heap, so the size changes the cost only, never the physics.
  int collision_pool_size = 64;
  // The chair's body (docs/env.md "Chair"): a chair file that says "dynamic": false is static in
  // every mode.
  ChairBody chair_body = ChairBody::kStatic;

  static PhysicsConfig FromJson(const Json& j, const std::string& ctx);
  Json ToJson() const;
};
// Every physics field, written once (common/field_table.h).
const FieldTable<PhysicsConfig>& PhysicsConfigFields();

// Where the chair stands: rotation about the vertical axis, then translation.
struct ChairPlacement {
  double x = 0.0, y = 0.0;  // [m]
  double yaw = 0.0;         // [rad]
  Eigen::Isometry3d Transform() const;
};

struct HumanoidState {
  Eigen::Vector3d root_pos = Eigen::Vector3d::Zero();             // torso body origin, world [m]
  Eigen::Quaterniond root_quat = Eigen::Quaterniond::Identity();  // torso frame -> world
  Eigen::Vector3d root_lin_vel = Eigen::Vector3d::Zero();  // of the torso origin, world [m/s]
  Eigen::Vector3d root_ang_vel = Eigen::Vector3d::Zero();  // world [rad/s]
  std::array<double, HumanoidModel::kNumJoints> q{};       // observation order [rad]
  std::array<double, HumanoidModel::kNumJoints> qd{};      // observation order [rad/s]
};

struct ChairState {
  Eigen::Vector3d pos = Eigen::Vector3d::Zero();  // chair frame origin, world [m]
  Eigen::Quaterniond quat = Eigen::Quaterniond::Identity();
  Eigen::Vector3d lin_vel = Eigen::Vector3d::Zero();  // of the chair's com, world [m/s]
  Eigen::Vector3d ang_vel = Eigen::Vector3d::Zero();  // world [rad/s]
};

struct WorldState {
  HumanoidState humanoid;
  ChairState chair;  // ignored without a chair
};

struct Contacts {
  bool foot_floor[2] = {false, false};  // [right, left] foot touches the floor
  bool pelvis_chair = false;            // pelvis touches any chair box
  bool humanoid_chair = false;          // any humanoid body touches the chair
};

// The authors' 51-column qpos row (notes 7.2) <-> humanoid state. Root angular velocity is not in
// the row: it is set to zero, as the authors' reset does (notes 1.6).
HumanoidState StateFromQpos(const double* qpos51);
void QposFromState(const HumanoidState& s, double* qpos51);

class World {
 public:
  // `model` and `chair` must outlive the world; chair may be null (no chair).
  World(const HumanoidModel& model, const Chair* chair, const ChairPlacement& placement,
        const PhysicsConfig& config);
  ~World();
  World(const World&) = delete;
  World& operator=(const World&) = delete;

  // Wipes the Bullet world, rebuilds it and writes the state (the chair at rest at its placement
  // when `chair_state` is null). Deterministic: the same state gives the same future.
  void SetState(const HumanoidState& humanoid, const ChairState* chair_state = nullptr);
  void SetState(const WorldState& s) { SetState(s.humanoid, &s.chair); }
  WorldState GetState() const;

  // Torques [N m] per joint in observation order, applied at every following physics step.
  void SetJointTorques(const double* tau);
  // A force [N] on the root body (pelvis) at its centre of mass, world frame, applied at every
  // following physics step until changed (zero: none). A SetState clears it.
  void SetRootForce(const Eigen::Vector3d& force) { root_force_ = force; }
  const Eigen::Vector3d& root_force() const { return root_force_; }
  void StepPhysics();

  void ReadJoints(double* q, double* qd) const;  // [num_joints] each, observation order
  Eigen::Isometry3d BodyPose(int body) const;    // world pose of a body frame
  // Centre of mass of the humanoid's bodies, world [m].
  Eigen::Vector3d CenterOfMass() const;
  // Scans the contact manifolds of the last collision detection.
  Contacts ReadContacts() const;
  // Contact points in all manifolds, and how many of them are between two humanoid bodies.
  int NumContactPoints(int* self_points = nullptr) const;
  // Contact manifolds (one per broadphase pair that reached the narrowphase) and how many of them
  // pair a body with the floor.
  int NumManifolds(int* floor_manifolds = nullptr) const;
  // Whether Bullet simulates the chair now (false for a static or sleeping chair).
  bool ChairAwake() const;
  bool has_chair() const { return chair_ != nullptr; }
  // Another chair (not null when there was one; it must outlive the world), from the next
  // SetState on: per-episode random chairs.
  void SetChair(const Chair* chair) { chair_ = chair; }
  const Chair* chair() const { return chair_; }
  Eigen::Isometry3d ChairPlacementTransform() const { return placement_.Transform(); }
  // The seat target (seat surface centre) at the chair's placement, world [m].
  Eigen::Vector3d SeatTargetWorld() const;
  // Per-episode physics (env.randomize), from the next SetState on: the floor's and the chair's
  // friction x friction (so every contact of the humanoid with them), and every humanoid body's
  // mass and inertia x mass. 1, 1: as configured.
  void SetDynamicsScales(double friction, double mass);
  double friction_scale() const { return friction_scale_; }
  double mass_scale() const { return mass_scale_; }

  const HumanoidModel& model() const { return model_; }
  const PhysicsConfig& config() const { return config_; }

  // Baseline for `perch bench env`: n control steps of a bare Bullet loop that, at every physics
  // step, reads the joints, applies `pd`'s torques for the fixed `action` and steps.
  void RawControlStepsPd(int n, const PdController& pd, const float* action);

 private:
  struct Scene;
  struct MeshShapes;  // a mesh chair's Bullet shapes, built once per chair and shared by scenes
  // SetState's steps, in order, on the new scene: the floor, the chair (at its placement, or
  // where chair_state says), the humanoid's multibody (links from the model), its pose and
  // velocities, its colliders and its joint limits.
  void AddFloor(Scene& sc);
  void AddChair(Scene& sc, const ChairState* chair_state);
  const MeshShapes& ChairMeshShapes();
  void BuildHumanoid(Scene& sc);
  void PlaceHumanoid(Scene& sc, const HumanoidState& hs);
  void AddColliders(Scene& sc);
  void AddJointLimits(Scene& sc);
  void UpdateJointLimits();
  // The joint block of the free-floating inverse mass matrix in pose s [1/(kg m^2)], observation
  // order; rebuilds the world.
  Eigen::MatrixXd InverseJointInertia(HumanoidState s);
  // Adds tau [num_joints] (observation order) plus the implicit passive damping to the joints.
  void AddJointTorques(const double* tau);
  const HumanoidModel& model_;
  const Chair* chair_;
  ChairPlacement placement_;
  PhysicsConfig config_;
  std::unique_ptr<MeshShapes> mesh_shapes_;  // declared before scene_: outlives its bodies
  std::unique_ptr<Scene> scene_;
  std::array<double, HumanoidModel::kNumJoints> tau_{};
  Eigen::Vector3d root_force_ = Eigen::Vector3d::Zero();
  std::vector<double> damping_;     // [num_joints] passive damping c_j [N m s/rad]
  Eigen::MatrixXd damp_push_;       // [nj x nj] h Minv [s/(kg m^2)]; empty: no damping
  Eigen::MatrixXd damp_solve_;      // [nj x nj] (1 + h Minv C)^-1
  Eigen::MatrixXd damp_push_unit_;  // damp_push_ at mass scale 1
  double friction_scale_ = 1.0, mass_scale_ = 1.0;
};

}  // namespace perch
