// `perch train`: learner + N actor processes on loopback, actor restarts, SIGTERM shutdown.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
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
  const pid_t train = Spawn(TrainArgv(cfg, run), dir + "/train.log");
  ASSERT_TRUE(WaitUntil([&] { return ReadMetrics(run).size() >= 2; }, 30.0))
      << ReadFile(dir + "/train.log");
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
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
      << DescribeStatus(status) << "\n" << ReadFile(dir + "/train.log");
  const std::vector<Json> rows = ReadMetrics(run);
  char name[64];
  std::snprintf(name, sizeof(name), "/checkpoints/ckpt-%010d.bin",
                rows.back()["update"].get<int>());
  EXPECT_EQ(::access((run + name).c_str(), F_OK), 0) << run + name << "\n"
                                                    << ReadFile(dir + "/train.log");
  for (pid_t c : children) EXPECT_NE(::kill(c, 0), 0) << "child " << c << " still running";
}

}  // namespace
}  // namespace perch
