#include "launch/local_training.h"

#include <signal.h>
#include <spdlog/spdlog.h>
#include <sys/types.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <thread>

#include "actor/process.h"
#include "common/json_util.h"
#include "common/stop_signal.h"
#include "experiment/experiment.h"
#include "learner/service/checkpoint.h"
#include "learner/service/learner.h"
#include "learner/service/learner_setup.h"
#include "protocol/clock.h"
#include "protocol/security.h"

namespace perch {
namespace {

std::vector<std::string> LearnerArgv(const LocalTrainingOptions& o, bool resume) {
  std::vector<std::string> a = {
      SelfExe(),        "learner",
      "--config",       o.config,
      "--run-dir",      o.run_dir,
      "--rollout-bind", "tcp://127.0.0.1:" + std::to_string(o.rollout_port),
      "--weights-bind", "tcp://127.0.0.1:" + std::to_string(o.weights_port),
      "--metrics-port", std::to_string(o.metrics_port)};
  if (resume) a.push_back("--resume");
  for (const std::string& s : o.learner_sets) {
    a.push_back("--set");
    a.push_back(s);
  }
  if (o.max_updates > 0) {
    a.push_back("--max-updates");
    a.push_back(std::to_string(o.max_updates));
  }
  return a;
}

std::vector<std::string> ActorArgv(const LocalTrainingOptions& o, int id) {
  std::vector<std::string> a = {SelfExe(),        "actor",
                                "--config",       o.config,
                                "--learner-host", "127.0.0.1",
                                "--rollout-port", std::to_string(o.rollout_port),
                                "--weights-port", std::to_string(o.weights_port),
                                "--actor-id",     std::to_string(id)};
  // The actors build the same env as the learner: the same overrides.
  for (const std::string& s : o.actor_sets) {
    a.push_back("--set");
    a.push_back(s);
  }
  if (o.envs > 0) {
    a.push_back("--envs");
    a.push_back(std::to_string(o.envs));
  }
  return a;
}

// The learner and its actors as child processes, restarted on failure within their policies.
class Supervisor {
 public:
  Supervisor(const LocalTrainingOptions& o, const ExperimentConfig& cfg)
      : o_(o),
        cfg_(cfg),
        logs_(o.run_dir + "/logs"),
        rpc_(PolicyConfigOf(cfg)),
        learner_policy_(rpc_),
        actor_policy_(o.actors, RestartPolicy(rpc_)),
        actors_(o.actors, -1),
        restart_at_(o.actors, 0.0),
        gave_up_(o.actors, false) {}

