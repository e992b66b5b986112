// Real processes on loopback: `perch learner` and `perch actor` from PERCH_BIN, mock env.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>
#include <zmq.hpp>

#include "common/proto/model.pb.h"
#include "common/proto/wire.pb.h"
#include "learner/service/checkpoint.h"
#include "policy/rollout.h"
#include "tests/actor/cluster_fixture.h"

namespace perch {
namespace {

using namespace testing_util;

class ClusterProcessTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (PerchBin().empty()) GTEST_SKIP() << "PERCH_BIN not set";
    dir_ = TempDir("cluster");
    run_dir_ = dir_ + "/run";
  }
  void TearDown() override {
    for (pid_t p : actors_) {
      if (p > 0) Stop(p, 5.0);
    }
    // Keep the run dir and logs of a failed test for inspection.
    if (!HasFailure() && dir_.rfind("/tmp/perch-", 0) == 0) {
      (void)!std::system(("rm -rf '" + dir_ + "' '" + dir_ + "-other'*").c_str());
    }
  }
  size_t Updates() const { return ReadMetrics(run_dir_).size(); }

  std::string dir_, run_dir_;
  std::vector<pid_t> actors_;
};

TEST_F(ClusterProcessTest, LearnerAndTwoActorsTrainAndStopAtMaxUpdates) {
  const std::string cfg = WriteConfig(dir_, MockConfig());
  LearnerProc l;
  // Actors first: they connect and wait for weights, so both take part from the first update.
  actors_.push_back(StartActor(cfg, l, 0, dir_ + "/a0.log"));
  actors_.push_back(StartActor(cfg, l, 1, dir_ + "/a1.log"));
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  l.Start(cfg, run_dir_, false, 6);
  int status = 0;
  ASSERT_TRUE(WaitFor(l.pid, 60.0, &status)) << ReadFile(l.log);
  l.pid = -1;
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << DescribeStatus(status);
  const std::vector<Json> rows = ReadMetrics(run_dir_);
  ASSERT_EQ(rows.size(), 6u);
  uint64_t prev = 0;
  for (size_t i = 0; i < rows.size(); ++i) {
    EXPECT_EQ(rows[i]["update"].get<uint64_t>(), i + 1);
    // Each batch holds at least steps_per_update accepted samples.
    EXPECT_GE(rows[i]["samples"].get<uint64_t>() - prev, 512u);
    prev = rows[i]["samples"].get<uint64_t>();
    EXPECT_LE(rows[i]["policy_lag_mean"].get<double>(), 2.0);
    EXPECT_TRUE(rows[i]["ppo"]["policy_loss"].is_number());
  }
  // Both actors were heard and contributed.
  const std::string log = ReadFile(l.log);
  EXPECT_NE(log.find("actor 0 ("), std::string::npos) << log;
  EXPECT_NE(log.find("actor 1 ("), std::string::npos) << log;
  // The run dir holds the resolved config with its seed and the final checkpoint.
  const Json saved = LoadJsonFile(run_dir_ + "/config.json");
  EXPECT_EQ(saved["seed"], 0);
  EXPECT_EQ(saved["cluster"]["segment_steps"], 64);
  EXPECT_EQ(saved["ppo"]["steps_per_update"], 512);
  EXPECT_EQ(::access((run_dir_ + "/checkpoints/ckpt-0000000006.bin").c_str(), F_OK), 0);
}

