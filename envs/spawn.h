// Spawn sampling (notes 6): where an episode's initial pose is placed, in the chair frame.
#pragma once

#include "common/rng.h"
#include "envs/env_config.h"
#include "envs/humanoid_world.h"

namespace perch {

struct SpawnPose {
  double x = 0.0, y = 0.0;  // torso position on the floor plane, chair frame [m]
  double yaw_added = 0.0;   // rotation added to the initial pose about z [rad]
  double theta = 0.0;       // azimuth around the zone centre (zones 1-3) [rad]
};

// Zone 0: the fixed pose; zones 1-3: theta = sign x U(lo, hi) deg (zone 1 = the authors'
// U(-90, 90) deg), position centre + radius (cos theta, sin theta), yaw_added = theta + pi.
SpawnPose SampleSpawn(const SpawnConfig& config, Rng& rng);

// Moves `pose` (its x, y are replaced; z kept) to `spawn` and rotates its orientation and its
// linear and angular velocities by yaw_added; then maps the result from the chair frame into the
// world through the chair placement.
HumanoidState PlaceAtSpawn(const HumanoidState& pose, const SpawnPose& spawn,
                           const ChairPlacement& placement);

// Rotates a whole state about the vertical axis through the world origin, then translates it
// horizontally.
HumanoidState TransformHorizontally(const HumanoidState& s, double yaw, double dx, double dy);

}  // namespace perch
