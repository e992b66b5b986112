// The cluster's subcommands: `perch keygen`, `perch learner`, `perch actor`, `perch train` (local
// launch of both) and `perch run-summary`; their benchmarks are in bench/ (app/cmd_bench.cc).
// Command lines are used verbatim by k8s/*.yaml and scripts/train.sh.
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
#include "app/commands.h"
#include "common/config_file.h"
#include "common/stop_signal.h"
#include "experiment/experiment.h"
#include "launch/local_training.h"
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

uint32_t HostnameHash() {
  char host[256] = {0};
  ::gethostname(host, sizeof(host) - 1);
  uint32_t h = 2166136261u;  // FNV-1a: stable across restarts of the same pod
  for (const char* p = host; *p; ++p) h = (h ^ static_cast<unsigned char>(*p)) * 16777619u;
  return h & 0x7fffffff;
}

// Two listeners on one port of one host fail at bind time; say which flags clash, before any
// socket is opened. Port 0 (any free port) never clashes.
void CheckDistinctEndpoints(const std::vector<std::pair<std::string, std::string>>& named) {
  auto port_of = [](const std::string& e) -> int {
    if (e.rfind("tcp://", 0) != 0) return 0;
    const size_t colon = e.rfind(':');
    try {
      return colon == std::string::npos ? 0 : std::stoi(e.substr(colon + 1));
    } catch (...) {
      return 0;
    }
  };
  for (size_t i = 0; i < named.size(); ++i) {
    for (size_t k = i + 1; k < named.size(); ++k) {
      const int a = port_of(named[i].second), b = port_of(named[k].second);
      if (a != 0 && a == b) {
        throw ConfigError(named[i].first + " and " + named[k].first + ": both use port " +
                          std::to_string(a));
      }
    }
  }
}

// ---- perch keygen ----
struct KeygenFlags {
  std::string out;
};

int RunKeygen(const KeygenFlags& f) {
  if (f.out.empty()) throw ConfigError("--out: required");
  WriteClusterKeys(f.out);
  std::cout << "perch keygen: wrote " << f.out << "/{learner,actor}.{pub,key}; give the learner "
            << "learner.key, learner.pub and actor.pub, the actors learner.pub, actor.pub and "
               "actor.key (cluster.keys_dir or PERCH_KEYS_DIR)\n";
  return 0;
}

// ---- perch learner ----
// Config overrides shared by perch learner and perch train: --set, and --max-samples /
// --target-success as shorthands for --set cluster.max_samples=N / cluster.target_success=R.
struct OverrideFlags {
  std::vector<std::string> sets;
  int64_t max_samples = 0;
  double target_success = 0.0;

  void Register(CLI::App* app) {
    app->add_option("--set", sets, "override a config field: section.field=VALUE (repeatable)");
    app->add_option("--max-samples", max_samples,
                    "end the run after this many samples (cluster.max_samples; 0: the config's)");
    app->add_option("--target-success", target_success,
                    "end the run at this success rate over cluster.target_window judged episodes "
                    "(cluster.target_success; 0: the config's)");
  }
  // The --set list with the shorthands appended; ConfigError names a bad shorthand.
  std::vector<std::string> All() const {
    if (max_samples < 0) throw ConfigError("--max-samples: must be >= 0");
    if (!(target_success >= 0 && target_success <= 1)) {
      throw ConfigError("--target-success: must be in [0, 1]");
    }
    std::vector<std::string> all = sets;
    if (max_samples > 0) all.push_back("cluster.max_samples=" + std::to_string(max_samples));
    if (target_success > 0)
      all.push_back("cluster.target_success=" + fmt::format("{}", target_success));
    return all;
  }
};

struct LearnerFlags {
  std::string config;
  OverrideFlags overrides;
  std::string run_dir;
  bool resume = false;
  // Loopback unless told otherwise (a cluster binds all interfaces explicitly, k8s/learner.yaml).
  std::string rollout_bind = "tcp://127.0.0.1:5555";
  std::string weights_bind = "tcp://127.0.0.1:5556";
  int metrics_port = 9100;
  std::string metrics_bind = "127.0.0.1";
  int64_t max_updates = 0;
  int rank = 0;  // in a group of cluster.learners
  bool check_config = false;
};

