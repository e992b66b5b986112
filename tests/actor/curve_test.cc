// Only cluster members talk to the learner (issue 17): CURVE keys on the TCP sockets, a ZAP handler
// that accepts only the authorized actor key. Real sockets on loopback, real learner and actor.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <zmq.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <zmq.hpp>

#include "actor/actor.h"
#include "actor/process.h"
#include "actor/role_setup.h"
#include "experiment/experiment.h"
#include "learner/service/learner.h"
#include "learner/service/learner_setup.h"
#include "protocol/security.h"
#include "tests/actor/cluster_fixture.h"

namespace perch {
namespace {

using namespace testing_util;

TEST(CurveTest, KeygenWritesTwoPairsAndNeverOverwritesThem) {
  const std::string dir = TempDir("keys") + "/k";
  WriteClusterKeys(dir);
  const CurveKeys l = ReadLearnerKeys(dir), a = ReadActorKeys(dir);
  EXPECT_EQ(l.learner_public.size(), 40u);
  EXPECT_EQ(l.learner_public, a.learner_public);
  ASSERT_EQ(l.authorized.size(), 1u);
  EXPECT_EQ(l.authorized[0], a.actor_public);
  EXPECT_NE(l.learner_secret, a.actor_secret);
  struct stat st {};
  ASSERT_EQ(::stat((dir + "/learner.key").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  const std::string before = ReadFile(dir + "/learner.key");
  try {
    WriteClusterKeys(dir);
    FAIL() << "keys overwritten";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("never overwritten"), std::string::npos) << e.what();
  }
  EXPECT_EQ(ReadFile(dir + "/learner.key"), before);
  // A damaged key and a bad authorized_keys line are named.
  std::ofstream(dir + "/authorized_keys") << "# extra actors\n"
                                          << a.actor_public << "\nnot-a-key\n";
  try {
    ReadLearnerKeys(dir);
    FAIL() << "a bad authorized key accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("authorized_keys:3"), std::string::npos) << e.what();
  }
  std::ofstream(dir + "/actor.key") << "short\n";
  try {
    ReadActorKeys(dir);
    FAIL() << "a damaged key accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("actor.key: not a CURVE key"), std::string::npos)
        << e.what();
  }
}

TEST(CurveTest, ALearnerWithoutKeysRefusesToStartUnlessInsecure) {
  ::unsetenv("PERCH_KEYS_DIR");
  Json j = MockConfig(Json{{"insecure", false}});
  const ExperimentConfig cfg = ExperimentConfigFromJson(j, "curve");
  LearnerOptions lo;
  lo.rollout_bind = "tcp://127.0.0.1:" + std::to_string(PickFreePort());
  lo.weights_bind = "tcp://127.0.0.1:" + std::to_string(PickFreePort());
  lo.metrics_port = -1;
  lo.run_dir = TempDir("curve-nokeys") + "/run";
  zmq::context_t ctx(1);
  try {
    LearnerService learner(ctx, MakeLearnerSetup(cfg), lo);
    FAIL() << "a learner on tcp started without keys";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("cluster.keys_dir"), std::string::npos) << e.what();
  }
}

TEST(CurveTest, OnlyTheAuthorizedActorTrainsOrReadsTheLearner) {
  const std::string dir = TempDir("curve");
  WriteClusterKeys(dir + "/keys");
  Json j = MockConfig(Json{{"insecure", false}, {"keys_dir", dir + "/keys"}});
  const ExperimentConfig cfg = ExperimentConfigFromJson(j, "curve");
  LearnerOptions lo;
  const int rp = PickFreePort(), wp = PickFreePort();
  lo.rollout_bind = "tcp://127.0.0.1:" + std::to_string(rp);
  lo.weights_bind = "tcp://127.0.0.1:" + std::to_string(wp);
  lo.metrics_port = -1;
  lo.run_dir = dir + "/run";
  lo.max_updates = 3;
  zmq::context_t ctx(1);
  LearnerService learner(ctx, MakeLearnerSetup(cfg), lo);
  std::thread run([&] { learner.Run(); });

  // Strangers: one without CURVE, one with a key pair of its own (it knows the learner's public
  // key, which is not a secret), and a subscriber with that stranger's key.
  zmq::context_t other(1);
  char pub[41], sec[41];
  ASSERT_EQ(zmq_curve_keypair(pub, sec), 0);
  CurveKeys stranger = ReadActorKeys(dir + "/keys");
  stranger.actor_public = pub;
  stranger.actor_secret = sec;
  zmq::socket_t plain(other, zmq::socket_type::push), curve(other, zmq::socket_type::push),
      sub(other, zmq::socket_type::sub);
  for (zmq::socket_t* s : {&plain, &curve, &sub}) s->set(zmq::sockopt::linger, 0);
  MakeCurveClient(curve, stranger);
  MakeCurveClient(sub, stranger);
  sub.set(zmq::sockopt::subscribe, "");
  plain.connect(lo.rollout_bind);
  curve.connect(lo.rollout_bind);
  sub.connect(lo.weights_bind);
  for (int i = 0; i < 5; ++i) {
    (void)plain.send(zmq::buffer(std::string("not a segment")), zmq::send_flags::dontwait);
    (void)curve.send(zmq::buffer(std::string("not a segment")), zmq::send_flags::dontwait);
  }
  EXPECT_TRUE(WaitUntil([&] { return learner.auth_refused() > 0; }, 10.0));
  // The client without CURVE fails the handshake before ZAP: counted by the socket monitor.
  EXPECT_TRUE(WaitUntil([&] { return learner.handshake_failures() > 0; }, 10.0));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(learner.stats().messages, 0u) << "a stranger's message reached the learner";

  // The member trains it.
  std::atomic<bool> stop{false};
  ActorOptions ao;
  ao.rollout_connect = lo.rollout_bind;
  ao.weights_connect = lo.weights_bind;
  ao.num_envs = 2;
  ao.stop = &stop;
  ActorService actor(ctx, MakeActorSetup(cfg), ao);
  std::thread at([&] { actor.Run(); });
  run.join();
  stop = true;
  at.join();
  EXPECT_EQ(learner.counters().updates(), 3u);
  EXPECT_GT(actor.counters().weights_loaded, 0u);
  EXPECT_EQ(learner.counters().rejected(), 0u);
  // The stranger's subscription never got the weights the member got.
  zmq::message_t m;
  EXPECT_FALSE(sub.recv(m, zmq::recv_flags::dontwait));
}

}  // namespace
}  // namespace perch