TEST_F(ClusterProcessTest, KilledActorLeavesLearnerRunningAndRestartedActorJoins) {
  const std::string cfg = WriteConfig(dir_, MockConfig());
  LearnerProc l;
  l.Start(cfg, run_dir_, false);
  actors_.push_back(StartActor(cfg, l, 0, dir_ + "/a0.log"));
  actors_.push_back(StartActor(cfg, l, 1, dir_ + "/a1.log"));
  ASSERT_TRUE(WaitUntil([&] { return Updates() >= 2; }, 30.0)) << ReadFile(l.log);
  // Both actors have joined (a slow start must not pass for a kill).
  ASSERT_TRUE(WaitUntil([&] { return Scrape(l.metrics_port, "perch_hellos_total") >= 2; }, 20.0))
      << ReadFile(l.log);
  ::kill(actors_[0], SIGKILL);
  Stop(actors_[0], 1.0);
  actors_[0] = -1;
  const size_t at_kill = Updates();
  // The learner keeps training with the remaining actor.
  ASSERT_TRUE(WaitUntil([&] { return Updates() >= at_kill + 2; }, 30.0)) << ReadFile(l.log);
  EXPECT_TRUE(Alive(l.pid));
  // A restarted actor (same id) is greeted with the current weights, not version 0.
  const double hellos = Scrape(l.metrics_port, "perch_hellos_total");
  EXPECT_EQ(hellos, 2.0);
  const size_t before_rejoin = Updates();
  actors_[0] = StartActor(cfg, l, 0, dir_ + "/a0-restarted.log");
  ASSERT_TRUE(WaitUntil([&] { return Scrape(l.metrics_port, "perch_hellos_total") >= 3; }, 20.0));
  ASSERT_TRUE(WaitUntil(
      [&] {
        return ReadFile(dir_ + "/a0-restarted.log").find("weights version") != std::string::npos;
      },
      20.0));
  const std::string alog = ReadFile(dir_ + "/a0-restarted.log");
  const size_t at = alog.find("weights version ");
  const int joined_version = std::stoi(alog.substr(at + 16));
  EXPECT_GE(joined_version, static_cast<int>(before_rejoin));
  ASSERT_TRUE(WaitUntil([&] { return Updates() >= before_rejoin + 2; }, 30.0));
  EXPECT_TRUE(Alive(l.pid));
}

TEST_F(ClusterProcessTest, LearnerKilledAndResumedKeepsCounters) {
  const std::string cfg = WriteConfig(dir_, MockConfig({{"checkpoint_every", 2}}));
  int last_ckpt = 0;
  int ports[3];
  {
    LearnerProc l;
    ports[0] = l.rollout_port;
    ports[1] = l.weights_port;
    ports[2] = l.metrics_port;
    l.Start(cfg, run_dir_, false);
    actors_.push_back(StartActor(cfg, l, 0, dir_ + "/a0.log"));
    ASSERT_TRUE(WaitUntil([&] { return Updates() >= 5; }, 40.0)) << ReadFile(l.log);
    ::kill(l.pid, SIGKILL);  // no final checkpoint: the resume must use the periodic ones
    Stop(l.pid, 1.0);
    l.pid = -1;
    // The newest complete checkpoint file (the kill may have hit a write: its .tmp is ignored).
    const std::vector<uint64_t> present = CheckpointStore(run_dir_, 3, 0).List();
    ASSERT_FALSE(present.empty());
    last_ckpt = static_cast<int>(present.back());
    // Restarting the same learner command without --resume is refused (nothing overwritten).
    LearnerProc again;
    again.Start(cfg, run_dir_, false);
    int status = 0;
    ASSERT_TRUE(WaitFor(again.pid, 20.0, &status));
    again.pid = -1;
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << DescribeStatus(status);
    EXPECT_NE(ReadFile(again.log).find("--resume"), std::string::npos);
  }
  const std::vector<Json> before = ReadMetrics(run_dir_);
  Json at_ckpt;
  for (const Json& r : before) {
    if (r["update"] == last_ckpt) at_ckpt = r;
  }
  ASSERT_FALSE(at_ckpt.is_null());
  // Resume; the old actor keeps running and reconnects by itself.
  LearnerProc l2;
  l2.rollout_port = ports[0];  // where the running actor reconnects to
  l2.weights_port = ports[1];
  l2.metrics_port = ports[2];
  l2.Start(cfg, run_dir_, true, last_ckpt + 3);
  int status = 0;
  ASSERT_TRUE(WaitFor(l2.pid, 60.0, &status)) << ReadFile(l2.log);
  l2.pid = -1;
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << ReadFile(l2.log);
  const std::string log = ReadFile(l2.log);
  char name[32];
  std::snprintf(name, sizeof(name), "ckpt-%010d.bin", last_ckpt);
  EXPECT_NE(log.find(std::string("resumed from ") + run_dir_ + "/checkpoints/" + name),
            std::string::npos)
      << log;
  const std::vector<Json> after = ReadMetrics(run_dir_);
  ASSERT_EQ(after.size(), before.size() + 3);
  const Json& first = after[before.size()];
  EXPECT_EQ(first["update"].get<int>(), last_ckpt + 1);
  EXPECT_GE(first["samples"].get<uint64_t>(), at_ckpt["samples"].get<uint64_t>() + 512);
  EXPECT_GE(first["time_s"].get<double>(), at_ckpt["time_s"].get<double>());
  EXPECT_EQ(after.back()["update"].get<int>(), last_ckpt + 3);
}

