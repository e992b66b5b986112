// Helpers for the cluster tests: temporary run dirs, mock-env configs, the perch binary
// (PERCH_BIN) as real processes on loopback, bounded waits, metrics scraping.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "actor/process.h"
#include "common/json_util.h"
#include "learner/service/metrics_http.h"

namespace perch {
namespace testing_util {

inline std::string TempDir(const std::string& tag) {
  std::string tmpl = "/tmp/perch-" + tag + "-XXXXXX";
  std::vector<char> buf(tmpl.begin(), tmpl.end());
  buf.push_back('\0');
  const char* d = ::mkdtemp(buf.data());
  EXPECT_NE(d, nullptr);
  return d ? d : "/tmp";
}

inline std::string PerchBin() {
  const char* p = std::getenv("PERCH_BIN");
  return p ? p : "";
}

// A small, fast experiment on the mock env; `cluster` entries override the defaults.
inline Json MockConfig(const Json& cluster = Json::object(), int steps_per_update = 512) {
  Json c{{"seed", 0},
         {"env_backend", "mock"},
         {"mock_env", {{"act_dim", 2}, {"noise_dims", 2}, {"episode_steps", 32}}},
         {"ppo",
          {{"steps_per_update", steps_per_update},
           {"num_minibatches", 4},
           {"num_epochs", 2},
           {"learning_rate", 0.001}}},
         {"cluster",
          {{"task", "stand"},
           // The transport tests run without keys; tests/actor/curve_test.cc runs with them.
           {"insecure", true},
           {"segment_steps", 64},
           {"envs_per_actor", 2},
           {"checkpoint_every", 2},
           {"keep_last", 3},
           {"heartbeat_s", 0.2},
           {"reconnect_ivl_ms", 50},
           {"restart_backoff_ms", 100}}}};
  for (auto it = cluster.begin(); it != cluster.end(); ++it) c["cluster"][it.key()] = it.value();
  return c;
}

inline std::string WriteConfig(const std::string& dir, const Json& j) {
  const std::string path = dir + "/config.json";
  std::ofstream(path) << j.dump(2);
  return path;
}

inline std::vector<Json> ReadMetrics(const std::string& run_dir) {
  std::vector<Json> rows;
  std::ifstream in(run_dir + "/metrics.jsonl");
  for (std::string line; std::getline(in, line);) {
    if (line.empty()) continue;
    try {
      rows.push_back(Json::parse(line));
    } catch (...) {
      break;  // a line being written right now
    }
  }
  return rows;
}

inline std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Polls pred every 50 ms until true or timeout_s. Returns pred's last value.
inline bool WaitUntil(const std::function<bool()>& pred, double timeout_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return pred();
}

// Value of `name` in the learner's /metrics, or -1 when it cannot be read.
inline double Scrape(int port, const std::string& name) {
  try {
    const std::string body = HttpGetLocal(port, "/metrics", 1000);
    const std::string key = "\n" + name + " ";
    const size_t at = body.find(key);
    if (at == std::string::npos) return -1;
    return std::stod(body.substr(at + key.size()));
  } catch (...) {
    return -1;
  }
}

inline bool Alive(pid_t pid) {
  int status;
  return ::waitpid(pid, &status, WNOHANG) == 0;
}

// A learner process on free loopback ports.
struct LearnerProc {
  int rollout_port = PickFreePort();
  int weights_port = PickFreePort();
  int metrics_port = PickFreePort();
  pid_t pid = -1;
  std::string log;

  void Start(const std::string& config, const std::string& run_dir, bool resume,
             int64_t max_updates = 0) {
    std::vector<std::string> a = {PerchBin(),       "learner",        "--config",
                                  config,           "--run-dir",      run_dir,
                                  "--rollout-bind", Rollout(),        "--weights-bind",
                                  Weights(),        "--metrics-port", std::to_string(metrics_port)};
    if (resume) a.push_back("--resume");
    if (max_updates > 0) {
      a.push_back("--max-updates");
      a.push_back(std::to_string(max_updates));
    }
    log = run_dir + ".learner.log";
    pid = Spawn(a, log);
  }
  std::string Rollout() const { return "tcp://127.0.0.1:" + std::to_string(rollout_port); }
  std::string Weights() const { return "tcp://127.0.0.1:" + std::to_string(weights_port); }
  ~LearnerProc() {
    if (pid > 0) Stop(pid, 10.0);
  }
};

inline pid_t StartActor(const std::string& config, const LearnerProc& l, int id,
                        const std::string& log) {
  return Spawn({PerchBin(), "actor", "--config", config, "--learner-host", "127.0.0.1",
                "--rollout-port", std::to_string(l.rollout_port), "--weights-port",
                std::to_string(l.weights_port), "--actor-id", std::to_string(id)},
               log);
}

}  // namespace testing_util
}  // namespace perch
