// `perch train`: learner + N actor processes on loopback, actor restarts, SIGTERM shutdown.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <ctime>
#include <fstream>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "tests/actor/cluster_fixture.h"

namespace perch {
namespace {

using namespace testing_util;

std::vector<pid_t> Children(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/task/" + std::to_string(pid) + "/children");
  std::vector<pid_t> out;
  for (pid_t c; in >> c;) out.push_back(c);
  return out;
}

std::string Cmdline(pid_t pid) {
  std::string s = ReadFile("/proc/" + std::to_string(pid) + "/cmdline");
  for (char& c : s) {
    if (c == '\0') c = ' ';
  }
  return s;
}

std::set<pid_t> ActorChildren(pid_t train) {
  std::set<pid_t> out;
  for (pid_t c : Children(train)) {
    if (Cmdline(c).find(" actor ") != std::string::npos) out.insert(c);
  }
  return out;
}

// A loopback port this test holds (bound; listening when asked) so that nothing else takes it.
struct HeldPort {
  int fd = -1;
  int port = 0;
  explicit HeldPort(bool listen) {
    fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)), 0);
    if (listen) {
      EXPECT_EQ(::listen(fd, 1), 0);
    }
    socklen_t len = sizeof(a);
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    port = ntohs(a.sin_port);
  }
  ~HeldPort() { ::close(fd); }
};

std::vector<std::string> TrainArgv(const std::string& cfg, const std::string& run_dir) {
  return {PerchBin(),       "train",
          "--config",       cfg,
          "--actors",       "2",
          "--run-dir",      run_dir,
          "--rollout-port", std::to_string(PickFreePort()),
          "--weights-port", std::to_string(PickFreePort()),
          "--metrics-port", std::to_string(PickFreePort())};
}

TEST(TrainLauncherTest, RunsToMaxUpdatesAndExits) {
  if (PerchBin().empty()) GTEST_SKIP() << "PERCH_BIN not set";
  const std::string dir = TempDir("train");
  const std::string cfg = WriteConfig(dir, MockConfig());
  std::vector<std::string> argv = TrainArgv(cfg, dir + "/run");
  argv.push_back("--max-updates");
  argv.push_back("4");
  const pid_t pid = Spawn(argv, dir + "/train.log");
  int status = 0;
  ASSERT_TRUE(WaitFor(pid, 60.0, &status)) << ReadFile(dir + "/train.log");
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << ReadFile(dir + "/train.log");
  EXPECT_EQ(ReadMetrics(dir + "/run").size(), 4u);
  EXPECT_EQ(::access((dir + "/run/checkpoints/ckpt-0000000004.bin").c_str(), F_OK), 0);
  EXPECT_EQ(::access((dir + "/run/logs/actor-1.log").c_str(), F_OK), 0);
}

TEST(TrainLauncherTest, RestartsDeadActorAndStopsCleanlyOnSigterm) {
  if (PerchBin().empty()) GTEST_SKIP() << "PERCH_BIN not set";
  const std::string dir = TempDir("train");
  // Checkpoints rarely: the one at the end must come from the SIGTERM shutdown.
  const std::string cfg = WriteConfig(dir, MockConfig({{"checkpoint_every", 1000}}));
  const std::string run = dir + "/run";
  const std::vector<std::string> argv = TrainArgv(cfg, run);
  const int metrics_port = std::stoi(argv.back());
  const pid_t train = Spawn(argv, dir + "/train.log");
  ASSERT_TRUE(WaitUntil([&] { return ReadMetrics(run).size() >= 2; }, 30.0))
      << ReadFile(dir + "/train.log");
  EXPECT_EQ(Scrape(metrics_port, "perch_actor_restarts_total"), 0.0);
  std::set<pid_t> actors = ActorChildren(train);
  ASSERT_EQ(actors.size(), 2u);
  const pid_t victim = *actors.begin();
  ::kill(victim, SIGKILL);
  ASSERT_TRUE(WaitUntil(
      [&] {
        const std::set<pid_t> now = ActorChildren(train);
        return now.size() == 2 && now.count(victim) == 0;
      },
      20.0))
      << ReadFile(dir + "/train.log");
  EXPECT_NE(ReadFile(dir + "/train.log").find("killed by signal 9; restarting it"),
            std::string::npos);
  // The restart is counted on the learner's /metrics (from the launcher's launcher.json).
  EXPECT_TRUE(
      WaitUntil([&] { return Scrape(metrics_port, "perch_actor_restarts_total") == 1.0; }, 10.0));
  const size_t n = ReadMetrics(run).size();
  ASSERT_TRUE(WaitUntil([&] { return ReadMetrics(run).size() >= n + 2; }, 30.0));
  const std::vector<pid_t> children = Children(train);
  ::kill(train, SIGTERM);
  int status = 0;
  ASSERT_TRUE(WaitFor(train, 60.0, &status)) << ReadFile(dir + "/train.log");
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << DescribeStatus(status);
  // The final checkpoint holds the last update, and no child is left running.
  const std::vector<Json> rows = ReadMetrics(run);
  char name[64];
  std::snprintf(name, sizeof(name), "/checkpoints/ckpt-%010d.bin",
                rows.back()["update"].get<int>());
  EXPECT_EQ(::access((run + name).c_str(), F_OK), 0) << run + name;
  for (pid_t c : children) EXPECT_NE(::kill(c, 0), 0) << "child " << c << " still running";
}

