// BVH motion files: reader (hierarchy + motion, any channel order, end sites), writer, and
// forward kinematics of the BVH skeleton. Units are whatever the file uses (cgspeed CMU files:
// 1 unit = 0.0254/0.45 m, Y up); angles in the file are Euler degrees.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace perch {

enum class BvhChannel { kXpos, kYpos, kZpos, kXrot, kYrot, kZrot };

struct BvhJoint {
  std::string name;                                  // end sites are named "<parent>_End"
  int parent = -1;                                   // index into BvhClip::joints, -1 for the root
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();  // from the parent, file units
  std::vector<BvhChannel> channels;                  // in file order
  int first_channel = 0;                             // column of channels[0] in a frame row
  bool end_site = false;
};

struct BvhClip {
  std::vector<BvhJoint> joints;  // parents precede children (file order)
  int num_channels = 0;
  double frame_time = 0.0;  // seconds per frame as written in the header
  Eigen::MatrixXd frames;   // [num_frames, num_channels] channel values (units, degrees)

  int num_frames() const { return static_cast<int>(frames.rows()); }
  // Index of a joint by name, -1 if absent.
  int Find(const std::string& name) const;
};

// Parses BVH text; `source` (usually the path) names errors: "SOURCE:LINE: message".
// Throws ConfigError on malformed input (unknown keyword, truncated file, wrong value count,
// bad numbers, channel names).
BvhClip ParseBvh(const std::string& text, const std::string& source);
BvhClip ReadBvhFile(const std::string& path);

// Writes BVH text (tabs, 6 significant decimals by default is not enough for round trips, so
// values are written with 9 significant digits).
std::string WriteBvh(const BvhClip& clip);
// Writes atomically (temporary file + rename).
void SaveBvhFile(const std::string& path, const BvhClip& clip);

// World transforms of every joint (end sites included) for one frame. The local transform of a
// joint is translate(offset + position channels) * rotations in channel order.
struct BvhPose {
  std::vector<Eigen::Vector3d> pos;  // [num_joints] world positions, file units
  std::vector<Eigen::Matrix3d> rot;  // [num_joints] world rotations
};
BvhPose BvhForwardKinematics(const BvhClip& clip, int frame);
BvhPose BvhForwardKinematics(const BvhClip& clip, const Eigen::VectorXd& channel_values);

// Local rotation of joint j from a frame row (channel order respected).
Eigen::Matrix3d BvhLocalRotation(const BvhJoint& j, const double* row);

}  // namespace perch
