// Receiving side of the wire schema (common/proto/wire.proto): size limits, parsing and shape
// checks. Nothing here throws on bad input: a message is either accepted or rejected with a reason
// that the learner counts and logs (rate-limited).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "common/env.h"
#include "common/proto/wire.pb.h"

namespace perch {

struct WireLimits {
  size_t max_message_bytes = 64 << 20;
  int max_segment_steps = 8192;
  int obs_dim = 0;  // expected; 0 accepts any
  int act_dim = 0;  // action_size
  int max_pose_dim = 4096;
  // Meta policies: the first action number is a switch class, an integer in [0, num_choices)
  // (anything else would index past the logits in the PPO update). 0: not a meta policy.
  int num_choices = 0;
  // |x| above this in any number of a segment is rejected before it touches learner state (a
  // finite 1e30 would otherwise overflow the normaliser or the weights; issue 17).
  double max_abs_value = 1e6;
};

// Why a message was rejected; kOk when accepted. Counted per kind in the learner's metrics.
enum class WireReject { kOk, kTooBig, kParse, kVersion, kEmpty, kShape, kNonFinite, kRange };
const char* WireRejectName(WireReject r);

// Frozen policies (common/env.h) on the wire: a TaskPolicy with frozen = true. ConfigError for
// an unknown subtask name or a model that does not parse.
proto::TaskPolicy FrozenPolicyToProto(const FrozenPolicyData& p);
FrozenPolicyData FrozenPolicyFromProto(const proto::TaskPolicy& p);

// Parses and validates an actor -> learner message.
WireReject ParseActorMessage(const void* data, size_t size, const WireLimits& limits,
                             proto::ActorMessage* out, std::string* why);
// Shape and finiteness checks of one segment (called by ParseActorMessage).
WireReject ValidateSegment(const proto::Segment& s, const WireLimits& limits, std::string* why);

// Parses a learner -> actor message (the actor's side of the same checks).
WireReject ParseLearnerMessage(const void* data, size_t size, size_t max_bytes,
                               proto::LearnerMessage* out, std::string* why);

// Routes protobuf's own log lines (e.g. "invalid UTF-8" for every hostile Hello) through spdlog,
// at most one line per 5 s with a count of the rest: a flood of bad messages cannot flood the log.
// Call once at start (perch's main does).
void RateLimitProtobufLogs();

}  // namespace perch
