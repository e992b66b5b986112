#include "motion/ik.h"

#include <gtest/gtest.h>

#include "common/rng.h"

namespace perch {
namespace {

// A floating root with two 3-hinge arms: hinge z and y at the arm base, a link along x, hinge x,
// a link along y. Key points: three on the root, the elbow and the tip of each arm. The pose is
// uniquely determined by these points for angles inside the (narrow) limits.
class TwoArmModel : public IkModel {
 public:
  int num_joints() const override { return 6; }
  int num_points() const override { return 7; }
  double lower(int) const override { return -1.2; }
  double upper(int) const override { return 1.2; }
  void KeyPoints(const IkPose& p, Eigen::Matrix3Xd* out) const override {
    out->resize(3, 7);
    const Eigen::Matrix3d r = p.root_rot.toRotationMatrix();
    out->col(0) = p.root_pos;
    out->col(1) = p.root_pos + r * Eigen::Vector3d(0, 0, 0.3);
    for (int a = 0; a < 2; ++a) {
      const double side = a == 0 ? 1.0 : -1.0;
      const Eigen::Vector3d base = p.root_pos + r * Eigen::Vector3d(0, side * 0.2, 0);
      if (a == 0) out->col(2) = base;
      const Eigen::Matrix3d r1 = r * Eigen::AngleAxisd(p.q[3 * a], Eigen::Vector3d::UnitZ()) *
                                 Eigen::AngleAxisd(p.q[3 * a + 1], Eigen::Vector3d::UnitY());
      const Eigen::Vector3d elbow = base + r1 * Eigen::Vector3d(0.4, 0, 0);
      const Eigen::Matrix3d r2 = r1 * Eigen::AngleAxisd(p.q[3 * a + 2], Eigen::Vector3d::UnitX());
      out->col(3 + 2 * a) = elbow;
      out->col(4 + 2 * a) = elbow + r2 * Eigen::Vector3d(0, side * 0.3, 0.05);
    }
  }
};

IkPose RandomPose(Rng& rng, double joint_range) {
  IkPose p;
  p.root_pos = Eigen::Vector3d(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(0.5, 1.5));
  p.root_rot = Eigen::Quaterniond(Eigen::AngleAxisd(
      rng.Uniform(-3, 3), Eigen::Vector3d(rng.Normal(), rng.Normal(), rng.Normal()).normalized()));
  p.q.resize(6);
  for (int j = 0; j < 6; ++j) p.q[j] = rng.Uniform(-joint_range, joint_range);
  return p;
}

TEST(Ik, RecoversTheExactPoseOfASyntheticSkeleton) {
  TwoArmModel model;
  Rng rng(7);
  for (int trial = 0; trial < 10; ++trial) {
    const IkPose truth = RandomPose(rng, 1.0);
    Eigen::Matrix3Xd targets;
    model.KeyPoints(truth, &targets);
    // Warm start a few centimetres / a few tenths of a radian away, as from the previous frame.
    IkPose init = truth;
    init.root_pos += Eigen::Vector3d(0.05, -0.04, 0.03);
    init.root_rot = truth.root_rot * Eigen::AngleAxisd(0.2, Eigen::Vector3d(1, 1, 0).normalized());
    for (int j = 0; j < 6; ++j) init.q[j] += rng.Uniform(-0.2, 0.2);
    const IkResult r = SolveIk(model, targets, Eigen::VectorXd::Ones(7), init, IkOptions{});
    EXPECT_LT((r.pose.q - truth.q).cwiseAbs().maxCoeff(), 1e-5) << "trial " << trial;
    EXPECT_LT((r.pose.root_pos - truth.root_pos).norm(), 1e-6);
    EXPECT_LT(r.pose.root_rot.angularDistance(truth.root_rot), 1e-5);
    EXPECT_LT(r.weighted_sq_err, 1e-10);
  }
}

TEST(Ik, KeepsJointsInsideTheirLimits) {
  TwoArmModel model;
  Rng rng(3);
  IkPose truth = RandomPose(rng, 0.5);
  truth.q[1] = 1.6;  // beyond the 1.2 rad limit: unreachable exactly
  Eigen::Matrix3Xd targets;
  model.KeyPoints(truth, &targets);
  IkPose init = truth;
  init.q[1] = 0.0;
  const IkResult r = SolveIk(model, targets, Eigen::VectorXd::Ones(7), init, IkOptions{});
  for (int j = 0; j < 6; ++j) {
    EXPECT_GE(r.pose.q[j], model.lower(j));
    EXPECT_LE(r.pose.q[j], model.upper(j));
  }
  // The best fit within the limits pushes the joint to its bound.
  EXPECT_NEAR(r.pose.q[1], 1.2, 0.05);
  EXPECT_GT(r.weighted_sq_err, 1e-4);
}

TEST(Ik, WeightsSelectWhichPointsAreMatched) {
  TwoArmModel model;
  Rng rng(11);
  const IkPose truth = RandomPose(rng, 0.8);
  Eigen::Matrix3Xd targets;
  model.KeyPoints(truth, &targets);
  targets.col(6) += Eigen::Vector3d(0.5, 0.5, 0.5);  // an inconsistent target for the last tip
  Eigen::VectorXd w = Eigen::VectorXd::Ones(7);
  w[6] = 0.0;  // ... which is ignored
  const IkResult r = SolveIk(model, targets, w, truth, IkOptions{});
  EXPECT_LT((r.pose.q - truth.q).cwiseAbs().maxCoeff(), 1e-6);
}

}  // namespace
}  // namespace perch
