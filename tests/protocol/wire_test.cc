#include "protocol/wire.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "common/proto/model.pb.h"
#include "common/rng.h"
#include "policy/rollout.h"

namespace perch {
namespace {

constexpr int kObs = 5, kAct = 3, kSteps = 8;

proto::ActorMessage ValidSegment() {
  Rng rng(1);
  Rollout r(kObs, kAct);
  std::vector<float> obs(kObs), act(kAct);
  for (int t = 0; t < kSteps; ++t) {
    for (float& o : obs) o = static_cast<float>(rng.Normal());
    for (float& a : act) a = static_cast<float>(rng.Normal());
    r.Add(obs.data(), act.data(), -1.0f, 0.5f, 1.0f, false, t == 3, t == 3 ? 0.2f : 0.0f);
  }
  r.bootstrap_values.back() = 0.7f;
  proto::ActorMessage m;
  m.set_wire_version(proto::WIRE_VERSION_CURRENT);
  r.ToProto(m.mutable_segment()->mutable_rollout());
  auto* pv = m.mutable_segment()->add_policy_versions();
  pv->set_task(proto::TASK_STAND);
  pv->set_version(0);
  return m;
}

WireLimits Limits() {
  WireLimits l;
  l.obs_dim = kObs;
  l.act_dim = kAct;
  l.max_segment_steps = 64;
  l.max_message_bytes = 1 << 20;
  return l;
}

WireReject ParseBytes(const std::string& bytes, std::string* why) {
  proto::ActorMessage out;
  return ParseActorMessage(bytes.data(), bytes.size(), Limits(), &out, why);
}

TEST(WireTest, AcceptsValidSegment) {
  std::string why;
  EXPECT_EQ(ParseBytes(ValidSegment().SerializeAsString(), &why), WireReject::kOk) << why;
}

TEST(WireTest, RejectsGarbageAndTruncation) {
  std::string why;
  const std::string good = ValidSegment().SerializeAsString();
  // Every strict prefix of a valid message must be rejected, never crash.
  int rejected = 0;
  for (size_t n = 0; n < good.size(); ++n) {
    rejected += ParseBytes(good.substr(0, n), &why) != WireReject::kOk;
  }
  EXPECT_EQ(rejected, static_cast<int>(good.size()));
  Rng rng(7);
  for (int k = 0; k < 200; ++k) {
    std::string junk(1 + rng.UniformInt(300), '\0');
    for (char& c : junk) c = static_cast<char>(rng.UniformInt(256));
    EXPECT_NE(ParseBytes(junk, &why), WireReject::kOk);
  }
}

TEST(WireTest, RejectsWrongVersionEmptyAndTooBig) {
  std::string why;
  proto::ActorMessage m = ValidSegment();
  m.set_wire_version(99);
  EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kVersion);
  proto::ActorMessage empty;
  empty.set_wire_version(proto::WIRE_VERSION_CURRENT);
  EXPECT_EQ(ParseBytes(empty.SerializeAsString(), &why), WireReject::kEmpty);
  proto::ActorMessage out;
  WireLimits small = Limits();
  small.max_message_bytes = 10;
  const std::string good = ValidSegment().SerializeAsString();
  EXPECT_EQ(ParseActorMessage(good.data(), good.size(), small, &out, &why), WireReject::kTooBig);
}

TEST(WireTest, RejectsShapeErrors) {
  std::string why;
  {
    proto::ActorMessage m = ValidSegment();
    m.mutable_segment()->mutable_rollout()->mutable_obs()->RemoveLast();
    EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kShape);
    EXPECT_NE(why.find("obs"), std::string::npos) << why;
  }
  {
    proto::ActorMessage m = ValidSegment();
    m.mutable_segment()->mutable_rollout()->mutable_truncated()->push_back(0);
    EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kShape);
  }
  {
    proto::ActorMessage m = ValidSegment();
    m.mutable_segment()->mutable_rollout()->set_obs_dim(kObs + 1);
    EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kShape);
  }
  {
    proto::ActorMessage m = ValidSegment();
    m.mutable_segment()->clear_policy_versions();
    EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kShape);
  }
  {
    WireLimits l = Limits();
    l.max_segment_steps = kSteps - 1;
    proto::ActorMessage out;
    const std::string good = ValidSegment().SerializeAsString();
    EXPECT_EQ(ParseActorMessage(good.data(), good.size(), l, &out, &why), WireReject::kShape);
  }
}

