// The learner role: binds the rollout (PULL) and weights (XPUB) sockets, validates incoming
// segments, drops stale ones, runs PPO when a batch is full, publishes versioned weights, reports
// progress (console, <run_dir>/metrics.jsonl, Prometheus /metrics) and writes checkpoints.
// The same class runs in the `perch learner` process (tcp://) and inside tests (inproc://).
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>
#include <zmq.hpp>

#include "common/json_util.h"
#include "common/proto/wire.pb.h"
#include "common/rng.h"
#include "learner/ppo.h"
#include "learner/service/checkpoint.h"
#include "learner/service/group.h"
#include "learner/service/metrics_http.h"
#include "learner/service/progress.h"
#include "policy/policy.h"
#include "policy/rollout.h"
#include "protocol/clock.h"
#include "protocol/cluster_config.h"
#include "protocol/security.h"
#include "protocol/wire.h"

namespace perch {

// Everything the learner needs from the experiment config, resolved by the caller.
struct LearnerSetup {
  uint64_t seed = 0;
  PolicyConfig policy;  // dims resolved from the env spec
  PpoConfig ppo;
  ClusterConfig cluster;
  Json resolved_config;     // the whole experiment config, saved into the run dir and checkpoints
  std::string compat_key;   // must match a checkpoint to resume from it
  double control_dt = 0.0;  // [s] per env step, for the console (0: lengths in steps)
  MirrorMap mirror;         // the env's left/right symmetry (cluster.init_mirror)
  // Policies the env runs frozen inside its step (meta: the subtasks), frozen = true. Shipped
  // with the first weights and to every (re)subscribing actor; kept in checkpoints, and a
  // resumed run keeps the checkpoint's.
  std::vector<proto::TaskPolicy> frozen;
};

struct LearnerOptions {
  // Loopback by default: a cluster binds all interfaces explicitly (k8s/learner.yaml).
  std::string rollout_bind = "tcp://127.0.0.1:5555";
  std::string weights_bind = "tcp://127.0.0.1:5556";
  int metrics_port = 9100;  // -1: no /metrics endpoint; 0: any free port
  std::string metrics_bind = "127.0.0.1";
  // Weights resent to (re)subscribing actors at most this often; a flood of subscriptions costs
  // one resend per interval (issue 17). 0: every subscription.
  double republish_min_interval_s = 0.2;
  std::string run_dir;
  bool resume = false;
  int64_t max_updates = 0;  // stop after this many updates in total (0: never)
  double console_every_s = 5.0;
  const std::atomic<bool>* stop = nullptr;  // set by a signal handler or a test
  // This learner's rank in a group of cluster.learners (0..learners-1); group_address overrides
  // cluster.group_address (tests: inproc://).
  int group_rank = 0;
  std::string group_address;
};

// Counts of what arrived, for metrics and tests.
struct LearnerStats {
  uint64_t messages = 0;
  uint64_t hellos = 0;
  uint64_t heartbeats = 0;
  uint64_t end_pose_batches = 0;
  uint64_t weights_published = 0;
  uint64_t weights_republished = 0;                  // to late joiners / reconnecting actors
  uint64_t credit_regrants = 0;                      // flow control: grants for a stalled batch
  std::map<std::string, uint64_t> rejected_by_kind;  // WireRejectName -> count
};

class LearnerService {
 public:
  // Loads the checkpoint when options.resume (throws CheckpointError when checkpoints exist but
  // none is usable) and binds the sockets (throws zmq::error_t / std::runtime_error).
  LearnerService(zmq::context_t& ctx, const LearnerSetup& setup, const LearnerOptions& options);
  ~LearnerService();

  // Runs until options.stop is set or max_updates is reached, then writes a final checkpoint.
  void Run();

  const proto::Counters& counters() const { return counters_; }
  const LearnerStats& stats() const { return stats_; }
  uint64_t version() const { return static_cast<uint64_t>(ppo_->num_updates()); }
  int metrics_port() const { return metrics_ ? metrics_->port() : -1; }
  const std::string& resumed_from() const { return resumed_from_; }
  std::string SaveCheckpoint();  // returns its path
  // Why Run() returned: "max_samples", "target_success", "max_updates", "stopped",
  // "group_stopped" (another learner of the group stopped) or "group_failed" (group_error()).
  const std::string& stop_reason() const { return stop_reason_; }
  const RunProgress* progress() const { return progress_.get(); }
  uint64_t nonfinite_updates() const { return nonfinite_updates_; }
  const std::string& group_error() const { return group_error_; }
  // CURVE handshakes refused (clients without an authorized key); 0 when insecure.
  static constexpr size_t kMaxTrackedActors = 65536;
  // Actor instances tracked for liveness (bounded by kMaxTrackedActors).
  size_t tracked_actors() const { return actor_last_seen_.size(); }
  uint64_t handshake_failures() const { return handshake_failures_; }
  uint64_t auth_refused() const { return zap_ ? zap_->refused() : 0; }
  const ZmqGroup* group() const { return group_.get(); }
  // The group fingerprint: config, update count and weights, equal on every member that may join.
  std::string GroupFingerprint() const;

