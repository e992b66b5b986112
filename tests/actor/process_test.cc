// The launcher's restart policy (issue 17): exponential backoff, giving up on identical failures,
// a healthy run starting the count again; process helpers and port picking.
#include "actor/process.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <fstream>
#include <set>

namespace perch {
namespace {

TEST(RestartPolicyTest, BacksOffExponentiallyAndGivesUpOnIdenticalFailures) {
  RestartPolicyConfig c;
  c.base_s = 0.5;
  c.max_s = 3.0;
  c.give_up_after = 4;
  c.healthy_s = 60;
  RestartPolicy p(c);
  p.OnStart(0);
  EXPECT_DOUBLE_EQ(p.OnFailure("exited 1", 1), 0.5);
  p.OnStart(2);
  EXPECT_DOUBLE_EQ(p.OnFailure("exited 1", 3), 1.0);
  p.OnStart(4);
  EXPECT_DOUBLE_EQ(p.OnFailure("exited 1", 5), 2.0);
  p.OnStart(6);
  EXPECT_LT(p.OnFailure("exited 1", 7), 0.0) << "the 4th identical failure in a row gives up";
  EXPECT_EQ(p.restarts(), 3);
}

TEST(RestartPolicyTest, ADifferentFailureOrAHealthyRunStartsTheCountAgain) {
  RestartPolicyConfig c;
  c.base_s = 1.0;
  c.max_s = 5.0;
  c.give_up_after = 2;
  c.healthy_s = 60;
  RestartPolicy p(c);
  p.OnStart(0);
  EXPECT_DOUBLE_EQ(p.OnFailure("exited 1", 1), 1.0);
  p.OnStart(2);
  // Another cause: not identical, but still a failure in a row (the delay grows).
  EXPECT_DOUBLE_EQ(p.OnFailure("killed by signal 9", 3), 2.0);
  p.OnStart(4);
  EXPECT_LT(p.OnFailure("killed by signal 9", 5), 0.0);
  RestartPolicy q(c);
  q.OnStart(0);
  EXPECT_DOUBLE_EQ(q.OnFailure("exited 1", 1), 1.0);
  q.OnStart(2);
  // Ran for 100 s before failing the same way: a fresh start, not a give-up.
  EXPECT_DOUBLE_EQ(q.OnFailure("exited 1", 102), 1.0);
  EXPECT_EQ(q.identical_in_a_row(), 1);
  // The delay is capped.
  for (int i = 0; i < 10; ++i) {
    q.OnStart(200 + 2 * i);
    EXPECT_LE(q.OnFailure(i % 2 ? "a" : "b", 201 + 2 * i), 5.0);
  }
}

TEST(ProcessTest, LastLinesAndProcessState) {
  char tmpl[] = "/tmp/perch-lines-XXXXXX";
  const int fd = ::mkstemp(tmpl);
  ASSERT_GE(fd, 0);
  ::close(fd);
  {
    std::ofstream out(tmpl);
    for (int i = 1; i <= 20; ++i) out << "line " << i << "\n";
  }
  EXPECT_EQ(LastLines(tmpl, 2), "  line 19\n  line 20\n");
  EXPECT_EQ(LastLines("/nonexistent/file", 3), "");
  const pid_t child = Spawn({"/bin/sleep", "30"});
  ::usleep(100000);
  EXPECT_NE(ProcessState(child), 'T');
  ::kill(child, SIGSTOP);
  ::usleep(100000);
  EXPECT_EQ(ProcessState(child), 'T');
  ::kill(child, SIGCONT);
  Stop(child, 5.0);
}

// Two recipe stages started side by side once got the same port (a pick inside the ephemeral
// range, taken by an outgoing connection before the learner bound it): picks lie below that
// range, are never repeated in one process, and can be bound.
TEST(ProcessTest, PickedPortsAreDistinctBindableAndBelowTheEphemeralRange) {
  int lo = 32768, hi = 60999;
  {
    std::ifstream f("/proc/sys/net/ipv4/ip_local_port_range");
    f >> lo >> hi;
  }
  std::set<int> seen;
  for (int i = 0; i < 50; ++i) {
    const int port = PickFreePort();
    EXPECT_TRUE(seen.insert(port).second) << "port " << port << " handed out twice";
    EXPECT_LT(port, lo);
    EXPECT_GE(port, 1024);
  }
  const int port = *seen.begin();
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_ANY);
  addr.sin_port = htons(static_cast<uint16_t>(port));
  EXPECT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
  ::close(fd);
}

}  // namespace
}  // namespace perch
