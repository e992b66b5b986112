// A learner group over real ZeroMQ sockets (inproc): the collectives, start-up refusals, stopping,
// and PPO data parallelism (members keep the same weights; a group step is the whole batch's).
#include "learner/service/group.h"

#include <gtest/gtest.h>
#include <zmq.h>

#include <atomic>
#include <cmath>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "common/proto/model.pb.h"
#include "learner/ppo.h"
#include "policy/policy.h"
#include "protocol/security.h"

namespace perch {
namespace {

int PickFreePortForTest() {
  zmq::context_t c;
  zmq::socket_t s(c, zmq::socket_type::rep);
  s.bind("tcp://127.0.0.1:*");
  const std::string e = s.get(zmq::sockopt::last_endpoint);
  return std::stoi(e.substr(e.rfind(':') + 1));
}

GroupOptions Member(int rank, int size, const std::string& address, const std::string& fp = "x") {
  GroupOptions o;
  o.rank = rank;
  o.size = size;
  o.address = address;
  o.fingerprint = fp;
  o.timeout_s = 20;
  o.join_timeout_s = 20;
  return o;
}

// Runs body(rank, group) for every member on a thread of its own; rank 0 binds first (inproc).
void RunGroup(zmq::context_t& ctx, int size, const std::string& address,
              const std::function<void(int, ZmqGroup&)>& body) {
  std::vector<std::thread> threads;
  std::atomic<bool> bound{false};
  std::vector<std::string> errors(size);
  for (int r = 0; r < size; ++r) {
    threads.emplace_back([&, r] {
      try {
        if (r > 0) {
          while (!bound.load()) std::this_thread::yield();
        }
        GroupOptions o = Member(r, size, address);
        if (r == 0) {
          // The bind happens in the constructor, which blocks until everybody joined.
          std::thread flag([&] {
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
            bound = true;
          });
          ZmqGroup g(ctx, o);
          flag.join();
          body(r, g);
        } else {
          ZmqGroup g(ctx, o);
          body(r, g);
        }
      } catch (const std::exception& e) {
        errors[r] = e.what();
      }
    });
  }
  for (std::thread& t : threads) t.join();
  for (int r = 0; r < size; ++r) EXPECT_EQ(errors[r], "") << "rank " << r;
}

TEST(GroupTest, AllReduceSumsInRankOrderAndEveryMemberGetsTheSameBits) {
  zmq::context_t ctx;
  const int size = 3, n = 1000;
  std::vector<std::vector<float>> data(size, std::vector<float>(n));
  for (int r = 0; r < size; ++r) {
    for (int i = 0; i < n; ++i) data[r][i] = std::sin(0.37f * i + r) * std::pow(10.0f, r - 1);
  }
  std::vector<float> expect(n);
  for (int i = 0; i < n; ++i) expect[i] = (data[0][i] + data[1][i]) + data[2][i];
  std::vector<std::vector<float>> got = data;
  RunGroup(ctx, size, "inproc://group-reduce", [&](int r, ZmqGroup& g) {
    g.AllReduceSum(got[r].data(), n);
    g.AllReduceSum(got[r].data(), 0);  // empty operations keep the members in step
  });
  for (int r = 0; r < size; ++r) {
    for (int i = 0; i < n; ++i) ASSERT_EQ(got[r][i], expect[i]) << "rank " << r << " i " << i;
  }
}

TEST(GroupTest, AllGatherGivesEveryMemberAllBytesInRankOrder) {
  zmq::context_t ctx;
  const int size = 3;
  std::vector<std::vector<std::string>> got(size);
  RunGroup(ctx, size, "inproc://group-gather", [&](int r, ZmqGroup& g) {
    got[r] = g.AllGather(std::string(r + 1, static_cast<char>('a' + r)));
    EXPECT_GT(g.stats().operations, 0u);
  });
  const std::vector<std::string> expect = {"a", "bb", "ccc"};
  for (int r = 0; r < size; ++r) EXPECT_EQ(got[r], expect) << "rank " << r;
}

TEST(GroupTest, PackedStringsRoundTripAndDamageIsNamed) {
  const std::vector<std::string> parts = {"", "abc", std::string(3, '\0')};
  EXPECT_EQ(UnpackStrings(PackStrings(parts), "t"), parts);
  std::string packed = PackStrings(parts);
  packed.pop_back();
  try {
    UnpackStrings(packed, "the reply");
    FAIL() << "truncated bytes accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("the reply: truncated"), std::string::npos) << e.what();
  }
}

TEST(GroupTest, AMemberWithAnotherFingerprintIsRefusedAndTheRightOneStillJoins) {
  zmq::context_t ctx;
  const std::string address = "inproc://group-refuse";
  std::string wrong_error;
  std::thread root([&] {
    ZmqGroup g(ctx, Member(0, 2, address, "config=1 updates=5"));
    std::vector<float> x = {1.0f};
    g.AllReduceSum(x.data(), 1);
    EXPECT_EQ(x[0], 3.0f);
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  try {
    ZmqGroup bad(ctx, Member(1, 2, address, "config=1 updates=4"));
    wrong_error = "joined";
  } catch (const std::runtime_error& e) {
    wrong_error = e.what();
  }
  EXPECT_NE(wrong_error.find("refused this member"), std::string::npos) << wrong_error;
  EXPECT_NE(wrong_error.find("updates=4"), std::string::npos) << wrong_error;
  try {
    ZmqGroup wrong_size(ctx, Member(1, 3, address, "config=1 updates=5"));
    ADD_FAILURE() << "a member of a group of 3 joined a group of 2";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cluster.learners"), std::string::npos) << e.what();
  }
  ZmqGroup good(ctx, Member(1, 2, address, "config=1 updates=5"));
  std::vector<float> x = {2.0f};
  good.AllReduceSum(x.data(), 1);
  EXPECT_EQ(x[0], 3.0f);
  root.join();
}

TEST(GroupTest, AMemberThatStopsStopsTheOthersAtTheirNextOperation) {
  zmq::context_t ctx;
  const std::string address = "inproc://group-stop";
  std::atomic<bool> stop1{false};
  std::string root_error, member_error;
  std::thread root([&] {
    ZmqGroup g(ctx, Member(0, 2, address));
    try {
      std::vector<std::string> all = g.AllGather("one");
      EXPECT_EQ(all.size(), 2u);
      g.AllGather("two");  // rank 1 stops instead of answering
      root_error = "completed";
    } catch (const GroupStopped& e) {
      root_error = e.what();
    }
    EXPECT_THROW(g.AllGather("three"), GroupStopped);  // a group that stopped stays stopped
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  GroupOptions o = Member(1, 2, address);
  o.stop = &stop1;
  ZmqGroup g(ctx, o);
  g.AllGather("one");
  stop1 = true;
  try {
    g.AllGather("two");
    member_error = "completed";
  } catch (const GroupStopped& e) {
    member_error = e.what();
  }
  root.join();
  EXPECT_NE(member_error.find("stopping"), std::string::npos) << member_error;
  EXPECT_NE(root_error.find("rank 1 stopped"), std::string::npos) << root_error;
}

// The race behind a CI failure (2026-12-05): a member stopped while waiting for the reply to a part
// rank 0 already had; rank 0 finished that operation (the last of an update) and the member did
// not, so the two ended one update apart. Now both finish it and both stop at the next one.
TEST(GroupTest, AMemberThatStopsAfterSendingItsPartStillTakesTheReply) {
  zmq::context_t ctx;
  const std::string address = "inproc://group-stop-sent";
  std::atomic<bool> stop1{false};
  std::string root_next, member_next;
  float root_sum = 0.0f, member_sum = 0.0f;
  bool member_completed = false;
  std::thread root([&] {
    ZmqGroup g(ctx, Member(0, 2, address));
    // Rank 1's part and then its bye are queued before rank 0 starts the operation.
    while (!stop1.load()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    float x = 1.0f;
    g.AllReduceSum(&x, 1);
    root_sum = x;
    try {
      g.AllReduceSum(&x, 1);
      root_next = "completed";
    } catch (const GroupStopped& e) {
      root_next = e.what();
    }
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  GroupOptions o = Member(1, 2, address);
  o.stop = &stop1;
  ZmqGroup g(ctx, o);
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    stop1 = true;  // while the member waits for the reply
  });
  float x = 2.0f;
  try {
    g.AllReduceSum(&x, 1);
    member_completed = true;
    member_sum = x;
    g.AllReduceSum(&x, 1);
    member_next = "completed";
  } catch (const GroupStopped& e) {
    member_next = e.what();
  }
  stopper.join();
  root.join();
  EXPECT_TRUE(member_completed) << "rank 0 finished the operation, rank 1 did not: " << member_next;
  EXPECT_EQ(root_sum, 3.0f);
  EXPECT_EQ(member_sum, 3.0f);
  EXPECT_TRUE(g.left());
  EXPECT_NE(member_next.find("left"), std::string::npos) << member_next;
  EXPECT_NE(root_next.find("rank 1 stopped"), std::string::npos) << root_next;
}

TEST(GroupTest, AMissingRankZeroIsNamedAfterTheTimeout) {
  zmq::context_t ctx;
  GroupOptions o = Member(1, 2, "tcp://127.0.0.1:1");  // nothing listens there
  o.join_timeout_s = 0.3;
  try {
    ZmqGroup g(ctx, o);
    FAIL() << "joined a group without rank 0";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("rank 0 at tcp://127.0.0.1:1 did not answer"),
              std::string::npos)
        << e.what();
  }
}

// With keys (issue 17), members join over TCP; a process without the learner's key pair does not.
TEST(GroupTest, OverTcpWithKeysOnlyHoldersOfTheLearnersKeyJoin) {
  char tmpl[] = "/tmp/perch-group-keys-XXXXXX";
  ASSERT_NE(::mkdtemp(tmpl), nullptr);
  const std::string dir = std::string(tmpl) + "/keys";
  WriteClusterKeys(dir);
  const CurveKeys keys = ReadLearnerKeys(dir);
  zmq::context_t ctx;
  ZapAuthenticator zap(ctx, {keys.learner_public});
  const std::string address = "tcp://127.0.0.1:" + std::to_string(PickFreePortForTest());
  std::vector<float> got(2);
  std::thread root([&] {
    GroupOptions o = Member(0, 2, address);
    o.keys = &keys;
    ZmqGroup g(ctx, o);
    float x = 1.0f;
    g.AllReduceSum(&x, 1);
    got[0] = x;
  });
  // A stranger first: no keys at all, then a key pair of its own.
  {
    zmq::context_t other;
    GroupOptions o = Member(1, 2, address);
    o.join_timeout_s = 0.5;
    EXPECT_THROW(ZmqGroup g(other, o), GroupError);
    CurveKeys stranger = keys;
    char pub[41], sec[41];
    ASSERT_EQ(zmq_curve_keypair(pub, sec), 0);
    stranger.learner_public = pub;  // its own pair, the learner's public key as the server key
    stranger.learner_secret = sec;
    zmq::socket_t s(other, zmq::socket_type::dealer);
    s.set(zmq::sockopt::linger, 0);
    s.set(zmq::sockopt::curve_serverkey, keys.learner_public);
    s.set(zmq::sockopt::curve_publickey, std::string(pub));
    s.set(zmq::sockopt::curve_secretkey, std::string(sec));
    s.connect(address);
    (void)s.send(zmq::buffer(std::string("H")), zmq::send_flags::dontwait);
    for (int i = 0; i < 100 && zap.refused() == 0; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    EXPECT_GT(zap.refused(), 0u);
  }
  GroupOptions o = Member(1, 2, address);
  o.keys = &keys;
  {
    ZmqGroup g(ctx, o);
    float x = 2.0f;
    g.AllReduceSum(&x, 1);
    got[1] = x;
  }
  root.join();
  EXPECT_EQ(got[0], 3.0f);
  EXPECT_EQ(got[1], 3.0f);
}

// --- PPO over a group ----------------------------------------------------------------------

Rollout Acted(const PpoLearner& learner, int steps, uint64_t seed) {
  const PolicyConfig& c = learner.model().config();
  PolicyRunner runner(c, learner.config().obs_norm);
  runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(), 0);
  Rng rng(seed);
  Rollout r(c.obs_dim, c.action_size());
  r.stream_id = seed;
  std::vector<float> raw(c.obs_dim), norm(c.obs_dim), a(c.action_size());
  for (int t = 0; t < steps; ++t) {
    for (float& x : raw) x = static_cast<float>(rng.Normal(2.0, 3.0));
    const auto o = runner.Act(raw.data(), rng, false, norm.data(), a.data());
    r.Add(norm.data(), a.data(), o.log_prob, o.value, static_cast<float>(rng.Normal(1.0, 1.0)),
          t % 97 == 96, false, t + 1 == steps ? o.value : 0.0f);
  }
  r.obs_stats_delta = runner.obs_stats_delta();
  return r;
}

// Two members on two halves of a batch; returns their states after `updates` updates.
std::vector<proto::LearnerState> TrainPair(const PpoConfig& cfg, const std::string& address,
                                           int updates, const std::vector<Rollout>& half0,
                                           const std::vector<Rollout>& half1) {
  zmq::context_t ctx;
  std::vector<proto::LearnerState> out(2);
  RunGroup(ctx, 2, address, [&](int r, ZmqGroup& g) {
    PpoLearner learner(PolicyConfig::Subtask(7), cfg, 3);
    if (r > 0) learner.SeedShuffle(3, r);
    learner.SetCollective(&g);
    for (int u = 0; u < updates; ++u) {
      const UpdateStats st = learner.Update(r == 0 ? half0 : half1);
      int total = 0;
      for (const Rollout& x : half0) total += x.size();
      for (const Rollout& x : half1) total += x.size();
      EXPECT_EQ(st.group_samples, total);
    }
    learner.ExportState(&out[r]);
  });
  return out;
}

TEST(PpoGroupTest, MembersKeepTheSameWeightsMomentsAndStatistics) {
  for (int threads : {1, 2}) {
    PpoConfig cfg;
    cfg.num_minibatches = 4;
    cfg.num_epochs = 2;
    cfg.threads = threads;
    PpoLearner init(PolicyConfig::Subtask(7), cfg, 3);
    const std::vector<Rollout> half0 = {Acted(init, 200, 11), Acted(init, 90, 12)};
    const std::vector<Rollout> half1 = {Acted(init, 256, 13)};
    const std::vector<proto::LearnerState> s =
        TrainPair(cfg, "inproc://ppo-same-" + std::to_string(threads), 2, half0, half1);
    EXPECT_EQ(s[0].model().SerializeAsString(), s[1].model().SerializeAsString())
        << threads << " thread(s): weights or observation statistics differ";
    EXPECT_EQ(s[0].adam().SerializeAsString(), s[1].adam().SerializeAsString());
    EXPECT_EQ(s[0].return_stats().SerializeAsString(), s[1].return_stats().SerializeAsString());
    // Both halves' observations in the statistics: prior + 546 per update.
    EXPECT_NEAR(s[0].model().obs_stats().count(), 2 * 546 + 1e-4, 1e-6);
    // The members shuffled differently (their own streams) yet ended equal.
    EXPECT_NE(s[0].rng().SerializeAsString(), s[1].rng().SerializeAsString());
  }
}

TEST(PpoGroupTest, AGroupStepIsTheWholeBatchsStep) {
  // Full-batch steps without per-member advantage normalization or reward scaling: a group of two
  // on the halves takes the steps one learner takes on the whole batch, up to summation order.
  PpoConfig cfg;
  cfg.num_minibatches = 1;
  cfg.num_epochs = 3;
  cfg.normalize_advantages = false;
  cfg.reward_scaling.enabled = false;
  PpoLearner one(PolicyConfig::Subtask(7), cfg, 3);
  const std::vector<Rollout> half0 = {Acted(one, 200, 11), Acted(one, 90, 12)};
  const std::vector<Rollout> half1 = {Acted(one, 256, 13)};
  const VectorXf start = one.model().params();
  std::vector<Rollout> whole = half0;
  whole.insert(whole.end(), half1.begin(), half1.end());
  one.Update(whole);
  const std::vector<proto::LearnerState> s = TrainPair(cfg, "inproc://ppo-whole", 1, half0, half1);
  const Eigen::Map<const VectorXf> group(s[0].model().params().data(), start.size());
  const float moved = (one.model().params() - start).norm();
  ASSERT_GT(moved, 0.0f);
  EXPECT_LT((group - one.model().params()).norm(), 1e-3f * moved);
}

TEST(PpoGroupTest, ARefusedBatchIsDroppedByEveryMemberAndChangesNothing) {
  PpoConfig cfg;
  cfg.num_minibatches = 2;
  cfg.num_epochs = 1;
  PpoLearner init(PolicyConfig::Subtask(7), cfg, 3);
  const Rollout good = Acted(init, 64, 11);
  Rollout bad = Acted(init, 64, 12);
  bad.rewards[5] = std::nanf("");
  zmq::context_t ctx;
  std::vector<std::string> errors(2);
  std::vector<bool> unchanged(2, false);
  RunGroup(ctx, 2, "inproc://ppo-refuse", [&](int r, ZmqGroup& g) {
    PpoLearner learner(PolicyConfig::Subtask(7), cfg, 3);
    learner.SetCollective(&g);
    const VectorXf before = learner.model().params();
    try {
      learner.Update({r == 0 ? good : bad});
    } catch (const ConfigError& e) {
      errors[r] = e.what();
    }
    unchanged[r] = learner.model().params() == before && learner.num_updates() == 0 &&
                   learner.obs_normalizer().stats().count() < 1e-3;
  });
  EXPECT_NE(errors[0].find("rank 1 refused its batch"), std::string::npos) << errors[0];
  EXPECT_NE(errors[1].find("rollout[0]"), std::string::npos) << errors[1];
  EXPECT_TRUE(unchanged[0]);
  EXPECT_TRUE(unchanged[1]);
}

}  // namespace
}  // namespace perch
