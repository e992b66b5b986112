// Settings of the cluster roles (learner, actor, launcher): the "cluster" section of an experiment
// config. Defaults follow the authors where they had an equivalent (checkpoint every 100 updates,
// notes §8.1); the rest are transport choices documented in docs/cluster.md.
#pragma once

#include <cstdint>
#include <string>

#include "common/field_table.h"
#include "common/json_util.h"
#include "common/proto/wire.pb.h"

namespace perch {

struct ClusterConfig {
  // Which policy of the hierarchy is trained: walk, turn_left, turn_right, sit, meta, stand. For
  // the bullet backend it must name env.task (meta: the hierarchy env); --check-config says so.
  std::string task = "stand";
  int segment_steps = 256;           // T: control steps per rollout segment
  int envs_per_actor = 4;            // default for `perch actor --envs`
  int max_policy_lag = 2;            // segments from versions older than current - lag are dropped
  int checkpoint_every = 100;        // updates between checkpoints (authors: 100)
  int keep_last = 3;                 // rotated checkpoints kept
  int milestone_every = 1000;        // updates; checkpoints at multiples are kept forever (0: none)
  double heartbeat_s = 5.0;          // actor -> learner heartbeat period
  double actor_timeout_s = 30.0;     // an actor silent this long is counted as gone
  int max_message_bytes = 64 << 20;  // bigger messages are dropped unparsed
  int max_segment_steps = 8192;      // T above this is rejected
  double max_wire_value = 1e6;       // |x| above this in a segment is rejected (ours; issue 17)
  int reconnect_ivl_ms = 200;        // ZeroMQ reconnect interval
  int hierarchy_meta_period = 30;    // control steps per meta decision (notes §4.7)
  bool hierarchy_enabled = false;    // run the 2 Hz meta policy over the subtasks
  // `perch train` supervision (issue 17): a dead child is restarted after restart_backoff_ms,
  // doubling per failure in a row up to restart_backoff_max_ms; after max_identical_failures
  // failures in a row with the same exit status the launcher gives up on it (0: never). A learner
  // that writes no update for learner_watchdog_s (or is stopped) is reported (0: no watchdog).
  int restart_backoff_ms = 500;
  int restart_backoff_max_ms = 30000;
  int max_identical_failures = 5;
  double learner_watchdog_s = 300.0;
  // Segments queued per actor connection at the learner (ZeroMQ receive high-water mark). Small,
  // so that a fast actor blocks instead of filling a queue whose tail would be stale on arrival.
  int learner_queue_segments = 16;
  // A new run (not a resume) starts from this checkpoint's policy weights and observation
  // normalizer: fine-tuning, e.g. walk stage 2 from stage 1 (notes §8.2 "init"). Adam, reward
  // scaling and counters start fresh. Empty: from scratch. Relative paths: the project root.
  std::string init_from;
  // init_from is a policy of the mirror-image task (ours): its weights are mirrored left/right
  // through the env's spec (EnvSpec::mirror, MirrorModelWeights), e.g. a right turn that starts
  // as the left turn's mirror image.
  bool init_mirror = false;
  // init_from also carries the source's trainer state (ours): Adam's moments, the reward scaler,
  // the observation normaliser's statistics and the PPO RNG, as a branch of that run resumed with
  // a new config (the delivered walker's fall-restart stretch was made so). The counters still
  // start at 0, so budgets and schedules count this run's own samples. Needs the same network.
  bool init_state = false;
  // A run ends by itself (final checkpoint, summary) once trained on max_samples env steps (0: no
  // budget; the console then shows percent done and an ETA), or once the success rate over the
  // newest target_window judged episodes reaches target_success (0: no target; tasks with a
  // success test only). Both ours; `perch train/learner --max-samples/--target-success` set them.
  int64_t max_samples = 0;
  double target_success = 0.0;
  int target_window = 200;
  // Flow control (ours, issue 20). With each weights version the learner grants every actor a
  // number of segments it may send stamped with that version: what the next batch still needs,
  // times (1 + credit_slack), shared among the live actors. An actor that has used its credit
  // waits (no stepping, no CPU) for the next version, so actors faster than the learner make no
  // samples that would go stale. Slack lets unevenly fast actors fill a batch without waiting for
  // each other; its surplus is trained on in the next batch (policy lag 1). 0: no credit (actors
  // never wait). A learner that has heard no segment for credit_regrant_s while its batch is not
  // full grants again (an actor that left took its credit with it).
  double credit_slack = 1.0;
  double credit_regrant_s = 0.25;
  // An experiment knob (ours, issue 20): each actor keeps the newest simulated_lag + 1 weights
  // versions it received and acts each segment with one drawn uniformly among them, so segments
  // arrive up to simulated_lag versions old (plus the natural lag). For measuring off-policy
  // corrections (ppo.vtrace) on a machine too small to lag by itself. 0: off.
  int simulated_lag = 0;
  // Several learners (ours, issue 20; docs/scaling.md "Several learners"): `learners` processes
  // (`perch learner --rank 0..learners-1`), each with its own actors and batch, sum every
  // minibatch's gradient over the group (DD-PPO), so they hold the same weights. Rank 0 binds
  // group_address, the others connect to it. An operation that has not completed on every member
  // within group_timeout_s fails (the members' batches fill at their actors' pace, so it must
  // exceed the slowest member's batch time). 1: one learner, no group.
  // Who may talk to the learner (issue 17; protocol/security.h): CURVE keys from keys_dir
  // (else $PERCH_KEYS_DIR) on every tcp/ipc socket. insecure: no keys, for a trusted network only.
  bool insecure = false;
  std::string keys_dir;
  int learners = 1;
  std::string group_address = "tcp://127.0.0.1:5570";
  double group_timeout_s = 600.0;
};

const FieldTable<ClusterConfig>& ClusterConfigFields();
Json ToJson(const ClusterConfig& c);
ClusterConfig ClusterConfigFromJson(const Json& j, const std::string& ctx);

// "walk" -> TASK_WALK, ...; throws ConfigError naming ctx for an unknown name.
proto::Task TaskFromName(const std::string& name, const std::string& ctx);
std::string TaskName(proto::Task task);

// Port numbers from a --*-port flag: 1..65535, else ConfigError naming the flag.
void CheckPort(int port, const std::string& flag);
// A ZeroMQ endpoint: tcp://HOST:PORT, tcp://*:PORT, inproc://NAME or ipc://PATH.
void CheckEndpoint(const std::string& endpoint, const std::string& flag);

}  // namespace perch
