// Learner and actor in separate network namespaces joined by a veth pair: the actor reaches the
// learner only through a real (virtual) network link, as pods do. Skipped when not root or when
// `ip netns` is unavailable.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <string>

#include "tests/actor/cluster_fixture.h"

namespace perch {
namespace {

using namespace testing_util;

int Sh(const std::string& cmd) {
  const int rc = std::system((cmd + " >/dev/null 2>&1").c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

class NetnsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (PerchBin().empty()) GTEST_SKIP() << "PERCH_BIN not set";
    if (::geteuid() != 0) GTEST_SKIP() << "needs root for ip netns";
    tag_ = std::to_string(::getpid() % 100000);
    ns_l_ = "perchl" + tag_;
    ns_a_ = "percha" + tag_;
    // A /30 from the pid so that parallel runs do not collide.
    const int net = (::getpid() % 250) + 1;
    ip_l_ = "10.213." + std::to_string(net) + ".1";
    ip_a_ = "10.213." + std::to_string(net) + ".2";
    const std::string vl = "vl" + tag_, va = "va" + tag_;
    if (Sh("ip netns add " + ns_l_) != 0 || Sh("ip netns add " + ns_a_) != 0 ||
        Sh("ip link add " + vl + " type veth peer name " + va) != 0 ||
        Sh("ip link set " + vl + " netns " + ns_l_) != 0 ||
        Sh("ip link set " + va + " netns " + ns_a_) != 0 ||
        Sh("ip -n " + ns_l_ + " addr add " + ip_l_ + "/30 dev " + vl) != 0 ||
        Sh("ip -n " + ns_a_ + " addr add " + ip_a_ + "/30 dev " + va) != 0 ||
        Sh("ip -n " + ns_l_ + " link set " + vl + " up") != 0 ||
        Sh("ip -n " + ns_a_ + " link set " + va + " up") != 0 ||
        Sh("ip -n " + ns_l_ + " link set lo up") != 0) {
      TearDown();
      GTEST_SKIP() << "ip netns / veth not supported here";
    }
    ready_ = true;
  }
  void TearDown() override {
    Sh("ip netns del " + ns_l_);
    Sh("ip netns del " + ns_a_);
  }
  std::string tag_, ns_l_, ns_a_, ip_l_, ip_a_;
  bool ready_ = false;
};

TEST_F(NetnsTest, ActorInAnotherNamespaceTrainsWithTheLearner) {
  ASSERT_TRUE(ready_);
  const std::string dir = TempDir("netns");
  const std::string cfg = WriteConfig(dir, MockConfig());
  const std::string run = dir + "/run";
  // The learner binds only its namespace's veth address: nothing else could reach it.
  const pid_t learner =
      Spawn({"/usr/sbin/ip", "netns", "exec", ns_l_, PerchBin(), "learner", "--config", cfg,
             "--run-dir", run, "--rollout-bind", "tcp://" + ip_l_ + ":5555", "--weights-bind",
             "tcp://" + ip_l_ + ":5556", "--metrics-port", "9100", "--max-updates", "3"},
            dir + "/learner.log");
  const pid_t actor = Spawn({"/usr/sbin/ip", "netns", "exec", ns_a_, PerchBin(), "actor",
                             "--config", cfg, "--learner-host", ip_l_, "--actor-id", "0"},
                            dir + "/actor.log");
  int status = 0;
  const bool done = WaitFor(learner, 60.0, &status);
  Stop(actor, 5.0);
  if (!done) Stop(learner, 5.0);
  ASSERT_TRUE(done) << ReadFile(dir + "/learner.log") << ReadFile(dir + "/actor.log");
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << ReadFile(dir + "/learner.log");
  EXPECT_EQ(ReadMetrics(run).size(), 3u);
}

}  // namespace
}  // namespace perch
