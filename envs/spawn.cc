#include "envs/spawn.h"

#include <cmath>

namespace perch {

namespace {

bool OnHardCircle(const SpawnConfig& c, int zone) {
  return (zone == 2 || zone == 3) && c.hard_radius > 0.0;
}

}  // namespace

SpawnCircle ZoneCircle(const SpawnConfig& c, int zone) {
  if (OnHardCircle(c, zone)) return {c.hard_center_x, c.hard_center_y, c.hard_radius};
  return {c.center_x, c.center_y, c.radius};
}

SpawnPose SampleSpawn(const SpawnConfig& c, Rng& rng) {
  SpawnPose s;
  if (c.zone == 0) {
    s.x = c.x;
    s.y = c.y;
    s.yaw_added = c.yaw_deg * M_PI / 180.0;
    return s;
  }
  // A draw only for a mixture, so the single zones keep their random streams.
  const int zone = c.zones.empty() ? c.zone
                                   : c.zones[rng.UniformInt(static_cast<int>(c.zones.size()))];
  const std::array<double, 2>& r = zone == 1   ? c.zone1_deg
                                   : zone == 2 ? c.zone2_deg
                                               : c.zone3_deg;
  const double magnitude = rng.Uniform(r[0], r[1]) * M_PI / 180.0;
  const double sign = rng.Uniform() < 0.5 ? -1.0 : 1.0;
  s.theta = sign * magnitude;
  const SpawnCircle circle = ZoneCircle(c, zone);
  // Extra draws only when asked for (Zone 1's circle), so the zones keep their random streams.
  const double radius = !OnHardCircle(c, zone) && c.radius_max > c.radius
                            ? rng.Uniform(c.radius, c.radius_max)
                            : circle.radius;
  s.x = circle.center_x + radius * std::cos(s.theta);
  s.y = circle.center_y + radius * std::sin(s.theta);
  s.yaw_added = s.theta + M_PI;  // facing the centre
  if (c.yaw_noise_deg > 0.0) {
    s.yaw_added += rng.Uniform(-c.yaw_noise_deg, c.yaw_noise_deg) * M_PI / 180.0;
  }
  return s;
}

HumanoidState TransformHorizontally(const HumanoidState& s, double yaw, double dx, double dy) {
  const Eigen::AngleAxisd rz(yaw, Eigen::Vector3d::UnitZ());
  HumanoidState o = s;
  o.root_pos = rz * s.root_pos + Eigen::Vector3d(dx, dy, 0.0);
  o.root_quat = (Eigen::Quaterniond(rz) * s.root_quat).normalized();
  o.root_lin_vel = rz * s.root_lin_vel;
  o.root_ang_vel = rz * s.root_ang_vel;
  return o;
}

HumanoidState PlaceAtSpawn(const HumanoidState& pose, const SpawnPose& spawn,
                           const ChairPlacement& placement) {
  HumanoidState local = pose;
  local.root_pos.x() = 0.0;
  local.root_pos.y() = 0.0;
  local = TransformHorizontally(local, spawn.yaw_added, spawn.x, spawn.y);
  return TransformHorizontally(local, placement.yaw, placement.x, placement.y);
}

}  // namespace perch
