// Several learners (issue 20): two LearnerService members, each with its own mock-env actor, over
// real ZeroMQ sockets (inproc). They must stay in lockstep (same weights after every update),
// count the group's samples, stop together, and resume together from their own checkpoints.
#include <gtest/gtest.h>

#include <atomic>
#include <memory>
#include <string>
#include <thread>
#include <vector>
#include <zmq.hpp>

#include "actor/actor.h"
#include "actor/role_setup.h"
#include "common/proto/model.pb.h"
#include "experiment/experiment.h"
#include "learner/service/checkpoint.h"
#include "learner/service/learner.h"
#include "learner/service/learner_setup.h"
#include "tests/actor/cluster_fixture.h"

namespace perch {
namespace {

using namespace testing_util;

Json GroupConfig(double learning_rate = 0.001) {
  Json j = MockConfig(Json{{"learners", 2}, {"group_timeout_s", 20.0}});
  j["ppo"]["learning_rate"] = learning_rate;
  return j;
}

struct Member {
  std::string run_dir;
  std::string stop_reason;
  std::string error;
  uint64_t updates = 0;
  uint64_t samples = 0;
};

// Runs both members (each with one actor) until max_updates or a stop; stop_after[r] > 0 sets
// member r's stop flag once it has made that many updates.
std::vector<Member> RunPair(const std::string& tag, const std::vector<std::string>& run_dirs,
                            int max_updates, bool resume, const std::vector<Json>& configs,
                            const std::vector<int>& stop_after = {0, 0}) {
  zmq::context_t ctx(1);
  std::vector<Member> out(2);
  std::vector<std::thread> threads;
  // Each member's actor runs until its own learner ends: a member waiting for its batch must get it
  // to see that the other one stopped.
  std::vector<std::atomic<bool>> stop(2), stop_actors(2);
  for (int r = 0; r < 2; ++r) stop[r] = stop_actors[r] = false;
  for (int r = 0; r < 2; ++r) {
    threads.emplace_back([&, r] {
      const ExperimentConfig cfg = ExperimentConfigFromJson(configs[r], "group");
      LearnerOptions lo;
      lo.rollout_bind = "inproc://rollouts-" + tag + std::to_string(r);
      lo.weights_bind = "inproc://weights-" + tag + std::to_string(r);
      lo.metrics_port = -1;
      lo.run_dir = run_dirs[r];
      lo.resume = resume;
      lo.max_updates = max_updates;
      lo.stop = &stop[r];
      lo.group_rank = r;
      lo.group_address = "inproc://group-" + tag;
      out[r].run_dir = run_dirs[r];
      try {
        LearnerService learner(ctx, MakeLearnerSetup(cfg), lo);
        ActorOptions ao;
        ao.rollout_connect = lo.rollout_bind;
        ao.weights_connect = lo.weights_bind;
        ao.actor_id = static_cast<uint32_t>(r);
        ao.num_envs = 2;
        ao.stop = &stop_actors[r];
        ActorService actor(ctx, MakeActorSetup(cfg), ao);
        std::thread at([&] { actor.Run(); });
        std::thread watch;
        if (stop_after[r] > 0) {
          watch = std::thread([&, r] {
            WaitUntil(
                [&] {
                  return learner.counters().updates() >= static_cast<uint64_t>(stop_after[r]) ||
                         !out[r].stop_reason.empty();
                },
                60);
            stop[r] = true;
          });
        }
        learner.Run();
        out[r].stop_reason = learner.stop_reason();
        out[r].updates = learner.counters().updates();
        out[r].samples = learner.counters().samples();
        if (watch.joinable()) watch.join();
        stop_actors[r] = true;
        at.join();
      } catch (const std::exception& e) {
        out[r].error = e.what();
      }
    });
  }
  for (auto& t : threads) t.join();
  return out;
}

proto::Checkpoint Latest(const std::string& run_dir) {
  CheckpointStore store(run_dir, 3, 0);
  const std::vector<uint64_t> present = store.List();
  EXPECT_FALSE(present.empty()) << run_dir;
  return ReadCheckpointFile(store.PathFor(present.back()));
}

uint64_t BatchSamples(const std::string& run_dir) {
  uint64_t n = 0;
  for (const Json& row : ReadMetrics(run_dir)) n += row["batch_samples"].get<uint64_t>();
  return n;
}

TEST(LearnerGroupTest, TwoLearnersStayInLockstepCountTheGroupsSamplesAndResumeTogether) {
  const std::string dir = TempDir("group");
  const std::vector<std::string> dirs = {dir + "/rank0", dir + "/rank1"};
  const std::vector<Json> cfgs = {GroupConfig(), GroupConfig()};
  std::vector<Member> m = RunPair("lock", dirs, 6, false, cfgs);
  for (int r = 0; r < 2; ++r) {
    ASSERT_EQ(m[r].error, "") << "rank " << r;
    EXPECT_EQ(m[r].stop_reason, "max_updates") << "rank " << r;
    EXPECT_EQ(m[r].updates, 6u);
  }
  // Every member counts the group's samples: both batches of every update.
  const uint64_t both = BatchSamples(dirs[0]) + BatchSamples(dirs[1]);
  EXPECT_EQ(m[0].samples, both);
  EXPECT_EQ(m[1].samples, both);
  EXPECT_GE(both, 2u * 6 * 512);
  const std::vector<Json> rows = ReadMetrics(dirs[0]);
  ASSERT_FALSE(rows.empty());
  EXPECT_EQ(rows.back()["group"]["size"].get<int>(), 2);
  EXPECT_GT(rows.back()["group"]["bytes_sent"].get<double>(), 0.0);
  // Same weights, normalizer and Adam moments on both members; their own shuffles.
  proto::Checkpoint c0 = Latest(dirs[0]), c1 = Latest(dirs[1]);
  EXPECT_EQ(c0.counters().updates(), 6u);
  EXPECT_TRUE(c0.trainer().model().SerializeAsString() == c1.trainer().model().SerializeAsString())
      << "the members' weights or normalizers differ";
  EXPECT_TRUE(c0.trainer().adam().SerializeAsString() == c1.trainer().adam().SerializeAsString());
  EXPECT_TRUE(c0.trainer().rng().SerializeAsString() != c1.trainer().rng().SerializeAsString());

  // Both resume from their own checkpoints and go on together.
  m = RunPair("resume", dirs, 9, true, cfgs);
  for (int r = 0; r < 2; ++r) {
    ASSERT_EQ(m[r].error, "") << "rank " << r;
    EXPECT_EQ(m[r].updates, 9u);
  }
  c0 = Latest(dirs[0]);
  c1 = Latest(dirs[1]);
  EXPECT_EQ(c0.counters().updates(), 9u);
  EXPECT_TRUE(c0.trainer().model().SerializeAsString() == c1.trainer().model().SerializeAsString())
      << "the members' weights or normalizers differ";
}

TEST(LearnerGroupTest, AMemberThatStopsEndsTheGroupAtTheSameUpdate) {
  const std::string dir = TempDir("group-stop");
  const std::vector<std::string> dirs = {dir + "/rank0", dir + "/rank1"};
  const std::vector<Member> m =
      RunPair("stop", dirs, 0, false, {GroupConfig(), GroupConfig()}, {0, 3});
  ASSERT_EQ(m[0].error, "");
  ASSERT_EQ(m[1].error, "");
  EXPECT_EQ(m[1].stop_reason, "stopped");
  EXPECT_EQ(m[0].stop_reason, "group_stopped");
  EXPECT_GE(m[1].updates, 3u);
  EXPECT_EQ(m[0].updates, m[1].updates);
  // The final checkpoints are of the same update, with the same weights.
  const proto::Checkpoint c0 = Latest(dirs[0]), c1 = Latest(dirs[1]);
  EXPECT_EQ(c0.counters().updates(), m[0].updates);
  EXPECT_TRUE(c0.trainer().model().SerializeAsString() == c1.trainer().model().SerializeAsString())
      << "the members' weights or normalizers differ";
}

TEST(LearnerGroupTest, AMemberWithAnotherConfigIsRefusedNamingTheFingerprint) {
  const std::string dir = TempDir("group-refuse");
  Json a = GroupConfig(), b = GroupConfig(0.002);
  a["cluster"]["group_timeout_s"] = 3.0;
  b["cluster"]["group_timeout_s"] = 3.0;
  const std::vector<Member> m =
      RunPair("refuse", {dir + "/rank0", dir + "/rank1"}, 2, false, {a, b});
  EXPECT_NE(m[1].error.find("fingerprint differs"), std::string::npos) << m[1].error;
  EXPECT_NE(m[1].error.find("config="), std::string::npos) << m[1].error;
  EXPECT_NE(m[0].error.find("rank(s) 1 did not join"), std::string::npos) << m[0].error;
}

TEST(LearnerGroupTest, ARankOutsideTheGroupIsAConfigError) {
  const ExperimentConfig cfg = ExperimentConfigFromJson(GroupConfig(), "group");
  LearnerOptions lo;
  lo.rollout_bind = "inproc://rollouts-rank";
  lo.weights_bind = "inproc://weights-rank";
  lo.metrics_port = -1;
  lo.run_dir = TempDir("group-rank") + "/run";
  lo.group_rank = 2;
  zmq::context_t ctx(1);
  try {
    LearnerService learner(ctx, MakeLearnerSetup(cfg), lo);
    FAIL() << "rank 2 of 2 accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("cluster.learners 2"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace perch
