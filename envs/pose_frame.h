// One recorded pose of an episode: data that tasks and evaluations write and viz/ draws
// (filmstrips) or the viewer plays, so that recording needs no drawing code.
#pragma once

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "envs/humanoid_world.h"  // HumanoidState (plain data, no Bullet)

namespace perch {

struct PoseFrame {
  Eigen::Vector3d root_pos = Eigen::Vector3d::Zero();  // torso body origin, world [m]
  Eigen::Quaterniond root_quat = Eigen::Quaterniond::Identity();
  std::vector<double> q;  // [21] joint angles, observation order [rad]
  double time_s = 0.0;
  std::string label;  // drawn after the time stamp (e.g. the active subtask); may be empty
};

// The frame of a simulated humanoid's state at `time_s` [s], labelled `label`.
PoseFrame PoseFrameOf(const HumanoidState& s, double time_s, std::string label = "");

}  // namespace perch
