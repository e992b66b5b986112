// Weights, optimizer, normalizer and learner state to and from Protobuf: round trips are exact,
// resuming continues bit for bit, another network shape or a corrupt blob is refused with an
// error that names the problem, and a refused import changes nothing.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "common/proto/model.pb.h"
#include "learner/ppo.h"
#include "policy/policy.h"

namespace perch {
namespace {

PpoConfig SmallPpo() {
  PpoConfig c;
  c.steps_per_update = 64;
  c.num_minibatches = 4;
  c.num_epochs = 2;
  return c;
}

// A synthetic batch acted by the learner's current policy.
std::vector<Rollout> MakeBatch(const PpoLearner& learner, uint64_t seed, int steps = 64) {
  const PolicyConfig& c = learner.model().config();
  PolicyRunner runner(c, learner.config().obs_norm);
  runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(), 0);
  Rng rng(seed);
  Rollout r(c.obs_dim, c.action_size());
  r.stream_id = 7;
  std::vector<float> raw(c.obs_dim), norm(c.obs_dim), a(c.action_size());
  for (int t = 0; t < steps; ++t) {
    for (float& x : raw) x = static_cast<float>(rng.Normal(0.5, 2.0));
    const auto o = runner.Act(raw.data(), rng, false, norm.data(), a.data());
    const bool term = t % 17 == 16, trunc = t % 23 == 22;
    r.Add(norm.data(), a.data(), o.log_prob, o.value, static_cast<float>(rng.Normal()), term, trunc,
          (trunc || t + 1 == steps) ? runner.Value(raw.data()) : 0.0f);
  }
  r.obs_stats_delta = runner.obs_stats_delta();
  return {r};
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(SerializeTest, WeightsRoundTripThroughBytesToARunner) {
  PpoLearner learner(PolicyConfig::Subtask(52), SmallPpo(), 1);
  learner.Update(MakeBatch(learner, 2));
  proto::ModelWeights w;
  learner.ExportWeights(&w);
  std::string bytes;
  ASSERT_TRUE(w.SerializeToString(&bytes));
  proto::ModelWeights back;
  ASSERT_TRUE(back.ParseFromString(bytes));
  EXPECT_EQ(back.version(), 1u);
  PolicyRunner runner(PolicyConfig::Subtask(52), NormalizerConfig());
  runner.LoadWeights(back);
  EXPECT_EQ(runner.model().params(), learner.model().params());
  EXPECT_EQ(runner.normalizer().stats().mean(), learner.obs_normalizer().stats().mean());
  EXPECT_EQ(runner.version(), 1u);
  // A learner importing the blob gets the same weights and statistics.
  PpoLearner other(PolicyConfig::Subtask(52), SmallPpo(), 9);
  other.ImportWeights(back, "blob");
  EXPECT_EQ(other.model().params(), learner.model().params());
  EXPECT_EQ(other.obs_normalizer().stats().var(), learner.obs_normalizer().stats().var());
}

TEST(SerializeTest, AnotherShapeIsRefusedNamingTheField) {
  PpoLearner src(PolicyConfig::Subtask(52), SmallPpo(), 1);
  proto::ModelWeights w;
  src.ExportWeights(&w);
  PolicyConfig wider = PolicyConfig::Subtask(52);
  wider.policy_net.hidden = {128, 64};
  PolicyConfig fixed = PolicyConfig::Subtask(52);
  fixed.std_mode = StdMode::kFixed;
  const std::pair<PolicyConfig, std::string> cases[] = {{PolicyConfig::Subtask(57), "obs_dim"},
                                                        {wider, "policy_hidden"},
                                                        {fixed, "std_mode"},
                                                        {PolicyConfig::Meta(52), "kind"}};
  for (const auto& [cfg, field] : cases) {
    PpoLearner dst(cfg, SmallPpo(), 3);
    const VectorXf before = dst.model().params();
    const std::string err = ErrorOf([&] { dst.ImportWeights(w, "ckpt.pb"); });
    EXPECT_NE(err.find(field), std::string::npos) << err;
    EXPECT_NE(err.find("ckpt.pb"), std::string::npos) << err;
    EXPECT_EQ(dst.model().params(), before);
    PolicyRunner runner(cfg, NormalizerConfig());
    EXPECT_THROW(runner.LoadWeights(w), ConfigError);
  }
}

TEST(SerializeTest, InconsistentOrCorruptBlobsAreRefused) {
  PpoLearner learner(PolicyConfig::Subtask(52), SmallPpo(), 1);
  proto::ModelWeights w;
  learner.ExportWeights(&w);
  proto::ModelWeights short_params = w;
  short_params.mutable_params()->RemoveLast();
  EXPECT_NE(ErrorOf([&] { learner.ImportWeights(short_params, "x"); }).find("params"),
            std::string::npos);
  proto::ModelWeights nan = w;
  nan.set_params(3, std::nanf(""));
  EXPECT_NE(ErrorOf([&] { learner.ImportWeights(nan, "x"); }).find("NaN"), std::string::npos);
  proto::ModelWeights stats = w;
  stats.mutable_obs_stats()->mutable_mean()->RemoveLast();
  EXPECT_NE(ErrorOf([&] { learner.ImportWeights(stats, "x"); }).find("obs_stats"),
            std::string::npos);
  // Truncated bytes: either the parse fails or the import refuses.
  std::string bytes;
  w.SerializeToString(&bytes);
  proto::ModelWeights cut;
  const bool parsed = cut.ParseFromString(bytes.substr(0, bytes.size() / 2));
  if (parsed) {
    EXPECT_THROW(learner.ImportWeights(cut, "x"), ConfigError);
  }
}

TEST(SerializeTest, ResumingFromLearnerStateContinuesBitForBit) {
  const PolicyConfig pc = PolicyConfig::Meta(9);
  PpoLearner a(pc, SmallPpo(), 11);
  for (int u = 0; u < 2; ++u) a.Update(MakeBatch(a, 20 + u));
  proto::LearnerState s;
  a.ExportState(&s);
  std::string bytes;
  ASSERT_TRUE(s.SerializeToString(&bytes));
  proto::LearnerState parsed;
  ASSERT_TRUE(parsed.ParseFromString(bytes));
  PpoLearner b(pc, SmallPpo(), 999);  // other seed: everything must come from the blob
  b.ImportState(parsed, "state.pb");
  EXPECT_EQ(b.num_updates(), 2);
  EXPECT_EQ(b.optimizer().step(), a.optimizer().step());
  EXPECT_EQ(b.reward_scaler().streams(), a.reward_scaler().streams());
  const std::vector<Rollout> next = MakeBatch(a, 30);
  const UpdateStats sa = a.Update(next);
  const UpdateStats sb = b.Update(next);
  EXPECT_EQ(a.model().params(), b.model().params());
  EXPECT_EQ(a.optimizer().m(), b.optimizer().m());
  EXPECT_EQ(sa.policy_loss, sb.policy_loss);
  EXPECT_EQ(a.obs_normalizer().stats().mean(), b.obs_normalizer().stats().mean());
  EXPECT_FALSE(s.ppo_config_json().empty());
}

TEST(SerializeTest, BadLearnerStateChangesNothing) {
  PpoLearner a(PolicyConfig::Subtask(9), SmallPpo(), 1);
  a.Update(MakeBatch(a, 1));
  proto::LearnerState s;
  a.ExportState(&s);
  s.mutable_adam()->mutable_v()->RemoveLast();
  PpoLearner b(PolicyConfig::Subtask(9), SmallPpo(), 2);
  const VectorXf before = b.model().params();
  const std::string err = ErrorOf([&] { b.ImportState(s, "state.pb"); });
  EXPECT_NE(err.find("state.pb.adam"), std::string::npos) << err;
  EXPECT_EQ(b.model().params(), before);
  EXPECT_EQ(b.num_updates(), 0);
}

TEST(SerializeTest, RolloutSegmentRoundTripAndValidation) {
  PpoLearner learner(PolicyConfig::Subtask(9), SmallPpo(), 1);
  const Rollout r = MakeBatch(learner, 3)[0];
  proto::RolloutSegment p;
  r.ToProto(&p);
  std::string bytes;
  p.SerializeToString(&bytes);
  proto::RolloutSegment q;
  ASSERT_TRUE(q.ParseFromString(bytes));
  const Rollout back = Rollout::FromProto(q, "segment");
  EXPECT_EQ(back.obs, r.obs);
  EXPECT_EQ(back.actions, r.actions);
  EXPECT_EQ(back.terminated, r.terminated);
  EXPECT_EQ(back.truncated, r.truncated);
  EXPECT_EQ(back.bootstrap_values, r.bootstrap_values);
  EXPECT_EQ(back.stream_id, 7u);
  EXPECT_EQ(back.obs_stats_delta.mean(), r.obs_stats_delta.mean());
  proto::RolloutSegment huge = q;
  huge.set_obs_dim(1 << 30);  // garbage size: refused before anything is allocated
  EXPECT_NE(ErrorOf([&] { Rollout::FromProto(huge, "segment"); }).find("out of range"),
            std::string::npos);
  q.mutable_obs()->RemoveLast();
  EXPECT_NE(ErrorOf([&] { Rollout::FromProto(q, "segment"); }).find("segment.obs"),
            std::string::npos);
}

TEST(SerializeTest, UpdateRefusesABadMetaChoiceBeforeChangingAnything) {
  PpoLearner learner(PolicyConfig::Meta(9), SmallPpo(), 1);
  std::vector<Rollout> batch = MakeBatch(learner, 3);
  batch[0].actions[5 * 3] = 4.0f;  // step 5 chooses a subtask that does not exist
  const VectorXf before = learner.model().params();
  const std::string err = ErrorOf([&] { learner.Update(batch); });
  EXPECT_NE(err.find("rollout[0].actions"), std::string::npos) << err;
  EXPECT_EQ(learner.model().params(), before);
  EXPECT_EQ(learner.optimizer().step(), 0);
}

TEST(SerializeTest, UpdateRefusesMismatchedRollouts) {
  PpoLearner learner(PolicyConfig::Subtask(9), SmallPpo(), 1);
  std::vector<Rollout> batch = MakeBatch(learner, 3);
  batch.push_back(Rollout(8, 21));
  const VectorXf before = learner.model().params();
  EXPECT_NE(ErrorOf([&] { learner.Update(batch); }).find("rollout[1]"), std::string::npos);
  EXPECT_EQ(learner.model().params(), before);
}

}  // namespace
}  // namespace perch