  // Runs until the learner ends, everything failed, or a stop signal; returns the exit code.
  int Run() {
    learner_ = Spawn(LearnerArgv(o_, o_.resume), "");
    learner_policy_.OnStart(MonotonicSeconds());
    for (int i = 0; i < o_.actors; ++i) StartActor(i, MonotonicSeconds());
    WriteRestarts();
    last_size_ = MetricsSize();
    last_progress_ = MonotonicSeconds();
    while (!StopFlag().load() && !done_) {
      int status = 0;
      const pid_t pid = ::waitpid(-1, &status, WNOHANG);
      const double now = MonotonicSeconds();
      if (pid > 0 && pid == learner_) {
        OnLearnerExit(status, now);
      } else if (pid > 0) {
        OnActorExit(pid, status, now);
      }
      if (done_) break;
      RestartDue(now);
      Watch(now);
      if (pid <= 0) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    Shutdown();
    return exit_code_;
  }

 private:
  static RestartPolicyConfig PolicyConfigOf(const ExperimentConfig& cfg) {
    RestartPolicyConfig rpc;
    rpc.base_s = cfg.cluster.restart_backoff_ms / 1000.0;
    rpc.max_s = cfg.cluster.restart_backoff_max_ms / 1000.0;
    rpc.give_up_after = cfg.cluster.max_identical_failures;
    return rpc;
  }
  std::string ActorLog(int i) const { return logs_ + "/actor-" + std::to_string(i) + ".log"; }
  void StartActor(int i, double now) {
    actors_[i] = Spawn(ActorArgv(o_, i), ActorLog(i));
    actor_policy_[i].OnStart(now);
  }
  // The learner's metrics.jsonl grows by a line per update (the watchdog's signal).
  uintmax_t MetricsSize() const {
    std::error_code e;
    const auto n = std::filesystem::file_size(o_.run_dir + "/metrics.jsonl", e);
    return e ? uintmax_t{0} : n;
  }
  // Restart counts for the learner's /metrics (perch_*_restarts_total) and for operators.
  void WriteRestarts() {
    int actor_restarts = 0, given_up = 0;
    for (int i = 0; i < o_.actors; ++i) {
      actor_restarts += actor_policy_[i].restarts();
      given_up += gave_up_[i];
    }
    try {
      SaveJsonFileAtomic(o_.run_dir + "/launcher.json",
                         Json{{"learner_restarts", learner_policy_.restarts()},
                              {"actor_restarts", actor_restarts},
                              {"actors_given_up", given_up}});
    } catch (const std::exception& e) {
      spdlog::warn("train: cannot write {}/launcher.json: {}", o_.run_dir, e.what());
    }
  }
  void OnLearnerExit(int status, double now) {
    learner_ = -1;
    if (WIFEXITED(status) && (WEXITSTATUS(status) == 0 || WEXITSTATUS(status) == 2)) {
      exit_code_ = WEXITSTATUS(status);
      spdlog::info("train: learner {}; stopping actors", DescribeStatus(status));
      done_ = true;
      return;
    }
    const double delay = learner_policy_.OnFailure(DescribeStatus(status), now);
    if (delay < 0) {
      spdlog::error(
          "train: learner {} {} times in a row; giving up (its output is above; "
          "cluster.max_identical_failures)",
          DescribeStatus(status), learner_policy_.identical_in_a_row());
      exit_code_ = 1;
      done_ = true;
      return;
    }
    spdlog::error(
        "train: learner {}; restarting it with --resume in {:.1f} s (failure {} in a row)",
        DescribeStatus(status), delay, learner_policy_.failures_in_a_row());
    learner_restart_at_ = now + delay;
  }
  void OnActorExit(pid_t pid, int status, double now) {
    for (int i = 0; i < o_.actors; ++i) {
      if (actors_[i] != pid) continue;
      actors_[i] = -1;
      const double delay = actor_policy_[i].OnFailure(DescribeStatus(status), now);
      if (delay < 0) {
        gave_up_[i] = true;
        spdlog::error(
            "train: actor {} {} {} times in a row; not restarting it (cluster."
            "max_identical_failures). The end of {}:\n{}",
            i, DescribeStatus(status), actor_policy_[i].identical_in_a_row(), ActorLog(i),
            LastLines(ActorLog(i), 10));
      } else {
        spdlog::warn("train: actor {} {}; restarting it in {:.1f} s", i, DescribeStatus(status),
                     delay);
        restart_at_[i] = now + delay;
      }
    }
  }
  void RestartDue(double now) {
    if (learner_ < 0 && learner_restart_at_ >= 0 && now >= learner_restart_at_) {
      learner_ = Spawn(LearnerArgv(o_, true), "");
      learner_policy_.OnStart(now);
      learner_restart_at_ = -1.0;
      WriteRestarts();
    }
    int alive_or_due = 0;
    for (int i = 0; i < o_.actors; ++i) {
      if (actors_[i] < 0 && !gave_up_[i] && now >= restart_at_[i]) {
        StartActor(i, now);
        WriteRestarts();
      }
      alive_or_due += !gave_up_[i];
    }
    if (alive_or_due == 0) {
      spdlog::error("train: every actor failed {} times in a row; stopping the run",
                    rpc_.give_up_after);
      exit_code_ = 1;
      done_ = true;
    }
  }
  // Once a second: a learner stopped by a signal, or one that has not updated for
  // cluster.learner_watchdog_s, is reported.
  void Watch(double now) {
    if (now - last_watch_ < 1.0 || learner_ <= 0) return;
    last_watch_ = now;
    const uintmax_t size = MetricsSize();
    if (size != last_size_) {
      last_size_ = size;
      last_progress_ = now;
    }
    const char state = ProcessState(learner_);
    if (state == 'T' && !stopped_warned_) {
      spdlog::warn(
          "train: the learner (pid {}) is stopped (SIGSTOP?): no training until it gets SIGCONT",
          learner_);
      stopped_warned_ = true;
    } else if (state != 'T') {
      stopped_warned_ = false;
    }
    const double w = cfg_.cluster.learner_watchdog_s;
    if (w > 0 && now - last_progress_ >= w && now - last_stall_warning_ >= w) {
      spdlog::warn(
          "train: no update from the learner for {:.0f} s (pid {}, state {}); actors alive: {} "
          "(cluster.learner_watchdog_s)",
          now - last_progress_, learner_, state,
          std::count_if(actors_.begin(), actors_.end(), [](pid_t a) { return a > 0; }));
      last_stall_warning_ = now;
    }
  }
  // Ctrl-C / SIGTERM: the learner writes its final checkpoint on SIGTERM.
  void Shutdown() {
    if (learner_ > 0) {
      ::kill(learner_, SIGTERM);
      const int st = Stop(learner_, 60.0);
      spdlog::info("train: learner {}", DescribeStatus(st));
    }
    for (pid_t a : actors_) {
      if (a > 0) ::kill(a, SIGTERM);
    }
    for (pid_t a : actors_) {
      if (a > 0) Stop(a, 10.0);
    }
    spdlog::info("train: stopped");
  }

  const LocalTrainingOptions& o_;
  const ExperimentConfig& cfg_;
  const std::string logs_;
  const RestartPolicyConfig rpc_;
  RestartPolicy learner_policy_;
  std::vector<RestartPolicy> actor_policy_;
  pid_t learner_ = -1;
  double learner_restart_at_ = -1.0;  // >= 0: a restart is due then
  std::vector<pid_t> actors_;
  std::vector<double> restart_at_;
  std::vector<bool> gave_up_;
  int exit_code_ = 0;
  bool done_ = false;
  uintmax_t last_size_ = 0;
  double last_progress_ = 0.0, last_watch_ = 0.0, last_stall_warning_ = -1e9;
  bool stopped_warned_ = false;
};

}  // namespace

int RunLocalTraining(LocalTrainingOptions o) {
  const ExperimentConfig cfg = LoadExperimentConfig(o.config, o.learner_sets);
  // The learner would refuse these only after the actors started.
  CheckRunTimeConfig(MakeLearnerSetup(cfg));
  if (o.run_dir.empty()) {
    std::string base = o.config.substr(o.config.rfind('/') + 1);
    base = base.substr(0, base.rfind('.'));
    o.run_dir = "runs/" + base;
  }
  // Refuse early (as the learner would) rather than start actors for nothing.
  CheckpointStore store(o.run_dir, cfg.cluster.keep_last, cfg.cluster.milestone_every);
  if (!o.resume && !store.List().empty()) {
    throw ConfigError("--run-dir " + o.run_dir +
                      ": holds checkpoints; pass --resume to continue or choose another --run-dir");
  }
  LogToStderr("train");
  InstallStopHandlers();
  const std::string logs = o.run_dir + "/logs";
  std::error_code ec;
  std::filesystem::create_directories(logs, ec);  // runs/ may not exist yet on a fresh clone
  if (ec) throw ConfigError("--run-dir " + o.run_dir + ": cannot create it: " + ec.message());
  // Members only, on loopback too: a run without keys of its own makes them in its run dir (a
  // resumed run reuses them) and hands them to its learner and actors.
  if (const std::string keys = EnsureLocalKeys(cfg.cluster, o.run_dir + "/keys"); !keys.empty()) {
    spdlog::info("train: CURVE keys in {}", keys);
  }
  spdlog::info("train: learner + {} actors on loopback, run dir {}, logs in {}", o.actors,
               o.run_dir, logs);
  Supervisor s(o, cfg);
  return s.Run();
}

}  // namespace perch
