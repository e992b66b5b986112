#include "motion/reference_motion.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "common/rng.h"
#include "envs/humanoid_model.h"

namespace perch {
namespace {

const HumanoidModel& Model() {
  static const HumanoidModel m = HumanoidModel::Load(HumanoidModel::DefaultPath());
  return m;
}

MotionPose RandomPose(Rng& rng) {
  MotionPose p;
  p.root_pos = Eigen::Vector3d(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(0.8, 1.3));
  p.root_rot = Eigen::Quaterniond(Eigen::AngleAxisd(
      rng.Uniform(-3, 3), Eigen::Vector3d(rng.Normal(), rng.Normal(), rng.Normal()).normalized()));
  p.q.resize(21);
  for (int j = 0; j < 21; ++j) p.q[j] = rng.Uniform(Model().joint(j).lower, Model().joint(j).upper);
  p.qdot = Eigen::VectorXd::Zero(21);
  return p;
}

// A motion whose root moves at constant velocity and turns at a constant rate about z, with
// joint angles linear in time: velocities and interpolation have exact answers.
ReferenceMotion LinearMotion(int n, double dt, bool loop) {
  std::vector<MotionPose> frames;
  for (int i = 0; i < n; ++i) {
    MotionPose p;
    const double t = i * dt;
    p.root_pos = Eigen::Vector3d(0.5 * t, -0.2 * t, 1.0);
    p.root_rot = Eigen::Quaterniond(Eigen::AngleAxisd(0.3 * t, Eigen::Vector3d::UnitZ()));
    p.q = Eigen::VectorXd::LinSpaced(21, 0.0, 0.2) * t;
    frames.push_back(p);
  }
  return ReferenceMotion("linear", dt, frames, loop);
}

TEST(ReferenceMotion, InterpolatesPoseAndFiniteDifferenceVelocities) {
  const double dt = 1.0 / 60;
  const ReferenceMotion m = LinearMotion(31, dt, false);
  EXPECT_NEAR(m.duration(), 0.5, 1e-12);
  const MotionPose p = m.At(0.2 + 0.3 * dt);
  EXPECT_NEAR(p.root_pos.x(), 0.5 * (0.2 + 0.3 * dt), 1e-12);
  EXPECT_NEAR(p.q[20], 0.2 * (0.2 + 0.3 * dt), 1e-12);
  // Slerp of a constant-rate turn is exact.
  const Eigen::Quaterniond want(
      Eigen::AngleAxisd(0.3 * (0.2 + 0.3 * dt), Eigen::Vector3d::UnitZ()));
  EXPECT_LT(p.root_rot.angularDistance(want), 1e-9);
  EXPECT_NEAR(p.qdot[20], 0.2, 1e-9);
  EXPECT_NEAR(p.root_vel.y(), -0.2, 1e-9);
  EXPECT_NEAR(p.root_angvel.z(), 0.3, 1e-6);
  // The ends use one-sided differences and t is clamped.
  EXPECT_NEAR(m.At(-1.0).qdot[10], 0.1, 1e-9);
  EXPECT_NEAR(m.At(5.0).root_pos.x(), 0.25, 1e-12);
  EXPECT_NEAR(m.Phase(0.25), 0.5, 1e-12);
  EXPECT_EQ(m.Cycle(3.0), 0);
}

TEST(ReferenceMotion, LoopRepeatsWithCycleDisplacementAndYaw) {
  Rng rng(5);
  std::vector<MotionPose> frames;
  for (int i = 0; i < 10; ++i) frames.push_back(RandomPose(rng));
  frames.back() = frames.front();
  frames.back().root_pos += Eigen::Vector3d(1.0, 0.2, 0);
  ReferenceMotion m("loop", 0.1, frames, false);
  const Eigen::Vector3d disp(1.0, 0.2, 0);
  m.set_loop(true, disp, 0.0);
  m.ComputeVelocities();
  const double period = m.duration();
  for (double t : {0.0, 0.13, 0.5, 0.87}) {
    const MotionPose a = m.At(t), b = m.At(t + 2 * period);
    EXPECT_LT((b.root_pos - a.root_pos - 2 * disp).norm(), 1e-9) << t;
    EXPECT_LT((b.q - a.q).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_LT((b.qdot - a.qdot).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_NEAR(m.Phase(t + 2 * period), m.Phase(t), 1e-9);
  }
  EXPECT_EQ(m.Cycle(2.5 * period), 2);
  // Velocity at the seam: the same from both sides of the cycle boundary.
  EXPECT_LT((m.At(0).qdot - m.At(period - 1e-12).qdot).cwiseAbs().maxCoeff(), 1e-6);
  // A cycle yaw rotates each repetition about z.
  m.set_loop(true, disp, M_PI / 2);
  const MotionPose a = m.At(0.2), b = m.At(0.2 + period);
  const Eigen::Vector3d rotated(-a.root_pos.y(), a.root_pos.x(), a.root_pos.z());
  EXPECT_LT((b.root_pos - (rotated + disp)).norm(), 1e-9);
}

TEST(ReferenceMotion, JsonRoundTripAndStrictErrors) {
  Rng rng(9);
  std::vector<MotionPose> frames;
  for (int i = 0; i < 5; ++i) frames.push_back(RandomPose(rng));
  ReferenceMotion m("rt", 1.0 / 60, frames, false);
  m.meta()["source"] = {{"bvh", "x.bvh"}};
  const std::string path = ::testing::TempDir() + "/rt_motion.json";
  m.Save(path);
  const ReferenceMotion r = ReferenceMotion::Load(path);
  ASSERT_EQ(r.num_frames(), 5);
  EXPECT_EQ(r.meta()["source"]["bvh"], "x.bvh");
  for (int i = 0; i < 5; ++i) {
    EXPECT_LT((r.frame(i).q - m.frame(i).q).cwiseAbs().maxCoeff(), 1e-6);
    EXPECT_LT((r.frame(i).root_pos - m.frame(i).root_pos).norm(), 2e-6);
    EXPECT_LT(r.frame(i).root_rot.angularDistance(m.frame(i).root_rot), 1e-5);
  }
  Json j = m.ToJson();
  j["bogus"] = 1;
  EXPECT_THROW(ReferenceMotion::FromJson(j, "f.json"), ConfigError);
  j = m.ToJson();
  j["q_rad"][2].erase(0);
  try {
    ReferenceMotion::FromJson(j, "f.json");
    ADD_FAILURE();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("f.json.q_rad[2]"), std::string::npos) << e.what();
  }
  j = m.ToJson();
  j["num_frames"] = 6;
  EXPECT_THROW(ReferenceMotion::FromJson(j, "f.json"), ConfigError);
  std::filesystem::remove(path);
}

TEST(Mirror, JointMapFollowsTheAxes) {
  std::vector<int> c;
  std::vector<double> s;
  MirrorJointMap(Model(), &c, &s);
  const auto& m = Model();
  EXPECT_EQ(c[m.FindJoint("right_knee")], m.FindJoint("left_knee"));
  EXPECT_EQ(c[m.FindJoint("abdomen_y")], m.FindJoint("abdomen_y"));
  // Yaw and roll of the abdomen change sign; pitch does not.
  EXPECT_EQ(s[m.FindJoint("abdomen_z")], -1.0);
  EXPECT_EQ(s[m.FindJoint("abdomen_y")], 1.0);
  for (size_t j = 0; j < c.size(); ++j) EXPECT_EQ(c[c[j]], static_cast<int>(j));
}

TEST(Mirror, MirroredPoseIsTheReflectedBody) {
  Rng rng(21);
  const auto& m = Model();
  for (int trial = 0; trial < 5; ++trial) {
    const MotionPose p = RandomPose(rng);
    const MotionPose q = ReferenceMotion::MirrorPose(p, m);
    const FkResult a = ForwardKinematics(m, p.root_pos, p.root_rot, p.q.data());
    const FkResult b = ForwardKinematics(m, q.root_pos, q.root_rot, q.q.data());
    // Each body of the mirror lies at the reflection (y -> -y) of its counterpart.
    for (int i = 0; i < m.num_bodies(); ++i) {
      std::string name = m.body(i).name;
      if (name.rfind("right_", 0) == 0)
        name = "left_" + name.substr(6);
      else if (name.rfind("left_", 0) == 0)
        name = "right_" + name.substr(5);
      const Eigen::Vector3d pa = a.body_world[i].translation();
      const Eigen::Vector3d pb = b.body_world[m.FindBody(name)].translation();
      EXPECT_LT((Eigen::Vector3d(pa.x(), -pa.y(), pa.z()) - pb).norm(), 1e-9) << name;
    }
  }
}

TEST(Mirror, TwiceIsTheIdentity) {
  Rng rng(4);
  std::vector<MotionPose> frames;
  for (int i = 0; i < 6; ++i) frames.push_back(RandomPose(rng));
  ReferenceMotion m("x", 0.02, frames, false);
  m.set_loop(true, Eigen::Vector3d(0.7, 0.1, 0), 0.05);
  const ReferenceMotion once = m.Mirrored(Model());
  const ReferenceMotion twice = once.Mirrored(Model());
  EXPECT_GT((once.frame(2).q - m.frame(2).q).cwiseAbs().maxCoeff(), 1e-3);
  for (int i = 0; i < m.num_frames(); ++i) {
    EXPECT_LT((twice.frame(i).q - m.frame(i).q).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((twice.frame(i).qdot - m.frame(i).qdot).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((twice.frame(i).root_pos - m.frame(i).root_pos).norm(), 1e-12);
    EXPECT_LT(twice.frame(i).root_rot.angularDistance(m.frame(i).root_rot), 1e-12);
  }
  EXPECT_LT((twice.cycle_displacement() - m.cycle_displacement()).norm(), 1e-12);
  EXPECT_DOUBLE_EQ(twice.cycle_yaw(), m.cycle_yaw());
}

// The straightened sit clip keeps the pelvis and the feet where they were and the torso's
// orientation, and moves the back forward of where the slouched clip had it: placed at the
// authors' seat target, the original's torso and lower waist reach 14-15 cm behind the pelvis,
// through the backrest 10.4 cm behind it.
TEST(Straightened, KeepsPelvisFeetAndTorsoAndClearsTheBack) {
  const ReferenceMotion m =
      ReferenceMotion::Load(std::string(PERCH_SOURCE_DIR) + "/data/motions/sit.json");
  const double t0 = 1.4, t1 = 2.2;
  const ReferenceMotion s = m.Straightened(Model(), 20.0, t0, t1);
  ASSERT_EQ(s.num_frames(), m.num_frames());
  const int pelvis = Model().pelvis_body();
  const int ay = Model().FindJoint("abdomen_y");
  const int feet[2] = {Model().FindBody("right_foot"), Model().FindBody("left_foot")};
  for (int i = 0; i < m.num_frames(); ++i) {
    const MotionPose& a = m.frame(i);
    const MotionPose& b = s.frame(i);
    const FkResult fa = ForwardKinematics(Model(), a.root_pos, a.root_rot, a.q.data());
    const FkResult fb = ForwardKinematics(Model(), b.root_pos, b.root_rot, b.q.data());
    EXPECT_LT((fa.body_world[pelvis].translation() - fb.body_world[pelvis].translation()).norm(),
              1e-9)
        << i;
    EXPECT_LT(a.root_rot.angularDistance(b.root_rot), 1e-9) << i;
    const double want =
        20.0 * M_PI / 180.0 * std::clamp((i * m.frame_time() - t0) / (t1 - t0), 0.0, 1.0);
    EXPECT_NEAR(b.q[ay] - a.q[ay], want, 1e-9) << i;
    for (int f : feet) {
      EXPECT_LT((fa.body_world[f].translation() - fb.body_world[f].translation()).norm(), 0.03)
          << i;
    }
  }
  const MotionPose& a = m.frame(m.num_frames() - 1);
  const MotionPose& b = s.frame(s.num_frames() - 1);
  const FkResult fa = ForwardKinematics(Model(), a.root_pos, a.root_rot, a.q.data());
  const FkResult fb = ForwardKinematics(Model(), b.root_pos, b.root_rot, b.q.data());
  for (const char* body : {"torso", "lwaist"}) {
    EXPECT_GT(ReferenceMotion::ReachBehindPelvis(Model(), a, body), 0.13)
        << body << ": the slouch this is about";
    EXPECT_LT(ReferenceMotion::ReachBehindPelvis(Model(), b, body), 0.10)
        << body << ": straightened";
  }
  EXPECT_THROW(m.Straightened(Model(), 20.0, 2.0, 1.0), ConfigError);
}

TEST(Straightened, KeepPelvisSitsTheTorsoUpAndMovesNothingBelowTheWaist) {
  const ReferenceMotion m =
      ReferenceMotion::Load(std::string(PERCH_SOURCE_DIR) + "/data/motions/sit.json");
  const ReferenceMotion s = m.Straightened(Model(), 8.0, 1.6, 2.4, "pelvis");
  const int ay = Model().FindJoint("abdomen_y");
  const int pelvis = Model().pelvis_body();
  const int torso = Model().FindBody("torso");
  const int last = m.num_frames() - 1;
  for (int i : {0, last / 2, last}) {
    const MotionPose& a = m.frame(i);
    const MotionPose& b = s.frame(i);
    const FkResult fa = ForwardKinematics(Model(), a.root_pos, a.root_rot, a.q.data());
    const FkResult fb = ForwardKinematics(Model(), b.root_pos, b.root_rot, b.q.data());
    // Every body from the pelvis down keeps its world pose; only abdomen_y differs.
    for (const char* body : {"pelvis", "right_thigh", "left_shin", "right_foot", "left_foot"}) {
      const int k = Model().FindBody(body);
      EXPECT_LT((fa.body_world[k].translation() - fb.body_world[k].translation()).norm(), 1e-9)
          << body << " frame " << i;
      EXPECT_LT(Eigen::Quaterniond(fa.body_world[k].linear())
                    .angularDistance(Eigen::Quaterniond(fb.body_world[k].linear())),
                1e-9)
          << body;
    }
    for (int j = 0; j < Model().num_joints(); ++j) {
      if (j != ay) {
        EXPECT_EQ(a.q[j], b.q[j]) << j;
      }
    }
  }
  // Seated (last frame): the torso is 8 deg more upright, so its centre lies further forward
  // (+x, the chair is behind) of the pelvis than the clip's.
  const MotionPose& a = m.frame(last);
  const MotionPose& b = s.frame(last);
  const FkResult fa = ForwardKinematics(Model(), a.root_pos, a.root_rot, a.q.data());
  const FkResult fb = ForwardKinematics(Model(), b.root_pos, b.root_rot, b.q.data());
  const double xa = (fa.body_world[torso].translation() - fa.body_world[pelvis].translation()).x();
  const double xb = (fb.body_world[torso].translation() - fb.body_world[pelvis].translation()).x();
  EXPECT_GT(xb, xa + 0.02) << xa << " -> " << xb;
  EXPECT_NEAR(a.root_rot.angularDistance(b.root_rot), 8.0 * M_PI / 180.0, 1e-6);
  EXPECT_NEAR(b.q[ay] - a.q[ay], -8.0 * M_PI / 180.0, 1e-12);
  EXPECT_THROW(m.Straightened(Model(), 8.0, 1.6, 2.4, "knees"), ConfigError);
}

}  // namespace
}  // namespace perch