TEST_F(ClusterProcessTest, CorruptNewestCheckpointFallsBackToPrevious) {
  const std::string cfg = WriteConfig(dir_, MockConfig({{"checkpoint_every", 1}}));
  {
    LearnerProc l;
    l.Start(cfg, run_dir_, false, 3);
    actors_.push_back(StartActor(cfg, l, 0, dir_ + "/a0.log"));
    int status = 0;
    ASSERT_TRUE(WaitFor(l.pid, 40.0, &status)) << ReadFile(l.log);
    l.pid = -1;
  }
  const std::string newest = run_dir_ + "/checkpoints/ckpt-0000000003.bin";
  std::string bytes = ReadFile(newest);
  ASSERT_GT(bytes.size(), 100u);
  bytes[bytes.size() - 10] ^= 0x5a;
  std::ofstream(newest, std::ios::binary | std::ios::trunc) << bytes;
  LearnerProc l2;
  l2.Start(cfg, run_dir_, true, 4);
  actors_.push_back(StartActor(cfg, l2, 0, dir_ + "/a0-second.log"));
  int status = 0;
  ASSERT_TRUE(WaitFor(l2.pid, 40.0, &status)) << ReadFile(l2.log);
  l2.pid = -1;
  const std::string log = ReadFile(l2.log);
  EXPECT_NE(log.find(newest + ": checkpoint CRC-32 mismatch"), std::string::npos) << log;
  EXPECT_NE(log.find("resumed from " + run_dir_ + "/checkpoints/ckpt-0000000002.bin"),
            std::string::npos)
      << log;
  // Rows 1..3 of the first run, then 3 and 4 again: the run continued from update 2.
  const std::vector<Json> rows = ReadMetrics(run_dir_);
  ASSERT_EQ(rows.size(), 5u);
  EXPECT_EQ(rows[3]["update"], 3);
  EXPECT_EQ(rows[4]["update"], 4);
}

TEST_F(ClusterProcessTest, MismatchedConfigIsRefusedOnResume) {
  const std::string cfg = WriteConfig(dir_, MockConfig());
  {
    LearnerProc l;
    l.Start(cfg, run_dir_, false, 2);
    actors_.push_back(StartActor(cfg, l, 0, dir_ + "/a0.log"));
    int status = 0;
    ASSERT_TRUE(WaitFor(l.pid, 40.0, &status)) << ReadFile(l.log);
    l.pid = -1;
  }
  Json other = MockConfig();
  other["mock_env"]["act_dim"] = 3;  // another action size: the network does not fit
  const std::string other_dir = TempDir("cluster-other");
  const std::string cfg2 = WriteConfig(other_dir, other);
  const std::string before = ReadFile(run_dir_ + "/checkpoints/ckpt-0000000002.bin");
  LearnerProc l2;
  l2.Start(cfg2, run_dir_, true);
  int status = 0;
  ASSERT_TRUE(WaitFor(l2.pid, 20.0, &status));
  l2.pid = -1;
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << DescribeStatus(status);
  const std::string log = ReadFile(l2.log);
  EXPECT_NE(log.find("incompatible config"), std::string::npos) << log;
  EXPECT_NE(log.find("no usable checkpoint"), std::string::npos) << log;
  EXPECT_EQ(ReadFile(run_dir_ + "/checkpoints/ckpt-0000000002.bin"), before);
}

// A valid segment for the mock env of MockConfig() (obs 6, actions 2) stamped with `version`.
std::string SegmentBytes(uint64_t version, int steps = 16) {
  Rollout r(6, 2);
  std::vector<float> obs(6, 0.1f), act(2, 0.2f);
  for (int t = 0; t < steps; ++t)
    r.Add(obs.data(), act.data(), -1.0f, 0.0f, 0.5f, false, false, 0.0f);
  r.policy_version = version;
  r.stream_id = 999;
  proto::ActorMessage m;
  m.set_wire_version(proto::WIRE_VERSION_CURRENT);
  proto::Segment* s = m.mutable_segment();
  s->set_actor_id(999);
  s->set_task(proto::TASK_STAND);
  auto* pv = s->add_policy_versions();
  pv->set_task(proto::TASK_STAND);
  pv->set_version(version);
  r.ToProto(s->mutable_rollout());
  return m.SerializeAsString();
}