 private:
  void HandleRollout(const zmq::message_t& msg);
  bool HandleSegment(const proto::Segment& seg);  // true when accepted
  void Reject(WireReject kind, const std::string& why);
  void Publish(bool republish);
  void Train();
  void DrainRollouts();           // queued segments into the batch, up to a full batch
  void ClearBatch();              // empties the batch and the statistics gathered with it
  double CreditPerActor() const;  // cluster.credit_slack: segments per actor for this version
  // A new grant, published with the weights; stalled: the batch stopped filling, so the grant
  // must grow.
  void GrantCredit(bool stalled = false);
  void WriteMetrics(const UpdateStats& u, double dt_s, uint64_t batch_samples);
  void UpdateGauges();
  int ActorsAlive() const;
  void SeeActor(uint64_t instance, double now);  // liveness, bounded (kMaxTrackedActors)
  void PruneActors(double now);                  // forgets actors silent for actor_timeout_s
  void DrainMonitors();  // counts handshake failures reported by the socket monitors
  void Resume();
  void InitFrom();  // cluster.init_from, for a new run

  LearnerSetup setup_;
  LearnerOptions options_;
  proto::Task task_;
  std::vector<proto::TaskPolicy> frozen_;  // setup.frozen, or the resumed checkpoint's
  bool frozen_published_ = false;
  // The experiment config and the files it names, for actors started without one
  // (wire.proto Weights.experiment_config_json): with the first weights and every republish.
  std::string config_json_;
  std::vector<proto::ConfigFile> config_files_;
  bool config_published_ = false;
  WireLimits limits_;
  std::unique_ptr<PpoLearner> ppo_;
  CheckpointStore store_;
  Rng rng_;
  uint64_t run_id_ = 0;
  proto::Counters counters_;
  LearnerStats stats_;
  std::string resumed_from_;

  zmq::socket_t rollout_sock_;
  zmq::socket_t weights_sock_;
  std::unique_ptr<MetricsServer> metrics_;
  std::string weights_bytes_;  // the last published LearnerMessage, for late joiners

  std::vector<Rollout> batch_;
  uint64_t batch_samples_ = 0;
  double batch_lag_sum_ = 0.0;  // sum over accepted segments of (version - segment version)
  uint64_t batch_segments_ = 0;
  std::vector<double> batch_returns_;
  std::vector<double> batch_lengths_;
  int batch_terminated_ = 0;   // episodes of the batch that ended by termination (fell)
  int batch_judged_ = 0;       // ... that the task's success test judged (EpisodeStats.has_success)
  int batch_succeeded_ = 0;    // ... and that passed it
  uint64_t wire_samples_ = 0;  // samples in those messages, since this process started
  uint64_t wire_bytes_ = 0;    // bytes of accepted segment messages (wire_bytes_per_sample)
  std::map<uint64_t, double> actor_last_seen_;  // actor_instance -> monotonic seconds
  double last_return_mean_ = 0.0;
  double last_samples_per_s_ = 0.0;
  double last_lag_mean_ = 0.0;
  double rejects_logged_at_ = -1e9;
  uint64_t rejects_unlogged_ = 0;
  double start_s_ = 0.0;
  double last_update_s_ = 0.0;
  double last_republish_s_ = -1e9;
  double credit_segments_ = 0.0;
  uint64_t credit_epoch_ = 0;
  uint64_t granted_version_ = ~uint64_t{0};
  uint64_t segments_at_version_ = 0;  // accepted segments stamped with the granted version
  bool credit_pending_ = false;       // actors joined since the last grant
  double last_grant_s_ = 0.0;
  double last_segment_s_ = 0.0;
  bool republish_pending_ = false;
  double train_time_base_s_ = 0.0;
  int64_t last_checkpoint_update_ = -1;
  std::string last_checkpoint_path_;
  std::unique_ptr<RunProgress> progress_;  // created when Run() starts
  uint64_t nonfinite_updates_ = 0;         // updates discarded for non-finite results
  std::string stop_reason_;
  std::unique_ptr<CurveKeys> keys_;        // CURVE: this learner's keys (null when insecure)
  std::unique_ptr<ZapAuthenticator> zap_;  // CURVE: answers the sockets' handshakes
  std::unique_ptr<ZmqGroup> group_;        // cluster.learners > 1
  std::vector<zmq::socket_t> monitors_;    // CURVE: handshake events of the two sockets
  uint64_t handshake_failures_ = 0;
  RunningMeanStd pending_obs_delta_;  // group: received observation statistics, merged at update
  std::string group_end_;             // set when the group stopped or failed: the run ends
  std::string group_error_;
};

// cluster.init_from onto a new run's learner (weights and normalizer; mapped to fewer inputs,
// another sigma mode or wider layers as needed). ConfigError naming the file and the reason.
void ApplyInitFrom(const LearnerSetup& setup, PpoLearner* ppo);
// What would fail only once the run started, as a ConfigError now: cluster.max_message_bytes too
// small for the weights or a whole segment, cluster.init_from missing or not a compatible policy.
void CheckRunTimeConfig(const LearnerSetup& setup);

// Cuts a torn last line (no newline) off a metrics.jsonl, so rows appended later stay parseable.
void RepairMetricsFile(const std::string& path);

}  // namespace perch
