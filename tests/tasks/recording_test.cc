// Recordings: episodes are the same with and without recording, the frames hold the simulator's
// body poses, bad files are refused by reason, and a recorded episode round-trips through BVH.
#include "tasks/recording.h"

#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/paths.h"
#include "envs/chair.h"
#include "learner/ppo.h"
#include "motion/bvh.h"
#include "motion/bvh_export.h"
#include "tasks/registry.h"
#include "tasks/task_eval.h"
#include "tests/support/untrained.h"

namespace perch {
namespace {

TaskEnvConfig SitConfig() {
  return TaskEnvConfig::FromJson(Json{{"task", "sit"}, {"sit", {{"eval_episode_s", 1.0}}}}, "t");
}

// Evaluates 3 sit episodes of an untrained policy, optionally recording the first 2.
Json Evaluate(EpisodeRecorder* rec) {
  const TaskEnvConfig c = SitConfig();
  EvalOptions o;
  o.episodes = 3;
  o.seed = 7;
  o.stochastic = true;
  o.recorder = rec;
  return GetTask("sit", "t").evaluate(c, Untrained(57, 3), o, nullptr);
}

std::string TempPath(const std::string& name) { return ::testing::TempDir() + name; }

TEST(Recording, RecordingDoesNotChangeTheEpisodesAndHoldsTheSimulatorsPoses) {
  EpisodeRecorder rec(2);
  const Json with = Evaluate(&rec);
  const Json without = Evaluate(nullptr);
  EXPECT_EQ(with.dump(), without.dump());  // same falls, steps, returns
  const proto::Recording& r = rec.recording();
  ASSERT_EQ(r.episodes_size(), 2);
  ASSERT_EQ(r.bodies_size(), 13);
  EXPECT_EQ(r.joint_names_size(), 21);
  EXPECT_NEAR(r.control_dt(), 1.0 / 60.0, 1e-6);
  const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
  for (const proto::RecEpisode& ep : r.episodes()) {
    // Frames: the reset and one per step; the outcome agrees with the evaluation's fall list.
    const bool fell = std::find(with["fall_episodes"].begin(), with["fall_episodes"].end(),
                                ep.index()) != with["fall_episodes"].end();
    EXPECT_EQ(ep.fell(), fell);
    EXPECT_EQ(ep.outcome(), ep.success() ? "success" : fell ? "fell" : "time_limit");
    ASSERT_GT(ep.frames_size(), 2);
    EXPECT_EQ(ep.frames(0).step(), 0);
    EXPECT_EQ(ep.frames(ep.frames_size() - 1).step(), ep.frames_size() - 1);
    ASSERT_TRUE(ep.has_chair());
    EXPECT_FALSE(ep.chair().boxes().empty());
    double reward_sum = 0;
    for (const proto::RecFrame& f : ep.frames()) {
      ASSERT_EQ(f.body_pos_size(), 39);
      ASSERT_EQ(f.chair_pos_size(), 3);
      reward_sum += f.reward();
      // Every body where forward kinematics of the recorded root and joint angles puts it.
      const Eigen::Vector3d root(f.body_pos(0), f.body_pos(1), f.body_pos(2));
      const Eigen::Quaterniond rq(f.body_quat(0), f.body_quat(1), f.body_quat(2), f.body_quat(3));
      std::vector<double> q(f.q().begin(), f.q().end());
      const FkResult fk = ForwardKinematics(model, root, rq.normalized(), q.data());
      for (int b = 0; b < 13; ++b) {
        const Eigen::Vector3d p(f.body_pos(3 * b), f.body_pos(3 * b + 1), f.body_pos(3 * b + 2));
        EXPECT_LT((p - fk.body_world[b].translation()).norm(), 2e-3) << b << " step " << f.step();
      }
      if (f.step() > 0) {
        EXPECT_TRUE(f.reward_terms().count("pose")) << f.step();
      }
    }
    EXPECT_NE(reward_sum, 0.0);
  }
}

TEST(Recording, FilesRoundTripAndBadFilesAreRefusedByReason) {
  EpisodeRecorder rec(1);
  Evaluate(&rec);
  const std::string path = TempPath("rec_roundtrip.rec");
  std::filesystem::remove(path);
  WriteRecording(path, rec.recording(), false);
  const proto::Recording back = ReadRecording(path);
  using google::protobuf::util::MessageDifferencer;
  EXPECT_TRUE(MessageDifferencer::Equals(back, rec.recording()));
  // Not overwritten without the flag; the file is unchanged.
  EXPECT_THROW(WriteRecording(path, proto::Recording(), false), ConfigError);
  EXPECT_TRUE(MessageDifferencer::Equals(ReadRecording(path), rec.recording()));

  std::ifstream in(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  auto expect_refused = [&](const std::string& data, const std::string& why) {
    const std::string bad = TempPath("rec_bad.rec");
    std::ofstream(bad, std::ios::binary) << data;
    try {
      ReadRecording(bad);
      ADD_FAILURE() << "accepted: " << why;
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    }
  };
  expect_refused(bytes.substr(0, bytes.size() - 100), "truncated");
  std::string flipped = bytes;
  flipped[bytes.size() / 2] ^= 0x40;
  expect_refused(flipped, "CRC");
  std::string magic = bytes;
  magic[0] = 'X';
  expect_refused(magic, "not a recording");
  std::string format = bytes;
  format[8] = 2;
  expect_refused(format, "format 2");
  expect_refused("", "not a recording");
}

TEST(Recording, ARecordedEpisodeRoundTripsThroughBvh) {
  EpisodeRecorder rec(1);
  Evaluate(&rec);
  const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
  const ReferenceMotion m = RecordedMotion(rec.recording(), 0, model, "rec");
  const proto::RecEpisode& ep = rec.recording().episodes(0);
  ASSERT_EQ(m.num_frames(), ep.frames_size());
  const BvhClip clip = ParseBvh(
      WriteBvh(HumanoidMotionToBvh(model, m, rec.recording().control_dt(), 0.0)), "ep.bvh");
  ASSERT_EQ(clip.num_frames(), ep.frames_size());
  for (int f = 0; f < clip.num_frames(); f += 7) {
    const std::vector<double> q = HumanoidJointAnglesFromBvh(model, clip, f);
    for (int j = 0; j < 21; ++j) EXPECT_NEAR(q[j], ep.frames(f).q(j), 1e-4) << j << " " << f;
  }
  EXPECT_THROW(RecordedMotion(rec.recording(), 5, model, "rec"), ConfigError);
}

// A mesh chair's triangles travel in the recording, so it plays back without the mesh file.
TEST(Recording, AMeshChairsTrianglesAreInTheRecording) {
  if (SharedDir().empty()) GTEST_SKIP() << "../shared is absent";
  const TaskEnvConfig c =
      TaskEnvConfig::FromJson(Json{{"task", "sit"},
                                   {"chair", "data/chairs/meshes/dining_scenic.json"},
                                   {"sit", {{"eval_episode_s", 0.1}}}},
                              "t");
  EpisodeRecorder rec(1);
  EvalOptions o;
  o.episodes = 1;
  o.seed = 7;
  o.recorder = &rec;
  GetTask("sit", "t").evaluate(c, Untrained(57, 3), o, nullptr);
  ASSERT_EQ(rec.recording().episodes_size(), 1);
  const proto::RecChair& rc = rec.recording().episodes(0).chair();
  const Chair chair = Chair::Load(c.env.ChairPath());
  EXPECT_TRUE(rc.boxes().empty());
  ASSERT_EQ(rc.mesh_vertices_size(), 3 * static_cast<int>(chair.mesh->visual.vertices.size()));
  ASSERT_EQ(rc.mesh_triangles_size(), 3 * static_cast<int>(chair.mesh->visual.triangles.size()));
  for (int i = 0; i < rc.mesh_vertices_size(); ++i) {
    EXPECT_NEAR(rc.mesh_vertices(i), chair.mesh->visual.vertices[i / 3][i % 3], 1e-6);
  }
  for (int i = 0; i < rc.mesh_triangles_size(); ++i) {
    EXPECT_EQ(static_cast<int>(rc.mesh_triangles(i)), chair.mesh->visual.triangles[i / 3][i % 3]);
  }
  EXPECT_NE(rc.source().find("Scenic"), std::string::npos);  // the provenance, cited
}

}  // namespace
}  // namespace perch