void RawTcpSend(int port, const std::string& bytes) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(static_cast<uint16_t>(port));
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0) {
    (void)!::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
  }
  ::close(fd);
}

TEST_F(ClusterProcessTest, GarbageTruncatedAndStaleMessagesAreCountedAndIgnored) {
  const std::string cfg = WriteConfig(dir_, MockConfig({{"max_policy_lag", 1}}));
  LearnerProc l;
  l.Start(cfg, run_dir_, false);
  actors_.push_back(StartActor(cfg, l, 0, dir_ + "/a0.log"));
  ASSERT_TRUE(WaitUntil([&] { return Updates() >= 3; }, 30.0)) << ReadFile(l.log);
  Stop(actors_[0], 5.0);  // quiet socket: every count below is ours
  actors_[0] = -1;
  ASSERT_TRUE(WaitUntil([&] { return Scrape(l.metrics_port, "perch_messages_total") >= 0; }, 5.0));
  // Let the counters settle (in-flight segments of the stopped actor): unchanged for 1.5 s.
  double msgs = -2;
  auto changed = std::chrono::steady_clock::now();
  ASSERT_TRUE(WaitUntil(
      [&] {
        const double m = Scrape(l.metrics_port, "perch_messages_total");
        const auto now = std::chrono::steady_clock::now();
        if (m != msgs) {
          msgs = m;
          changed = now;
        }
        return now - changed > std::chrono::milliseconds(1500);
      },
      15.0));
  const double rejected0 = Scrape(l.metrics_port, "perch_rejected_total");
  const double stale0 = Scrape(l.metrics_port, "perch_dropped_stale_total");
  const double segments0 = Scrape(l.metrics_port, "perch_segments_total");
  const double version = Scrape(l.metrics_port, "perch_weights_version");
  ASSERT_GE(version, 3);

  zmq::context_t ctx(1);
  zmq::socket_t push(ctx, zmq::socket_type::push);
  push.set(zmq::sockopt::linger, 2000);
  push.connect(l.Rollout());
  const std::string good = SegmentBytes(static_cast<uint64_t>(version));
  push.send(zmq::buffer(std::string("\x00\x01garbage\xff", 10)), zmq::send_flags::none);  // junk
  push.send(zmq::buffer(good.substr(0, good.size() / 2)), zmq::send_flags::none);  // truncated
  push.send(zmq::buffer(good.substr(0, good.size() - 1)), zmq::send_flags::none);  // truncated
  push.send(zmq::message_t(), zmq::send_flags::none);                              // empty
  push.send(zmq::buffer(SegmentBytes(0)), zmq::send_flags::none);                  // stale
  push.send(zmq::buffer(SegmentBytes(static_cast<uint64_t>(version) + 100)), zmq::send_flags::none);
  push.send(zmq::buffer(good), zmq::send_flags::none);  // accepted
  // Not even ZMTP: raw bytes on both TCP ports.
  RawTcpSend(l.rollout_port, std::string(4096, '\x7f'));
  RawTcpSend(l.weights_port, "GET / HTTP/1.0\r\n\r\n");

  ASSERT_TRUE(WaitUntil(
      [&] { return Scrape(l.metrics_port, "perch_segments_total") >= segments0 + 1; }, 10.0));
  EXPECT_EQ(Scrape(l.metrics_port, "perch_rejected_total"), rejected0 + 4);
  // Each reason is its own labelled series, and they add up to the total.
  EXPECT_GE(Scrape(l.metrics_port, "perch_rejected_by_reason_total{reason=\"parse\"}"), 3.0);
  double by_reason = 0;
  for (const char* r :
       {"too_big", "parse", "version", "empty", "shape", "non_finite", "out_of_range", "ppo"}) {
    by_reason += std::max(0.0, Scrape(l.metrics_port, std::string("perch_rejected_by_reason_total"
                                                                  "{reason=\"") +
                                                          r + "\"}"));
  }
  EXPECT_EQ(by_reason, Scrape(l.metrics_port, "perch_rejected_total"));
  EXPECT_EQ(Scrape(l.metrics_port, "perch_dropped_stale_total"), stale0 + 2);
  EXPECT_EQ(Scrape(l.metrics_port, "perch_segments_total"), segments0 + 1);
  EXPECT_TRUE(Alive(l.pid));
  // And it still trains afterwards.
  const size_t n = Updates();
  actors_[0] = StartActor(cfg, l, 0, dir_ + "/a0-again.log");
  EXPECT_TRUE(WaitUntil([&] { return Updates() >= n + 2; }, 30.0)) << ReadFile(l.log);
  EXPECT_TRUE(Alive(l.pid));
}

}  // namespace
}  // namespace perch

