// Every container command line in k8s/*.yaml must be accepted by `perch ... --check-config`
// (with the ConfigMap's config.json in place of /etc/perch/config.json).
#include <dirent.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <algorithm>
#include <fstream>
#include <regex>
#include <string>
#include <vector>

#include "tests/actor/cluster_fixture.h"

namespace perch {
namespace {

using namespace testing_util;

std::vector<std::string> YamlFiles() {
  std::vector<std::string> out;
  const std::string dir = std::string(PERCH_SOURCE_DIR) + "/k8s";
  DIR* d = ::opendir(dir.c_str());
  if (d == nullptr) return out;
  while (dirent* e = ::readdir(d)) {
    const std::string n = e->d_name;
    if (n.size() > 5 && (n.substr(n.size() - 5) == ".yaml" || n.substr(n.size() - 4) == ".yml")) {
      out.push_back(dir + "/" + n);
    }
  }
  ::closedir(d);
  std::sort(out.begin(), out.end());
  return out;
}

std::string Unquote(std::string s) {
  s = std::regex_replace(s, std::regex("^\\s+|\\s+$"), "");
  if (s.size() >= 2 && (s[0] == '"' || s[0] == '\'') && s.back() == s[0])
    s = s.substr(1, s.size() - 2);
  return s;
}

struct Container {
  std::string file;
  std::vector<std::string> argv;
};

// command:/args: as a flow list [..] (JSON-compatible) or as a block list of "- item" lines.
std::vector<Container> ParseContainers(const std::string& path) {
  std::vector<Container> out;
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  const std::regex key("^(\\s*)(-\\s+)?(command|args):\\s*(.*)$");
  for (size_t i = 0; i < lines.size(); ++i) {
    std::smatch m;
    if (!std::regex_match(lines[i], m, key)) continue;
    std::vector<std::string> items;
    const std::string rest = m[4];
    if (!rest.empty() && rest[0] == '[') {
      const Json arr = Json::parse(rest);
      for (const auto& a : arr) items.push_back(a.is_string() ? a.get<std::string>() : a.dump());
    } else {
      for (size_t k = i + 1; k < lines.size(); ++k) {
        std::smatch b;
        if (!std::regex_match(lines[k], b, std::regex("^\\s*-\\s+(.*)$"))) break;
        items.push_back(Unquote(b[1]));
      }
    }
    if (m[3] == "command" || out.empty()) {
      out.push_back({path, items});
    } else {
      out.back().argv.insert(out.back().argv.end(), items.begin(), items.end());
    }
  }
  return out;
}

// The ConfigMap's config.json (a "config.json: |" block), or empty.
std::string ConfigMapJson(const std::vector<std::string>& files) {
  for (const auto& f : files) {
    std::ifstream in(f);
    std::vector<std::string> lines;
    for (std::string l; std::getline(in, l);) lines.push_back(l);
    for (size_t i = 0; i < lines.size(); ++i) {
      const size_t at = lines[i].find("config.json: |");
      if (at == std::string::npos) continue;
      std::string body;
      size_t indent = std::string::npos;
      for (size_t k = i + 1; k < lines.size(); ++k) {
        const std::string& l = lines[k];
        const size_t first = l.find_first_not_of(' ');
        if (first == std::string::npos) {
          body += "\n";
          continue;
        }
        if (indent == std::string::npos) indent = first;
        if (first < indent) break;
        body += l.substr(indent) + "\n";
      }
      return body;
    }
  }
  return "";
}

TEST(K8sCheckConfigTest, EveryContainerCommandIsAccepted) {
  if (PerchBin().empty()) GTEST_SKIP() << "PERCH_BIN not set";
  const std::vector<std::string> files = YamlFiles();
  std::vector<Container> containers;
  for (const auto& f : files) {
    for (auto& c : ParseContainers(f)) containers.push_back(c);
  }
  if (containers.empty()) GTEST_SKIP() << "k8s/ has no manifests with container commands yet";
  const std::string dir = TempDir("k8s");
  std::string config = ConfigMapJson(files);
  const std::string config_path = dir + "/config.json";
  if (!config.empty()) std::ofstream(config_path) << config;
  int checked = 0;
  for (Container c : containers) {
    ASSERT_FALSE(c.argv.empty()) << c.file;
    if (c.argv[0] != "perch" && c.argv[0].find("/perch") == std::string::npos) continue;
    c.argv[0] = PerchBin();
    for (size_t i = 1; i + 1 < c.argv.size(); ++i) {
      if (c.argv[i] == "--config" && c.argv[i + 1].rfind("/etc/perch/", 0) == 0) {
        ASSERT_FALSE(config.empty())
            << c.file << ": --config " << c.argv[i + 1] << " but no ConfigMap config.json in k8s/";
        c.argv[i + 1] = config_path;
      }
    }
    c.argv.push_back("--check-config");
    std::string cmd;
    for (const auto& a : c.argv) cmd += a + " ";
    const std::string log = dir + "/check-" + std::to_string(checked) + ".log";
    const pid_t pid = Spawn(c.argv, log);
    int status = 0;
    ASSERT_TRUE(WaitFor(pid, 30.0, &status)) << cmd;
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
        << c.file << ": " << cmd << "-> " << DescribeStatus(status) << "\n"
        << ReadFile(log);
    ++checked;
  }
  EXPECT_GT(checked, 0);
}

TEST(K8sCheckConfigTest, CheckConfigRejectsBadFlags) {
  if (PerchBin().empty()) GTEST_SKIP() << "PERCH_BIN not set";
  const std::string dir = TempDir("k8s-bad");
  const std::string cfg = WriteConfig(dir, MockConfig());
  auto rc = [&](std::vector<std::string> argv) {
    argv.insert(argv.begin(), PerchBin());
    argv.push_back("--check-config");
    int status = 0;
    const pid_t pid = Spawn(argv, dir + "/log");
    EXPECT_TRUE(WaitFor(pid, 30.0, &status));
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  };
  EXPECT_EQ(rc({"actor", "--config", cfg, "--learner-host", "h"}), 0);
  EXPECT_EQ(rc({"actor", "--config", cfg, "--learner-host", "h", "--rollout-port", "0"}), 2);
  EXPECT_EQ(rc({"actor", "--config", cfg}), 2);
  EXPECT_EQ(rc({"learner", "--config", cfg, "--run-dir", dir + "/r"}), 0);
  EXPECT_EQ(rc({"learner", "--config", cfg, "--run-dir", dir + "/r", "--rollout-bind", "tcp://x"}),
            2);
  EXPECT_EQ(rc({"learner", "--config", dir + "/missing.json", "--run-dir", dir + "/r"}), 2);
  // --check-config creates nothing.
  EXPECT_NE(::access((dir + "/r").c_str(), F_OK), 0);
}

// What used to pass --check-config and then fail at run time (issue 17) is refused by name.
TEST(K8sCheckConfigTest, CheckConfigCatchesRunTimeFailures) {
  if (PerchBin().empty()) GTEST_SKIP() << "PERCH_BIN not set";
  const std::string dir = TempDir("k8s-runtime");
  int n = 0;
  auto refused = [&](const Json& cluster, std::vector<std::string> extra, const std::string& why) {
    const std::string sub = dir + "/" + std::to_string(n++);
    ::mkdir(sub.c_str(), 0755);
    const std::string cfg = WriteConfig(sub, MockConfig(cluster));
    std::vector<std::string> argv = {PerchBin(),  "learner",  "--config",      cfg,
                                     "--run-dir", sub + "/r", "--check-config"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    int status = 0;
    const pid_t pid = Spawn(argv, sub + "/log");
    EXPECT_TRUE(WaitFor(pid, 30.0, &status));
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2)
        << why << ": " << ReadFile(sub + "/log");
    EXPECT_NE(ReadFile(sub + "/log").find(why), std::string::npos) << ReadFile(sub + "/log");
  };
  refused({{"init_from", dir + "/no_such_checkpoint.bin"}}, {}, "cluster.init_from");
  std::ofstream(dir + "/not_a_checkpoint.bin") << "hello";
  refused({{"init_from", dir + "/not_a_checkpoint.bin"}}, {}, "cluster.init_from");
  refused({{"max_message_bytes", 2048}}, {}, "cluster.max_message_bytes");
  refused({{"envs_per_actor", 1000000000}}, {}, "envs_per_actor");
  refused({}, {"--rollout-bind", "tcp://127.0.0.1:7000", "--weights-bind", "tcp://127.0.0.1:7000"},
          "both use port 7000");
  // perch train refuses bad numbers before it starts anything.
  const std::string cfg = WriteConfig(dir, MockConfig());
  for (const std::vector<std::string>& bad : {std::vector<std::string>{"--max-updates", "-5"},
                                              std::vector<std::string>{"--envs", "-1"}}) {
    std::vector<std::string> argv = {PerchBin(), "train", "--config", cfg, "--run-dir", dir + "/t"};
    argv.insert(argv.end(), bad.begin(), bad.end());
    int status = 0;
    const pid_t pid = Spawn(argv, dir + "/train.log");
    EXPECT_TRUE(WaitFor(pid, 30.0, &status)) << bad[0];
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2)
        << bad[0] << ReadFile(dir + "/train.log");
    EXPECT_NE(ReadFile(dir + "/train.log").find(bad[0] + ":"), std::string::npos);
  }
}

}  // namespace
}  // namespace perch