int RunLearner(const LearnerFlags& f) {
  CheckEndpoint(f.rollout_bind, "--rollout-bind");
  CheckEndpoint(f.weights_bind, "--weights-bind");
  if (f.metrics_port != 0) CheckPort(f.metrics_port, "--metrics-port");
  if (f.max_updates < 0) throw ConfigError("--max-updates: must be >= 0");
  if (f.run_dir.empty()) throw ConfigError("--run-dir: required");
  const ExperimentConfig cfg = LoadExperimentConfig(f.config, f.overrides.All());
  const LearnerSetup setup = MakeLearnerSetup(cfg);
  if (f.rank < 0 || f.rank >= setup.cluster.learners) {
    throw ConfigError("--rank: " + std::to_string(f.rank) + " is not in 0.." +
                      std::to_string(setup.cluster.learners - 1) + " (cluster.learners " +
                      std::to_string(setup.cluster.learners) + ")");
  }
  // What is known to fail at run time, found now: messages too small for the weights or a
  // segment, an init_from that is missing or not a compatible policy, clashing ports.
  CheckRunTimeConfig(setup);
  CheckDistinctEndpoints(
      {{"--rollout-bind", f.rollout_bind},
       {"--weights-bind", f.weights_bind},
       {"--metrics-port", "tcp://" + f.metrics_bind + ":" + std::to_string(f.metrics_port)}});
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
  o.metrics_bind = f.metrics_bind;
  o.run_dir = f.run_dir;
  o.resume = f.resume;
  o.max_updates = f.max_updates;
  o.stop = &StopFlag();
  o.group_rank = f.rank;
  zmq::context_t ctx(1);
  try {
    LearnerService learner(ctx, setup, o);
    learner.Run();
    // The last good state is saved; the exit status tells a supervisor the group broke.
    if (learner.stop_reason() == "group_failed") throw GroupError(learner.group_error());
  } catch (const CheckpointError& e) {
    throw ConfigError(e.what());
  }
  return 0;
}

// ---- perch actor ----
struct ActorFlags {
  std::string config;
  std::vector<std::string> sets;
  std::string learner_host;
  int rollout_port = 5555;
  int weights_port = 5556;
  std::string rollout_connect;
  std::string weights_connect;
  int64_t actor_id = -1;
  int envs = 0;
  int64_t max_segments = 0;
  std::string alive_file;
  bool check_config = false;
};

// An actor without --config (a recipe on a cluster, issue 48): it builds its envs from the
// experiment the learner publishes with its weights, and rebuilds when that changes (the
// recipe's next stage). It needs no files: those the config names come with it.
int RunActorFromLearner(const ActorFlags& f, ActorOptions o) {
  if (!f.sets.empty()) {
    throw ConfigError("--set: needs --config (without one the learner's experiment is used as is)");
  }
  const ClusterConfig cluster;  // keys from PERCH_KEYS_DIR; message limits until the config
  o.actor_id = f.actor_id >= 0 ? static_cast<uint32_t>(f.actor_id) : HostnameHash();
  o.max_segments = f.max_segments;
  o.alive_file = f.alive_file;
  o.end_on_new_config = true;
  if (f.check_config) {
    std::cerr << "perch actor: flags OK (the experiment comes from the learner)\n";
    return 0;
  }
  LogToStderr("actor " + std::to_string(o.actor_id));
  InstallStopHandlers();
  o.stop = &StopFlag();
  const char* tmp = std::getenv("TMPDIR");
  const std::string cache =
      std::string(tmp ? tmp : "/tmp") + "/perch-actor-" + std::to_string(::getpid()) + "-files";
  zmq::context_t ctx(1);
  while (!StopFlag().load()) {
    spdlog::info("actor {}: waiting for the learner's experiment on {}", o.actor_id,
                 o.weights_connect);
    LearnerExperiment ex;
    if (!FetchLearnerExperiment(ctx, o.weights_connect, cluster, &StopFlag(), &ex)) break;
    ExperimentConfig cfg;
    try {
      Json j = Json::parse(ex.config_json);
      j = LocalizeConfigFiles(j, ex.files, cache);
      cfg = ExperimentConfigFromJson(j, "the learner's experiment config");
    } catch (const std::exception& e) {
      // A learner of another build, say: keep waiting for one this actor can serve.
      spdlog::error("actor {}: cannot build the learner's experiment: {}", o.actor_id, e.what());
      std::this_thread::sleep_for(std::chrono::seconds(5));
      continue;
    }
    ActorSetup setup = MakeActorSetup(cfg);
    setup.config_json = ex.config_json;
    o.num_envs = f.envs > 0 ? f.envs : cfg.cluster.envs_per_actor;
    spdlog::info("actor {}: experiment task {} ({} files from the learner), {} envs", o.actor_id,
                 cfg.cluster.task, ex.files.size(), o.num_envs);
    ActorService actor(ctx, setup, o);
    actor.Run();
    if (!actor.config_changed()) break;
  }
  return 0;
}

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
  if (f.envs < 0 || f.envs > 1024) throw ConfigError("--envs: must be in 1..1024");
  if (f.max_segments < 0) throw ConfigError("--max-segments: must be >= 0");
  if (f.config.empty()) return RunActorFromLearner(f, o);
  const ExperimentConfig cfg = LoadExperimentConfig(f.config, f.sets);
  const ActorSetup setup = MakeActorSetup(cfg);
  o.actor_id = f.actor_id >= 0 ? static_cast<uint32_t>(f.actor_id) : HostnameHash();
  o.num_envs = f.envs > 0 ? f.envs : cfg.cluster.envs_per_actor;
  o.max_segments = f.max_segments;
  o.alive_file = f.alive_file;
  if (f.check_config) {
    std::cerr << "perch actor: config " << f.config << " and flags OK\n";
    return 0;
  }
  LogToStderr("actor " + std::to_string(o.actor_id));
  InstallStopHandlers();
  o.stop = &StopFlag();
  zmq::context_t ctx(1);
  ActorService actor(ctx, setup, o);
  actor.Run();
  return 0;
}

