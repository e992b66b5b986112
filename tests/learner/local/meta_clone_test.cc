#include "learner/local/meta_clone.h"

#include <gtest/gtest.h>

#include <memory>

#include "hierarchy/hierarchy.h"
#include "hierarchy/meta_env.h"
#include "hierarchy/meta_expert.h"
#include "tests/hierarchy/planned_meta.h"

namespace perch {
namespace {

using testing_util::PlannedMeta;

TEST(MetaClone, ClonesThePlannersChoicesAndDaggerAddsTheClonesStates) {
  const TaskEnvConfig c = PlannedMeta(2);
  const std::vector<FrozenPolicyData> frozen = LoadFrozenPolicies(c);
  auto plan = std::make_shared<const MetaPlan>(
      BuildMetaPlan(c, frozen, c.Section<SitChairTaskConfig>().meta.planner));
  PolicyConfig pc = PolicyConfig::Meta(62);
  CloneOptions o;
  o.episodes = 12;
  o.rounds = 2;
  o.epochs = 60;
  o.threads = 2;
  o.seed = 5;
  const CloneResult r = CloneMeta(c, frozen, pc, NormalizerConfig(), plan, o);
  const Json& rounds = r.summary["rounds"];
  ASSERT_EQ(rounds.size(), 2u);
  EXPECT_GT(rounds[1]["samples_total"].get<int>(), rounds[0]["samples_total"].get<int>());
  EXPECT_EQ(rounds[0]["samples_total"], rounds[0]["meta_steps"]);
  EXPECT_GT(rounds[0]["switch_accuracy"].get<double>(), 0.9);
  // The weights load as the meta policy of this config, with the target's spread reset.
  PolicyRunner runner(pc, NormalizerConfig());
  runner.LoadWeights(r.weights);
  EXPECT_FLOAT_EQ(runner.model().params()[runner.model().log_std_offset()], o.target_log_std);
  EXPECT_GT(r.weights.obs_stats().count(), rounds[1]["samples_total"].get<int>() - 1);
  // Same seed, same clone.
  EXPECT_EQ(CloneMeta(c, frozen, pc, NormalizerConfig(), plan, o).weights.SerializeAsString(),
            r.weights.SerializeAsString());
  // Hand-overs (labels that change the acting subtask) are few: every episode has at least the
  // walk -> turn one. Weighting them fits them at least as well, and changes the clone.
  const int handovers = rounds[0]["handover_samples"].get<int>();
  EXPECT_GE(handovers, o.episodes);
  EXPECT_LT(handovers, rounds[0]["samples_total"].get<int>() / 2);
  CloneOptions weighted = o;
  weighted.switch_weight = 20;
  const CloneResult w = CloneMeta(c, frozen, pc, NormalizerConfig(), plan, weighted);
  EXPECT_EQ(w.summary["rounds"][0]["handover_samples"].get<int>(), handovers);
  EXPECT_GE(w.summary["rounds"][0]["handover_accuracy"].get<double>(),
            rounds[0]["handover_accuracy"].get<double>());
  EXPECT_NE(w.weights.SerializeAsString(), r.weights.SerializeAsString());
  EXPECT_EQ(w.summary["switch_weight"].get<double>(), 20.0);
  weighted.switch_weight = 0.5;
  EXPECT_THROW(CloneMeta(c, frozen, pc, NormalizerConfig(), plan, weighted), ConfigError);
}

// A curriculum stage starts from the previous stage's meta policy: its first round is driven by
// that policy (a DAgger round), and the fit continues from its weights.
TEST(MetaClone, AStageStartsFromThePreviousStagesPolicy) {
  const TaskEnvConfig c = PlannedMeta(2);
  const std::vector<FrozenPolicyData> frozen = LoadFrozenPolicies(c);
  auto plan = std::make_shared<const MetaPlan>(
      BuildMetaPlan(c, frozen, c.Section<SitChairTaskConfig>().meta.planner));
  const PolicyConfig pc = PolicyConfig::Meta(62);
  CloneOptions o;
  o.episodes = 6;
  o.epochs = 20;
  o.threads = 2;
  o.seed = 7;
  const CloneResult first = CloneMeta(c, frozen, pc, NormalizerConfig(), plan, o);
  EXPECT_DOUBLE_EQ(first.summary["rounds"][0]["planner_acts_prob"].get<double>(), 1.0);

  CloneOptions stage = o;
  stage.init = first.weights;
  stage.dagger_beta = 0.0;      // the previous stage acts alone; the planner only labels
  stage.learning_rate = 1e-7f;  // so that the fit barely moves the weights
  stage.epochs = 1;
  const CloneResult next = CloneMeta(c, frozen, pc, NormalizerConfig(), plan, stage);
  EXPECT_DOUBLE_EQ(next.summary["rounds"][0]["planner_acts_prob"].get<double>(), 0.0);
  EXPECT_TRUE(next.summary["init_from_stage"].get<bool>());
  ASSERT_EQ(next.weights.params_size(), first.weights.params_size());
  double max_diff = 0, max_fresh = 0;
  CloneOptions fresh = stage;
  fresh.init.reset();
  const CloneResult scratch = CloneMeta(c, frozen, pc, NormalizerConfig(), plan, fresh);
  for (int i = 0; i < first.weights.params_size(); ++i) {
    max_diff =
        std::max(max_diff, std::abs(double(next.weights.params(i)) - first.weights.params(i)));
    max_fresh =
        std::max(max_fresh, std::abs(double(scratch.weights.params(i)) - first.weights.params(i)));
  }
  EXPECT_LT(max_diff, 1e-3);   // continued from the first stage's weights
  EXPECT_GT(max_fresh, 1e-2);  // a fresh network is elsewhere

  // A network of another shape is refused, naming the option.
  proto::ModelWeights wrong = first.weights;
  wrong.mutable_params()->RemoveLast();
  stage.init = wrong;
  try {
    CloneMeta(c, frozen, pc, NormalizerConfig(), plan, stage);
    ADD_FAILURE() << "a mismatched start was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("--init-from"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace perch
