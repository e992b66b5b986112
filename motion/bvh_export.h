// Export of a humanoid motion as BVH (e.g. a synthesized motion, for viewing in Blender): one BVH
// joint per humanoid body, named after it, in metres, Y up (BVH convention; humanoid (x, y, z) ->
// BVH (y, z, x)). Every joint has 6 channels (Xposition Yposition Zposition Zrotation Yrotation
// Xrotation) because the hinges rotate about anchors away from the body origins, which moves a
// body's origin relative to its parent. OFFSET = the body's rest offset; the position channels
// hold the change from it, so the rest pose has all channels 0 except the root's position.
#pragma once

#include "envs/humanoid_model.h"
#include "motion/bvh.h"
#include "motion/reference_motion.h"

namespace perch {

// Samples `motion` at `frame_time` for `seconds` (<= 0: the clip's duration).
BvhClip HumanoidMotionToBvh(const HumanoidModel& model, const ReferenceMotion& motion,
                            double frame_time, double seconds);

// The humanoid's joint angles [num_joints, observation order, rad] of one frame of a BVH written by
// HumanoidMotionToBvh (or edited in a tool that keeps its skeleton): each body's rotation relative
// to its parent, read from the BVH, is decomposed into the rotations about its hinge axes
// (Gauss-Newton per body). For round-trip checks and for importing edited motions.
std::vector<double> HumanoidJointAnglesFromBvh(const HumanoidModel& model, const BvhClip& clip,
                                               int frame);

// humanoid world (z up) -> BVH axes (y up).
Eigen::Vector3d HumanoidToBvhAxes(const Eigen::Vector3d& v);

}  // namespace perch
