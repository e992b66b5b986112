// The actor role: steps several envs in one process with the current policy, ships fixed-length
// rollout segments (PUSH) and takes new weights (SUB) between segments. Reconnects by itself when
// the learner restarts (ZeroMQ reconnects; the learner republishes weights on every
// (re)subscription). The same class runs in `perch actor` (tcp://) and inside tests (inproc://).
#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <vector>
#include <zmq.hpp>

#include "common/env.h"
#include "common/proto/wire.pb.h"
#include "common/rng.h"
#include "policy/policy.h"
#include "policy/rollout.h"
#include "protocol/cluster_config.h"

namespace perch {

struct ActorSetup {
  uint64_t seed = 0;
  PolicyConfig policy;  // of the trained task
  NormalizerConfig obs_norm;
  ClusterConfig cluster;
  std::function<std::unique_ptr<Env>()> make_env;
  // The learner's resolved experiment config this setup was built from, verbatim (an actor
  // started without --config); "" otherwise.
  std::string config_json;
};

// A segment recorded from a real env, for actors that replay instead of stepping (bench scale).
struct RecordedSegment {
  Rollout rollout;
  EpisodeStats episodes;  // of the episodes that ended in it
};

struct ActorOptions {
  std::string rollout_connect = "tcp://127.0.0.1:5555";
  std::string weights_connect = "tcp://127.0.0.1:5556";
  uint32_t actor_id = 0;
  int num_envs = 4;
  int64_t max_segments = 0;  // per env; 0: until stopped (tests and benchmarks bound it)
  const std::atomic<bool>* stop = nullptr;
  // Touched (mtime) at every heartbeat and while waiting for an unreachable learner: a k8s
  // liveness probe checks that the actor's loop runs (k8s/actors.yaml). Empty: none.
  std::string alive_file;
  // `perch bench scale`: a synthetic actor. No env is built; each segment is the next of these
  // recordings (restamped with this actor's weights version), sent at replay_samples_per_s.
  // Hello, heartbeats, credit and weights run exactly as for a real actor.
  const std::vector<RecordedSegment>* replay = nullptr;
  double replay_samples_per_s = 0.0;  // 0: as fast as credit allows
  // An actor started without --config: Run() returns when the learner publishes another
  // experiment config than setup.config_json (a recipe's next stage), to be rebuilt from it.
  bool end_on_new_config = false;
  EnvSpec replay_spec;  // what Hello reports
};

struct ActorCounters {
  uint64_t env_steps = 0;
  uint64_t segments_sent = 0;
  uint64_t weights_loaded = 0;
  uint64_t weights_rejected = 0;
  uint64_t bytes_sent = 0;
  uint64_t episodes = 0;
  uint64_t credit_waits = 0;      // times the actor used up its credit and waited (flow control)
  double credit_wait_s = 0.0;     // seconds spent waiting for credit
  uint64_t weights_messages = 0;  // weights messages received (new versions, republishes, grants)
  uint64_t weights_bytes = 0;     // their bytes
};

// The learner's experiment as it publishes it with its weights (wire.proto Weights): what an
// actor started without --config builds its envs from.
struct LearnerExperiment {
  std::string config_json;
  std::vector<proto::ConfigFile> files;
};
// Subscribes to weights_connect (with the cluster's keys, as ActorService does) and waits for
// the first weights message that carries an experiment config. False when stopped first;
// messages that fail the wire checks are skipped.
bool FetchLearnerExperiment(zmq::context_t& ctx, const std::string& weights_connect,
                            const ClusterConfig& cluster, const std::atomic<bool>* stop,
                            LearnerExperiment* out);

class ActorService {
 public:
  ActorService(zmq::context_t& ctx, const ActorSetup& setup, const ActorOptions& options);
  ~ActorService();

  // Waits for the first weights, then collects and sends segments until stopped.
  void Run();
  const ActorCounters& counters() const { return counters_; }
  uint64_t weights_version() const { return runner_.version(); }
  // Run() returned because the learner's experiment changed (options.end_on_new_config).
  bool config_changed() const { return config_changed_; }

 private:
  bool Stopping() const { return config_changed_ || (options_.stop && options_.stop->load()); }
  // Applies the newest weights waiting on the socket; blocks up to timeout_ms for one.
  bool PollWeights(int timeout_ms);
  bool Send(const std::string& bytes);  // false when stopped before it could be queued
  void TouchAliveFile();                // options_.alive_file, at most once a second
  void SendHello();
  void MaybeHeartbeat();
  void TakeCredit(const proto::Weights& w);
  void TakeFrozen(const proto::Weights& w);  // frozen policies for the envs that need them
  void WaitForCredit();                      // blocks while this version's credit is used up
  const EnvSpec& spec() const { return options_.replay ? options_.replay_spec : envs_[0]->spec(); }
  // The next segment of stream i: stepped in its env, or replayed (paced).
  void Produce(size_t i, PolicyRunner* runner, Rollout* out, EpisodeStats* eps);
  size_t replay_next_ = 0;
  double replay_due_s_ = 0.0;

  ActorSetup setup_;
  ActorOptions options_;
  proto::Task task_;
  uint64_t instance_ = 0;
  zmq::socket_t push_;
  zmq::socket_t sub_;
  PolicyRunner runner_;
  uint64_t weights_run_id_ = 0;
  bool have_weights_ = false;
  bool config_changed_ = false;
  double credit_segments_ = 0.0;  // granted per weights version; 0: no limit
  uint64_t credit_epoch_ = 0;
  double credit_carry_ = 0.0;      // fraction carried into the next version, in [0, 1)
  double credit_base_ = 0.0;       // the carry this version started with
  uint64_t credit_allowance_ = 0;  // floor(base + grant): segments this version may send
  uint64_t sent_in_grant_ = 0;     // segments sent stamped with credit_version_
  uint64_t credit_run_id_ = 0;
  uint64_t credit_version_ = ~uint64_t{0};
  std::vector<std::unique_ptr<Env>> envs_;
  std::vector<std::unique_ptr<RolloutCollector>> collectors_;
  // Envs that run frozen policies (the meta env): they get the learner's before stepping.
  std::vector<FrozenPolicyEnv*> frozen_envs_;
  bool frozen_ready_ = true;  // every env in frozen_envs_ has its policies
  double last_resubscribe_s_ = 0.0;
  Rng rng_;
  // cluster.simulated_lag: the newest weights versions received, newest first; each segment acts
  // with one drawn by lag_rng_ (its own stream, so the envs' randomness is the same as without).
  std::deque<PolicyRunner> lag_history_;
  Rng lag_rng_;
  ActorCounters counters_;
  double start_s_ = 0.0;
  double last_alive_touch_s_ = -1e9;
  double last_heartbeat_s_ = 0.0;
};

}  // namespace perch
