// The cluster's subcommands: `perch learner`, `perch actor`, `perch train` (local launch of both)
// and `perch bench cluster`. Command lines are used verbatim by k8s/*.yaml and scripts/train.sh.
#include <signal.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "actor/actor.h"
#include "actor/experiment.h"
#include "actor/process.h"
#include "actor/role_setup.h"
#include "app/commands.h"
#include "learner/service/checkpoint.h"
#include "learner/service/learner.h"
#include "learner/service/run_summary.h"

namespace perch {
namespace {

std::atomic<bool> g_stop{false};

void OnStopSignal(int) { g_stop.store(true); }

void InstallStopHandlers() {
  struct sigaction sa {};
  sa.sa_handler = OnStopSignal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: blocking calls return so loops see the flag
  ::sigaction(SIGINT, &sa, nullptr);
  ::sigaction(SIGTERM, &sa, nullptr);
  ::signal(SIGPIPE, SIG_IGN);
}

// Logs go to stderr; stdout is for --json results.
void LogToStderr(const std::string& name) {
  auto logger = spdlog::stderr_color_mt(name);
  spdlog::set_default_logger(logger);
  spdlog::set_pattern("[%H:%M:%S.%e] [" + name + "] %v");
}

uint32_t HostnameHash() {
  char host[256] = {0};
  ::gethostname(host, sizeof(host) - 1);
  uint32_t h = 2166136261u;  // FNV-1a: stable across restarts of the same pod
  for (const char* p = host; *p; ++p) h = (h ^ static_cast<unsigned char>(*p)) * 16777619u;
  return h & 0x7fffffff;
}

// ---- perch learner ----
struct LearnerFlags {
  std::string config;
  std::string run_dir;
  bool resume = false;
  std::string rollout_bind = "tcp://*:5555";
  std::string weights_bind = "tcp://*:5556";
  int metrics_port = 9100;
  int64_t max_updates = 0;
  bool check_config = false;
};

int RunLearner(const LearnerFlags& f) {
  CheckEndpoint(f.rollout_bind, "--rollout-bind");
  CheckEndpoint(f.weights_bind, "--weights-bind");
  if (f.metrics_port != 0) CheckPort(f.metrics_port, "--metrics-port");
  if (f.max_updates < 0) throw ConfigError("--max-updates: must be >= 0");
  if (f.run_dir.empty()) throw ConfigError("--run-dir: required");
  const ExperimentConfig cfg = LoadExperimentConfig(f.config);
  const LearnerSetup setup = MakeLearnerSetup(cfg);
  if (f.check_config) {
    std::cerr << "perch learner: config " << f.config << " and flags OK\n";
    return 0;
  }
  LogToStderr("learner");
  InstallStopHandlers();
  LearnerOptions o;
  o.rollout_bind = f.rollout_bind;
  o.weights_bind = f.weights_bind;
  o.metrics_port = f.metrics_port;
  o.run_dir = f.run_dir;
  o.resume = f.resume;
  o.max_updates = f.max_updates;
  o.stop = &g_stop;
  zmq::context_t ctx(1);
  try {
    LearnerService learner(ctx, setup, o);
    learner.Run();
  } catch (const CheckpointError& e) {
    throw ConfigError(e.what());
  }
  return 0;
}

// ---- perch actor ----
struct ActorFlags {
  std::string config;
  std::string learner_host;
  int rollout_port = 5555;
  int weights_port = 5556;
  std::string rollout_connect;
  std::string weights_connect;
  int64_t actor_id = -1;
  int envs = 0;
  int64_t max_segments = 0;
  bool check_config = false;
};

int RunActor(const ActorFlags& f) {
  CheckPort(f.rollout_port, "--rollout-port");
  CheckPort(f.weights_port, "--weights-port");
  if (f.learner_host.empty() && (f.rollout_connect.empty() || f.weights_connect.empty())) {
    throw ConfigError("--learner-host: required (or both --rollout-connect and --weights-connect)");
  }
  ActorOptions o;
  o.rollout_connect = !f.rollout_connect.empty()
                          ? f.rollout_connect
                          : "tcp://" + f.learner_host + ":" + std::to_string(f.rollout_port);
  o.weights_connect = !f.weights_connect.empty()
                          ? f.weights_connect
                          : "tcp://" + f.learner_host + ":" + std::to_string(f.weights_port);
  CheckEndpoint(o.rollout_connect, "--rollout-connect");
  CheckEndpoint(o.weights_connect, "--weights-connect");
  if (f.actor_id < -1 || f.actor_id > 0x7fffffff) throw ConfigError("--actor-id: out of range");
  if (f.envs < 0) throw ConfigError("--envs: must be >= 1");
  if (f.max_segments < 0) throw ConfigError("--max-segments: must be >= 0");
  const ExperimentConfig cfg = LoadExperimentConfig(f.config);
  const ActorSetup setup = MakeActorSetup(cfg);
  o.actor_id = f.actor_id >= 0 ? static_cast<uint32_t>(f.actor_id) : HostnameHash();
  o.num_envs = f.envs > 0 ? f.envs : cfg.cluster.envs_per_actor;
  o.max_segments = f.max_segments;
  if (f.check_config) {
    std::cerr << "perch actor: config " << f.config << " and flags OK\n";
    return 0;
  }
  LogToStderr("actor " + std::to_string(o.actor_id));
  InstallStopHandlers();
  o.stop = &g_stop;
  zmq::context_t ctx(1);
  ActorService actor(ctx, setup, o);
  actor.Run();
  return 0;
}

// ---- perch train ----
struct TrainFlags {
  std::string config;
  int actors = 2;
  int envs = 0;
  std::string run_dir;
  bool resume = false;
  int64_t max_updates = 0;
  int rollout_port = 5555;
  int weights_port = 5556;
  int metrics_port = 9100;
};

std::vector<std::string> LearnerArgv(const TrainFlags& f, bool resume) {
  std::vector<std::string> a = {
      SelfExe(),        "learner",
      "--config",       f.config,
      "--run-dir",      f.run_dir,
      "--rollout-bind", "tcp://127.0.0.1:" + std::to_string(f.rollout_port),
      "--weights-bind", "tcp://127.0.0.1:" + std::to_string(f.weights_port),
      "--metrics-port", std::to_string(f.metrics_port)};
  if (resume) a.push_back("--resume");
  if (f.max_updates > 0) {
    a.push_back("--max-updates");
    a.push_back(std::to_string(f.max_updates));
  }
  return a;
}

std::vector<std::string> ActorArgv(const TrainFlags& f, int id) {
  std::vector<std::string> a = {SelfExe(),        "actor",
                                "--config",       f.config,
                                "--learner-host", "127.0.0.1",
                                "--rollout-port", std::to_string(f.rollout_port),
                                "--weights-port", std::to_string(f.weights_port),
                                "--actor-id",     std::to_string(id)};
  if (f.envs > 0) {
    a.push_back("--envs");
    a.push_back(std::to_string(f.envs));
  }
  return a;
}

int RunTrain(TrainFlags f) {
  if (f.actors < 1) throw ConfigError("--actors: must be >= 1");
  CheckPort(f.rollout_port, "--rollout-port");
  CheckPort(f.weights_port, "--weights-port");
  CheckPort(f.metrics_port, "--metrics-port");
  const ExperimentConfig cfg = LoadExperimentConfig(f.config);
  if (f.run_dir.empty()) {
    std::string base = f.config.substr(f.config.rfind('/') + 1);
    base = base.substr(0, base.rfind('.'));
    f.run_dir = "runs/" + base;
  }
  // Refuse early (as the learner would) rather than start actors for nothing.
  CheckpointStore store(f.run_dir, cfg.cluster.keep_last, cfg.cluster.milestone_every);
  if (!f.resume && !store.List().empty()) {
    throw ConfigError("--run-dir " + f.run_dir +
                      ": holds checkpoints; pass --resume to continue or choose another --run-dir");
  }
  LogToStderr("train");
  InstallStopHandlers();
  ::mkdir(f.run_dir.c_str(), 0755);
  const std::string logs = f.run_dir + "/logs";
  ::mkdir(logs.c_str(), 0755);
  spdlog::info("train: learner + {} actors on loopback, run dir {}, logs in {}", f.actors,
               f.run_dir, logs);
  pid_t learner = Spawn(LearnerArgv(f, f.resume), "");
  std::vector<pid_t> actors(f.actors, -1);
  std::vector<double> restart_at(f.actors, 0.0);
  std::vector<int> restarts(f.actors, 0);
  for (int i = 0; i < f.actors; ++i) {
    actors[i] = Spawn(ActorArgv(f, i), logs + "/actor-" + std::to_string(i) + ".log");
  }
  int exit_code = 0;
  const double backoff_s = cfg.cluster.restart_backoff_ms / 1000.0;
  while (!g_stop.load()) {
    int status = 0;
    const pid_t pid = ::waitpid(-1, &status, WNOHANG);
    const double now = MonotonicSeconds();
    if (pid == learner) {
      if (WIFEXITED(status) && (WEXITSTATUS(status) == 0 || WEXITSTATUS(status) == 2)) {
        exit_code = WEXITSTATUS(status);
        spdlog::info("train: learner {}; stopping actors", DescribeStatus(status));
        learner = -1;
        break;
      }
      spdlog::error("train: learner {}; restarting it with --resume", DescribeStatus(status));
      std::this_thread::sleep_for(std::chrono::duration<double>(backoff_s));
      learner = Spawn(LearnerArgv(f, true), "");
    } else if (pid > 0) {
      for (int i = 0; i < f.actors; ++i) {
        if (actors[i] != pid) continue;
        spdlog::warn("train: actor {} {}; restarting it", i, DescribeStatus(status));
        actors[i] = -1;
        restart_at[i] = now + backoff_s;
      }
    }
    for (int i = 0; i < f.actors; ++i) {
      if (actors[i] < 0 && now >= restart_at[i]) {
        actors[i] = Spawn(ActorArgv(f, i), logs + "/actor-" + std::to_string(i) + ".log");
        ++restarts[i];
      }
    }
    if (pid <= 0) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  // Ctrl-C / SIGTERM: the learner writes its final checkpoint on SIGTERM.
  if (learner > 0) {
    ::kill(learner, SIGTERM);
    const int st = Stop(learner, 60.0);
    spdlog::info("train: learner {}", DescribeStatus(st));
  }
  for (pid_t a : actors) {
    if (a > 0) ::kill(a, SIGTERM);
  }
  for (pid_t a : actors) {
    if (a > 0) Stop(a, 10.0);
  }
  spdlog::info("train: stopped");
  return exit_code;
}

// ---- perch bench cluster ----
struct BenchFlags {
  std::string config = std::string(PERCH_SOURCE_DIR) + "/configs/default.json";
  int actors = 0;  // 0: one per core
  int envs = 0;
  double env_seconds = 5.0;
  double cluster_seconds = 30.0;
  bool json = false;
};

// utime + stime of a live process, in seconds (/proc/PID/stat fields 14 and 15).
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

// Env-only baseline: one thread per actor, each stepping its envs with actions drawn as the
// untrained policy draws them (mean ~0, sigma = exp(init_log_std), unclipped; the env clips). The
// env's cost depends on the actions (falls, contacts, resets), so uniform actions would not be the
// same work as the cluster's.
// Returns samples per wall second; *per_cpu_s gets samples per CPU second of the stepping threads.
double EnvOnlySamplesPerS(const ExperimentConfig& cfg, int threads, int envs, double seconds,
                          double* per_cpu_s) {
  std::unique_ptr<Env> probe = MakeExperimentEnv(cfg);
  const double sigma = std::exp(ResolvePolicyConfig(cfg, probe->spec()).init_log_std);
  std::vector<uint64_t> steps(threads, 0);
  std::vector<double> cpu(threads, 0.0);
  std::vector<std::thread> pool;
  const double t0 = MonotonicSeconds();
  for (int k = 0; k < threads; ++k) {
    pool.emplace_back([&, k] {
      std::vector<std::unique_ptr<Env>> es;
      for (int i = 0; i < envs; ++i) es.push_back(MakeExperimentEnv(cfg));
      const EnvSpec& spec = es[0]->spec();
      Rng rng(cfg.seed + k);
      std::vector<float> obs(spec.obs_dim), act(spec.act_dim);
      for (auto& e : es) {
        e->Seed(rng.NextU64());
        e->Reset(obs.data());
      }
      const double c0 = ThreadCpuSeconds();
      while (MonotonicSeconds() - t0 < seconds) {
        for (auto& e : es) {
          for (int j = 0; j < spec.act_dim; ++j) {
            act[j] = static_cast<float>(sigma * rng.Normal());
          }
          const StepResult r = e->Step(act.data(), obs.data());
          if (r.terminated || r.truncated) e->Reset(obs.data());
          ++steps[k];
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

int RunBenchCluster(const BenchFlags& f) {
  LogToStderr("bench");
  const ExperimentConfig cfg = LoadExperimentConfig(f.config);
  const int cores = std::max(1u, std::thread::hardware_concurrency());
  const int actors = f.actors > 0 ? f.actors : cores;
  const int envs = f.envs > 0 ? f.envs : cfg.cluster.envs_per_actor;
  // The baseline runs before and after the cluster and is averaged, so that a change in the
  // machine's load during the run (other jobs on shared cores) biases neither side.
  spdlog::info("bench cluster: env only, {} threads x {} envs, {:.0f} s", actors, envs,
               f.env_seconds);
  double env_cpu_before = 0, env_cpu_after = 0;
  const double env_before = EnvOnlySamplesPerS(cfg, actors, envs, f.env_seconds, &env_cpu_before);
  spdlog::info("bench cluster: env only {:.0f} samples/s", env_before);

  char tmpl[] = "/tmp/perch-bench-XXXXXX";
  const char* dir = ::mkdtemp(tmpl);
  if (dir == nullptr) throw std::runtime_error("mkdtemp failed");
  const std::string run_dir = std::string(dir) + "/run";
  const int rp = PickFreePort(), wp = PickFreePort();
  const std::string exe = SelfExe();
  pid_t learner = Spawn(
      {exe, "learner", "--config", f.config, "--run-dir", run_dir, "--rollout-bind",
       "tcp://127.0.0.1:" + std::to_string(rp), "--weights-bind",
       "tcp://127.0.0.1:" + std::to_string(wp), "--metrics-port", std::to_string(PickFreePort())},
      std::string(dir) + "/learner.log");
  std::vector<pid_t> pids;
  for (int i = 0; i < actors; ++i) {
    pids.push_back(
        Spawn({exe, "actor", "--config", f.config, "--learner-host", "127.0.0.1", "--rollout-port",
               std::to_string(rp), "--weights-port", std::to_string(wp), "--actor-id",
               std::to_string(i), "--envs", std::to_string(envs)},
              std::string(dir) + "/actor-" + std::to_string(i) + ".log"));
  }
  spdlog::info("bench cluster: learner + {} actors x {} envs for {:.0f} s (logs in {})", actors,
               envs, f.cluster_seconds, dir);
  // Sample the CPU time of all cluster processes whenever an update lands, so that samples and CPU
  // are measured over the same steady-state window (robust to other load on shared cores).
  std::vector<double> cpu_at_update;  // [update index] summed CPU seconds of learner and actors
  const double t_end = MonotonicSeconds() + f.cluster_seconds;
  size_t seen = 0;
  while (MonotonicSeconds() < t_end) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    std::ifstream mf(run_dir + "/metrics.jsonl");
    size_t lines = 0;
    for (std::string line; std::getline(mf, line);) lines += !line.empty();
    if (lines > seen) {
      double cpu = ProcessCpuSeconds(learner);
      for (pid_t p : pids) cpu += ProcessCpuSeconds(p);
      while (seen < lines) {
        cpu_at_update.push_back(cpu);
        ++seen;
      }
    }
  }
  for (pid_t p : pids) ::kill(p, SIGTERM);
  for (pid_t p : pids) Stop(p, 10.0);
  Stop(learner, 30.0);
  const double env_after = EnvOnlySamplesPerS(cfg, actors, envs, f.env_seconds, &env_cpu_after);
  spdlog::info("bench cluster: env only (after) {:.0f} samples/s", env_after);
  const double env_sps = 0.5 * (env_before + env_after);

  // Steady state: from the first update (start-up and the first batch excluded) to the last.
  std::ifstream in(run_dir + "/metrics.jsonl");
  std::vector<Json> rows;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) rows.push_back(Json::parse(line));
  }
  Json out{{"env_samples_per_s", env_sps},
           {"env_samples_per_s_before", env_before},
           {"env_samples_per_s_after", env_after},
           {"actors", actors},
           {"envs_per_actor", envs},
           {"cores", cores},
           {"env_backend", cfg.env_backend},
           {"updates", rows.size()},
           {"cluster_seconds", f.cluster_seconds},
           {"config", f.config}};
  if (rows.size() >= 3) {
    const Json& a = rows.front();
    const Json& b = rows.back();
    const double dt = b["time_s"].get<double>() - a["time_s"].get<double>();
    const double ds = b["samples"].get<double>() - a["samples"].get<double>();
    const double sps = dt > 0 ? ds / dt : 0.0;
    double lag = 0.0;
    for (const Json& r : rows) lag += r["policy_lag_mean"].get<double>();
    out["cluster_samples_per_s"] = sps;
    if (cpu_at_update.size() >= rows.size()) {
      const double dcpu = cpu_at_update[rows.size() - 1] - cpu_at_update[0];
      const double env_cpu = 0.5 * (env_cpu_before + env_cpu_after);
      const double per_cpu = dcpu > 0 ? ds / dcpu : 0.0;
      out["cluster_samples_per_cpu_s"] = per_cpu;
      out["env_samples_per_cpu_s"] = env_cpu;
      out["ratio_cluster_to_env_per_cpu_s"] = env_cpu > 0 ? per_cpu / env_cpu : 0.0;
    }
    out["ratio_cluster_to_env"] = env_sps > 0 ? sps / env_sps : 0.0;
    out["wire_bytes_per_sample"] = b["wire_bytes_per_sample"];
    out["policy_lag_mean"] = lag / rows.size();
    out["dropped_stale"] = b["dropped_stale"];
  } else {
    out["cluster_samples_per_s"] = nullptr;
    out["error"] = "fewer than 3 updates in " + std::to_string(f.cluster_seconds) +
                   " s; raise --cluster-seconds";
  }
  if (f.json) {
    std::cout << out.dump() << std::endl;
  } else {
    std::cout << out.dump(2) << std::endl;
  }
  return rows.size() >= 3 ? 0 : 1;
}

}  // namespace

void RegisterClusterCommands(CLI::App& root, CLI::App& bench) {
  // perch learner
  auto lf = std::make_shared<LearnerFlags>();
  CLI::App* l = root.add_subcommand("learner", "Run the learner: PPO over rollouts from actors");
  l->add_option("--config", lf->config, "experiment config (JSON)")->required();
  l->add_option("--run-dir", lf->run_dir, "checkpoints, metrics.jsonl, config.json")->required();
  l->add_flag("--resume", lf->resume, "continue from the last good checkpoint in --run-dir");
  l->add_option("--rollout-bind", lf->rollout_bind, "ZeroMQ endpoint for rollouts (PULL)");
  l->add_option("--weights-bind", lf->weights_bind, "ZeroMQ endpoint for weights (XPUB)");
  l->add_option("--metrics-port", lf->metrics_port, "Prometheus /metrics port (0: any free)");
  l->add_option("--max-updates", lf->max_updates, "stop after this many updates (0: never)");
  l->add_flag("--check-config", lf->check_config, "validate config and flags, then exit");
  l->callback([lf] {
    const int rc = RunLearner(*lf);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });

  // perch actor
  auto af = std::make_shared<ActorFlags>();
  CLI::App* a = root.add_subcommand("actor", "Run an actor: step envs, ship rollouts");
  a->add_option("--config", af->config, "experiment config (JSON)")->required();
  a->add_option("--learner-host", af->learner_host, "host name or address of the learner");
  a->add_option("--rollout-port", af->rollout_port, "learner rollout port");
  a->add_option("--weights-port", af->weights_port, "learner weights port");
  a->add_option("--rollout-connect", af->rollout_connect,
                "explicit endpoint (overrides host/port)");
  a->add_option("--weights-connect", af->weights_connect,
                "explicit endpoint (overrides host/port)");
  a->add_option("--actor-id", af->actor_id, "actor id (default: hash of the host name)");
  a->add_option("--envs", af->envs, "envs in this process (default: cluster.envs_per_actor)");
  a->add_option("--max-segments", af->max_segments, "stop after this many segments per env");
  a->add_flag("--check-config", af->check_config, "validate config and flags, then exit");
  a->callback([af] { RunActor(*af); });

  // perch train
  auto tf = std::make_shared<TrainFlags>();
  CLI::App* t = root.add_subcommand("train", "Local launch: learner + N actor processes");
  t->add_option("--config", tf->config, "experiment config (JSON)")->required();
  t->add_option("--actors", tf->actors, "actor processes");
  t->add_option("--envs", tf->envs, "envs per actor (default: cluster.envs_per_actor)");
  t->add_option("--run-dir", tf->run_dir, "run directory (default: runs/<config name>)");
  t->add_flag("--resume", tf->resume, "continue the run in --run-dir");
  t->add_option("--max-updates", tf->max_updates, "stop after this many updates (0: never)");
  t->add_option("--rollout-port", tf->rollout_port, "loopback rollout port");
  t->add_option("--weights-port", tf->weights_port, "loopback weights port");
  t->add_option("--metrics-port", tf->metrics_port, "Prometheus /metrics port");
  t->callback([tf] {
    const int rc = RunTrain(*tf);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });

  // perch bench cluster
  auto bf = std::make_shared<BenchFlags>();
  CLI::App* b = bench.add_subcommand("cluster", "Cluster throughput vs the env alone");
  b->add_option("--config", bf->config, "experiment config");
  b->add_option("--actors", bf->actors, "actor processes (default: one per core)");
  b->add_option("--envs", bf->envs, "envs per actor");
  b->add_option("--env-seconds", bf->env_seconds, "duration of the env-only baseline");
  b->add_option("--cluster-seconds", bf->cluster_seconds, "duration of the cluster run");
  b->add_flag("--json", bf->json, "print one JSON object");
  b->callback([bf] {
    const int rc = RunBenchCluster(*bf);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });

  // perch run-summary
  struct SummaryFlags {
    std::string run_dir, csv;
    bool json = false;
  };
  auto sf = std::make_shared<SummaryFlags>();
  CLI::App* s = root.add_subcommand(
      "run-summary", "What a training run did: samples, wall time, throughput, learning curve");
  s->add_option("--run-dir", sf->run_dir, "the run directory (metrics.jsonl)")->required();
  s->add_option("--csv", sf->csv, "write the learning curve here as CSV");
  s->add_flag("--json", sf->json, "print one JSON object");
  s->callback([sf] {
    const RunSummary summary = SummarizeRun(sf->run_dir);
    if (!sf->csv.empty()) WriteCurveCsv(summary, sf->csv);
    Json j = ToJson(summary);
    if (!sf->csv.empty()) j["csv"] = sf->csv;
    if (sf->json) {
      std::cout << j.dump() << "\n";
    } else {
      std::cout << "updates " << summary.updates << ", samples " << summary.samples
                << ", wall time " << summary.wall_time_s << " s, "
                << j["samples_per_s"].get<double>() << " samples/s, up to " << summary.max_actors
                << " actors\n";
    }
  });
}

}  // namespace perch
