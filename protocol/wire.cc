#include "protocol/wire.h"

#include <google/protobuf/stubs/logging.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <utility>

#include "common/json_util.h"
#include "protocol/cluster_config.h"

namespace perch {
namespace {

// Index of the first |x| > bound, or -1.
template <typename R>
int FirstAbove(const R& r, double bound) {
  int i = 0;
  for (auto v : r) {
    if (std::abs(static_cast<double>(v)) > bound) return i;
    ++i;
  }
  return -1;
}

template <typename R>
bool AllFinite(const R& r) {
  for (float v : r) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

WireReject Shape(std::string* why, const std::string& msg) {
  *why = msg;
  return WireReject::kShape;
}

std::string Got(const char* field, int got, int64_t want) {
  return std::string(field) + " has " + std::to_string(got) + " values, expected " +
         std::to_string(want);
}

}  // namespace

const char* WireRejectName(WireReject r) {
  switch (r) {
    case WireReject::kOk:
      return "ok";
    case WireReject::kTooBig:
      return "too_big";
    case WireReject::kParse:
      return "parse";
    case WireReject::kVersion:
      return "version";
    case WireReject::kEmpty:
      return "empty";
    case WireReject::kShape:
      return "shape";
    case WireReject::kNonFinite:
      return "non_finite";
    case WireReject::kRange:
      return "out_of_range";
  }
  return "?";
}

WireReject ValidateSegment(const proto::Segment& seg, const WireLimits& lim, std::string* why) {
  const proto::RolloutSegment& s = seg.rollout();
  const int64_t t = s.rewards_size();
  if (t < 1 || t > lim.max_segment_steps) {
    return Shape(why, "segment of " + std::to_string(t) + " steps, outside 1.." +
                          std::to_string(lim.max_segment_steps));
  }
  if (s.obs_dim() < 1 || s.action_size() < 1) return Shape(why, "obs_dim/action_size must be >= 1");
  if (lim.obs_dim > 0 && s.obs_dim() != lim.obs_dim) {
    return Shape(why, "obs_dim " + std::to_string(s.obs_dim()) + ", learner expects " +
                          std::to_string(lim.obs_dim));
  }
  if (lim.act_dim > 0 && s.action_size() != lim.act_dim) {
    return Shape(why, "action_size " + std::to_string(s.action_size()) + ", learner expects " +
                          std::to_string(lim.act_dim));
  }
  if (s.obs_size() != t * s.obs_dim()) return Shape(why, Got("obs", s.obs_size(), t * s.obs_dim()));
  if (s.actions_size() != t * s.action_size()) {
    return Shape(why, Got("actions", s.actions_size(), t * s.action_size()));
  }
  if (s.log_probs_size() != t) return Shape(why, Got("log_probs", s.log_probs_size(), t));
  if (s.values_size() != t) return Shape(why, Got("values", s.values_size(), t));
  if (static_cast<int64_t>(s.terminated().size()) != t) {
    return Shape(why, Got("terminated", static_cast<int>(s.terminated().size()), t));
  }
  if (static_cast<int64_t>(s.truncated().size()) != t) {
    return Shape(why, Got("truncated", static_cast<int>(s.truncated().size()), t));
  }
  if (s.bootstrap_values_size() != t) {
    return Shape(why, Got("bootstrap_values", s.bootstrap_values_size(), t));
  }
  if (seg.policy_versions_size() < 1) return Shape(why, "policy_versions is empty");
  const auto& m = s.obs_stats_delta();
  if (m.count() > 0 && (m.mean_size() != s.obs_dim() || m.var_size() != s.obs_dim())) {
    return Shape(why, "obs_stats_delta mean/var must have obs_dim values");
  }
  if (!AllFinite(s.obs()) || !AllFinite(s.actions()) || !AllFinite(s.log_probs()) ||
      !AllFinite(s.values()) || !AllFinite(s.rewards()) || !AllFinite(s.bootstrap_values()) ||
      !std::isfinite(seg.bootstrap_value())) {
    *why = "NaN or Inf in a segment array";
    return WireReject::kNonFinite;
  }
  if (!std::isfinite(m.count()) || m.count() < 0) {
    return *why = "bad obs_stats_delta.count", WireReject::kNonFinite;
  }
  for (double v : m.mean()) {
    if (!std::isfinite(v)) return *why = "NaN in obs_stats_delta", WireReject::kNonFinite;
  }
  for (double v : m.var()) {
    if (!std::isfinite(v) || v < 0) return *why = "bad obs_stats_delta.var", WireReject::kNonFinite;
  }
  // Finite but absurd: bounded by what a segment can hold and by max_abs_value.
  auto range = [why](const std::string& msg) {
    *why = msg;
    return WireReject::kRange;
  };
  // The actor's delta counts this segment's steps (policy/rollout.cc): no more than T.
  if (m.count() > static_cast<double>(t) + 1e-6) {
    return range("obs_stats_delta.count " + std::to_string(m.count()) + " exceeds the segment's " +
                 std::to_string(t) + " steps");
  }
  const double b = lim.max_abs_value;
  const std::pair<const char*, int> arrays[] = {
      {"obs", FirstAbove(s.obs(), b)},
      {"actions", FirstAbove(s.actions(), b)},
      {"log_probs", FirstAbove(s.log_probs(), b)},
      {"values", FirstAbove(s.values(), b)},
      {"rewards", FirstAbove(s.rewards(), b)},
      {"bootstrap_values", FirstAbove(s.bootstrap_values(), b)},
      {"obs_stats_delta.mean", FirstAbove(m.mean(), b)},
      {"obs_stats_delta.var", FirstAbove(m.var(), b * b)}};
  for (const auto& [name, i] : arrays) {
    if (i >= 0) return range(std::string(name) + "[" + std::to_string(i) + "] above max_abs_value");
  }
  if (std::abs(seg.bootstrap_value()) > b) return range("bootstrap_value above max_abs_value");
  if (lim.num_choices > 0) {
    const int a = s.action_size();
    for (int i = 0; i < s.actions_size(); i += a) {
      const float c = s.actions(i);
      if (c < 0 || c > lim.num_choices - 1 || c != std::round(c)) {
        return range("actions[" + std::to_string(i) + "]: meta switch class " + std::to_string(c) +
                     " is not an integer in [0, " + std::to_string(lim.num_choices) + ")");
      }
    }
  }
  for (const proto::EpisodeStats& e : seg.episodes()) {
    if (!std::isfinite(e.episode_return()))
      return *why = "NaN episode_return", WireReject::kNonFinite;
    if (std::abs(e.episode_return()) > b * std::max<double>(1, e.length()) ||
        e.length() > (1u << 30)) {
      return range("episode stats out of range");
    }
  }
  return WireReject::kOk;
}

proto::TaskPolicy FrozenPolicyToProto(const FrozenPolicyData& p) {
  proto::TaskPolicy t;
  t.set_task(TaskFromName(p.name, "frozen policy " + p.source));
  if (!t.mutable_model()->ParseFromString(p.model)) {
    throw ConfigError("frozen " + p.name + " policy " + p.source + ": model does not parse");
  }
  t.set_frozen(true);
  t.set_saved_config_json(p.saved_config);
  t.set_source(p.source);
  return t;
}

FrozenPolicyData FrozenPolicyFromProto(const proto::TaskPolicy& t) {
  FrozenPolicyData p;
  p.name = TaskName(t.task());
  p.model = t.model().SerializeAsString();
  p.saved_config = t.saved_config_json();
  p.source = t.source();
  return p;
}

WireReject ParseActorMessage(const void* data, size_t size, const WireLimits& lim,
                             proto::ActorMessage* out, std::string* why) {
  if (size > lim.max_message_bytes) {
    *why = std::to_string(size) + " bytes exceeds max_message_bytes " +
           std::to_string(lim.max_message_bytes);
    return WireReject::kTooBig;
  }
  if (!out->ParseFromArray(data, static_cast<int>(size))) {
    *why = "does not parse as perch.proto.ActorMessage";
    return WireReject::kParse;
  }
  if (out->wire_version() != proto::WIRE_VERSION_CURRENT) {
    *why = "wire_version " + std::to_string(out->wire_version()) + ", expected " +
           std::to_string(proto::WIRE_VERSION_CURRENT);
    return WireReject::kVersion;
  }
  switch (out->body_case()) {
    case proto::ActorMessage::kSegment:
      return ValidateSegment(out->segment(), lim, why);
    case proto::ActorMessage::kEndPoses: {
      const auto& p = out->end_poses();
      if (p.pose_dim() < 1 || static_cast<int>(p.pose_dim()) > lim.max_pose_dim ||
          p.poses_size() % p.pose_dim() != 0) {
        return Shape(why, "end_poses: pose_dim " + std::to_string(p.pose_dim()) +
                              " does not divide " + std::to_string(p.poses_size()) + " values");
      }
      if (!AllFinite(p.poses())) return *why = "NaN in end_poses", WireReject::kNonFinite;
      return WireReject::kOk;
    }
    case proto::ActorMessage::kHello:
    case proto::ActorMessage::kHeartbeat:
      return WireReject::kOk;
    default:
      *why = "message has no body";
      return WireReject::kEmpty;
  }
}

WireReject ParseLearnerMessage(const void* data, size_t size, size_t max_bytes,
                               proto::LearnerMessage* out, std::string* why) {
  if (size > max_bytes) {
    *why = std::to_string(size) + " bytes exceeds the limit " + std::to_string(max_bytes);
    return WireReject::kTooBig;
  }
  if (!out->ParseFromArray(data, static_cast<int>(size))) {
    *why = "does not parse as perch.proto.LearnerMessage";
    return WireReject::kParse;
  }
  if (out->wire_version() != proto::WIRE_VERSION_CURRENT) {
    *why = "wire_version " + std::to_string(out->wire_version());
    return WireReject::kVersion;
  }
  if (out->body_case() != proto::LearnerMessage::kWeights) {
    *why = "message has no body";
    return WireReject::kEmpty;
  }
  return WireReject::kOk;
}

namespace {

void ProtobufLogHandler(google::protobuf::LogLevel level, const char* filename, int line,
                        const std::string& message) {
  static std::mutex mu;
  static double last_s = -1e9;
  static uint64_t suppressed = 0;
  const double now =
      std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
  std::lock_guard<std::mutex> lock(mu);
  if (level < google::protobuf::LOGLEVEL_FATAL && now - last_s < 5.0) {
    ++suppressed;
    return;
  }
  last_s = now;
  spdlog::warn("protobuf: {} ({}:{}){}", message, filename, line,
               suppressed ? " (+" + std::to_string(suppressed) + " not logged)" : std::string());
  suppressed = 0;
}

}  // namespace

void RateLimitProtobufLogs() { google::protobuf::SetLogHandler(&ProtobufLogHandler); }

}  // namespace perch