// A meta segment's first action number indexes the switch's logits in the PPO update: anything
// but an integer class in range is refused before it gets there.
TEST(WireTest, RejectsMetaSwitchClassesOutOfRange) {
  WireLimits l = Limits();
  l.num_choices = 4;
  for (const float c : {0.0f, 3.0f, 2.5f, -1.0f, 4.0f, 1e5f}) {
    proto::ActorMessage m = ValidSegment();
    auto* r = m.mutable_segment()->mutable_rollout();
    for (int t = 0; t < kSteps; ++t) r->set_actions(t * kAct, 1.0f);
    r->set_actions(2 * kAct, c);
    const std::string bytes = m.SerializeAsString();
    proto::ActorMessage out;
    std::string why;
    const bool ok = c == 0.0f || c == 3.0f;
    EXPECT_EQ(ParseActorMessage(bytes.data(), bytes.size(), l, &out, &why),
              ok ? WireReject::kOk : WireReject::kRange)
        << c << " " << why;
    if (!ok) {
      EXPECT_NE(why.find("switch class"), std::string::npos) << why;
    }
  }
}

TEST(WireTest, RejectsNonFinite) {
  std::string why;
  proto::ActorMessage m = ValidSegment();
  m.mutable_segment()->mutable_rollout()->set_rewards(2, std::nanf(""));
  EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kNonFinite);
  proto::ActorMessage m2 = ValidSegment();
  m2.mutable_segment()->set_bootstrap_value(std::numeric_limits<float>::infinity());
  EXPECT_EQ(ParseBytes(m2.SerializeAsString(), &why), WireReject::kNonFinite);
}

// Raw-observation statistics of `count` samples (mean 0, var 1 per input).
void SetStats(proto::ActorMessage* m, double count) {
  auto* st = m->mutable_segment()->mutable_rollout()->mutable_obs_stats_delta();
  st->Clear();
  st->set_count(count);
  for (int i = 0; i < kObs; ++i) {
    st->add_mean(0.0);
    st->add_var(1.0);
  }
}

TEST(WireTest, RejectsFiniteButAbsurdValuesBeforeTheyTouchState) {
  // The attacks of issue 17: a statistics count far beyond what a segment holds (1e308 stopped
  // training), and finite values of 1e30 (they made the learner publish NaN weights).
  std::string why;
  {
    proto::ActorMessage m = ValidSegment();
    SetStats(&m, 1e308);
    EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kRange);
    EXPECT_NE(why.find("obs_stats_delta.count"), std::string::npos) << why;
  }
  {
    proto::ActorMessage m = ValidSegment();  // the count of the segment's own steps is fine
    SetStats(&m, kSteps);
    EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kOk) << why;
  }
  {
    proto::ActorMessage m = ValidSegment();
    m.mutable_segment()->mutable_rollout()->set_rewards(3, 1e30f);
    EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kRange);
    EXPECT_NE(why.find("rewards[3]"), std::string::npos) << why;
  }
  {
    proto::ActorMessage m = ValidSegment();
    m.mutable_segment()->mutable_rollout()->set_obs(7, -2e6f);
    EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kRange);
  }
  {
    proto::ActorMessage m = ValidSegment();
    SetStats(&m, kSteps);
    m.mutable_segment()->mutable_rollout()->mutable_obs_stats_delta()->set_var(0, 1e20);
    EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kRange);
  }
  {
    proto::ActorMessage m = ValidSegment();
    proto::EpisodeStats* e = m.mutable_segment()->add_episodes();
    e->set_length(10);
    e->set_episode_return(1e300);
    EXPECT_EQ(ParseBytes(m.SerializeAsString(), &why), WireReject::kRange);
  }
  {
    // The bound is the config's: a tighter one rejects what the default accepts.
    proto::ActorMessage m = ValidSegment();
    m.mutable_segment()->mutable_rollout()->set_rewards(0, 50.0f);
    const std::string bytes = m.SerializeAsString();
    proto::ActorMessage out;
    EXPECT_EQ(ParseActorMessage(bytes.data(), bytes.size(), Limits(), &out, &why), WireReject::kOk);
    WireLimits tight = Limits();
    tight.max_abs_value = 10.0;
    EXPECT_EQ(ParseActorMessage(bytes.data(), bytes.size(), tight, &out, &why), WireReject::kRange);
  }
  EXPECT_STREQ(WireRejectName(WireReject::kRange), "out_of_range");
}

TEST(WireTest, LearnerMessageChecks) {
  std::string why;
  proto::LearnerMessage out;
  proto::LearnerMessage m;
  m.set_wire_version(proto::WIRE_VERSION_CURRENT);
  m.mutable_weights()->set_version(3);
  const std::string good = m.SerializeAsString();
  EXPECT_EQ(ParseLearnerMessage(good.data(), good.size(), 1 << 20, &out, &why), WireReject::kOk);
  EXPECT_EQ(out.weights().version(), 3u);
  EXPECT_EQ(ParseLearnerMessage(good.data(), good.size(), 2, &out, &why), WireReject::kTooBig);
  const std::string junk = "\xff\xff\xff\xff garbage";
  EXPECT_NE(ParseLearnerMessage(junk.data(), junk.size(), 1 << 20, &out, &why), WireReject::kOk);
}

}  // namespace
}  // namespace perch