namespace perch {
namespace {

TEST_F(ClusterProcessTest, LearnerAndTwoActorsTrainOnTheRealEnv) {
  Json j = MockConfig({{"segment_steps", 128}}, 512);
  j["env_backend"] = "bullet";
  j["env"] = {{"task", "stand"}};
  j.erase("mock_env");
  const std::string cfg = WriteConfig(dir_, j);
  LearnerProc l;
  l.Start(cfg, run_dir_, false, 3);
  for (int i = 0; i < 2; ++i) {
    actors_.push_back(
        Spawn({PerchBin(), "actor", "--config", cfg, "--learner-host", "127.0.0.1",
               "--rollout-port", std::to_string(l.rollout_port), "--weights-port",
               std::to_string(l.weights_port), "--actor-id", std::to_string(i), "--envs", "1"},
              dir_ + "/a" + std::to_string(i) + ".log"));
  }
  int status = 0;
  ASSERT_TRUE(WaitFor(l.pid, 90.0, &status)) << ReadFile(l.log);
  l.pid = -1;
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << ReadFile(l.log);
  const std::vector<Json> rows = ReadMetrics(run_dir_);
  ASSERT_EQ(rows.size(), 3u);
  const std::string log = ReadFile(l.log);
  // The real env's observation (52 = proprioception + goal) reached the learner.
  EXPECT_NE(log.find("obs_dim 52 action_size 21"), std::string::npos) << log;
  for (const Json& r : rows) {
    EXPECT_GE(r["batch_samples"].get<int>(), 512);
    EXPECT_TRUE(std::isfinite(r["ppo"]["value_loss"].get<double>()));
  }
  // Episodes of the stand task end (falls or time limit) and are reported.
  int episodes = 0;
  for (const Json& r : rows) episodes += r["episodes"].get<int>();
  EXPECT_GT(episodes, 0);
}

}  // namespace
}  // namespace perch

namespace perch {
namespace {

using namespace testing_util;

// Issue 17's attacks against one running cluster (a real learner process and a real actor on
// loopback, keys off so that the attacks reach the learner at all): poisoned statistics, huge and
// NaN values, a subscription flood, a heartbeat flood with made-up ids, stuck /metrics clients,
// raw garbage on the ports. The run must keep training, publish finite weights, write finite
// checkpoints, and resume from its newest one.
class AttackTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (PerchBin().empty()) GTEST_SKIP() << "PERCH_BIN not set";
    dir_ = TempDir("attack");
    run_dir_ = dir_ + "/run";
  }
  size_t Updates() const { return ReadMetrics(run_dir_).size(); }
  std::string dir_, run_dir_;
};

bool FiniteState(const proto::Checkpoint& c) {
  auto finite = [](const auto& v) {
    for (float x : v) {
      if (!std::isfinite(x)) return false;
    }
    return true;
  };
  const proto::RunningStats& s = c.trainer().model().obs_stats();
  for (double x : s.mean()) {
    if (!std::isfinite(x)) return false;
  }
  return finite(c.trainer().model().params()) && std::isfinite(s.count()) && s.count() < 1e12;
}

