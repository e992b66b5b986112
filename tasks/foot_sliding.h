// Foot sliding as DAFNet measures it (§6.2): a toe slides in a frame when its toe-base point is
// below 7 cm and moves faster than 0.4 cm/s. Our toe-base point is the front end of the foot
// capsule's axis (its centre line, like a joint, not the surface). Counts the swing foot too while
// it is low, so even a clean reference walk scores well above zero: compare with the reference. Fed
// with world body poses, from physics (perch eval) or from forward kinematics (a reference motion),
// so the same meter checks both.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <functional>
#include <vector>

#include "common/json_util.h"
#include "envs/humanoid_model.h"
#include "motion/reference_motion.h"

namespace perch {

struct FootSlidingOptions {
  double toe_height_m = 0.07;      // DAFNet: toe-base point below 7 cm ...
  double slide_speed_mps = 0.004;  // ... and moving faster than 0.4 cm/s: sliding
};

class FootSlidingMeter {
 public:
  // The toe of each foot body is the end point of its geoms farthest forward (body +x).
  FootSlidingMeter(const HumanoidModel& model, const FootSlidingOptions& options);

  using BodyPoseFn = std::function<Eigen::Isometry3d(int body)>;
  // First frame of an episode: remembers the toe positions, measures nothing.
  void Start(const BodyPoseFn& body_pose);
  // A frame dt seconds after the previous one.
  void Observe(const BodyPoseFn& body_pose, double dt);

  int64_t near_ground_samples() const { return near_ground_; }
  double mean_toe_speed_mps() const { return near_ground_ ? speed_sum_ / near_ground_ : 0.0; }
  double sliding_fraction() const {
    return near_ground_ ? static_cast<double>(sliding_) / near_ground_ : 0.0;
  }
  // {toe_height_m, slide_speed_mps, mean_toe_speed_mps, sliding_fraction, sliding_count_per_s}
  Json ToJson(double seconds) const;

 private:
  struct Toe {
    int body;
    Eigen::Vector3d local;  // body frame [m]
  };
  FootSlidingOptions options_;
  std::vector<Toe> toes_;
  std::vector<Eigen::Vector3d> prev_;  // [toes] world [m]
  double speed_sum_ = 0.0;
  int64_t near_ground_ = 0;
  int64_t sliding_ = 0;
};

// The meter on a reference motion played by forward kinematics for `seconds` at step dt, lowered
// so that its lowest frame touches z = 0: the baseline a policy imitating it can be held against.
FootSlidingMeter ReferenceFootSliding(const HumanoidModel& model, const ReferenceMotion& motion,
                                      double seconds, double dt, const FootSlidingOptions& options);

}  // namespace perch
