#include "bench/cluster_bench.h"

#include <signal.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "actor/actor.h"
#include "actor/process.h"
#include "actor/role_setup.h"
#include "common/config_file.h"
#include "common/stop_signal.h"
#include "experiment/experiment.h"
#include "learner/service/checkpoint.h"
#include "learner/service/learner.h"
#include "learner/service/learner_setup.h"
#include "learner/service/run_summary.h"
#include "policy/policy.h"
#include "policy/rollout.h"
#include "protocol/config_files.h"
#include "protocol/security.h"

namespace perch {
namespace {

// ---- cluster runs for the benchmarks ----

// utime + stime of a live (or not yet reaped) process, in seconds (/proc/PID/stat fields 14, 15).
double ProcessCpuSeconds(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string stat((std::istreambuf_iterator<char>(in)), {});
  const size_t close = stat.rfind(')');
  if (close == std::string::npos) return 0.0;
  std::istringstream rest(stat.substr(close + 2));
  std::string field;
  double utime = 0, stime = 0;
  for (int i = 3; i <= 15 && rest >> field; ++i) {
    if (i == 14) utime = std::stod(field);
    if (i == 15) stime = std::stod(field);
  }
  return (utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

double ThreadCpuSeconds() {
  timespec ts{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

std::vector<Json> ReadMetricsRows(const std::string& run_dir) {
  std::ifstream in(run_dir + "/metrics.jsonl");
  std::vector<Json> rows;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) rows.push_back(Json::parse(line));
  }
  return rows;
}

struct ClusterRunOptions {
  std::string exe;  // the perch program run as learner and actors
  std::string config;
  int actors = 2;
  int envs = 4;
  double seconds = 0.0;     // stop after this long (0: no limit)
  int64_t max_updates = 0;  // the learner stops after this many updates (0: no limit)
  double timeout_s = 900.0;
  std::string dir;                         // run dir and logs go here
  int rollout_port = 0, weights_port = 0;  // 0: free ports picked here
  bool self_cpu = false;  // count this process's CPU as actors' (bench scale's in-process actors)
  // A group of learners (the config's cluster.learners): rank r binds these ports (rank 0: the
  // two above); actor i goes to learner i % learners. Empty: picked here.
  int learners = 1;
  std::vector<int> rollout_ports, weights_ports;
};

// One learner + actors on loopback. CPU time of every process is sampled whenever an update lands,
// so that samples and CPU are measured over the same steady-state window: from the first update
// (start-up and the first batch excluded) to the last.
// CPU is read once per poll, so several updates that land between two polls share a reading;
// the window therefore starts at the last update of the first poll that saw any (`first`), never
// at an update whose CPU reading was taken later than its metrics row.
struct ClusterRun {
  std::vector<Json> rows;                     // metrics.jsonl
  std::vector<double> cpu_at_update;          // [update] CPU s of the learner and all actors
  std::vector<double> learner_cpu_at_update;  // [update] CPU s of the learner
  std::vector<int> poll_of_update;            // [update] the poll that first saw it
  double wall_s = 0.0;

  size_t First() const {
    size_t f = 0;
    while (f + 1 < rows.size() && poll_of_update[f + 1] == poll_of_update[0]) ++f;
    return f;
  }
  bool ok() const { return rows.size() >= 3 && First() + 2 <= rows.size() - 1; }
  double Samples() const {
    return rows.back()["samples"].get<double>() - rows[First()]["samples"].get<double>();
  }
  double Seconds() const {
    return rows.back()["time_s"].get<double>() - rows[First()]["time_s"].get<double>();
  }
  double Cpu() const { return cpu_at_update[rows.size() - 1] - cpu_at_update[First()]; }
  double LearnerCpu() const {
    return learner_cpu_at_update[rows.size() - 1] - learner_cpu_at_update[First()];
  }
};

ClusterRun RunCluster(const ClusterRunOptions& o) {
  // Rank 0's run dir: its metrics count the whole group's samples.
  const std::string run_dir = o.dir + "/run";
  EnsureLocalKeys(LoadExperimentConfig(o.config).cluster, o.dir + "/keys");
  const int k = std::max(1, o.learners);
  std::vector<int> rps = o.rollout_ports, wps = o.weights_ports;
  if (static_cast<int>(rps.size()) != k || static_cast<int>(wps.size()) != k) {
    rps.assign(k, 0);
    wps.assign(k, 0);
    for (int r = 0; r < k; ++r) {
      rps[r] = r == 0 && o.rollout_port > 0 ? o.rollout_port : PickFreePort();
      wps[r] = r == 0 && o.weights_port > 0 ? o.weights_port : PickFreePort();
    }
  }
  const double t0 = MonotonicSeconds();
  std::vector<pid_t> learners;
  for (int r = 0; r < k; ++r) {
    std::vector<std::string> largv = {o.exe,
                                      "learner",
                                      "--config",
                                      o.config,
                                      "--run-dir",
                                      r == 0 ? run_dir : run_dir + "-rank" + std::to_string(r),
                                      "--rollout-bind",
                                      "tcp://127.0.0.1:" + std::to_string(rps[r]),
                                      "--weights-bind",
                                      "tcp://127.0.0.1:" + std::to_string(wps[r]),
                                      "--metrics-port",
                                      std::to_string(PickFreePort())};
    if (k > 1) {
      largv.push_back("--rank");
      largv.push_back(std::to_string(r));
    }
    if (o.max_updates > 0) {
      largv.push_back("--max-updates");
      largv.push_back(std::to_string(o.max_updates));
    }
    learners.push_back(Spawn(
        largv, o.dir + (r == 0 ? "/learner.log" : "/learner-rank" + std::to_string(r) + ".log")));
  }
  pid_t learner = learners[0];
  std::vector<pid_t> pids;
  for (int i = 0; i < o.actors; ++i) {
    pids.push_back(Spawn(
        {o.exe, "actor", "--config", o.config, "--learner-host", "127.0.0.1", "--rollout-port",
         std::to_string(rps[i % k]), "--weights-port", std::to_string(wps[i % k]), "--actor-id",
         std::to_string(i), "--envs", std::to_string(o.envs)},
        o.dir + "/actor-" + std::to_string(i) + ".log"));
  }
  ClusterRun r;
  size_t seen = 0;
  int polls = 0;
  while (!StopFlag().load()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    std::ifstream mf(run_dir + "/metrics.jsonl");
    size_t lines = 0;
    for (std::string line; std::getline(mf, line);) lines += !line.empty();
    if (lines > seen) {
      // An exited learner is not reaped yet, so its /proc entry still holds its CPU time.
      double lcpu = 0.0;
      for (pid_t l : learners) lcpu += l > 0 ? ProcessCpuSeconds(l) : 0.0;
      double cpu = lcpu;
      for (pid_t p : pids) cpu += ProcessCpuSeconds(p);
      if (o.self_cpu) cpu += ProcessCpuSeconds(::getpid());
      for (; seen < lines; ++seen) {
        r.cpu_at_update.push_back(cpu);
        r.learner_cpu_at_update.push_back(lcpu);
        r.poll_of_update.push_back(polls);
      }
      ++polls;
    }
    const double t = MonotonicSeconds() - t0;
    if (o.max_updates > 0 && seen >= static_cast<size_t>(o.max_updates)) break;
    if ((o.seconds > 0 && t >= o.seconds) || t >= o.timeout_s) break;
    int status = 0;
    if (::waitpid(learner, &status, WNOHANG) == learner) {
      spdlog::warn("bench: learner {} (log {}/learner.log)", DescribeStatus(status), o.dir);
      learner = -1;
      break;
    }
  }
  r.wall_s = MonotonicSeconds() - t0;
  for (pid_t p : pids) ::kill(p, SIGTERM);
  for (pid_t p : pids) Stop(p, 10.0);
  if (learner > 0) Stop(learner, 30.0);
  for (int r = 1; r < k; ++r) Stop(learners[r], 30.0);
  r.rows = ReadMetricsRows(run_dir);
  // Updates that landed after the last poll have no CPU reading: leave them out.
  if (r.rows.size() > r.cpu_at_update.size()) r.rows.resize(r.cpu_at_update.size());
  return r;
}

std::string MakeTempDir() {
  char tmpl[] = "/tmp/perch-bench-XXXXXX";
  const char* dir = ::mkdtemp(tmpl);
  if (dir == nullptr) throw std::runtime_error("mkdtemp failed");
  return dir;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// min, median, max of the repeats: one noisy reading shows as a wide spread.
Json Spread(const std::vector<double>& v) {
  if (v.empty()) return nullptr;
  return Json{{"runs", v},
              {"median", Median(v)},
              {"min", *std::min_element(v.begin(), v.end())},
              {"max", *std::max_element(v.begin(), v.end())}};
}

// ---- perch bench cluster ----

// Env-only baseline: one thread per actor process, each collecting from its envs as an actor does
// (RolloutCollector with the learner's initial policy: the same network, initial weights and
// observation normalisation, sampled actions), without sockets or a learner. The env's cost
// depends on the actions (falls, contacts, resets): random N(0, sigma) actions made a step about
// 20% cheaper than the initial policy's (docs/cluster.md), so they would not be the same work.
// Returns samples per wall second; *per_cpu_s gets samples per CPU second of the stepping threads.
double EnvOnlySamplesPerS(const ExperimentConfig& cfg, int threads, int envs, double seconds,
                          double* per_cpu_s) {
  const ActorSetup setup = MakeActorSetup(cfg);
  std::vector<uint64_t> steps(threads, 0);
  std::vector<double> cpu(threads, 0.0);
  std::vector<std::thread> pool;
  const double t0 = MonotonicSeconds();
  for (int k = 0; k < threads; ++k) {
    pool.emplace_back([&, k] {
      PolicyRunner runner(setup.policy, setup.obs_norm);
      runner.SetWeights(ActorCritic(setup.policy, setup.seed).params(), runner.normalizer().stats(),
                        1);
      std::vector<std::unique_ptr<Env>> es;
      std::vector<std::unique_ptr<RolloutCollector>> collectors;
      Rng rng(cfg.seed + k);
      for (int i = 0; i < envs; ++i) {
        es.push_back(setup.make_env());
        es.back()->Seed(rng.NextU64());
        collectors.push_back(std::make_unique<RolloutCollector>(es.back().get(), i));
      }
      Rollout rollout;
      EpisodeStats stats;
      const double c0 = ThreadCpuSeconds();
      while (MonotonicSeconds() - t0 < seconds) {
        for (auto& c : collectors) {
          c->Collect(&runner, rng, setup.cluster.segment_steps, &rollout, &stats);
          steps[k] += rollout.size();
        }
      }
      cpu[k] = ThreadCpuSeconds() - c0;
    });
  }
  for (auto& t : pool) t.join();
  const double dt = MonotonicSeconds() - t0;
  uint64_t total = 0;
  double total_cpu = 0.0;
  for (int k = 0; k < threads; ++k) {
    total += steps[k];
    total_cpu += cpu[k];
  }
  *per_cpu_s = total_cpu > 0 ? total / total_cpu : 0.0;
  return total / dt;
}

int RunBenchClusterImpl(const BenchFlags& f) {
  LogToStderr("bench");
  InstallStopHandlers();
  if (f.repeats < 1) throw ConfigError("--repeats: must be >= 1");
  const ExperimentConfig cfg = LoadExperimentConfig(f.config);
  const int cores = std::max(1u, std::thread::hardware_concurrency());
  const int actors = f.actors > 0 ? f.actors : cores;
  const int envs = f.envs > 0 ? f.envs : cfg.cluster.envs_per_actor;
  // Env-only runs bracket every cluster run and each cluster run is compared with the mean of its
  // two neighbours, so that a change in the machine's load (other jobs on shared cores) biases
  // neither side; the repeats show the spread.
  std::vector<double> env_sps, env_cpu;
  auto env_run = [&] {
    double per_cpu = 0.0;
    env_sps.push_back(EnvOnlySamplesPerS(cfg, actors, envs, f.env_seconds, &per_cpu));
    env_cpu.push_back(per_cpu);
    spdlog::info("bench cluster: env only {:.0f} samples/s ({:.0f} per CPU s)", env_sps.back(),
                 per_cpu);
  };
  spdlog::info(
      "bench cluster: {} repeats of env only ({} threads x {} envs, {:.0f} s) and "
      "cluster (learner + {} actors, {:.0f} s)",
      f.repeats, actors, envs, f.env_seconds, actors, f.cluster_seconds);
  // The cluster's actors should do the env-only threads' work: by default the learner runs every
  // PPO epoch but with a learning rate of 1e-12, so the policy stays the initial one. A policy
  // that learns changes what the humanoid does, and with it the cost of a step, within seconds.
  std::string cluster_config = f.config;
  if (!f.train_policy) {
    Json j = LoadComposedConfig(f.config);
    j["ppo"]["learning_rate"] = 1e-12;
    cluster_config = MakeTempDir() + "/frozen_policy.json";
    SaveJsonFileAtomic(cluster_config, j);
  }
  env_run();
  std::vector<double> ratio, ratio_cpu, cluster_sps, cluster_cpu, learner_share;
  Json last;
  int updates = 0;
  for (int k = 0; k < f.repeats && !StopFlag().load(); ++k) {
    ClusterRunOptions o;
    o.exe = SelfExe();
    o.config = cluster_config;
    o.actors = actors;
    o.envs = envs;
    o.seconds = f.cluster_seconds;
    o.dir = MakeTempDir();
    const ClusterRun run = RunCluster(o);
    env_run();
    updates += static_cast<int>(run.rows.size());
    if (!run.ok()) {
      spdlog::warn("bench cluster: repeat {}: {} updates in {:.0f} s (logs in {})", k,
                   run.rows.size(), f.cluster_seconds, o.dir);
      continue;
    }
    const double sps = run.Seconds() > 0 ? run.Samples() / run.Seconds() : 0.0;
    const double per_cpu = run.Cpu() > 0 ? run.Samples() / run.Cpu() : 0.0;
    const double env_mean = 0.5 * (env_sps[k] + env_sps[k + 1]);
    const double env_cpu_mean = 0.5 * (env_cpu[k] + env_cpu[k + 1]);
    cluster_sps.push_back(sps);
    cluster_cpu.push_back(per_cpu);
    ratio.push_back(env_mean > 0 ? sps / env_mean : 0.0);
    ratio_cpu.push_back(env_cpu_mean > 0 ? per_cpu / env_cpu_mean : 0.0);
    learner_share.push_back(run.Cpu() > 0 ? run.LearnerCpu() / run.Cpu() : 0.0);
    last = run.rows.back();
    spdlog::info(
        "bench cluster: repeat {}: cluster {:.0f} samples/s, ratio {:.3f} (per CPU s {:.3f}), "
        "learner {:.1f}% of the CPU",
        k, sps, ratio.back(), ratio_cpu.back(), 100.0 * learner_share.back());
  }
  Json out{{"env_samples_per_s", Median(env_sps)},
           {"env_samples_per_cpu_s", Median(env_cpu)},
           {"actors", actors},
           {"envs_per_actor", envs},
           {"cores", cores},
           {"env_backend", cfg.env_backend},
           {"repeats", f.repeats},
           {"updates", updates},
           {"env_seconds", f.env_seconds},
           {"cluster_seconds", f.cluster_seconds},
           {"policy", f.train_policy ? "learning" : "frozen (learning_rate 1e-12)"},
           {"config", f.config}};
  const bool ok = !ratio.empty();
  if (ok) {
    out["cluster_samples_per_s"] = Median(cluster_sps);
    out["cluster_samples_per_cpu_s"] = Median(cluster_cpu);
    out["ratio_cluster_to_env"] = Median(ratio);
    out["ratio_cluster_to_env_per_cpu_s"] = Median(ratio_cpu);
    out["ratio_cluster_to_env_spread"] = Spread(ratio);
    out["ratio_cluster_to_env_per_cpu_s_spread"] = Spread(ratio_cpu);
    out["learner_cpu_share"] = Spread(learner_share);
    out["env_samples_per_s_runs"] = env_sps;
    out["wire_bytes_per_sample"] = last["wire_bytes_per_sample"];
    out["policy_lag_mean"] = last["policy_lag_mean"];
    out["dropped_stale"] = last["dropped_stale"];
  } else {
    out["cluster_samples_per_s"] = nullptr;
    out["error"] = "fewer than 3 updates per cluster run in " + std::to_string(f.cluster_seconds) +
                   " s; raise --cluster-seconds";
  }
  std::cout << (f.json ? out.dump() : out.dump(2)) << std::endl;
  return ok ? 0 : 1;
}

// ---- perch bench flow ----

// Flow control (issue 20): learner + N actor processes, with the config's credit and with none,
// on an env whose actors outrun the learner (the mock env by default). Per run, over the window
// from the first update to the last: the learner's samples/s, the share of segments dropped as
// stale, and the CPU the actors and the learner used (cores = CPU seconds per wall second).

int RunBenchFlowImpl(const BenchFlowFlags& f) {
  LogToStderr("bench");
  InstallStopHandlers();
  const Json base = LoadComposedConfig(f.config);
  const double slack = LoadExperimentConfig(f.config).cluster.credit_slack;
  const double slack_on = slack > 0 ? slack : 1.0;  // a config with credit off: the default
  Json runs = Json::array();
  bool ok = true;
  for (int n : f.actors) {
    if (n < 1) throw ConfigError("--actors: counts must be >= 1");
    for (const bool credit : {true, false}) {
      if (StopFlag().load()) break;
      Json j = base;
      j["cluster"]["credit_slack"] = credit ? slack_on : 0.0;
      const std::string dir = MakeTempDir();
      const std::string cfg = dir + "/config.json";
      SaveJsonFileAtomic(cfg, j);
      ClusterRunOptions o;
      o.exe = SelfExe();
      o.config = cfg;
      o.actors = n;
      o.envs = LoadExperimentConfig(cfg).cluster.envs_per_actor;
      o.seconds = f.seconds;
      o.dir = dir;
      const ClusterRun run = RunCluster(o);
      Json r{{"actors", n}, {"credit", credit}, {"credit_slack", credit ? slack_on : 0.0}};
      if (!run.ok()) {
        r["error"] = "fewer than 3 updates (logs in " + dir + ")";
        ok = false;
        runs.push_back(r);
        continue;
      }
      const Json& a = run.rows[run.First()];
      const Json& b = run.rows.back();
      const double secs = run.Seconds();
      const double stale = b["dropped_stale"].get<double>() - a["dropped_stale"].get<double>();
      const double segs = b["segments"].get<double>() - a["segments"].get<double>();
      r["learner_samples_per_s"] = run.Samples() / secs;
      r["updates"] = static_cast<int>(run.rows.size());
      r["segments_accepted"] = segs;
      r["segments_stale"] = stale;
      r["drop_share"] = segs + stale > 0 ? stale / (segs + stale) : 0.0;
      r["actor_cpu_cores"] = (run.Cpu() - run.LearnerCpu()) / secs;
      r["learner_cpu_cores"] = run.LearnerCpu() / secs;
      r["actor_cpu_s_per_1k_samples"] = 1e3 * (run.Cpu() - run.LearnerCpu()) / run.Samples();
      r["policy_lag_mean"] = b["policy_lag_mean"];
      r["credit_segments_last"] = b.value("credit_segments", 0);
      spdlog::info(
          "bench flow: {} actors, credit {}: {:.0f} samples/s, {:.1f}% stale, actors {:.2f} cores, "
          "learner {:.2f}",
          n, credit ? "on" : "off", r["learner_samples_per_s"].get<double>(),
          100 * r["drop_share"].get<double>(), r["actor_cpu_cores"].get<double>(),
          r["learner_cpu_cores"].get<double>());
      runs.push_back(r);
    }
  }
  const Json out{{"bench", "flow"},
                 {"config", f.config},
                 {"seconds", f.seconds},
                 {"cores", static_cast<int>(std::max(1u, std::thread::hardware_concurrency()))},
                 {"runs", runs}};
  std::cout << (f.json ? out.dump() : out.dump(2)) << std::endl;
  return ok ? 0 : 1;
}

// ---- perch bench scale ----

// One real learner process (the config's task and PPO) fed by N synthetic actors over loopback TCP:
// ActorService objects in this process that replay walk segments recorded from the real env at
// the start (restamped with their current weights version) at --rate samples/s each, one actor
// core's worth by default (measured here, env only). Hello, heartbeats, credit and weights are the
// real actor's, so the learner sees N members: N rollout connections, N weights subscribers.

std::vector<RecordedSegment> RecordSegments(const ExperimentConfig& cfg, int count) {
  const ActorSetup setup = MakeActorSetup(cfg);
  PolicyRunner runner(setup.policy, setup.obs_norm);
  runner.SetWeights(ActorCritic(setup.policy, setup.seed).params(), runner.normalizer().stats(), 0);
  std::vector<std::unique_ptr<Env>> envs;
  std::vector<std::unique_ptr<RolloutCollector>> collectors;
  Rng rng(cfg.seed + 17);
  const int streams = std::max(1, std::min(count, setup.cluster.envs_per_actor));
  for (int i = 0; i < streams; ++i) {
    envs.push_back(setup.make_env());
    envs.back()->Seed(rng.NextU64());
    collectors.push_back(std::make_unique<RolloutCollector>(envs.back().get(), i));
  }
  std::vector<RecordedSegment> out(count);
  for (int k = 0; k < count; ++k) {
    collectors[k % streams]->Collect(&runner, rng, setup.cluster.segment_steps, &out[k].rollout,
                                     &out[k].episodes);
  }
  return out;
}

int RunBenchScaleImpl(const BenchScaleFlags& f) {
  LogToStderr("bench");
  InstallStopHandlers();
  if (f.record < 1) throw ConfigError("--record: must be >= 1");
  if (!(f.rate >= 0 && std::isfinite(f.rate))) throw ConfigError("--rate: must be >= 0");
  if (!(f.seconds > 0)) throw ConfigError("--seconds: must be > 0");
  Json base = LoadComposedConfig(f.config);
  if (f.ppo_threads > 0) base["ppo"]["threads"] = f.ppo_threads;
  const ExperimentConfig cfg = ExperimentConfigFromJson(base, f.config);
  const int envs = f.envs > 0 ? f.envs : cfg.cluster.envs_per_actor;
  double rate = f.rate;
  if (rate == 0) {
    double per_cpu = 0;
    rate = EnvOnlySamplesPerS(cfg, 1, envs, 3.0, &per_cpu);
    spdlog::info("bench scale: one actor core steps {:.0f} samples/s ({:.0f} per CPU second)", rate,
                 per_cpu);
  }
  spdlog::info("bench scale: recording {} segments of the real env", f.record);
  const std::vector<RecordedSegment> recorded = RecordSegments(cfg, f.record);
  const ActorSetup actor_setup = MakeActorSetup(cfg);
  EnvSpec spec = actor_setup.make_env()->spec();
  for (int k : f.learners) {
    if (k < 1 || k > 64) throw ConfigError("--learners: group sizes must be in 1..64");
  }
  Json runs = Json::array();
  bool ok = true;
  for (int n : f.actors) {
    if (n < 1 || n > 4096) throw ConfigError("--actors: counts must be in 1..4096");
    for (int k : f.learners) {
      if (StopFlag().load()) break;
      const std::string dir = MakeTempDir();
      const std::string cfg_path = dir + "/config.json";
      Json run_cfg = base;
      run_cfg["cluster"]["learners"] = k;
      if (k > 1)
        run_cfg["cluster"]["group_address"] = "tcp://127.0.0.1:" + std::to_string(PickFreePort());
      SaveJsonFileAtomic(cfg_path, run_cfg);
      // The synthetic actors are members too: the same keys as the learners.
      EnsureLocalKeys(cfg.cluster, dir + "/keys");
      ClusterRunOptions o;
      o.exe = SelfExe();
      o.config = cfg_path;
      o.actors = 0;
      o.seconds = f.seconds;
      o.dir = dir;
      o.learners = k;
      for (int r = 0; r < k; ++r) {
        o.rollout_ports.push_back(PickFreePort());
        o.weights_ports.push_back(PickFreePort());
      }
      o.self_cpu = true;
      zmq::context_t ctx(2);
      std::atomic<bool> stop{false};
      std::vector<std::unique_ptr<ActorService>> actors;
      std::vector<std::thread> threads;
      for (int i = 0; i < n; ++i) {
        ActorOptions ao;
        // Round-robin over the group: each learner owns 1/k of the actors.
        ao.rollout_connect = "tcp://127.0.0.1:" + std::to_string(o.rollout_ports[i % k]);
        ao.weights_connect = "tcp://127.0.0.1:" + std::to_string(o.weights_ports[i % k]);
        ao.actor_id = static_cast<uint32_t>(i);
        ao.num_envs = envs;
        ao.stop = &stop;
        ao.replay = &recorded;
        ao.replay_samples_per_s = rate;
        ao.replay_spec = spec;
        actors.push_back(std::make_unique<ActorService>(ctx, actor_setup, ao));
      }
      for (auto& a : actors) threads.emplace_back([&a] { a->Run(); });
      const double cpu0 = ProcessCpuSeconds(::getpid());
      const ClusterRun run = RunCluster(o);
      stop = true;
      for (auto& t : threads) t.join();
      Json r{{"actors", n}, {"learners", k}, {"offered_samples_per_s", n * rate}};
      if (!run.ok()) {
        r["error"] = "fewer than 3 updates (logs in " + dir + ")";
        ok = false;
        runs.push_back(r);
        continue;
      }
      ActorCounters sum;
      for (const auto& a : actors) {
        const ActorCounters& c = a->counters();
        sum.segments_sent += c.segments_sent;
        sum.bytes_sent += c.bytes_sent;
        sum.weights_messages += c.weights_messages;
        sum.weights_bytes += c.weights_bytes;
        sum.credit_waits += c.credit_waits;
      }
      const Json& a = run.rows[run.First()];
      const Json& b = run.rows.back();
      const double secs = run.Seconds();
      const double stale = b["dropped_stale"].get<double>() - a["dropped_stale"].get<double>();
      const double segs = b["segments"].get<double>() - a["segments"].get<double>();
      const double wall = run.wall_s;
      r["learner_samples_per_s"] = run.Samples() / secs;
      r["learner_updates_per_s"] = (run.rows.size() - 1 - run.First()) / secs;
      r["segments_per_s"] = (segs + stale) / secs;
      r["drop_share"] = segs + stale > 0 ? stale / (segs + stale) : 0.0;
      r["learner_cpu_cores"] = run.LearnerCpu() / secs;
      r["synthetic_actor_cpu_cores"] = (ProcessCpuSeconds(::getpid()) - cpu0) / wall;
      // Whole-run counters of the synthetic actors (start-up included), per wall second.
      r["rollout_bytes_per_s"] = sum.bytes_sent / wall;
      r["rollout_messages_per_s"] = sum.segments_sent / wall;
      r["weights_bytes_per_s"] = sum.weights_bytes / wall;
      r["weights_messages_per_s"] = sum.weights_messages / wall;
      r["wire_bytes_per_sample"] = b["wire_bytes_per_sample"];
      r["policy_lag_mean"] = b["policy_lag_mean"];
      r["credit_waits"] = sum.credit_waits;
      r["actor_cores_fed"] =
          run.Samples() / secs / rate;  // how many actor cores the learner keeps up with
      if (k > 1 && a.contains("group") && b.contains("group")) {
        // Rank 0's side of the group: it receives every member's part and sends every reply.
        const Json& ga = a["group"];
        const Json& gb = b["group"];
        r["group_wait_share"] = (gb["wait_s"].get<double>() - ga["wait_s"].get<double>()) / secs;
        r["group_bytes_per_s"] =
            (gb["bytes_sent"].get<double>() + gb["bytes_received"].get<double>() -
             ga["bytes_sent"].get<double>() - ga["bytes_received"].get<double>()) /
            secs;
        r["group_operations_per_update"] =
            (gb["operations"].get<double>() - ga["operations"].get<double>()) /
            std::max<double>(1.0, run.rows.size() - 1 - run.First());
      }
      spdlog::info(
          "bench scale: {} actors, {} learner(s) (offered {:.0f}/s): learner {:.0f} samples/s "
          "({:.2f} cores), {:.1f}% stale, in {:.1f} MB/s, weights out {:.1f} MB/s",
          n, k, n * rate, r["learner_samples_per_s"].get<double>(),
          r["learner_cpu_cores"].get<double>(), 100 * r["drop_share"].get<double>(),
          r["rollout_bytes_per_s"].get<double>() / 1e6,
          r["weights_bytes_per_s"].get<double>() / 1e6);
      runs.push_back(r);
    }
  }
  const Json out{{"bench", "scale"},
                 {"config", f.config},
                 {"seconds", f.seconds},
                 {"rate_per_actor", rate},
                 {"envs_per_actor", envs},
                 {"ppo_threads", cfg.ppo.threads},
                 {"steps_per_update", cfg.ppo.steps_per_update},
                 {"cores", static_cast<int>(std::max(1u, std::thread::hardware_concurrency()))},
                 {"runs", runs}};
  std::cout << (f.json ? out.dump() : out.dump(2)) << std::endl;
  return ok ? 0 : 1;
}

// ---- perch bench group ----

// The learner group's collective on its own (issue 20): k members (threads, each with its own
// ZeroMQ context and TCP socket on loopback, as separate processes would have) all-reduce the
// walk policy's gradient (its parameters + 6 loss terms), `ops` times. Reported per operation, with
// the root's local summation of the same buffers as the baseline, and per PPO update (one
// operation per minibatch and epoch, plus 2 all-gathers).

int RunBenchGroupImpl(const BenchGroupFlags& f) {
  LogToStderr("bench");
  InstallStopHandlers();
  if (f.ops < 10) throw ConfigError("--ops: must be >= 10");
  const ExperimentConfig cfg = LoadExperimentConfig(f.config);
  const LearnerSetup ls = MakeLearnerSetup(cfg);
  const int n = ActorCritic(ls.policy, ls.seed).num_params() + 6;
  const int ops_per_update = ls.ppo.num_epochs * ls.ppo.num_minibatches + 2;
  Json runs = Json::array();
  for (int k : f.learners) {
    if (k < 2 || k > 64) throw ConfigError("--learners: group sizes must be in 2..64");
    if (StopFlag().load()) break;
    const std::string address = "tcp://127.0.0.1:" + std::to_string(PickFreePort());
    std::vector<double> seconds(k, 0.0);
    std::vector<std::string> errors(k);
    std::vector<GroupStats> stats(k);
    std::vector<std::thread> threads;
    for (int r = 0; r < k; ++r) {
      threads.emplace_back([&, r] {
        try {
          zmq::context_t ctx(1);
          GroupOptions o;
          o.rank = r;
          o.size = k;
          o.address = address;
          o.timeout_s = 60;
          o.join_timeout_s = 60;
          o.fingerprint = "bench";
          o.stop = &StopFlag();
          ZmqGroup g(ctx, o);
          std::vector<float> x(n);
          for (int i = 0; i < n; ++i) x[i] = 1e-3f * static_cast<float>((i * 7 + r) % 101);
          g.AllReduceSum(x.data(), n);  // warm-up: connections up, buffers allocated
          const double t0 = MonotonicSeconds();
          for (int i = 0; i < f.ops; ++i) g.AllReduceSum(x.data(), n);
          seconds[r] = MonotonicSeconds() - t0;
          stats[r] = g.stats();
        } catch (const std::exception& e) {
          errors[r] = e.what();
        }
      });
    }
    for (auto& t : threads) t.join();
    for (const std::string& e : errors) {
      if (!e.empty()) throw std::runtime_error("bench group: " + e);
    }
    // Baseline: the root's own arithmetic on the same buffers (k - 1 additions of n floats).
    std::vector<std::vector<float>> parts(k, std::vector<float>(n, 0.5f));
    const double b0 = MonotonicSeconds();
    int local_ops = 0;
    while (MonotonicSeconds() - b0 < 0.2) {
      for (int r = 1; r < k; ++r) {
        for (int i = 0; i < n; ++i) parts[0][i] += parts[r][i];
      }
      ++local_ops;
    }
    const double local_us = 1e6 * (MonotonicSeconds() - b0) / local_ops;
    const double us = 1e6 * seconds[0] / f.ops;
    Json r{{"learners", k},
           {"floats", n},
           {"bytes_per_member", 4 * n},
           {"us_per_all_reduce", us},
           {"local_sum_us", local_us},
           {"ratio_to_local_sum", local_us > 0 ? us / local_us : 0.0},
           {"root_bytes_per_s", (stats[0].bytes_sent + stats[0].bytes_received) / seconds[0]},
           {"ops_per_update", ops_per_update},
           {"ms_per_update", 1e-3 * us * ops_per_update}};
    spdlog::info(
        "bench group: {} members, {} floats: {:.0f} us per all-reduce ({:.1f}x the root's own "
        "sum), {:.1f} ms per PPO update ({} operations)",
        k, n, us, r["ratio_to_local_sum"].get<double>(), r["ms_per_update"].get<double>(),
        ops_per_update);
    runs.push_back(r);
  }
  const Json out{{"bench", "group"},
                 {"config", f.config},
                 {"ops", f.ops},
                 {"cores", static_cast<int>(std::max(1u, std::thread::hardware_concurrency()))},
                 {"runs", runs}};
  std::cout << (f.json ? out.dump() : out.dump(2)) << std::endl;
  return 0;
}

// ---- perch bench train ----

// The physics before issue 19 (docs/env.md): Bullet's infinite floor bounds, its 4096-entry
// pools, the authors' never-sleeping dynamic chair.
Json LegacyPhysics() {
  return Json{{"floor_half_extent", 0.0}, {"collision_pool_size", 4096}, {"chair_body", "dynamic"}};
}

struct TrainArm {
  std::string name, exe, physics, config_path;
  std::vector<double> samples, seconds, cpu, learner_cpu;  // per run, steady-state window
  std::vector<double> episodes;                            // per run, episodes ended in the window
};

Json ArmJson(const TrainArm& a) {
  double s = 0, t = 0, c = 0, l = 0, e = 0;
  std::vector<double> sps, us;
  for (size_t i = 0; i < a.samples.size(); ++i) {
    s += a.samples[i];
    t += a.seconds[i];
    c += a.cpu[i];
    l += a.learner_cpu[i];
    e += a.episodes[i];
    sps.push_back(a.seconds[i] > 0 ? a.samples[i] / a.seconds[i] : 0.0);
    us.push_back(a.samples[i] > 0 ? 1e6 * a.cpu[i] / a.samples[i] : 0.0);
  }
  return Json{{"exe", a.exe},
              {"physics", a.physics},
              {"config", a.config_path},
              {"samples_per_s", t > 0 ? s / t : 0.0},
              {"cpu_us_per_step", s > 0 ? 1e6 * c / s : 0.0},
              {"learner_cpu_share", c > 0 ? l / c : 0.0},
              {"samples", s},
              // Early in training episodes are short: resets (world rebuilds) weigh more.
              {"mean_episode_steps", e > 0 ? s / e : 0.0},
              {"samples_per_s_runs", sps},
              {"cpu_us_per_step_runs", us}};
}

int RunBenchTrainImpl(const BenchTrainFlags& f) {
  LogToStderr("bench");
  InstallStopHandlers();
  if (f.updates < 3) throw ConfigError("--updates: must be >= 3");
  if (f.rounds < 1) throw ConfigError("--rounds: must be >= 1");
  const Json base = LoadComposedConfig(f.config);
  const ExperimentConfig cfg = ExperimentConfigFromJson(base, f.config);
  const int cores = std::max(1u, std::thread::hardware_concurrency());
  const int actors = f.actors > 0 ? f.actors : cores;
  const int envs = f.envs > 0 ? f.envs : cfg.cluster.envs_per_actor;
  const std::string dir = MakeTempDir();
  auto make_arm = [&](const std::string& name, const std::string& exe, const std::string& physics,
                      const std::string& flag) {
    TrainArm a;
    a.name = name;
    a.exe = exe.empty() ? SelfExe() : exe;
    a.physics = physics;
    Json j = base;
    if (physics == "legacy") {
      if (!j.contains("env")) j["env"] = Json::object();
      Json& p = j["env"]["physics"];
      if (p.is_null()) p = Json::object();
      const Json legacy = LegacyPhysics();
      for (const auto& [k, v] : legacy.items()) p[k] = v;
    } else if (physics != "config") {
      throw ConfigError(flag + ": expected \"legacy\" or \"config\", got \"" + physics + "\"");
    }
    a.config_path = dir + "/" + name + ".json";
    if (exe.empty()) ExperimentConfigFromJson(j, a.config_path);  // refuse a bad config early
    SaveJsonFileAtomic(a.config_path, j);
    return a;
  };
  std::vector<TrainArm> arms = {
      make_arm("baseline", f.baseline_exe, f.baseline_physics, "--baseline-physics"),
      make_arm("candidate", f.candidate_exe, f.candidate_physics, "--candidate-physics")};
  spdlog::info(
      "bench train: {} rounds of baseline and candidate, {} updates each, learner + {} "
      "actors x {} envs (logs in {})",
      f.rounds, f.updates, actors, envs, dir);
  std::vector<double> round_ratio, round_cpu_ratio;
  for (int r = 0; r < f.rounds && !StopFlag().load(); ++r) {
    double sps[2] = {0, 0}, us[2] = {0, 0};
    // ABBA order: a drift in the machine's load biases neither arm.
    for (int i = 0; i < 2 && !StopFlag().load(); ++i) {
      const int k = r % 2 == 0 ? i : 1 - i;
      TrainArm& a = arms[k];
      ClusterRunOptions o;
      o.exe = a.exe;
      o.config = a.config_path;
      o.actors = actors;
      o.envs = envs;
      o.max_updates = f.updates;
      o.timeout_s = f.timeout_s;
      o.dir = dir + "/" + a.name + "-" + std::to_string(r);
      ::mkdir(o.dir.c_str(), 0755);
      const ClusterRun run = RunCluster(o);
      if (!run.ok()) {
        throw std::runtime_error("bench train: " + a.name + " run " + std::to_string(r) +
                                 " finished " + std::to_string(run.rows.size()) +
                                 " updates, too few after the first CPU reading (logs in " + o.dir +
                                 "); raise --updates");
      }
      if (!(run.Cpu() > 0.0 && run.Seconds() > 0.0)) {
        throw std::runtime_error("bench train: " + a.name + " run " + std::to_string(r) +
                                 ": no CPU time measured between the first and last update; "
                                 "raise --updates");
      }
      a.samples.push_back(run.Samples());
      a.seconds.push_back(run.Seconds());
      a.cpu.push_back(run.Cpu());
      a.learner_cpu.push_back(run.LearnerCpu());
      double episodes = 0;
      for (size_t u = run.First() + 1; u < run.rows.size(); ++u) {
        episodes += run.rows[u]["episodes"].get<double>();
      }
      a.episodes.push_back(episodes);
      sps[k] = run.Samples() / run.Seconds();
      us[k] = 1e6 * run.Cpu() / run.Samples();
      spdlog::info(
          "bench train: round {} {}: {:.0f} samples/s, {:.1f} CPU us per step, learner "
          "{:.1f}% of the CPU",
          r, a.name, sps[k], us[k], 100.0 * run.LearnerCpu() / run.Cpu());
    }
    round_ratio.push_back(sps[1] / sps[0]);
    round_cpu_ratio.push_back(us[0] / us[1]);
  }
  const Json b = ArmJson(arms[0]), c = ArmJson(arms[1]);
  const Json out{
      {"config", f.config},
      {"updates", f.updates},
      {"rounds", f.rounds},
      {"actors", actors},
      {"envs_per_actor", envs},
      {"steps_per_update", cfg.ppo.steps_per_update},
      {"baseline", b},
      {"candidate", c},
      {"legacy_physics", LegacyPhysics()},
      {"ratio_samples_per_s", c["samples_per_s"].get<double>() / b["samples_per_s"].get<double>()},
      {"ratio_cpu_per_step",
       b["cpu_us_per_step"].get<double>() / c["cpu_us_per_step"].get<double>()},
      {"ratio_samples_per_s_rounds", Spread(round_ratio)},
      {"ratio_cpu_per_step_rounds", Spread(round_cpu_ratio)},
      {"timing",
       "steady state (first update to last) of each run; CPU = learner + actors from "
       "/proc; ratio_cpu_per_step = baseline / candidate CPU per control step (> 1: "
       "candidate cheaper)"},
      {"logs", dir}};
  std::cout << (f.json ? out.dump() : out.dump(2)) << std::endl;
  return 0;
}

}  // namespace

int RunBenchCluster(const BenchFlags& f) { return RunBenchClusterImpl(f); }
int RunBenchFlow(const BenchFlowFlags& f) { return RunBenchFlowImpl(f); }
int RunBenchScale(const BenchScaleFlags& f) { return RunBenchScaleImpl(f); }
int RunBenchGroup(const BenchGroupFlags& f) { return RunBenchGroupImpl(f); }
int RunBenchTrain(const BenchTrainFlags& f) { return RunBenchTrainImpl(f); }

}  // namespace perch
