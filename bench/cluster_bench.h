// The cluster's benchmarks (perch bench cluster, flow, scale, group, train): each runs real
// learner and actor processes (or in-process actor services over loopback) and prints one JSON
// object with --json. Ratios are against a baseline measured in the same run (docs/scaling.md
// "Measured").
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace perch {

struct BenchFlags {
  std::string config = "configs/default.json";
  int actors = 0;  // 0: one per core
  int envs = 0;
  double env_seconds = 5.0;
  double cluster_seconds = 20.0;
  int repeats = 3;
  bool train_policy = false;
  bool json = false;
};

struct BenchFlowFlags {
  std::string config = "configs/mock.json";
  std::vector<int> actors = {1, 4, 16};
  double seconds = 15.0;
  bool json = false;
};

struct BenchScaleFlags {
  std::string config = "configs/default.json";
  std::vector<int> actors = {1, 4, 16, 64, 256};
  double rate = 0.0;  // samples/s per synthetic actor; 0: one actor core's, measured
  double seconds = 20.0;
  int envs = 0;                     // streams per synthetic actor; 0: the config's envs_per_actor
  int ppo_threads = 0;              // 0: the config's
  int record = 16;                  // segments recorded from the real env
  std::vector<int> learners = {1};  // group sizes (cluster.learners), each run at every actor count
  bool json = false;
};

struct BenchGroupFlags {
  std::string config = "configs/default.json";
  std::vector<int> learners = {2, 4};
  int ops = 500;
  bool json = false;
};

struct BenchTrainFlags {
  std::string config = "configs/default.json";
  int actors = 0;  // 0: one per core
  int envs = 0;
  int64_t updates = 20;
  int rounds = 2;
  std::string baseline_exe, candidate_exe;  // empty: this program
  std::string baseline_physics = "legacy";  // "legacy" or "config"
  std::string candidate_physics = "config";
  double timeout_s = 900.0;
  bool json = false;
};

// Each returns the process exit code (0: measured); ConfigError on a bad flag.
int RunBenchCluster(const BenchFlags& f);
int RunBenchFlow(const BenchFlowFlags& f);
int RunBenchScale(const BenchScaleFlags& f);
int RunBenchGroup(const BenchGroupFlags& f);
int RunBenchTrain(const BenchTrainFlags& f);

}  // namespace perch
