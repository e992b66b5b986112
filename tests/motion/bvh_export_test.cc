#include "motion/bvh_export.h"

#include <gtest/gtest.h>

#include "common/rng.h"

namespace perch {
namespace {

TEST(BvhExport, ExportedBvhReproducesTheHumanoidBodies) {
  const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
  Rng rng(13);
  std::vector<MotionPose> frames;
  for (int i = 0; i < 4; ++i) {
    MotionPose p;
    p.root_pos = Eigen::Vector3d(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(0.5, 1.3));
    p.root_rot = Eigen::Quaterniond(
        Eigen::AngleAxisd(rng.Uniform(-3, 3),
                          Eigen::Vector3d(rng.Normal(), rng.Normal(), rng.Normal()).normalized()));
    p.q.resize(21);
    for (int j = 0; j < 21; ++j) p.q[j] = rng.Uniform(model.joint(j).lower, model.joint(j).upper);
    frames.push_back(p);
  }
  const ReferenceMotion m("x", 0.1, frames, false);
  const BvhClip written = HumanoidMotionToBvh(model, m, 0.1, 0.0);
  // Through text and back: the BVH's forward kinematics puts every body where the humanoid's does.
  const BvhClip clip = ParseBvh(WriteBvh(written), "export.bvh");
  ASSERT_EQ(clip.num_frames(), 4);
  for (int f = 0; f < 4; ++f) {
    const BvhPose bp = BvhForwardKinematics(clip, f);
    const FkResult fk =
        ForwardKinematics(model, frames[f].root_pos, frames[f].root_rot, frames[f].q.data());
    for (int b = 0; b < model.num_bodies(); ++b) {
      const int j = clip.Find(model.body(b).name);
      ASSERT_GE(j, 0);
      EXPECT_LT((bp.pos[j] - HumanoidToBvhAxes(fk.body_world[b].translation())).norm(), 1e-6)
          << model.body(b).name << " frame " << f;
    }
  }
}

TEST(BvhExport, RoundTripReproducesTheJointAngles) {
  // Humanoid joint angles -> BVH text -> the project's BVH reader -> joint angles again.
  const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
  Rng rng(21);
  std::vector<MotionPose> frames;
  for (int i = 0; i < 6; ++i) {
    MotionPose p;
    p.root_pos = Eigen::Vector3d(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(0.5, 1.3));
    p.root_rot = Eigen::Quaterniond(Eigen::AngleAxisd(rng.Uniform(-3, 3), Eigen::Vector3d::UnitZ()));
    p.q.resize(21);
    for (int j = 0; j < 21; ++j) {
      const Joint& jt = model.joint(j);
      p.q[j] = rng.Uniform(jt.lower + 0.05 * (jt.upper - jt.lower),
                           jt.upper - 0.05 * (jt.upper - jt.lower));
    }
    frames.push_back(p);
  }
  const ReferenceMotion m("x", 1.0 / 60.0, frames, false);
  const BvhClip clip = ParseBvh(WriteBvh(HumanoidMotionToBvh(model, m, 1.0 / 60.0, 0.0)), "rt.bvh");
  ASSERT_EQ(clip.num_frames(), 6);
  EXPECT_NEAR(clip.frame_time, 1.0 / 60.0, 1e-8);  // the control rate
  for (int f = 0; f < 6; ++f) {
    const std::vector<double> q = HumanoidJointAnglesFromBvh(model, clip, f);
    for (int j = 0; j < 21; ++j) {
      EXPECT_NEAR(q[j], frames[f].q[j], 1e-5) << model.joint(j).name << " frame " << f;
    }
  }
}

}  // namespace
}  // namespace perch
