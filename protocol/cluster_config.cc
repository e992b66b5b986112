#include "protocol/cluster_config.h"

#include <cmath>
#include <cstdlib>

#include "common/subtasks.h"

namespace perch {

namespace {

// The message the hand-written checks gave: "CTX.field: MESSAGE".
std::string Fail(const std::string& ctx, const char* field, const std::string& what) {
  return ctx + "." + field + ": " + what;
}

}  // namespace

const FieldTable<ClusterConfig>& ClusterConfigFields() {
  using C = ClusterConfig;
  static const FieldTable<ClusterConfig> t =
      FieldTable<C>()
          .Custom(
              "task", "the policy trained: a subtask, meta or stand",
              [](const Json& j, C& c, const std::string& ctx) {
                GetOptional(j, "task", c.task, ctx);
                c.task = TaskName(TaskFromName(c.task, ctx + ".task"));  // one spelling
              },
              [](const C& c, Json& j) { j["task"] = c.task; })
          .Add("segment_steps", &C::segment_steps, "T: control steps per rollout segment",
               AtLeast<int>(1))
          .Add("envs_per_actor", &C::envs_per_actor, "default for `perch actor --envs`",
               AtLeast<int>(1))
          .Add("max_policy_lag", &C::max_policy_lag,
               "segments from versions older than current - lag are dropped", AtLeast<int>(0))
          .Add("checkpoint_every", &C::checkpoint_every, "updates between checkpoints",
               AtLeast<int>(1))
          .Add("keep_last", &C::keep_last, "rotated checkpoints kept", AtLeast<int>(1))
          .Add("milestone_every", &C::milestone_every,
               "updates; checkpoints at multiples are kept forever (0: none)", AtLeast<int>(0))
          .Add("heartbeat_s", &C::heartbeat_s, "actor -> learner heartbeat period",
               AtLeast<double>(0.01))
          .Add("actor_timeout_s", &C::actor_timeout_s,
               "an actor silent this long is counted as gone", AtLeast<double>(0.01))
          .Add("max_message_bytes", &C::max_message_bytes, "bigger messages are dropped unparsed",
               AtLeast<int>(1024))
          .Add("max_segment_steps", &C::max_segment_steps, "T above this is rejected",
               AtLeast<int>(1))
          .Add("max_wire_value", &C::max_wire_value, "|x| above this in a segment is rejected",
               Satisfies<double>([](const double& v) { return v > 0 && std::isfinite(v); },
                                 "must be finite and > 0"))
          .Add("reconnect_ivl_ms", &C::reconnect_ivl_ms, "ZeroMQ reconnect interval",
               AtLeast<int>(1))
          .Add("hierarchy_meta_period", &C::hierarchy_meta_period,
               "control steps per meta decision", AtLeast<int>(1))
          .Add("hierarchy_enabled", &C::hierarchy_enabled,
               "run the 2 Hz meta policy over the subtasks")
          .Add("restart_backoff_ms", &C::restart_backoff_ms,
               "a dead child is restarted after this, doubling per failure in a row",
               AtLeast<int>(0))
          .Add("restart_backoff_max_ms", &C::restart_backoff_max_ms, "the backoff's ceiling")
          .Add("max_identical_failures", &C::max_identical_failures,
               "failures in a row with the same status before giving up (0: never)",
               AtLeast<int>(0))
          .Add("learner_watchdog_s", &C::learner_watchdog_s,
               "a learner without an update this long is reported (0: no watchdog)",
               AtLeast<double>(0))
          .Add("learner_queue_segments", &C::learner_queue_segments,
               "segments queued per actor connection at the learner", AtLeast<int>(1))
          .Add("init_from", &C::init_from,
               "a new run starts from this checkpoint's policy and normalizer (empty: scratch)")
          .Add("init_mirror", &C::init_mirror, "init_from is the mirror-image task's policy")
          .Add("init_state", &C::init_state,
               "init_from also carries Adam, reward scaling and the PPO RNG (a branch)")
          .Add("max_samples", &C::max_samples, "the run ends after this many samples (0: none)",
               Satisfies<int64_t>([](const int64_t& v) { return v >= 0; },
                                  "must be >= 0 (0: no budget)"))
          .Add("target_success", &C::target_success,
               "the run ends at this success rate over target_window episodes (0: none)",
               Satisfies<double>([](const double& v) { return v >= 0.0 && v <= 1.0; },
                                 "must be in [0, 1] (0: no target)"))
          .Add("target_window", &C::target_window, "episodes judged for target_success",
               AtLeast<int>(1))
          .Add("credit_slack", &C::credit_slack,
               "flow control: credit beyond the next batch's need (0: no flow control)",
               Satisfies<double>([](const double& v) { return v >= 0.0 && v <= 100.0; },
                                 "must be in [0, 100] (0: no flow control)"))
          .Add("credit_regrant_s", &C::credit_regrant_s,
               "a learner that heard nothing this long grants again", AtLeast<double>(0.01))
          .Add("simulated_lag", &C::simulated_lag,
               "actors act with weights up to this many versions old (0: off)", AtLeast<int>(0))
          .Add("insecure", &C::insecure, "no CURVE keys: for a trusted network only")
          .Add("keys_dir", &C::keys_dir, "CURVE keys (else $PERCH_KEYS_DIR)")
          .Add("learners", &C::learners, "learner processes in a DD-PPO group",
               Satisfies<int>([](const int& v) { return v >= 1 && v <= 64; }, "must be in 1..64")
                   .WithValue())
          .Add("group_address", &C::group_address, "rank 0 binds it, the others connect")
          .Add("group_timeout_s", &C::group_timeout_s,
               "a group operation not completed on every member within this fails",
               AtLeast<double>(1.0))
          .Rule([](const C& c, const std::string& ctx) {
            if (c.envs_per_actor > 1024) {
              // Each env is a Bullet world (~1 MB) stepped in turn on one core: thousands are a
              // mistake (1e9 made the actor crash at 1.5 GB).
              return Fail(ctx, "envs_per_actor",
                          std::to_string(c.envs_per_actor) +
                              " is more than 1024 (one actor steps its envs on one core; add "
                              "actors)");
            }
            if (c.restart_backoff_max_ms < c.restart_backoff_ms) {
              return Fail(ctx, "restart_backoff_max_ms",
                          "must be >= " + std::to_string(double(c.restart_backoff_ms)) + ", got " +
                              std::to_string(double(c.restart_backoff_max_ms)));
            }
            if (c.init_mirror && c.init_from.empty()) {
              return Fail(ctx, "init_mirror", "needs cluster.init_from (the policy to mirror)");
            }
            if (c.simulated_lag > c.max_policy_lag) {
              // Every segment drawn past the learner's window would be dropped as stale.
              return Fail(ctx, "simulated_lag",
                          std::to_string(c.simulated_lag) + " exceeds max_policy_lag " +
                              std::to_string(c.max_policy_lag));
            }
            if (c.segment_steps > c.max_segment_steps) {
              return Fail(ctx, "segment_steps",
                          std::to_string(c.segment_steps) + " exceeds max_segment_steps " +
                              std::to_string(c.max_segment_steps));
            }
            if (c.learners > 1) CheckEndpoint(c.group_address, ctx + ".group_address");
            return std::string();
          });
  return t;
}

Json ToJson(const ClusterConfig& c) { return ClusterConfigFields().Write(c); }

ClusterConfig ClusterConfigFromJson(const Json& j, const std::string& ctx) {
  return ClusterConfigFields().Read(j, ctx);
}

proto::Task TaskFromName(const std::string& name, const std::string& ctx) {
  if (const int id = SubtaskIdOf(name); id >= 0) return Subtasks()[id].wire;
  // The older left_turn / right_turn still read.
  if (name == "left_turn") return proto::TASK_LEFT_TURN;
  if (name == "right_turn") return proto::TASK_RIGHT_TURN;
  if (name == "meta") return proto::TASK_META;
  if (name == "stand") return proto::TASK_STAND;
  throw ConfigError(ctx + ": unknown task '" + name + "' (" + SubtaskNamesJoined() +
                    ", meta, stand)");
}

std::string TaskName(proto::Task task) {
  if (const int id = SubtaskIdOfWire(task); id >= 0) return SubtaskName(id);
  switch (task) {
    case proto::TASK_META:
      return "meta";
    case proto::TASK_STAND:
      return "stand";
    default:
      return "unspecified";
  }
}

void CheckPort(int port, const std::string& flag) {
  if (port < 1 || port > 65535) {
    throw ConfigError(flag + ": port must be in 1..65535, got " + std::to_string(port));
  }
}

void CheckEndpoint(const std::string& e, const std::string& flag) {
  auto starts = [&](const char* p) { return e.rfind(p, 0) == 0; };
  if (starts("inproc://") || starts("ipc://")) {
    if (e.find("://") + 3 >= e.size())
      throw ConfigError(flag + ": empty endpoint name in '" + e + "'");
    return;
  }
  if (!starts("tcp://")) {
    throw ConfigError(flag + ": expected tcp://HOST:PORT, inproc://NAME or ipc://PATH, got '" + e +
                      "'");
  }
  const size_t colon = e.rfind(':');
  if (colon == std::string::npos || colon < 6 || colon + 1 >= e.size() || colon == 3) {
    throw ConfigError(flag + ": missing port in '" + e + "'");
  }
  const std::string host = e.substr(6, colon - 6);
  if (host.empty()) throw ConfigError(flag + ": missing host in '" + e + "'");
  char* end = nullptr;
  const long port = std::strtol(e.c_str() + colon + 1, &end, 10);
  if (*end != '\0') throw ConfigError(flag + ": bad port in '" + e + "'");
  CheckPort(static_cast<int>(port), flag);
}

}  // namespace perch