// ---- perch train ----
struct TrainFlags {
  std::string config;
  OverrideFlags overrides;
  int actors = 2;
  int envs = 0;
  std::string run_dir;
  bool resume = false;
  int64_t max_updates = 0;
  int rollout_port = 5555;
  int weights_port = 5556;
  int metrics_port = 9100;
};

int RunTrain(const TrainFlags& f) {
  if (f.actors < 1) throw ConfigError("--actors: must be >= 1");
  if (f.envs < 0 || f.envs > 1024) throw ConfigError("--envs: must be in 1..1024");
  if (f.max_updates < 0) throw ConfigError("--max-updates: must be >= 0");
  CheckPort(f.rollout_port, "--rollout-port");
  CheckPort(f.weights_port, "--weights-port");
  CheckPort(f.metrics_port, "--metrics-port");
  CheckDistinctEndpoints({{"--rollout-port", "tcp://h:" + std::to_string(f.rollout_port)},
                          {"--weights-port", "tcp://h:" + std::to_string(f.weights_port)},
                          {"--metrics-port", "tcp://h:" + std::to_string(f.metrics_port)}});
  LocalTrainingOptions o;
  o.config = f.config;
  o.learner_sets = f.overrides.All();
  o.actor_sets = f.overrides.sets;
  o.actors = f.actors;
  o.envs = f.envs;
  o.run_dir = f.run_dir;
  o.resume = f.resume;
  o.max_updates = f.max_updates;
  o.rollout_port = f.rollout_port;
  o.weights_port = f.weights_port;
  o.metrics_port = f.metrics_port;
  return RunLocalTraining(o);
}

