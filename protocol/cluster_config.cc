#include "protocol/cluster_config.h"

#include <cmath>
#include <cstdlib>

#include "common/subtasks.h"

namespace perch {

Json ToJson(const ClusterConfig& c) {
  return Json{{"task", c.task},
              {"segment_steps", c.segment_steps},
              {"envs_per_actor", c.envs_per_actor},
              {"max_policy_lag", c.max_policy_lag},
              {"checkpoint_every", c.checkpoint_every},
              {"keep_last", c.keep_last},
              {"milestone_every", c.milestone_every},
              {"heartbeat_s", c.heartbeat_s},
              {"actor_timeout_s", c.actor_timeout_s},
              {"max_message_bytes", c.max_message_bytes},
              {"max_segment_steps", c.max_segment_steps},
              {"max_wire_value", c.max_wire_value},
              {"reconnect_ivl_ms", c.reconnect_ivl_ms},
              {"hierarchy_meta_period", c.hierarchy_meta_period},
              {"hierarchy_enabled", c.hierarchy_enabled},
              {"restart_backoff_ms", c.restart_backoff_ms},
              {"restart_backoff_max_ms", c.restart_backoff_max_ms},
              {"max_identical_failures", c.max_identical_failures},
              {"learner_watchdog_s", c.learner_watchdog_s},
              {"learner_queue_segments", c.learner_queue_segments},
              {"init_from", c.init_from},
              {"init_mirror", c.init_mirror},
              {"max_samples", c.max_samples},
              {"target_success", c.target_success},
              {"target_window", c.target_window},
              {"credit_slack", c.credit_slack},
              {"credit_regrant_s", c.credit_regrant_s},
              {"simulated_lag", c.simulated_lag},
              {"insecure", c.insecure},
              {"keys_dir", c.keys_dir},
              {"learners", c.learners},
              {"group_address", c.group_address},
              {"group_timeout_s", c.group_timeout_s}};
}

namespace {
void CheckMin(const std::string& ctx, const char* field, double v, double lo) {
  if (v < lo) {
    throw ConfigError(ctx + "." + field + ": must be >= " + std::to_string(lo) + ", got " +
                      std::to_string(v));
  }
}
}  // namespace

ClusterConfig ClusterConfigFromJson(const Json& j, const std::string& ctx) {
  CheckKnownKeys(j,
                 {"task",
                  "segment_steps",
                  "envs_per_actor",
                  "max_policy_lag",
                  "checkpoint_every",
                  "keep_last",
                  "milestone_every",
                  "heartbeat_s",
                  "actor_timeout_s",
                  "max_message_bytes",
                  "max_segment_steps",
                  "max_wire_value",
                  "reconnect_ivl_ms",
                  "hierarchy_meta_period",
                  "hierarchy_enabled",
                  "restart_backoff_ms",
                  "restart_backoff_max_ms",
                  "max_identical_failures",
                  "learner_watchdog_s",
                  "learner_queue_segments",
                  "init_from",
                  "init_mirror",
                  "max_samples",
                  "target_success",
                  "target_window",
                  "credit_slack",
                  "credit_regrant_s",
                  "simulated_lag",
                  "insecure",
                  "keys_dir",
                  "learners",
                  "group_address",
                  "group_timeout_s"},
                 ctx);
  ClusterConfig c;
  GetOptional(j, "task", c.task, ctx);
  GetOptional(j, "segment_steps", c.segment_steps, ctx);
  GetOptional(j, "envs_per_actor", c.envs_per_actor, ctx);
  GetOptional(j, "max_policy_lag", c.max_policy_lag, ctx);
  GetOptional(j, "checkpoint_every", c.checkpoint_every, ctx);
  GetOptional(j, "keep_last", c.keep_last, ctx);
  GetOptional(j, "milestone_every", c.milestone_every, ctx);
  GetOptional(j, "heartbeat_s", c.heartbeat_s, ctx);
  GetOptional(j, "actor_timeout_s", c.actor_timeout_s, ctx);
  GetOptional(j, "max_message_bytes", c.max_message_bytes, ctx);
  GetOptional(j, "max_segment_steps", c.max_segment_steps, ctx);
  GetOptional(j, "max_wire_value", c.max_wire_value, ctx);
  GetOptional(j, "reconnect_ivl_ms", c.reconnect_ivl_ms, ctx);
  GetOptional(j, "hierarchy_meta_period", c.hierarchy_meta_period, ctx);
  GetOptional(j, "hierarchy_enabled", c.hierarchy_enabled, ctx);
  GetOptional(j, "restart_backoff_ms", c.restart_backoff_ms, ctx);
  GetOptional(j, "restart_backoff_max_ms", c.restart_backoff_max_ms, ctx);
  GetOptional(j, "max_identical_failures", c.max_identical_failures, ctx);
  GetOptional(j, "learner_watchdog_s", c.learner_watchdog_s, ctx);
  GetOptional(j, "learner_queue_segments", c.learner_queue_segments, ctx);
  GetOptional(j, "init_from", c.init_from, ctx);
  GetOptional(j, "init_mirror", c.init_mirror, ctx);
  GetOptional(j, "max_samples", c.max_samples, ctx);
  GetOptional(j, "target_success", c.target_success, ctx);
  GetOptional(j, "target_window", c.target_window, ctx);
  GetOptional(j, "credit_slack", c.credit_slack, ctx);
  GetOptional(j, "credit_regrant_s", c.credit_regrant_s, ctx);
  GetOptional(j, "simulated_lag", c.simulated_lag, ctx);
  GetOptional(j, "insecure", c.insecure, ctx);
  GetOptional(j, "keys_dir", c.keys_dir, ctx);
  GetOptional(j, "learners", c.learners, ctx);
  GetOptional(j, "group_address", c.group_address, ctx);
  GetOptional(j, "group_timeout_s", c.group_timeout_s, ctx);
  c.task = TaskName(TaskFromName(c.task, ctx + ".task"));  // one spelling from here on
  CheckMin(ctx, "segment_steps", c.segment_steps, 1);
  CheckMin(ctx, "envs_per_actor", c.envs_per_actor, 1);
  // Each env is a Bullet world (~1 MB) stepped in turn on one core: thousands are a mistake (1e9
  // made the actor crash at 1.5 GB).
  if (c.envs_per_actor > 1024) {
    throw ConfigError(ctx + ".envs_per_actor: " + std::to_string(c.envs_per_actor) +
                      " is more than 1024 (one actor steps its envs on one core; add actors)");
  }
  CheckMin(ctx, "max_policy_lag", c.max_policy_lag, 0);
  CheckMin(ctx, "checkpoint_every", c.checkpoint_every, 1);
  CheckMin(ctx, "keep_last", c.keep_last, 1);
  CheckMin(ctx, "milestone_every", c.milestone_every, 0);
  CheckMin(ctx, "heartbeat_s", c.heartbeat_s, 0.01);
  CheckMin(ctx, "actor_timeout_s", c.actor_timeout_s, 0.01);
  CheckMin(ctx, "max_message_bytes", c.max_message_bytes, 1024);
  CheckMin(ctx, "max_segment_steps", c.max_segment_steps, 1);
  if (!(c.max_wire_value > 0 && std::isfinite(c.max_wire_value))) {
    throw ConfigError(ctx + ".max_wire_value: must be finite and > 0");
  }
  CheckMin(ctx, "reconnect_ivl_ms", c.reconnect_ivl_ms, 1);
  CheckMin(ctx, "hierarchy_meta_period", c.hierarchy_meta_period, 1);
  CheckMin(ctx, "restart_backoff_ms", c.restart_backoff_ms, 0);
  CheckMin(ctx, "restart_backoff_max_ms", c.restart_backoff_max_ms, c.restart_backoff_ms);
  CheckMin(ctx, "max_identical_failures", c.max_identical_failures, 0);
  CheckMin(ctx, "learner_watchdog_s", c.learner_watchdog_s, 0);
  CheckMin(ctx, "learner_queue_segments", c.learner_queue_segments, 1);
  if (c.init_mirror && c.init_from.empty()) {
    throw ConfigError(ctx + ".init_mirror: needs cluster.init_from (the policy to mirror)");
  }
  if (c.max_samples < 0) throw ConfigError(ctx + ".max_samples: must be >= 0 (0: no budget)");
  if (!(c.target_success >= 0.0 && c.target_success <= 1.0)) {
    throw ConfigError(ctx + ".target_success: must be in [0, 1] (0: no target)");
  }
  CheckMin(ctx, "target_window", c.target_window, 1);
  if (!(c.credit_slack >= 0.0 && c.credit_slack <= 100.0)) {
    throw ConfigError(ctx + ".credit_slack: must be in [0, 100] (0: no flow control)");
  }
  CheckMin(ctx, "credit_regrant_s", c.credit_regrant_s, 0.01);
  CheckMin(ctx, "simulated_lag", c.simulated_lag, 0);
  if (c.simulated_lag > c.max_policy_lag) {
    // Every segment drawn past the learner's window would be dropped as stale.
    throw ConfigError(ctx + ".simulated_lag: " + std::to_string(c.simulated_lag) +
                      " exceeds max_policy_lag " + std::to_string(c.max_policy_lag));
  }
  if (c.learners < 1 || c.learners > 64) {
    throw ConfigError(ctx + ".learners: must be in 1..64, got " + std::to_string(c.learners));
  }
  CheckMin(ctx, "group_timeout_s", c.group_timeout_s, 1.0);
  if (c.learners > 1) CheckEndpoint(c.group_address, ctx + ".group_address");
  if (c.segment_steps > c.max_segment_steps) {
    throw ConfigError(ctx + ".segment_steps: " + std::to_string(c.segment_steps) +
                      " exceeds max_segment_steps " + std::to_string(c.max_segment_steps));
  }
  return c;
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