// Ctrl-C in a terminal sends SIGINT to every process of the job at once; each blocking socket
// call is interrupted (EINTR) and the learner must still write its final checkpoint.
TEST(TrainLauncherTest, CtrlCToTheWholeJobWritesFinalCheckpoint) {
  if (PerchBin().empty()) GTEST_SKIP() << "PERCH_BIN not set";
  const std::string dir = TempDir("train-int");
  const std::string cfg = WriteConfig(dir, MockConfig({{"checkpoint_every", 1000}}));
  const std::string run = dir + "/run";
  const pid_t train = Spawn(TrainArgv(cfg, run), dir + "/train.log");
  ASSERT_TRUE(WaitUntil([&] { return ReadMetrics(run).size() >= 2; }, 30.0))
      << ReadFile(dir + "/train.log");
  const std::vector<pid_t> children = Children(train);
  ASSERT_EQ(children.size(), 3u);  // learner + 2 actors
  // Pause the actors so that the learner sits in its socket poll, where the signal lands.
  const std::set<pid_t> actors = ActorChildren(train);
  for (pid_t a : actors) ::kill(a, SIGSTOP);
  ::usleep(300 * 1000);
  ::kill(train, SIGINT);
  for (pid_t c : children) ::kill(c, SIGINT);
  for (pid_t a : actors) ::kill(a, SIGCONT);
  int status = 0;
  ASSERT_TRUE(WaitFor(train, 60.0, &status)) << ReadFile(dir + "/train.log");
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << DescribeStatus(status) << "\n"
                                                             << ReadFile(dir + "/train.log");
  const std::vector<Json> rows = ReadMetrics(run);
  char name[64];
  std::snprintf(name, sizeof(name), "/checkpoints/ckpt-%010d.bin",
                rows.back()["update"].get<int>());
  EXPECT_EQ(::access((run + name).c_str(), F_OK), 0) << run + name << "\n"
                                                     << ReadFile(dir + "/train.log");
  for (pid_t c : children) EXPECT_NE(::kill(c, 0), 0) << "child " << c << " still running";
}

// A learner that cannot start (its metrics port is taken) is restarted with growing delays and
// given up on after cluster.max_identical_failures identical failures: no endless restart loop.
TEST(TrainLauncherTest, GivesUpOnALearnerThatFailsTheSameWayAgainAndAgain) {
  if (PerchBin().empty()) GTEST_SKIP() << "PERCH_BIN not set";
  const std::string dir = TempDir("train-giveup");
  const std::string cfg =
      WriteConfig(dir, MockConfig({{"restart_backoff_ms", 50}, {"max_identical_failures", 3}}));
  auto busy = std::make_unique<HeldPort>(/*listen=*/true);
  std::vector<std::string> argv = TrainArgv(cfg, dir + "/run");
  argv.back() = std::to_string(busy->port);  // --metrics-port
  const pid_t train = Spawn(argv, dir + "/train.log");
  int status = 0;
  const bool ended = WaitFor(train, 30.0, &status);
  busy.reset();
  if (!ended) Stop(train, 5.0);
  ASSERT_TRUE(ended) << "still restarting after 30 s:\n" << ReadFile(dir + "/train.log");
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1) << DescribeStatus(status);
  const std::string log = ReadFile(dir + "/train.log");
  EXPECT_NE(log.find("3 times in a row; giving up"), std::string::npos) << log;
  EXPECT_NE(log.find("failure 2 in a row"), std::string::npos) << log;
}

// A stopped learner (SIGSTOP) is reported, and an actor that cannot reach its learner says so.
TEST(TrainLauncherTest, ReportsAStoppedLearnerAndActorsThatCannotReachIt) {
  if (PerchBin().empty()) GTEST_SKIP() << "PERCH_BIN not set";
  const std::string dir = TempDir("train-stopped");
  const std::string cfg = WriteConfig(dir, MockConfig({{"learner_watchdog_s", 2.0}}));
  const std::string run = dir + "/run";
  const pid_t train = Spawn(TrainArgv(cfg, run), dir + "/train.log");
  ASSERT_TRUE(WaitUntil([&] { return ReadMetrics(run).size() >= 2; }, 30.0))
      << ReadFile(dir + "/train.log");
  pid_t learner = -1;
  for (pid_t c : Children(train)) {
    if (Cmdline(c).find(" learner ") != std::string::npos) learner = c;
  }
  ASSERT_GT(learner, 0);
  ::kill(learner, SIGSTOP);
  const bool seen = WaitUntil(
      [&] {
        const std::string log = ReadFile(dir + "/train.log");
        return log.find("is stopped (SIGSTOP?)") != std::string::npos &&
               log.find("no update from the learner for") != std::string::npos;
      },
      20.0);
  ::kill(learner, SIGCONT);
  ::kill(train, SIGTERM);
  int status = 0;
  WaitFor(train, 60.0, &status);
  EXPECT_TRUE(seen) << ReadFile(dir + "/train.log");

  // An actor alone, its learner nowhere: a line every few seconds. Its ports are held (bound, not
  // listening) so that no other test's learner can take them meanwhile.
  const HeldPort rp(/*listen=*/false), wp(/*listen=*/false);
  const pid_t actor = Spawn({PerchBin(), "actor", "--config", cfg, "--learner-host", "127.0.0.1",
                             "--rollout-port", std::to_string(rp.port), "--weights-port",
                             std::to_string(wp.port), "--alive-file", dir + "/alive"},
                            dir + "/actor.log");
  const bool said = WaitUntil(
      [&] {
        return ReadFile(dir + "/actor.log").find("cannot reach the learner") != std::string::npos;
      },
      15.0);
  // Waiting for its learner, the actor still touches its liveness file (k8s/actors.yaml).
  struct stat st {};
  EXPECT_EQ(::stat((dir + "/alive").c_str(), &st), 0);
  EXPECT_LE(std::time(nullptr) - st.st_mtime, 3);
  Stop(actor, 5.0);
  EXPECT_TRUE(said) << ReadFile(dir + "/actor.log");
}

}  // namespace
}  // namespace perch