// perch keygen
void RegisterKeygen(CLI::App& root) {
  auto kf = std::make_shared<KeygenFlags>();
  CLI::App* kg =
      root.add_subcommand("keygen", "Write the cluster's CURVE key pairs (learner, actors)");
  kg->add_option("--out", kf->out, "directory for learner.{pub,key} and actor.{pub,key}")
      ->required();
  kg->callback([kf] {
    const int rc = RunKeygen(*kf);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

// perch learner
void RegisterLearner(CLI::App& root) {
  auto lf = std::make_shared<LearnerFlags>();
  CLI::App* l = root.add_subcommand("learner", "Run the learner: PPO over rollouts from actors");
  l->add_option("--config", lf->config, "experiment config (JSON)")->required();
  l->add_option("--run-dir", lf->run_dir, "checkpoints, metrics.jsonl, config.json")->required();
  l->add_flag("--resume", lf->resume, "continue from the last good checkpoint in --run-dir");
  l->add_option("--rollout-bind", lf->rollout_bind, "ZeroMQ endpoint for rollouts (PULL)");
  l->add_option("--weights-bind", lf->weights_bind, "ZeroMQ endpoint for weights (XPUB)");
  l->add_option("--metrics-port", lf->metrics_port, "Prometheus /metrics port (0: any free)");
  l->add_option("--metrics-bind", lf->metrics_bind,
                "address /metrics listens on (0.0.0.0: every interface, for a scraper)");
  l->add_option("--max-updates", lf->max_updates, "stop after this many updates (0: never)");
  l->add_option(
      "--rank", lf->rank,
      "this learner's rank in a group of cluster.learners (0 binds cluster.group_address)");
  lf->overrides.Register(l);
  l->add_flag("--check-config", lf->check_config, "validate config and flags, then exit");
  l->callback([lf] {
    const int rc = RunLearner(*lf);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

// perch actor
void RegisterActor(CLI::App& root) {
  auto af = std::make_shared<ActorFlags>();
  CLI::App* a = root.add_subcommand("actor", "Run an actor: step envs, ship rollouts");
  a->add_option("--config", af->config,
                "experiment config (JSON); without it the actor builds what the learner publishes "
                "and follows it from stage to stage (perch recipe run --cluster)");
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
  a->add_option("--alive-file", af->alive_file,
                "touched at every heartbeat (a liveness probe checks its age)");
  a->add_option("--set", af->sets, "override a config field: section.field=VALUE (repeatable)");
  a->add_flag("--check-config", af->check_config, "validate config and flags, then exit");
  a->callback([af] { RunActor(*af); });
}

// perch train
void RegisterTrain(CLI::App& root) {
  auto tf = std::make_shared<TrainFlags>();
  CLI::App* t = root.add_subcommand("train", "Local launch: learner + N actor processes");
  t->add_option("--config", tf->config, "experiment config (JSON)")->required();
  t->add_option("--actors", tf->actors, "actor processes");
  t->add_option("--envs", tf->envs, "envs per actor (default: cluster.envs_per_actor)");
  t->add_option("--run-dir", tf->run_dir, "run directory (default: runs/<config name>)");
  t->add_flag("--resume", tf->resume, "continue the run in --run-dir");
  t->add_option("--max-updates", tf->max_updates, "stop after this many updates (0: never)");
  tf->overrides.Register(t);
  t->add_option("--rollout-port", tf->rollout_port, "loopback rollout port");
  t->add_option("--weights-port", tf->weights_port, "loopback weights port");
  t->add_option("--metrics-port", tf->metrics_port, "Prometheus /metrics port");
  t->callback([tf] {
    const int rc = RunTrain(*tf);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

// perch run-summary
void RegisterRunSummary(CLI::App& root) {
  struct SummaryFlags {
    std::vector<std::string> run_dirs;
    std::string csv, plot;
    bool json = false;
  };
  auto sf = std::make_shared<SummaryFlags>();
  CLI::App* s = root.add_subcommand(
      "run-summary", "What a training run did: samples, wall time, throughput, learning curve");
  s->add_option("--run-dir", sf->run_dirs,
                "the run directory (metrics.jsonl); several (repeat the flag) overlay in --plot")
      ->required();
  s->add_option("--csv", sf->csv, "write the learning curve here as CSV (the first run)");
  s->add_option("--plot", sf->plot,
                "draw the learning curves of all --run-dir runs into this PNG (gnuplot)");
  s->add_flag("--json", sf->json, "print one JSON object");
  s->callback([sf] {
    std::vector<RunSummary> runs;
    for (const std::string& d : sf->run_dirs) runs.push_back(SummarizeRun(d));
    if (runs.size() > 1 && sf->plot.empty()) {
      throw ConfigError("--run-dir: several runs need --plot (the summary is of one run)");
    }
    const RunSummary& summary = runs.front();
    if (!sf->csv.empty()) WriteCurveCsv(summary, sf->csv);
    if (!sf->plot.empty()) PlotRuns(runs, sf->plot);
    Json j = ToJson(summary);
    if (!sf->csv.empty()) j["csv"] = sf->csv;
    if (!sf->plot.empty()) j["plot"] = sf->plot;
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

}  // namespace

void RegisterClusterCommands(CLI::App& root, CLI::App& /*bench*/) {
  RegisterKeygen(root);
  RegisterLearner(root);
  RegisterActor(root);
  RegisterTrain(root);
  RegisterRunSummary(root);
}

}  // namespace perch
