#include "hierarchy/chain_plan.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "hierarchy/hierarchy.h"
#include "hierarchy/meta_env.h"
#include "hierarchy/meta_eval.h"
#include "hierarchy/meta_expert.h"
#include "hierarchy/meta_lookahead.h"
#include "tests/hierarchy/planned_meta.h"

namespace perch {
namespace {

Eigen::Vector2d Dir(double yaw) { return {std::cos(yaw), std::sin(yaw)}; }

// A turn that rotates steadily to 180 deg over 100 steps while moving 0.8 m forward and then
// 0.4 m to its left.
TurnCalibration SyntheticLeftTurn() {
  TurnCalibration c;
  for (int k = 0; k <= 100; ++k) {
    const double f = k / 100.0;
    c.rotation_rad.push_back(M_PI * f);
    c.disp.push_back({0.8 * std::min(1.0, 2 * f), 0.4 * std::max(0.0, 2 * f - 1)});
    c.disp_std.push_back({0.0, 0.0});
  }
  c.runs = 1;
  return c;
}

TEST(ChainPlan, DisplacementIsReadWhereTheTurnHasRotatedThatFar) {
  const TurnCalibration c = SyntheticLeftTurn();
  EXPECT_NEAR(c.DisplacementAt(0.0).x(), 0.0, 1e-12);
  EXPECT_NEAR(c.DisplacementAt(M_PI / 2).x(), 0.8, 1e-9);  // step 50
  EXPECT_NEAR(c.DisplacementAt(M_PI / 2).y(), 0.0, 1e-9);
  // A rotation the turn never reaches: where it ended.
  EXPECT_NEAR(c.DisplacementAt(4.0).y(), 0.4, 1e-9);
}

TEST(ChainPlan, AtTheRightStartThePredictedEndIsTheSitStartAndItHandsOver) {
  const TurnCalibration turn = SyntheticLeftTurn();
  PlanarPose sit;
  sit.xy = {0.35, 0.0};
  sit.yaw = 0.0;
  PlanRule rule;
  rule.tolerance_rad = 0.0;
  // Walking toward the chair (heading pi): a left turn of 180 deg ends 0.8 m further along and
  // 0.4 m to the left (-y); start where that lands on the sit start.
  const double yaw = M_PI;
  const Eigen::Vector2d disp(0.8, 0.4);
  const Eigen::Vector2d rotated(-disp.x(), -disp.y());  // R(pi) disp
  PlanarPose root{sit.xy - rotated, yaw};
  PlanView v = PlanStep(root, sit, turn, true, rule);
  EXPECT_NEAR(v.rotation_rad, M_PI, 1e-9);
  EXPECT_NEAR(v.error_m, 0.0, 1e-9);
  EXPECT_TRUE(HandOverNow(v, Dir(yaw) * 1.2, 0.5, sit.xy, rule));
  // The walk target is never nearer than the look-ahead and points the same way.
  EXPECT_NEAR((v.walk_target - root.xy).norm(), rule.lookahead_m, 1e-9);
  // 0.6 m short of that point, walking on toward it: not yet, and the target is that point.
  PlanarPose early{root.xy - 0.6 * Dir(yaw), yaw};
  rule.lookahead_m = 0.3;
  v = PlanStep(early, sit, turn, true, rule);
  EXPECT_NEAR(v.error_m, 0.6, 1e-9);
  EXPECT_NEAR((v.walk_target - root.xy).norm(), 0.0, 1e-9);
  EXPECT_FALSE(HandOverNow(v, Dir(yaw) * 1.2, 0.2, sit.xy, rule));
  // ... but if the next decision is 1.5 s away it would overshoot by more: hand over now.
  rule.pass_m = 1.0;
  EXPECT_FALSE(HandOverNow(v, Dir(yaw) * 1.2, 0.2, sit.xy, rule));
  EXPECT_TRUE(HandOverNow(v, Dir(yaw) * 1.2, 1.5, sit.xy, rule));
}

TEST(ChainPlan, TheRotationNeededDependsOnTheSide) {
  const TurnCalibration turn = SyntheticLeftTurn();
  const PlanarPose sit{{0.0, 0.0}, 0.0};
  const PlanarPose walking_down{{0.0, 2.0}, -M_PI / 2};  // heading -y
  PlanRule rule;
  EXPECT_NEAR(PlanStep(walking_down, sit, turn, true, rule).rotation_rad, M_PI / 2, 1e-9);
  EXPECT_NEAR(PlanStep(walking_down, sit, turn, false, rule).rotation_rad, 1.5 * M_PI, 1e-9);
  // The tolerance cuts the turn short: the displacement is read that much earlier.
  rule.tolerance_rad = M_PI / 4;
  const PlanView cut = PlanStep(walking_down, sit, turn, true, rule);
  const Eigen::Vector2d d = turn.DisplacementAt(M_PI / 4);
  EXPECT_NEAR((cut.predicted_end - walking_down.xy).norm(), d.norm(), 1e-9);
}

TEST(ChainPlan, AnApproachLineLeadsOntoItsStartFromBehind) {
  const TurnCalibration turn = SyntheticLeftTurn();
  const PlanarPose sit{{0.35, 0.0}, 0.0};
  PlanRule rule;
  rule.approach_rad = M_PI / 2;  // walk past the chair's front (heading -y), then turn 90 deg
  // Far up the +y side and off the line: the target lies on the line x = start.x, ahead.
  const PlanarPose root{{1.5, 3.0}, -M_PI / 2};
  const PlanView v = PlanStep(root, sit, turn, true, rule);
  const Eigen::Vector2d start = sit.xy - Eigen::Vector2d(turn.DisplacementAt(M_PI / 2).y(),
                                                         -turn.DisplacementAt(M_PI / 2).x());
  EXPECT_NEAR(v.walk_target.x(), start.x(), 1e-9);
  EXPECT_LT(v.walk_target.y(), root.xy.y());
  EXPECT_GT(v.walk_target.y(), start.y());
  // Without the line the walker heads straight for where its present heading says to turn.
  rule.approach_rad = -1.0;
  EXPECT_NEAR(PlanStep(root, sit, turn, true, rule).walk_target.x(), v.start_point.x(), 1e-9);
}

TEST(ChainPlan, WalksAroundTheChairOnlyWhenTheWayPassesIt) {
  const Eigen::Vector2d chair(0.0, 0.0);
  // Clear of it: unchanged.
  const Eigen::Vector2d far_target(2.0, 2.0);
  EXPECT_EQ(AvoidChair({2.0, -2.0}, far_target, chair, 0.6), far_target);
  // From behind the chair to its front: a point beside it, 0.6 m out, on the target's side.
  const Eigen::Vector2d w = AvoidChair({-1.5, 0.0}, {1.0, 0.3}, chair, 0.6);
  EXPECT_NEAR(w.norm(), 0.6, 1e-9);
  EXPECT_GT(w.y(), 0.4);
  EXPECT_LT(w.x(), 0.0);  // still on the root's side: passed, not circled
  EXPECT_LT(AvoidChair({-1.5, 0.0}, {1.0, -0.3}, chair, 0.6).y(), -0.4);
  EXPECT_EQ(AvoidChair({-1.5, 0.0}, {1.0, 0.3}, chair, 0.0), Eigen::Vector2d(1.0, 0.3));  // off
}

TEST(ChainPlan, RoundsTheChairOnlyFromBesideOrBehindIt) {
  const Eigen::Vector2d chair(0.0, 0.0);
  const double facing = 0.0;  // the chair faces +x
  // From in front (1.0 m out) to a turn start whose way passes the seat within 1.2 m: straight.
  const Eigen::Vector2d ahead(1.3, 0.9);
  EXPECT_EQ(WalkAroundChair({1.0, -1.0}, ahead, chair, facing, 1.2, 0.3), ahead);
  // The old rule (everywhere) would have sent it around.
  EXPECT_NE(WalkAroundChair({1.0, -1.0}, ahead, chair, facing, 1.2, 3.0), ahead);
  // From behind: around, as AvoidChair says.
  EXPECT_EQ(WalkAroundChair({-1.5, 0.0}, {1.0, 0.3}, chair, facing, 1.2, 0.3),
            AvoidChair({-1.5, 0.0}, {1.0, 0.3}, chair, 1.2));
  EXPECT_NE(WalkAroundChair({-1.5, 0.0}, {1.0, 0.3}, chair, facing, 1.2, 0.3),
            Eigen::Vector2d(1.0, 0.3));
  // The facing decides what "in front" is: the same root is behind a chair facing -x.
  EXPECT_NE(WalkAroundChair({1.0, -1.0}, ahead, chair, M_PI, 1.2, 0.3), ahead);
}

TEST(ChainPlan, SitNowAtTheToleranceOrAtTheClosestDecision) {
  const double tol = 15 * M_PI / 180;
  EXPECT_TRUE(SitNow(0.1, 2.0, 0.0, tol, 0.0165));
  EXPECT_FALSE(SitNow(0.5, 0.0, 0.0, tol, 0.0165));  // every step: only the tolerance
  // 0.5 s between decisions, turning at 2 rad/s: 0.5 rad short now, 0.5 rad past at the next.
  EXPECT_TRUE(SitNow(-0.4, 2.0, 0.0, tol, 0.5));
  EXPECT_FALSE(SitNow(-0.7, 2.0, 0.0, tol, 0.5));  // the next decision lands nearer (0.3)
}

TEST(ChainPlan, PlannerConfigIsStrictAndNamesTheField) {
  EXPECT_NO_THROW(PlannerConfig::FromJson(Json::object(), "p"));
  // A turn is begun only where it would not be handed back at once, unless told otherwise.
  EXPECT_EQ(PlannerConfig::FromJson(Json{{"turn_abort_value", 3.0}}, "p").turn_begin_value, 3.0);
  EXPECT_EQ(PlannerConfig::FromJson(Json{{"turn_abort_value", 3.0}, {"turn_begin_value", 0.0}}, "p")
                .turn_begin_value,
            0.0);
  const PlannerConfig c = PlannerConfig::FromJson(PlannerConfig().ToJson(), "p");
  EXPECT_EQ(c.ToJson(), PlannerConfig().ToJson());
  for (const Json& bad :
       {Json{{"pass", 0.3}},
        Json{{"side", "up"}},
        Json{{"reach_m", 2.0}},
        Json{{"aim_m", {3.0, 0.0}}},
        Json{{"pass_m", "x"}},
        Json{{"avoid_front_m", 5.0}},
        Json{{"turn_value_min", -1.0}},
        Json{{"sit_value_early", -0.5}},
        Json{{"sit_value_yaw_deg", 0.0}},
        Json{{"turn_abort_value", -1.0}},
        Json{{"value_wait_s", 5.0}},
        Json{{"abort_recover_s", -1.0}},
        Json{{"sit_retry_value", -1.0}},
        Json{{"lookahead_delays_s", {0.0}}},
        Json{{"lookahead_delays_s", {4.0}}},
        Json{{"lookahead_sides", true}, {"side", "left"}},
        Json{{"lookahead_straight_s", {0.5, -1.0}}},
        Json{{"lookahead_rank", "closer"}},
        Json{{"lookahead_detour_deg", {60.0}}},  // without lookahead_straight_s
        Json{{"lookahead_straight_s", {0.5}}, {"lookahead_detour_deg", {0.0}}},
        Json{{"lookahead_straight_s", {0.5}}, {"lookahead_detour_deg", {200.0}}}}) {
    try {
      PlannerConfig::FromJson(bad, "sit_chair.meta.planner");
      ADD_FAILURE() << "accepted " << bad.dump();
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("sit_chair.meta.planner"), std::string::npos)
          << e.what();
    }
  }
}

TEST(ChainPlan, TheNearerRankOrdersSuccessesByTheirMinimumDistance) {
  LookaheadOutcome soon_far, late_near, fell_near, stood_far;
  soon_far.success = true;
  soon_far.success_step = 300;
  soon_far.min_dist_m = 0.2;
  late_near = soon_far;
  late_near.success_step = 500;
  late_near.min_dist_m = 0.1;
  fell_near.fell = true;
  fell_near.min_dist_m = 0.05;
  stood_far.min_dist_m = 0.9;
  EXPECT_TRUE(soon_far.BetterThan(late_near));
  EXPECT_TRUE(late_near.BetterThan(soon_far, /*nearer=*/true));
  EXPECT_FALSE(soon_far.BetterThan(late_near, /*nearer=*/true));
  // Equally near: the sooner.
  LookaheadOutcome soon_near = late_near;
  soon_near.success_step = 200;
  EXPECT_TRUE(soon_near.BetterThan(late_near, true));
  EXPECT_FALSE(late_near.BetterThan(late_near, true));
  // Failures rank alike either way: a success first, then no fall, then nearer.
  for (bool nearer : {false, true}) {
    EXPECT_TRUE(soon_far.BetterThan(fell_near, nearer));
    EXPECT_TRUE(stood_far.BetterThan(fell_near, nearer));
    EXPECT_FALSE(fell_near.BetterThan(stood_far, nearer));
  }
}

// ---- with the delivered subtasks ---------------------------------------------------------------

// min_dist_mean_m is the trial-weighted mean of the successes' and the failures' means.
void ExpectMinDistSplitBySuccess(const Json& j) {
  const double n = j["trials"].get<double>(), s = j["success_rate"].get<double>();
  EXPECT_NEAR(j["min_dist_mean_m"].get<double>(),
              s * j["min_dist_success_mean_m"].get<double>() +
                  (1 - s) * j["min_dist_failure_mean_m"].get<double>(),
              1e-9);
  EXPECT_GT(n, 0);
}

using testing_util::PlannedMeta;

TEST(ChainPlan, PlanOfTheDeliveredSubtasks) {
  const TaskEnvConfig c = PlannedMeta(4);
  const std::vector<FrozenPolicyData> frozen = LoadFrozenPolicies(c);
  const MetaPlan plan = BuildMetaPlan(c, frozen, c.Section<SitChairTaskConfig>().meta.planner);
  // The sit's clip starts in front of the authors' seat (it faces +x), facing away from it;
  // the planner aims 0.1 m further out.
  EXPECT_GT(plan.sit_start.xy.x(), 0.3);
  EXPECT_LT(plan.sit_start.xy.x(), 0.7);
  EXPECT_LT(std::abs(plan.sit_start.xy.y()), 0.05);
  EXPECT_LT(std::abs(plan.sit_start.yaw), 10 * M_PI / 180);
  for (int side = 0; side < 2; ++side) {
    const TurnCalibration& t = plan.turns[side];
    EXPECT_GE(t.runs, 1);
    EXPECT_GT(t.rotation_rad.back(), 150 * M_PI / 180) << side;
    // Left turns drift left, right turns right.
    EXPECT_GT((side == 0 ? 1 : -1) * t.disp.back().y(), 0.1) << side;
    EXPECT_GT(t.disp.back().x(), 0.3) << side;
    // Every run's start is kept with whether it fell, and the survivors' starts are theirs.
    ASSERT_EQ(t.starts.size(), static_cast<size_t>(t.runs + t.fell));
    EXPECT_EQ(std::count_if(t.starts.begin(), t.starts.end(),
                            [](const TurnCalibration::Start& st) { return st.fell; }),
              t.fell);
    size_t kept = 0;
    for (size_t r = 0; r < t.starts.size(); ++r) {
      if (!t.starts[r].fell) {
        EXPECT_EQ(t.starts[r].features, t.run_features[kept++]) << r;
      }
    }
    EXPECT_EQ(t.ToJson()["starts"].size(), t.starts.size());
  }
  // A meta without the turns cannot be planned for.
  TaskEnvConfig walk_only = c;
  walk_only.MutableSection<SitChairTaskConfig>().meta.choices = {"walk"};
  EXPECT_THROW(BuildMetaPlan(walk_only, LoadFrozenPolicies(walk_only), PlannerConfig()),
               ConfigError);
  // A one-turn meta (Table 3) is planned for when the planner's side is that turn's, and only
  // that turn is measured; turning the short way needs both.
  TaskEnvConfig left_only = c;
  left_only.MutableSection<SitChairTaskConfig>().meta.choices = {"turn_left", "sit", "walk"};
  PlannerConfig left = c.Section<SitChairTaskConfig>().meta.planner;
  EXPECT_THROW(BuildMetaPlan(left_only, LoadFrozenPolicies(left_only), left), ConfigError);
  left.side = "left";
  const MetaPlan one = BuildMetaPlan(left_only, LoadFrozenPolicies(left_only), left);
  EXPECT_GE(one.turns[0].runs, 1);
  EXPECT_EQ(one.turns[1].runs + one.turns[1].fell, 0);
  EXPECT_NEAR(one.sit_start.xy.x(), plan.sit_start.xy.x(), 1e-9);

  // Driving the meta env at 2 Hz it runs walk -> turn -> sit and sits in some trials (the
  // trials are deterministic for their seed).
  MetaEvalOptions o;
  o.trials = 40;
  o.seed = 2;
  o.threads = 2;
  o.planner = std::make_shared<const MetaPlan>(plan);
  const Json j = EvaluateMeta(c, proto::ModelWeights(), frozen, o);
  EXPECT_GT(j["success_rate"].get<double>(), 0.0);
  EXPECT_EQ(j["decider"], "planner");
  for (const Json& s : j["sequences"]) {
    const std::string seq = s["sequence"];
    EXPECT_EQ(seq.rfind("walk", 0), 0u) << seq;
    EXPECT_EQ(seq.find("sit>"), std::string::npos) << seq;  // sit is never left
  }
  // Every run's start is rated by its subtask's critic: one walk per trial, and the sits that
  // went on (succeeded) started from states their critic rated higher than those that failed.
  const Json& hv = j["handover_values"];
  EXPECT_EQ(hv["walk"]["runs"].get<int>(), 40);
  ASSERT_TRUE(hv.contains("sit"));
  const Json& sit = hv["sit"];
  if (sit["went_on_rate"].get<double>() > 0 && sit["went_on_rate"].get<double>() < 1) {
    EXPECT_GT(sit["value_mean_went_on"].get<double>(), sit["value_mean_failed"].get<double>());
    EXPECT_GT(sit["auc"].get<double>(), 0.5);
  }

  // The critics' rules (ours): a turn its critic rates below turn_begin_value is never begun, so
  // with an unreachable threshold the planner only walks.
  MetaPlan no_turn = plan;
  no_turn.config.turn_begin_value = 1e3;
  o.trials = 3;
  o.planner = std::make_shared<const MetaPlan>(no_turn);
  const Json walked = EvaluateMeta(c, proto::ModelWeights(), frozen, o);
  for (const Json& s : walked["sequences"]) EXPECT_EQ(s["sequence"], "walk");
}

// The planner with lookahead (hierarchy/meta_lookahead.h): its simulator is exact (every trial ends
// as its last look ahead predicted), it looks ahead at the first decision (both turns) and at the
// hand-overs, and no trial ends worse than the rules alone would have from its first decision
// (with the same restores: without them the rules' trials differ chaotically).
TEST(ChainPlan, TheLookaheadIsExactAndDoesAtLeastAsWellAsTheRules) {
  const TaskEnvConfig c = PlannedMeta(4);
  const std::vector<FrozenPolicyData> frozen = LoadFrozenPolicies(c);
  const MetaPlan plan = BuildMetaPlan(c, frozen, c.Section<SitChairTaskConfig>().meta.planner);
  MetaEvalOptions o;
  o.trials = 6;
  o.seed = 3;
  o.threads = 2;
  o.planner = std::make_shared<const MetaPlan>(plan);
  const Json rules = EvaluateMeta(c, proto::ModelWeights(), frozen, o);
  EXPECT_FALSE(rules.contains("lookahead"));
  ExpectMinDistSplitBySuccess(rules);
  MetaPlan ahead = plan;
  ahead.config.lookahead_delays_s = {0.5};
  ahead.config.lookahead_sides = true;
  o.planner = std::make_shared<const MetaPlan>(ahead);
  const Json j = EvaluateMeta(c, proto::ModelWeights(), frozen, o);
  ASSERT_TRUE(j.contains("lookahead"));
  const Json& la = j["lookahead"];
  EXPECT_EQ(la["trials_predicted"].get<int>(), 6);
  EXPECT_EQ(la["trials_as_predicted"].get<int>(), 6);
  // Both sides at the first decision, and more at the hand-overs.
  EXPECT_GT(la["rollouts_per_trial"].get<double>(), 2.0);
  EXPECT_GE(la["points_per_trial"].get<double>(), 1.0);
  EXPECT_EQ(la["trials_not_worse_than_rules"].get<int>(), 6);
  EXPECT_GE(j["success_rate"].get<double>(), la["rules_success_rate"].get<double>());
  EXPECT_EQ(j["planner"]["config"]["lookahead_delays_s"], Json({0.5}));
  // Deterministic for the seed whatever the threads.
  o.threads = 1;
  const Json one = EvaluateMeta(c, proto::ModelWeights(), frozen, o);
  EXPECT_EQ(one["success_rate"], j["success_rate"]);
  EXPECT_EQ(one["sequences"], j["sequences"]);
  ExpectMinDistSplitBySuccess(j);
  // Ranked by the nearer success: exact, and never worse than the rules by that rank.
  ahead.config.lookahead_rank = "nearer";
  o.planner = std::make_shared<const MetaPlan>(ahead);
  const Json near = EvaluateMeta(c, proto::ModelWeights(), frozen, o);
  EXPECT_EQ(near["lookahead"]["trials_as_predicted"].get<int>(), 6);
  EXPECT_EQ(near["lookahead"]["trials_not_worse_than_rules"].get<int>(), 6);
  EXPECT_EQ(near["planner"]["config"]["lookahead_rank"], "nearer");
  EXPECT_GE(near["success_rate"].get<double>(),
            near["lookahead"]["rules_success_rate"].get<double>());
}

TEST(ChainPlan, ThePlannedChainRecordsWhereEachSitBegan) {
  const TaskEnvConfig c = PlannedMeta(4);
  std::array<proto::ModelWeights, kNumSubtasks> models;
  std::array<std::string, kNumSubtasks> names;
  std::array<Json, kNumSubtasks> saved;
  for (const FrozenPolicyData& f : LoadFrozenPolicies(c)) {
    const int id = SubtaskIdOf(f.name);
    ASSERT_GE(id, 0) << f.name;
    ASSERT_TRUE(models[id].ParseFromString(f.model)) << f.name;
    names[id] = f.name;
    saved[id] = Json::parse(f.saved_config);
  }
  ChainOptions o;
  o.episodes = 6;
  o.seed = 3;
  o.plan = true;
  o.planner.calibration_runs = 4;
  o.sit_yaw_deg = 25;
  o.stop_at_sit = true;
  const Json j = EvaluateChain(c, models, names, saved, o, nullptr);
  ASSERT_EQ(j["episodes_detail"].size(), 6u);
  std::vector<double> along;
  for (const Json& e : j["episodes_detail"]) {
    // [spawn azimuth, turn, subtask it fell in, success, sit start (along, across, yaw) or null]
    ASSERT_EQ(e.size(), 5u);
    if (e[4].is_null()) continue;
    EXPECT_EQ(e[2], "");  // it reached the sit, so it did not fall before
    along.push_back(e[4][0].get<double>());
    // Handed over within the tolerance of the sit's heading, from the turn's side.
    EXPECT_LE(std::abs(e[4][2].get<double>()), 25.0 + 1e-9);
  }
  ASSERT_EQ(static_cast<int>(along.size()), j["reached_sit"].get<int>());
  ASSERT_FALSE(along.empty());
  double mean = 0;
  for (double a : along) mean += a / along.size();
  EXPECT_NEAR(j["plan"]["sit_start_along_m_mean"].get<double>(), mean, 1e-9);
}

}  // namespace
}  // namespace perch
