#include "motion/bvh.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <functional>

#include "common/json_util.h"

namespace perch {
namespace {

// Two joints with unusual channel orders and an end site; 2 frames.
const char* kSmall = R"(HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Xrotation Zrotation Yrotation
  JOINT Leg
  {
    OFFSET 1 -2 0.5
    CHANNELS 3 Yrotation Xrotation Zrotation
    End Site
    {
      OFFSET 0 -3 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0083333
1 2 3 10 20 30 40 50 60
-1 0.5 0 0 0 90 0 90 0
)";

std::string ErrorOf(const std::string& text) {
  try {
    ParseBvh(text, "bad.bvh");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(Bvh, ParsesHierarchyChannelsAndFrames) {
  const BvhClip c = ParseBvh(kSmall, "small.bvh");
  ASSERT_EQ(c.joints.size(), 3u);
  EXPECT_EQ(c.num_channels, 9);
  EXPECT_EQ(c.joints[2].name, "Leg_End");
  EXPECT_TRUE(c.joints[2].end_site);
  EXPECT_EQ(c.joints[1].parent, 0);
  EXPECT_EQ(c.joints[1].first_channel, 6);
  EXPECT_EQ(c.joints[1].channels[0], BvhChannel::kYrot);
  EXPECT_DOUBLE_EQ(c.frame_time, 0.0083333);
  ASSERT_EQ(c.num_frames(), 2);
  EXPECT_DOUBLE_EQ(c.frames(0, 8), 60.0);
  EXPECT_DOUBLE_EQ(c.frames(1, 1), 0.5);
}

TEST(Bvh, ForwardKinematicsFollowsChannelOrder) {
  const BvhClip c = ParseBvh(kSmall, "small.bvh");
  // Frame 1: root at (-1, .5, 0) rotated Yrot 90 (channel order X, Z, Y); leg Xrot 90.
  const BvhPose p = BvhForwardKinematics(c, 1);
  EXPECT_NEAR(p.pos[0].x(), -1.0, 1e-12);
  // Leg offset (1, -2, .5) rotated 90 deg about Y: (x, y, z) -> (z, y, -x).
  EXPECT_NEAR((p.pos[1] - p.pos[0] - Eigen::Vector3d(0.5, -2, -1)).norm(), 0.0, 1e-12);
  // End (0, -3, 0): leg Xrot 90 maps -Y to -Z, then root Y 90 maps -Z to -X.
  EXPECT_NEAR((p.pos[2] - p.pos[1] - Eigen::Vector3d(-3, 0, 0)).norm(), 0.0, 1e-12);
}

TEST(Bvh, WriteThenReadIsIdentical) {
  const BvhClip a = ParseBvh(kSmall, "small.bvh");
  const BvhClip b = ParseBvh(WriteBvh(a), "written.bvh");
  ASSERT_EQ(a.joints.size(), b.joints.size());
  for (size_t i = 0; i < a.joints.size(); ++i) {
    EXPECT_EQ(a.joints[i].name, b.joints[i].name);
    EXPECT_EQ(a.joints[i].parent, b.joints[i].parent);
    EXPECT_EQ(a.joints[i].channels, b.joints[i].channels);
    EXPECT_EQ(a.joints[i].offset, b.joints[i].offset);
  }
  EXPECT_DOUBLE_EQ(a.frame_time, b.frame_time);
  EXPECT_EQ(a.frames, b.frames);
}

TEST(Bvh, RoundTripsARealCmuFile) {
  const std::string path = PERCH_SOURCE_DIR "/../shared/mocap/08_01.bvh";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "no " << path;
  const BvhClip a = ReadBvhFile(path);
  EXPECT_EQ(a.num_channels, 96);
  EXPECT_EQ(a.num_frames(), 70);
  const BvhClip b = ParseBvh(WriteBvh(a), "written.bvh");
  EXPECT_EQ(a.joints.size(), b.joints.size());
  EXPECT_LT((a.frames - b.frames).cwiseAbs().maxCoeff(), 1e-6);
  const BvhPose pa = BvhForwardKinematics(a, 30), pb = BvhForwardKinematics(b, 30);
  for (size_t i = 0; i < pa.pos.size(); ++i) EXPECT_LT((pa.pos[i] - pb.pos[i]).norm(), 1e-6);
  // cgspeed skeleton: standing hip height ~15-18 units (mocap README).
  EXPECT_GT(a.frames(1, 1), 14.0);
  EXPECT_LT(a.frames(1, 1), 19.0);
}

TEST(Bvh, MalformedFilesNameFileAndLine) {
  const std::string good = kSmall;
  auto replace = [&](const std::string& from, const std::string& to) {
    std::string s = good;
    s.replace(s.find(from), from.size(), to);
    return s;
  };
  struct Case {
    std::string text, line, what;
  };
  const std::vector<Case> cases = {
      {good.substr(0, good.rfind("-1 0.5")), "bad.bvh:19:", "only 1 frame lines"},
      {replace("40 50 60\n", "40 50\n"), "bad.bvh:19:", "has 8 values, expected 9"},
      {replace("40 50 60\n", "40 50 60 70\n"), "bad.bvh:19:", "has 10 values"},
      {replace("JOINT Leg", "JIONT Leg"), "bad.bvh:6:", "unknown keyword 'JIONT'"},
      {replace("Yrotation Xrotation Zrotation", "Yrotation Wrotation Zrotation"),
       "bad.bvh:9:", "unknown channel 'Wrotation'"},
      {replace("Frames: 2", "Frames: 3"), "bad.bvh:", "only 2 frame lines"},
      {replace("Frames: 2", "Frames: two"), "bad.bvh:17:", "bad frame count"},
      {replace("-1 0.5 0", "-1 0.5x 0"), "bad.bvh:20:", "bad number"},
      {replace("OFFSET 1 -2 0.5", "OFFSET 1 -2"), "bad.bvh:9:", "expected an OFFSET value"},
      {good.substr(0, good.find("MOTION")), "bad.bvh:", "no MOTION"},
      {replace("HIERARCHY", "HIERARCH"), "bad.bvh:1:", "expected 'HIERARCHY'"},
  };
  for (const Case& c : cases) {
    const std::string err = ErrorOf(c.text);
    EXPECT_NE(err.find(c.line), std::string::npos) << "got: " << err << " want " << c.line;
    EXPECT_NE(err.find(c.what), std::string::npos) << "got: " << err << " want " << c.what;
  }
  try {
    ReadBvhFile("/nonexistent/a.bvh");
    ADD_FAILURE();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/a.bvh"), std::string::npos);
  }
}

}  // namespace
}  // namespace perch
