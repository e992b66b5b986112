// The foot-sliding meter on kinematic motions with known answers: a gliding statue slides at its
// speed; the retargeted walk clip plants its feet, so its toes move far slower than its root.
#include "tasks/foot_sliding.h"

#include <gtest/gtest.h>

#include "common/paths.h"
#include "motion/reference_motion.h"

namespace perch {
namespace {


// Plays pose(t) through forward kinematics at 60 Hz for `seconds`.
template <typename PoseAt>
void Play(const HumanoidModel& model, PoseAt pose_at, double seconds, FootSlidingMeter* meter,
          double* root_speed) {
  const double dt = 1.0 / 60.0;
  const int n = static_cast<int>(seconds / dt);
  Eigen::Vector3d first = Eigen::Vector3d::Zero(), last = first;
  for (int i = 0; i <= n; ++i) {
    const MotionPose p = pose_at(i * dt);
    const FkResult fk = ForwardKinematics(model, p.root_pos, p.root_rot, p.q.data());
    auto body = [&](int b) { return fk.body_world[b]; };
    if (i == 0) {
      meter->Start(body);
      first = p.root_pos;
    } else {
      meter->Observe(body, dt);
    }
    last = p.root_pos;
  }
  *root_speed = (last - first).head<2>().norm() / (n * dt);
}

// The default pose (all joints 0) standing on the floor: both feet flat.
MotionPose Standing(const HumanoidModel& model) {
  MotionPose p;
  p.q = Eigen::VectorXd::Zero(model.num_joints());
  p.qdot = p.q;
  const FkResult fk = ForwardKinematics(model, p.root_pos, p.root_rot, p.q.data());
  p.root_pos.z() -= LowestGeomZ(model, fk);
  return p;
}

TEST(FootSliding, GlidingStatueSlidesAtItsSpeed) {
  const HumanoidModel model = HumanoidModel::Load(ResolveProjectPath("data/humanoid.json"));
  const MotionPose p0 = Standing(model);
  FootSlidingMeter meter(model, FootSlidingOptions());
  double speed = 0;
  Play(model, [&](double t) {
    MotionPose p = p0;
    p.root_pos.x() += 0.8 * t;
    return p;
  }, 2.0, &meter, &speed);
  EXPECT_NEAR(speed, 0.8, 1e-9);
  ASSERT_EQ(meter.near_ground_samples(), 2 * 120);  // both toes, every frame
  EXPECT_NEAR(meter.mean_toe_speed_mps(), 0.8, 1e-6);
  EXPECT_DOUBLE_EQ(meter.sliding_fraction(), 1.0);
  EXPECT_NEAR(meter.ToJson(2.0)["sliding_count_per_s"].get<double>(), 120.0, 1e-9);
  // Lifted 5 cm (toe axis then above 7 cm) nothing counts.
  FootSlidingMeter lifted(model, FootSlidingOptions());
  Play(model, [&](double t) {
    MotionPose p = p0;
    p.root_pos += Eigen::Vector3d(0.8 * t, 0, 0.05);
    return p;
  }, 1.0, &lifted, &speed);
  EXPECT_EQ(lifted.near_ground_samples(), 0);
}

TEST(FootSliding, StandingStillDoesNotSlide) {
  const HumanoidModel model = HumanoidModel::Load(ResolveProjectPath("data/humanoid.json"));
  const MotionPose p0 = Standing(model);
  FootSlidingMeter meter(model, FootSlidingOptions());
  double speed = 0;
  Play(model, [&](double) { return p0; }, 1.0, &meter, &speed);
  EXPECT_EQ(meter.near_ground_samples(), 2 * 60);
  EXPECT_EQ(meter.mean_toe_speed_mps(), 0.0);
  EXPECT_EQ(meter.sliding_fraction(), 0.0);
}

TEST(FootSliding, RetargetedWalkPlantsItsFeet) {
  const HumanoidModel model = HumanoidModel::Load(ResolveProjectPath("data/humanoid.json"));
  const ReferenceMotion walk = ReferenceMotion::Load(ResolveProjectPath("data/motions/walk.json"));
  const double seconds = 4.0, dt = 1.0 / 60.0;
  const double speed = (walk.At(seconds).root_pos - walk.At(0).root_pos).head<2>().norm() / seconds;
  ASSERT_GT(speed, 0.8);  // it walks
  // Toes on the ground (axis within 0.8 cm of the capsule radius): the stance foot, nearly still.
  FootSlidingOptions planted;
  planted.toe_height_m = 0.035;
  const FootSlidingMeter stance = ReferenceFootSliding(model, walk, seconds, dt, planted);
  ASSERT_GT(stance.near_ground_samples(), 0.3 * 2 * seconds / dt);  // each foot stands >= 30%
  EXPECT_LT(stance.mean_toe_speed_mps(), 0.25 * speed)
      << "stance toe speed " << stance.mean_toe_speed_mps() << " vs walking " << speed;
  // DAFNet's 7 cm band also holds the low swing foot: more samples, faster on average.
  const FootSlidingMeter dafnet = ReferenceFootSliding(model, walk, seconds, dt, {});
  EXPECT_GT(dafnet.near_ground_samples(), stance.near_ground_samples());
  EXPECT_GT(dafnet.mean_toe_speed_mps(), stance.mean_toe_speed_mps());
}

}  // namespace
}  // namespace perch