TEST_F(AttackTest, TheRunKeepsTrainingWithFiniteWeightsAndResumesAfterEveryAttack) {
  const std::string cfg = WriteConfig(dir_, MockConfig({{"max_policy_lag", 2}}));
  LearnerProc l;
  l.Start(cfg, run_dir_, false);
  const pid_t actor = StartActor(cfg, l, 0, dir_ + "/a0.log");
  ASSERT_TRUE(WaitUntil([&] { return Updates() >= 3; }, 30.0)) << ReadFile(l.log);
  const double version = Scrape(l.metrics_port, "perch_weights_version");

  zmq::context_t ctx(1);
  zmq::socket_t push(ctx, zmq::socket_type::push);
  push.set(zmq::sockopt::linger, 2000);
  push.connect(l.Rollout());
  auto send = [&](const proto::ActorMessage& m) {
    push.send(zmq::buffer(m.SerializeAsString()), zmq::send_flags::none);
  };
  auto segment = [&] {
    proto::ActorMessage m;
    m.ParseFromString(SegmentBytes(static_cast<uint64_t>(version)));
    return m;
  };
  // Poisoned statistics: a count of 1e308, a mean of 1e30.
  proto::ActorMessage poison = segment();
  proto::RunningStats* st = poison.mutable_segment()->mutable_rollout()->mutable_obs_stats_delta();
  st->set_count(1e308);
  st->clear_mean();
  st->clear_var();
  for (int i = 0; i < 6; ++i) {
    st->add_mean(0.1);
    st->add_var(1.0);
  }
  send(poison);
  // Huge observations and rewards, NaN values.
  proto::ActorMessage huge = segment();
  for (int i = 0; i < 4; ++i) huge.mutable_segment()->mutable_rollout()->set_rewards(i, 1e30f);
  send(huge);
  proto::ActorMessage nan = segment();
  nan.mutable_segment()->mutable_rollout()->set_values(0, std::nanf(""));
  send(nan);
  // A NaN episode return (the console's and the success target's input).
  proto::ActorMessage nan_return = segment();
  proto::EpisodeStats* e = nan_return.mutable_segment()->add_episodes();
  e->set_length(16);
  e->set_episode_return(std::nan(""));
  send(nan_return);
  // Heartbeats with 20,000 made-up instance ids.
  for (int i = 0; i < 20000; ++i) {
    proto::ActorMessage hb;
    hb.set_wire_version(proto::WIRE_VERSION_CURRENT);
    hb.mutable_heartbeat()->set_actor_instance(0xabc0000000ULL + i);
    send(hb);
  }
  // A subscription flood on the weights port.
  std::vector<std::unique_ptr<zmq::socket_t>> subs;
  for (int i = 0; i < 200; ++i) {
    subs.push_back(std::make_unique<zmq::socket_t>(ctx, zmq::socket_type::sub));
    subs.back()->set(zmq::sockopt::linger, 0);
    subs.back()->set(zmq::sockopt::subscribe, "");
    subs.back()->connect(l.Weights());
  }
  // Two stuck /metrics clients and raw garbage on every port.
  std::vector<int> stuck;
  for (int i = 0; i < 2; ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    addr.sin_port = htons(static_cast<uint16_t>(l.metrics_port));
    if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0) {
      (void)!::send(fd, "GET /me", 7, MSG_NOSIGNAL);
    }
    stuck.push_back(fd);
  }
  RawTcpSend(l.rollout_port, std::string(4096, '\x7f'));
  RawTcpSend(l.weights_port, std::string(100, '\0'));

  // Still training, still scraped, the poison refused.
  const size_t after = Updates();
  EXPECT_TRUE(WaitUntil([&] { return Updates() >= after + 4; }, 60.0)) << ReadFile(l.log);
  const double refused =
      std::max(0.0,
               Scrape(l.metrics_port, "perch_rejected_by_reason_total{reason=\"out_of_range\"}")) +
      std::max(0.0,
               Scrape(l.metrics_port, "perch_rejected_by_reason_total{reason=\"non_finite\"}"));
  EXPECT_GE(refused, 4.0) << "the poisoned, huge and NaN segments";
  EXPECT_TRUE(std::isfinite(Scrape(l.metrics_port, "perch_return_mean")));
  EXPECT_TRUE(Alive(l.pid));
  for (int fd : stuck) ::close(fd);
  subs.clear();
  Stop(actor, 5.0);
  Stop(l.pid, 10.0);
  l.pid = -1;

  // Every checkpoint finite; the newest resumes.
  CheckpointStore store(run_dir_, 3, 0);
  const std::vector<uint64_t> present = store.List();
  ASSERT_FALSE(present.empty());
  for (uint64_t u : present) {
    EXPECT_TRUE(FiniteState(ReadCheckpointFile(store.PathFor(u)))) << "update " << u;
  }
  LearnerProc again;
  again.Start(cfg, run_dir_, true);
  EXPECT_TRUE(WaitUntil(
      [&] { return ReadFile(again.log).find("resumed from") != std::string::npos; }, 20.0))
      << ReadFile(again.log);
  EXPECT_TRUE(Alive(again.pid));
}

}  // namespace
}  // namespace perch
