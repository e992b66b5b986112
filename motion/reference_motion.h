// A retargeted reference motion for the humanoid (immutable once loaded): root pose and the 21
// joint angles (observation order, notes 1.3) sampled at a fixed frame time, with finite-difference
// velocities. File format: JSON, documented in docs/motion.md ("perch.reference_motion.v1").
//
// Time t runs from 0 to duration(). A looping motion (walk) holds one cycle whose last frame is the
// same phase as its first; beyond it the cycle repeats, each repetition displaced by
// cycle_displacement (rotated by cycle_yaw per cycle). A non-looping motion clamps t to its ends.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "common/json_util.h"

namespace perch {

class HumanoidModel;

struct MotionPose {
  Eigen::Vector3d root_pos = Eigen::Vector3d::Zero();            // torso origin, world [m]
  Eigen::Quaterniond root_rot = Eigen::Quaterniond::Identity();  // torso to world
  Eigen::VectorXd q;                                             // [21] joint angles [rad]
  Eigen::VectorXd qdot;                                          // [21] joint velocities [rad/s]
  Eigen::Vector3d root_vel = Eigen::Vector3d::Zero();            // world [m/s]
  Eigen::Vector3d root_angvel = Eigen::Vector3d::Zero();         // world [rad/s]
};

class ReferenceMotion {
 public:
  static constexpr const char* kFormat = "perch.reference_motion.v1";

  // Strict: unknown fields, wrong types or inconsistent array lengths throw ConfigError naming
  // the file and field.
  static ReferenceMotion Load(const std::string& path);
  static ReferenceMotion FromJson(const Json& j, const std::string& ctx);
  Json ToJson() const;
  void Save(const std::string& path) const;  // atomic

  // Builds a motion from poses (velocities are recomputed by finite differences).
  ReferenceMotion(std::string name, double frame_time, std::vector<MotionPose> frames, bool loop);
  ReferenceMotion() = default;

  const std::string& name() const { return name_; }
  int num_frames() const { return static_cast<int>(frames_.size()); }
  double frame_time() const { return frame_time_; }  // [s]
  // Length of the clip (one cycle for a loop) [s] = (num_frames - 1) * frame_time.
  double duration() const { return (num_frames() - 1) * frame_time_; }
  bool loop() const { return loop_; }
  const Eigen::Vector3d& cycle_displacement() const { return cycle_disp_; }  // [m]
  double cycle_yaw() const { return cycle_yaw_; }                            // [rad]
  const MotionPose& frame(int i) const { return frames_[i]; }
  const std::vector<MotionPose>& frames() const { return frames_; }

  // Pose at time t: positions, angles and velocities linearly interpolated, root orientation by
  // slerp. Loops add cycle offsets; non-loops clamp t to [0, duration()].
  MotionPose At(double t) const;
  // Phase in [0, 1): fraction of the cycle (or of the clip) at time t.
  double Phase(double t) const;
  // Number of whole cycles completed at time t (0 for non-loops).
  int Cycle(double t) const;

  // Left/right mirror in the humanoid's sagittal plane (world y -> -y): swaps left/right joints,
  // flips signs from the joint axes. Mirroring twice gives the original motion.
  ReferenceMotion Mirrored(const HumanoidModel& model) const;
  static MotionPose MirrorPose(const MotionPose& p, const HumanoidModel& model);
  // How far body's geoms reach behind (-x of) the pelvis centre in pose p [m, >= 0 behind]: the
  // seated clip's clearance from a backrest (the sit clip faces +x).
  static double ReachBehindPelvis(const HumanoidModel& model, const MotionPose& p,
                                  const std::string& body);
  // Sitting up straighter (ours, for the sit clip), by deg(t) about the abdomen's flexion joint;
  // deg(t) ramps linearly from 0 at t0 to `deg` at t1 [s] and holds. Velocities recomputed.
  // keep = "torso": abdomen_y + deg, both hip_y - deg: the pelvis and legs rotate forward under
  // the torso, which keeps its orientation, the thighs their direction, and the root moves so
  // the pelvis stays where it was. keep = "pelvis": abdomen_y - deg, the pelvis and legs keep
  // their world pose and the torso pitches forward about the waist (nothing below it moves).
  // ConfigError when the model lacks those joints, t1 <= t0, or keep is neither.
  ReferenceMotion Straightened(const HumanoidModel& model, double deg, double t0, double t1,
                               const std::string& keep = "torso") const;

  // Metadata carried with the file (source clip, frame range, acknowledgement, measurements).
  Json& meta() { return meta_; }
  const Json& meta() const { return meta_; }
  void set_loop(bool loop, const Eigen::Vector3d& disp, double yaw) {
    loop_ = loop;
    cycle_disp_ = disp;
    cycle_yaw_ = yaw;
  }
  void set_name(const std::string& n) { name_ = n; }
  // Recomputes qdot, root_vel and root_angvel by central differences (one-sided at the ends of a
  // non-loop; wrapping through the cycle for a loop).
  void ComputeVelocities();

 private:
  std::string name_;
  double frame_time_ = 1.0 / 60.0;
  std::vector<MotionPose> frames_;
  bool loop_ = false;
  Eigen::Vector3d cycle_disp_ = Eigen::Vector3d::Zero();
  double cycle_yaw_ = 0.0;
  Json meta_ = Json::object();
};

}  // namespace perch
