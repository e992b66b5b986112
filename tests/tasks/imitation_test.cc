#include "tasks/imitation.h"

#include <cmath>

#include <gtest/gtest.h>

namespace perch {
namespace {

TEST(Imitation, AngleDiffWraps) {
  EXPECT_NEAR(AngleDiff(0.1, -0.1), 0.2, 1e-12);
  // 179 deg vs -179 deg are 2 deg apart, not 358.
  EXPECT_NEAR(AngleDiff(179.0 * M_PI / 180, -179.0 * M_PI / 180), -2.0 * M_PI / 180, 1e-12);
  EXPECT_NEAR(AngleDiff(3 * M_PI, 0.0), -M_PI, 1e-12);
}

TEST(Imitation, SimilarityMatchesHandComputed) {
  const double q[2] = {0.3, -0.2}, qr[2] = {0.1, 0.0};
  const double qd[2] = {1.0, 0.0}, qdr[2] = {0.5, 0.5};
  SimilarityRewardConfig c;  // paper: 0.5, 0.05, 1, 10
  // r^p = exp(-(0.04 + 0.04)) ; r^v = exp(-10 (0.25 + 0.25))
  const double expected = 0.5 * std::exp(-0.08) + 0.05 * std::exp(-5.0);
  EXPECT_NEAR(SimilarityReward(c, q, qr, qd, qdr, 2), expected, 1e-12);
  // Perfect tracking gives the sum of the weights, the maximum.
  EXPECT_NEAR(SimilarityReward(c, qr, qr, qdr, qdr, 2), 0.55, 1e-12);
}

TEST(Imitation, SimilarityTermsReadTheVelocitiesTheConfigNames) {
  const double q[2] = {0.3, -0.2}, q_prev[2] = {0.28, -0.2}, qr[2] = {0.1, 0.0},
               qr_prev[2] = {0.09, 0.01};
  const double qd[2] = {1.0, 0.0}, qdr[2] = {0.5, 0.5};
  const double dt = 0.02;
  SimilarityRewardConfig c;  // the simulator's velocities
  SimilarityTerms t = SimilarityTermsAt(c, q, q_prev, qd, qr, qr_prev, qdr, 2, dt);
  EXPECT_NEAR(t.pose, std::exp(-0.08), 1e-12);
  EXPECT_NEAR(t.joint_vel, std::exp(-5.0), 1e-12);
  EXPECT_NEAR(t.total, SimilarityReward(c, q, qr, qd, qdr, 2), 1e-12);
  // Finite differences: (0.02, 0) / dt = (1, 0) against (0.01, -0.01) / dt = (0.5, -0.5); the
  // stored velocities are not read (NaN would poison the sum).
  c.finite_difference_velocities = true;
  c.alpha_vel = 0.01;
  const double nan = std::nan("");
  const double nan2[2] = {nan, nan};
  t = SimilarityTermsAt(c, q, q_prev, nan2, qr, qr_prev, nan2, 2, dt);
  EXPECT_NEAR(t.joint_vel, std::exp(-0.01 * (0.25 + 0.25)), 1e-12);
  EXPECT_NEAR(t.pose, std::exp(-0.08), 1e-12);
  EXPECT_NEAR(t.total, 0.5 * t.pose + 0.05 * t.joint_vel, 1e-12);
  // And the previous poses are not read with the simulator's velocities.
  c.finite_difference_velocities = false;
  t = SimilarityTermsAt(c, q, nan2, qd, qr, nan2, qdr, 2, dt);
  EXPECT_TRUE(std::isfinite(t.total));
}

TEST(Imitation, TaskTermsHaveTheRightSign) {
  // Approaching the target (distance falls) earns more than half the weight; receding, less.
  const double dt = 1.0 / 60;
  EXPECT_GT(TargetProgressReward(2.0, 2.0 - 0.02, dt, 0.1, 10.0), 0.05);
  EXPECT_LT(TargetProgressReward(2.0, 2.0 + 0.02, dt, 0.1, 10.0), 0.05);
  EXPECT_NEAR(TargetProgressReward(2.0, 2.0, dt, 0.1, 10.0), 0.05, 1e-12);
  EXPECT_NEAR(ApproachReward(1.0, 0.99, 0.01, 0.5), 0.5, 1e-9);
  const double v[3] = {1, 0, 0}, vr[3] = {1.2, 0, 0};
  EXPECT_NEAR(RootVelocityReward(v, vr, 0.5, 10.0), 0.5 * std::exp(-0.4), 1e-12);
  const double rpy[3] = {0, 0, M_PI - 0.05}, rpyr[3] = {0, 0, -M_PI + 0.05};
  EXPECT_NEAR(RootRotationReward(rpy, rpyr, 0.1, 10.0), 0.1 * std::exp(-10 * 0.01), 1e-9);
}

TEST(Imitation, ConfigRoundTripAndStrictness) {
  SimilarityRewardConfig c;
  c.alpha_vel = 0.01;
  const SimilarityRewardConfig d = SimilarityRewardConfig::FromJson(c.ToJson(), "cfg");
  EXPECT_EQ(d.alpha_vel, 0.01);
  EXPECT_THROW(SimilarityRewardConfig::FromJson(Json{{"alpha_vle", 1.0}}, "cfg"), ConfigError);
}

}  // namespace
}  // namespace perch
