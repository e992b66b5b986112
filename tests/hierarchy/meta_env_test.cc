#include "hierarchy/meta_env.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <set>

#include "common/paths.h"
#include "hierarchy/meta_eval.h"
#include "learner/ppo.h"
#include "tasks/model_source.h"
#include "tasks/recording.h"

namespace perch {
namespace {

TaskEnvConfig MetaConfigFor(const std::vector<std::string>& choices, int zone = 1,
                            double radius = 1.5) {
  Json env{{"task", "sit_chair"},
           {"spawn", {{"zone", zone}, {"radius", radius}}},
           {"sit_chair", {{"meta", {{"choices", choices}}}}}};
  return TaskEnvConfig::FromJson(env, "t");
}

// Untrained frozen policies of the right layouts (fast, deterministic; the real ones are tested
// below where they matter).
std::vector<FrozenPolicyData> Untrained() {
  std::vector<FrozenPolicyData> out;
  for (int id = 0; id < kNumSubtasks; ++id) {
    PpoLearner l(PolicyConfig::Subtask(id == kWalk  ? 52
                                       : id == kSit ? 57
                                                    : 50),
                 PpoConfig::Subtask(), id + 1);
    proto::ModelWeights w;
    l.ExportWeights(&w);
    out.push_back({SubtaskName(id), w.SerializeAsString(), "", "untrained"});
  }
  return out;
}

// An untrained meta policy of the 57-input layout (seeded).
proto::ModelWeights UntrainedMeta(uint64_t seed) {
  PpoLearner l(PolicyConfig::Meta(57), PpoConfig::Meta(), seed);
  proto::ModelWeights meta;
  l.ExportWeights(&meta);
  return meta;
}

// The runs of one subtask in an evaluation: every transition into it, whichever row and side.
int RunsOf(const Json& r, const std::string& name, bool with_first = true) {
  int n = 0;
  for (const auto& [side, rows] : r["transitions"].items()) {
    for (const auto& [from, to] : rows.items()) {
      if (!with_first && from == "start") continue;
      if (to.contains(name)) n += to[name].get<int>();
    }
  }
  return n;
}

// The runs that began at a hand-over: not the episode's first, which begins at the spawn.
int HandOversTo(const Json& r, const std::string& name) { return RunsOf(r, name, false); }

TEST(MetaEnv, SpecIsTheMetaDecision) {
  MetaEnv env(MetaConfigFor({"turn_left", "turn_right", "sit", "walk"}));
  EXPECT_EQ(env.spec().obs_dim, 57);
  EXPECT_EQ(env.spec().act_dim, 3);
  EXPECT_TRUE(env.spec().has_success);
  // 990 control steps of 30: 33 meta steps of 0.495 s (notes 4.1, 4.7).
  EXPECT_EQ(env.spec().max_episode_steps, 33);
  EXPECT_NEAR(env.spec().control_dt, 30 * env.humanoid().spec().control_dt, 1e-12);
  EXPECT_EQ(env.frozen_policy_names(),
            (std::vector<std::string>{"turn_left", "turn_right", "sit", "walk"}));
  MetaEnv walk_only(MetaConfigFor({"walk"}));
  EXPECT_EQ(walk_only.frozen_policy_names(), std::vector<std::string>{"walk"});
}

TEST(MetaEnv, RefusesToStepWithoutSubtasksAndNamesAMissingOne) {
  MetaEnv env(MetaConfigFor({"turn_left", "sit", "walk"}));
  std::vector<float> obs(57), a{2, 0, 1};
  env.Reset(obs.data());
  EXPECT_THROW(env.Step(a.data(), obs.data()), std::logic_error);
  std::vector<FrozenPolicyData> p = Untrained();
  p.erase(p.begin() + kSit);
  try {
    env.SetFrozenPolicies(p);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("sit subtask"), std::string::npos) << e.what();
  }
  // A walk model where the sit one belongs: its observation size is refused, naming the file.
  p = Untrained();
  p[kSit].model = p[kWalk].model;
  p[kSit].source = "walk-as-sit.bin";
  try {
    env.SetFrozenPolicies(p);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("walk-as-sit.bin"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("57"), std::string::npos) << e.what();
  }
}

TEST(MetaEnv, OneStepRunsThePeriodWithTheChosenSubtaskAndPaysEq8) {
  MetaEnv env(MetaConfigFor({"turn_left", "turn_right", "sit", "walk"}));
  env.SetFrozenPolicies(Untrained());
  int steps = 0, last_active = -1;
  env.on_control_step = [&](const HumanoidChairEnv&, const StepResult&, int active) {
    ++steps;
    last_active = active;
  };
  std::vector<float> obs(57);
  env.Seed(5);
  env.Reset(obs.data());
  const double d0 = env.humanoid().PelvisSeatDistance();
  std::vector<float> a{1.0f, 0.3f, 2.0f};  // class 1 = right turn
  const StepResult r = env.Step(a.data(), obs.data());
  if (!r.terminated) {
    EXPECT_EQ(steps, 30);
  }
  EXPECT_EQ(last_active, kRightTurn);
  ASSERT_FALSE(env.episode().sequence.empty());
  EXPECT_EQ(env.episode().sequence[0], kRightTurn);
  // Not on the seat: 0.5 x the approach speed averaged over the meta step.
  const double d1 = env.humanoid().PelvisSeatDistance();
  const double dt = env.spec().control_dt;  // Phi's fixed 30-step scale, even when cut short
  EXPECT_NEAR(r.reward, 0.5 * (d0 - d1) / dt, 1e-4);
  // The walk target was set from the torso: dist along the heading turned by theta.
  // (checked on a fresh episode, before any physics moves the torso)
  env.Reset(obs.data());
  const Eigen::Vector3d root = env.humanoid().humanoid_state().root_pos;
  const double yaw = env.humanoid().RootRpy().z();
  steps = 0;
  a = {3.0f, -0.5f, 1.5f};  // walk
  env.Step(a.data(), obs.data());
  const Eigen::Vector2d want(root.x() + 1.5 * std::cos(yaw - 0.5),
                             root.y() + 1.5 * std::sin(yaw - 0.5));
  EXPECT_NEAR((env.humanoid().walk_target() - want).norm(), 0.0, 1e-9);
  EXPECT_EQ(env.episode().sequence, std::vector<int>{kWalk});
}

TEST(MetaEnv, FallPenaltyIsPaidOnTheMetaStepThatEndsInAFall) {
  TaskEnvConfig c = MetaConfigFor({"turn_left", "turn_right", "sit", "walk"});
  TaskEnvConfig p = c;
  p.MutableSection<SitChairTaskConfig>().fall_penalty = 3.0;
  MetaEnv plain(c), penalised(p);
  plain.SetFrozenPolicies(Untrained());
  penalised.SetFrozenPolicies(Untrained());
  std::vector<float> oa(57), ob(57), a{0.0f, 0.0f, 1.0f};
  plain.Seed(4);
  penalised.Seed(4);
  plain.Reset(oa.data());
  penalised.Reset(ob.data());
  bool fell = false;
  for (int m = 0; m < 33 && !fell; ++m) {  // untrained subtasks fall within a few meta steps
    const StepResult ra = plain.Step(a.data(), oa.data());
    const StepResult rb = penalised.Step(a.data(), ob.data());
    ASSERT_EQ(ra.terminated, rb.terminated);
    fell = ra.terminated;
    EXPECT_NEAR(rb.reward, ra.reward - (fell ? 3.0f : 0.0f), 1e-6) << m;
  }
  EXPECT_TRUE(fell);
  EXPECT_THROW(TaskEnvConfig::FromJson(
                   {{"task", "sit_chair"}, {"sit_chair", {{"fall_penalty", -1.0}}}}, "t"),
               ConfigError);
}

TEST(MetaEnv, ObserveActiveAppendsTheActingSubtaskAndItsTime) {
  TaskEnvConfig c = MetaConfigFor({"turn_left", "turn_right", "sit", "walk"});
  c.MutableSection<SitChairTaskConfig>().meta.observe_active = true;
  c.MutableSection<SitChairTaskConfig>().min_root_z = 0.0;  // untrained subtasks fall
  MetaEnv env(c);
  ASSERT_EQ(env.spec().obs_dim, 57 + kNumSubtasks + 1);
  env.SetFrozenPolicies(Untrained());
  std::vector<float> obs(env.spec().obs_dim), plain(57);
  env.Seed(2);
  env.Reset(obs.data());
  for (int id = 0; id < kNumSubtasks; ++id) EXPECT_EQ(obs[57 + id], id == kWalk ? 1.0f : 0.0f);
  EXPECT_EQ(obs[57 + kNumSubtasks], 0.0f);
  // The first 57 are the paper's state, as without the option.
  MetaEnv paper(MetaConfigFor({"turn_left", "turn_right", "sit", "walk"}));
  paper.SetFrozenPolicies(Untrained());
  paper.Seed(2);
  paper.Reset(plain.data());
  for (int i = 0; i < 57; ++i) EXPECT_EQ(obs[i], plain[i]) << i;
  const double dt = env.humanoid().spec().control_dt;
  std::vector<float> left{0.0f, 0.0f, 1.0f}, walk{3.0f, 0.0f, 1.0f};
  StepResult r = env.Step(left.data(), obs.data());
  ASSERT_FALSE(r.terminated);
  EXPECT_EQ(obs[57 + kLeftTurn], 1.0f);
  EXPECT_EQ(obs[57 + kWalk], 0.0f);
  EXPECT_NEAR(obs[57 + kNumSubtasks], 30 * dt / 3.0, 1e-6);
  r = env.Step(left.data(), obs.data());  // the same subtask goes on: its time too
  ASSERT_FALSE(r.terminated);
  EXPECT_NEAR(obs[57 + kNumSubtasks], 60 * dt / 3.0, 1e-6);
  r = env.Step(walk.data(), obs.data());  // another one starts its own clock
  ASSERT_FALSE(r.terminated);
  EXPECT_EQ(obs[57 + kWalk], 1.0f);
  EXPECT_NEAR(obs[57 + kNumSubtasks], 30 * dt / 3.0, 1e-6);
}

// Table 3's fixed-order baseline: the meta can only keep the running subtask or trigger the next.
TEST(MetaEnv, FixedOrderOnlyEverMovesToTheNextSubtask) {
  TaskEnvConfig c = MetaConfigFor({"walk", "turn_left", "sit"}, 1, 8.0);
  c.MutableSection<SitChairTaskConfig>().meta.fixed_order = true;
  c.MutableSection<SitChairTaskConfig>().meta.period = 1;  // seven decisions before any fall
  MetaEnv env(c);
  env.SetFrozenPolicies(Untrained());
  std::vector<float> obs(57);
  env.Seed(2);
  env.Reset(obs.data());
  std::vector<int> active;
  for (const float cls : {2.0f, 0.0f, 1.0f, 0.0f, 1.0f, 2.0f, 0.0f}) {
    std::vector<float> a{cls, 0.0f, 1.0f};
    const StepResult r = env.Step(a.data(), obs.data());
    active.push_back(env.active());
    if (r.terminated) break;
  }
  // sit skipped -> walk; 0 keeps it; 1 = next -> turn; 0, 1 keep the turn; 2 -> sit; 0 keeps sit.
  const std::vector<int> want{kWalk, kWalk, kLeftTurn, kLeftTurn, kLeftTurn, kSit, kSit};
  ASSERT_GE(active.size(), 6u) << "fell too early to judge";
  for (size_t i = 0; i < active.size(); ++i) EXPECT_EQ(active[i], want[i]) << i;
  for (size_t i = 1; i < env.episode().sequence.size(); ++i) {
    EXPECT_NE(env.episode().sequence[i], kWalk);  // never back
  }
}

TEST(MetaEnv, HostileActionsAreClampedNotFatal) {
  MetaEnv env(MetaConfigFor({"turn_left", "turn_right", "sit", "walk"}));
  env.SetFrozenPolicies(Untrained());
  std::vector<float> obs(57);
  env.Reset(obs.data());
  const float nan = std::nanf("");
  for (const std::vector<float>& a : std::vector<std::vector<float>>{
           {1e30f, nan, 1e30f}, {-7.0f, 1e9f, -1e9f}, {nan, nan, nan}}) {
    const StepResult r = env.Step(a.data(), obs.data());
    EXPECT_TRUE(std::isfinite(r.reward));
    for (float x : obs) EXPECT_TRUE(std::isfinite(x));
    if (r.terminated || r.truncated) env.Reset(obs.data());
  }
}

TEST(MetaEnv, SameSeedSameEpisode) {
  auto run = [] {
    MetaEnv env(MetaConfigFor({"turn_left", "turn_right", "sit", "walk"}));
    env.SetFrozenPolicies(Untrained());
    env.Seed(11);
    std::vector<float> obs(57);
    env.Reset(obs.data());
    std::vector<float> trace;
    for (int t = 0; t < 4; ++t) {
      std::vector<float> a{static_cast<float>(t % 4), 0.1f * t, 1.0f};
      const StepResult r = env.Step(a.data(), obs.data());
      trace.push_back(r.reward);
      trace.insert(trace.end(), obs.begin(), obs.end());
      if (r.terminated) break;
    }
    return trace;
  };
  EXPECT_EQ(run(), run());
}

// Trials are seeded by index: the same numbers whatever the thread count; the keys the issue
// names are there; the transition counts add up to the trials.
TEST(MetaEnv, RecordsEachSubtasksCriticWhereItBegan) {
  MetaEnv env(MetaConfigFor({"turn_left", "turn_right", "sit", "walk"}));
  env.SetFrozenPolicies(Untrained());
  std::vector<float> obs(57), left{0.0f, 0.0f, 1.0f}, sit{2.0f, 0.0f, 1.0f};
  env.Seed(7);
  env.Reset(obs.data());
  const float v_left = env.SubtaskValue(kLeftTurn);
  const float v_sit_now = env.SubtaskValue(kSit);
  EXPECT_NE(v_left, v_sit_now);  // each subtask's own critic
  env.Step(left.data(), obs.data());
  ASSERT_EQ(env.episode().begin_value.size(), 1u);
  EXPECT_EQ(env.episode().begin_value[0], v_left);
  EXPECT_EQ(env.ActiveValue(), env.SubtaskValue(kLeftTurn));  // a turn without a clock: the same
  // The next subtask is rated on the state it starts from, not the reset's.
  const float v_sit = env.SubtaskValue(kSit);
  EXPECT_NE(v_sit, v_sit_now);
  env.Step(sit.data(), obs.data());
  ASSERT_EQ(env.episode().sequence, (std::vector<int>{kLeftTurn, kSit}));
  EXPECT_EQ(env.episode().begin_value[1], v_sit);
  // Keeping the same subtask is not a new run.
  env.Step(sit.data(), obs.data());
  EXPECT_EQ(env.episode().begin_value.size(), 2u);
}

TEST(MetaEnv, ObserveValuesAppendsEverySubtasksCriticAndTheActingOnes) {
  TaskEnvConfig c = MetaConfigFor({"turn_left", "sit", "walk"});
  c.MutableSection<SitChairTaskConfig>().meta.observe_active = true;
  c.MutableSection<SitChairTaskConfig>().meta.observe_values = true;
  MetaEnv env(c);
  ASSERT_EQ(env.spec().obs_dim, 67);
  ASSERT_EQ(env.spec().obs_slices.back().name, "values");
  EXPECT_EQ(env.spec().obs_slices.back().offset, 62);
  env.SetFrozenPolicies(Untrained());
  std::vector<float> obs(67), left{0.0f, 0.0f, 1.0f};
  env.Seed(9);
  env.Reset(obs.data());
  EXPECT_EQ(obs[62 + kLeftTurn], env.SubtaskValue(kLeftTurn));
  EXPECT_EQ(obs[62 + kSit], env.SubtaskValue(kSit));
  EXPECT_EQ(obs[62 + kWalk], env.SubtaskValue(kWalk));
  EXPECT_EQ(obs[62 + kRightTurn], 0.0f);  // not among the choices: nothing to rate
  EXPECT_EQ(obs[66], 0.0f);               // nothing acts yet
  env.Step(left.data(), obs.data());
  EXPECT_EQ(obs[62 + kSit], env.SubtaskValue(kSit));
  EXPECT_EQ(obs[66], env.ActiveValue());
  EXPECT_NE(obs[66], 0.0f);
  // A config without it keeps the paper's 57 inputs (+5 with observe_active only).
  c.MutableSection<SitChairTaskConfig>().meta.observe_values = false;
  EXPECT_EQ(MetaEnv(c).spec().obs_dim, 62);
}

TEST(MetaEval, RankAucCountsPairsAndTiesHalf) {
  EXPECT_DOUBLE_EQ(RankAuc({{1, false}, {2, false}, {3, true}, {4, true}}), 1.0);
  EXPECT_DOUBLE_EQ(RankAuc({{1, true}, {2, true}, {3, false}}), 0.0);
  EXPECT_DOUBLE_EQ(RankAuc({{1, true}, {1, false}}), 0.5);
  // Positives 1 and 3, negative 2: one of the two pairs is ordered.
  EXPECT_DOUBLE_EQ(RankAuc({{3, true}, {2, false}, {1, true}}), 0.5);
  // Positives 2, 2; negatives 1, 2: pairs (2>1) x2 = 2, ties (2=2) x2 = 1 -> 3 / 4.
  EXPECT_DOUBLE_EQ(RankAuc({{2, true}, {2, true}, {1, false}, {2, false}}), 0.75);
  EXPECT_DOUBLE_EQ(RankAuc({{1, true}}), 0.5);  // no negatives
  EXPECT_DOUBLE_EQ(RankAuc({}), 0.5);
}

TEST(MetaEval, DeterministicOverThreadsAndCountsEveryTrial) {
  const TaskEnvConfig c = MetaConfigFor({"turn_left", "turn_right", "sit", "walk"});
  const proto::ModelWeights meta = UntrainedMeta(4);
  MetaEvalOptions o;
  o.trials = 6;
  o.seed = 3;
  o.stochastic = true;  // untrained: sampled, so the trials differ
  o.threads = 1;
  int calls = 0;
  o.progress = [&](int, int) { ++calls; };
  MetaTrialFrames fail;
  Json one = EvaluateMeta(c, meta, Untrained(), o, nullptr, &fail);
  EXPECT_EQ(calls, 6);
  o.threads = 3;
  o.progress = nullptr;
  Json three = EvaluateMeta(c, meta, Untrained(), o);
  for (const char* k : {"success_rate", "min_dist_mean_m", "min_dist_std_m", "fall_rate",
                        "transitions", "sequences", "by_side", "handover_values"}) {
    ASSERT_TRUE(one.contains(k)) << k;
    EXPECT_EQ(one[k], three[k]) << k;
  }
  EXPECT_TRUE(one.contains("success_ci95"));
  int starts = 0;
  for (const auto& [side, rows] : one["transitions"].items()) {
    for (const auto& [to, n] : rows["start"].items()) starts += n.get<int>();
  }
  EXPECT_EQ(starts, 6);
  // Each sequence's trials end in a success, a fall or the time limit (6 trials: all listed).
  int listed = 0, falls = 0;
  for (const Json& s : one["sequences"]) {
    listed += s["trials"].get<int>();
    falls += s["falls"].get<int>();
    EXPECT_LE(s["successes"].get<int>() + s["falls"].get<int>(), s["trials"].get<int>());
  }
  EXPECT_EQ(listed, 6);
  EXPECT_NEAR(falls, 6 * one["fall_rate"].get<double>(), 1e-9);
  EXPECT_GE(fail.trial, 0);
  EXPECT_FALSE(fail.frames.empty());
}

TEST(MetaEval, SavesTheStateAtEveryHandOverAndTheFailedTrialsOnes) {
  const TaskEnvConfig c = MetaConfigFor({"turn_left", "turn_right", "sit", "walk"});
  const proto::ModelWeights meta = UntrainedMeta(5);
  MetaEvalOptions o;
  constexpr int kTrials = 12;
  o.trials = kTrials;
  o.seed = 4;
  o.stochastic = true;  // untrained and sampled: each subtask is chosen, left and chosen again
  o.threads = 2;
  std::vector<proto::BankState> all, failed;
  o.sit_starts = &all;
  o.failed_sit_starts = &failed;
  // The sit's by default; an untrained meta's sits all begin at the spawn (the untrained subtasks
  // before them fall), so the left turn's hand-overs are the ones counted here.
  EXPECT_EQ(o.starts_subtask, kSit);
  o.starts_subtask = kLeftTurn;
  const Json r = EvaluateMeta(c, meta, Untrained(), o);
  // One state per hand-over to the left turn, whichever row it came from; a first run, from the
  // spawn, is none.
  const int hand_overs = HandOversTo(r, "turn_left");
  EXPECT_GT(RunsOf(r, "turn_left"), hand_overs) << "no trial began with it: the test cannot tell";
  int failed_trials = 0;
  ASSERT_GT(hand_overs, 0);
  EXPECT_EQ(static_cast<int>(all.size()), hand_overs);
  for (size_t i = 1; i < all.size(); ++i) EXPECT_LE(all[i - 1].episode(), all[i].episode());
  for (const proto::BankState& b : all) {
    EXPECT_LT(b.episode(), static_cast<uint64_t>(kTrials));
    EXPECT_TRUE(b.has_chair());
    EXPECT_EQ(b.q_size(), b.qd_size());
  }
  failed_trials = static_cast<int>(std::lround(kTrials * (1.0 - r["success_rate"].get<double>())));
  EXPECT_GT(failed_trials, 0);
  EXPECT_LE(failed.size(), all.size());
  // Nothing asked, nothing kept; the statistics do not depend on it.
  MetaEvalOptions plain = o;
  plain.sit_starts = nullptr;
  plain.failed_sit_starts = nullptr;
  const Json r2 = EvaluateMeta(c, meta, Untrained(), plain);
  EXPECT_EQ(r["transitions"], r2["transitions"]);
  EXPECT_EQ(r["min_dist_mean_m"], r2["min_dist_mean_m"]);
}

TEST(MetaEval, SavesTheHandOversToTheSubtaskItIsAskedFor) {
  const TaskEnvConfig c = MetaConfigFor({"turn_left", "turn_right", "sit", "walk"});
  const proto::ModelWeights meta = UntrainedMeta(5);
  MetaEvalOptions o;
  o.trials = 12;
  o.seed = 4;
  o.stochastic = true;
  o.threads = 2;
  // One state per hand-over to each subtask (not the first run, from the spawn), counted from
  // the transition matrices.
  for (int sub : {kLeftTurn, kRightTurn, kWalk}) {
    std::vector<proto::BankState> all;
    o.sit_starts = &all;
    o.starts_subtask = sub;
    const Json r = EvaluateMeta(c, meta, Untrained(), o);
    const int runs = HandOversTo(r, SubtaskName(sub));
    ASSERT_GT(runs, 0) << SubtaskName(sub);
    EXPECT_EQ(static_cast<int>(all.size()), runs) << SubtaskName(sub);
    EXPECT_NE(runs, HandOversTo(r, "sit")) << "the test cannot tell the subtasks apart";
    // The walker's hand-backs: its runs from the spawn are not among them.
    if (sub == kWalk) {
      EXPECT_GT(RunsOf(r, "walk"), runs);
    }
  }
}

TEST(MetaEnv, TheHandOverHookSeesTheStateTheSubtaskStartsFrom) {
  MetaEnv env(MetaConfigFor({"turn_left", "sit", "walk"}));
  env.SetFrozenPolicies(Untrained());
  std::vector<float> obs(57), walk{2.0f, 0.0f, 1.0f}, sit{1.0f, 0.0f, 1.0f};
  env.Seed(5);
  env.Reset(obs.data());
  std::vector<std::pair<int, Eigen::Vector3d>> seen;
  env.on_subtask_begin = [&](const HumanoidChairEnv& h, int sub) {
    seen.push_back({sub, h.humanoid_state().root_pos});
  };
  env.Step(walk.data(), obs.data());
  const Eigen::Vector3d before_sit = env.humanoid().humanoid_state().root_pos;
  env.Step(sit.data(), obs.data());
  ASSERT_EQ(seen.size(), 2u);
  EXPECT_EQ(seen[0].first, kWalk);
  EXPECT_EQ(seen[1].first, kSit);
  EXPECT_EQ(seen[1].second, before_sit);  // before the sit's first action
  EXPECT_NE(env.humanoid().humanoid_state().root_pos, before_sit);
}

// The delivered subtasks, loaded from the files the default config names.
TEST(MetaEnv, LoadsTheConfiguredSubtasksAndTheWalkerWalksToATarget) {
  // Spawned 8 m from the zone's centre, facing it: 4 s of walking stays clear of the chair.
  const TaskEnvConfig c = MetaConfigFor({"walk"}, 1, 8.0);
  const std::vector<FrozenPolicyData> p = LoadFrozenPolicies(c);
  ASSERT_EQ(p.size(), 1u);
  EXPECT_EQ(p[0].name, "walk");
  EXPECT_NE(p[0].source.find("sha256"), std::string::npos);
  MetaEnv env(c);
  env.SetFrozenPolicies(p);
  // Ten episodes walking straight on: the frozen walker must stay up for most of the 4 s, and
  // come closer to the chair.
  int falls = 0;
  for (int e = 0; e < 10; ++e) {
    env.Seed(100 + e);
    std::vector<float> obs(57), a{0.0f, 0.0f, 2.0f};
    env.Reset(obs.data());
    for (int t = 0; t < 8; ++t) {
      const StepResult r = env.Step(a.data(), obs.data());
      if (r.terminated) {
        ++falls;
        break;
      }
    }
    if (env.episode().control_steps == 240) {
      EXPECT_LT(env.episode().min_dist_m, 6.0);
    }
  }
  EXPECT_LE(falls, 3);
}

// The delivered meta policy with lookahead (perch eval --lookahead-delays-s): at each of its
// switches the delayed switches are simulated too; the simulator is exact (every trial ends as
// its last look ahead predicted) and no trial ends worse than the policy alone would have from
// its first switch on.
// Every aggregate key of an evaluation's JSON (all but `threads`, which says how it ran).
void ExpectSameResult(const Json& a, const Json& b) {
  std::set<std::string> keys;
  for (const auto& [k, v] : a.items()) keys.insert(k);
  for (const auto& [k, v] : b.items()) keys.insert(k);
  keys.erase("threads");
  for (const std::string& k : keys) {
    ASSERT_TRUE(a.contains(k) && b.contains(k)) << k;
    EXPECT_EQ(a[k], b[k]) << k;
  }
}

// `perch eval --records` / `--first-trial` / `perch eval-merge`: trials saved one per line and
// read back, from shards or a resumed run, give exactly the result of one run of all of them.
TEST(MetaEval, ShardsAndResumedRecordsGiveTheResultOfOneRun) {
  const TaskEnvConfig c = MetaConfigFor({"turn_left", "turn_right", "sit", "walk"});
  const proto::ModelWeights meta = UntrainedMeta(5);
  const std::vector<FrozenPolicyData> frozen = Untrained();
  MetaEvalOptions o;
  o.trials = 6;
  o.seed = 11;
  o.stochastic = true;  // untrained: sampled, so the trials differ
  o.threads = 2;
  const Json one = EvaluateMeta(c, meta, frozen, o);
  EXPECT_EQ(one["first_trial"], 0);
  // Two shards of three, their records through JSON lines and back.
  std::vector<MetaTrialRecord> records;
  o.on_record = [&](const MetaTrialRecord& r) {
    records.push_back(MetaTrialRecord::FromJson(Json::parse(r.ToJson().dump()), "line"));
  };
  o.trials = 3;
  const Json first = EvaluateMeta(c, meta, frozen, o);
  o.first_trial = 3;
  const Json second = EvaluateMeta(c, meta, frozen, o);
  EXPECT_EQ(first["trials"], 3);
  EXPECT_EQ(second["first_trial"], 3);
  ASSERT_EQ(records.size(), 6u);
  const Json header = MetaEvalHeader(c, meta, frozen, o);
  ExpectSameResult(AggregateMeta(header, records), one);
  // Each trial names the build that ran it; a record from before (no "build") counts apart, and
  // the figures do not depend on it.
  EXPECT_EQ(records[0].build, PerchVersion());
  EXPECT_EQ(one["builds"], Json({{PerchVersion(), 6}}));
  {
    std::vector<MetaTrialRecord> mixed = records;
    Json old = records[0].ToJson();
    ASSERT_EQ(old.erase("build"), 1u);
    mixed[0] = MetaTrialRecord::FromJson(old, "old line");
    EXPECT_EQ(mixed[0].build, "");
    const Json m = AggregateMeta(header, mixed);
    EXPECT_EQ(m["builds"], Json({{"(not recorded)", 1}, {PerchVersion(), 5}}));
    EXPECT_EQ(m["success_rate"], one["success_rate"]);
    EXPECT_EQ(m["min_dist_mean_m"], one["min_dist_mean_m"]);
  }
  // Resumed with two trials already run: only the other four run, and the result is the same.
  o.first_trial = 0;
  o.trials = 6;
  std::sort(records.begin(), records.end(),
            [](const MetaTrialRecord& a, const MetaTrialRecord& b) { return a.trial < b.trial; });
  o.done = {records[1], records[4]};
  int ran = 0;
  o.on_record = [&](const MetaTrialRecord& r) {
    ++ran;
    EXPECT_NE(r.trial, 1);
    EXPECT_NE(r.trial, 4);
  };
  ExpectSameResult(EvaluateMeta(c, meta, frozen, o), one);
  EXPECT_EQ(ran, 4);
  // A record outside the trials, or twice, is refused by name; so is aggregating a trial twice.
  o.done = {records[1]};
  o.done[0].trial = 6;
  EXPECT_THROW(EvaluateMeta(c, meta, frozen, o), ConfigError);
  o.done = {records[1], records[1]};
  EXPECT_THROW(EvaluateMeta(c, meta, frozen, o), ConfigError);
  EXPECT_THROW(AggregateMeta(header, {records[0], records[0]}), ConfigError);
  // A file written before an env field existed (here env.push) resumes while the field keeps its
  // default, and is refused once the run sets it.
  {
    Json old_header = header;
    old_header["env"].erase("push");
    ASSERT_NE(FirstHeaderDifference(header, old_header), "");
    const Json read =
        ParseMetaRecords(MetaRecordsHeaderLine(old_header) + "\n", "old.jsonl").header;
    EXPECT_EQ(FirstHeaderDifference(read, header), "");
    TaskEnvConfig pushed = c;
    pushed.env.push.rate_hz = 1.0;
    EXPECT_EQ(FirstHeaderDifference(read, MetaEvalHeader(pushed, meta, frozen, o)),
              "env.push.rate_hz");
  }
  // The header tells other trials apart, naming the field; where the files were does not count.
  o.seed = 12;
  Json moved = header;
  moved["about"] = {{"model", "elsewhere.bin"}};
  EXPECT_EQ(FirstHeaderDifference(header, moved), "");
  EXPECT_EQ(FirstHeaderDifference(header, MetaEvalHeader(c, meta, frozen, o)), "seed");
  TaskEnvConfig c2 = MetaConfigFor({"turn_left", "turn_right", "sit", "walk"}, 2);
  EXPECT_EQ(FirstHeaderDifference(header, MetaEvalHeader(c2, meta, frozen, o)), "env.spawn.zone");
  EXPECT_EQ(FirstHeaderDifference(header, MetaEvalHeader(c, UntrainedMeta(6), frozen, o)),
            "meta_sha256");

  // The file: a torn last line (a killed run) is left out; a bad line elsewhere is refused by
  // file and line.
  const std::string path = ::testing::TempDir() + "perch_meta_records.jsonl";
  std::string text = MetaRecordsHeaderLine(header) + "\n";
  for (const MetaTrialRecord& r : records) text += r.ToJson().dump() + "\n";
  { std::ofstream(path, std::ios::binary) << text << records[0].ToJson().dump().substr(0, 20); }
  MetaRecordsFile f = ReadMetaRecords(path);
  EXPECT_TRUE(f.torn_tail);
  EXPECT_EQ(f.header, header);
  ExpectSameResult(AggregateMeta(f.header, f.records), one);
  {
    // The writer resumes it: the torn line is cut in place, the trials come back as done, new
    // ones are appended after them; a second writer is refused while the first holds the file.
    MetaEvalOptions w;
    w.trials = 6;
    MetaRecordsWriter writer;
    const MetaRecordsWriter::Opened opened = writer.Open(path, header, &w);
    EXPECT_TRUE(opened.torn_tail);
    EXPECT_EQ(opened.resumed, 6);
    EXPECT_EQ(w.done.size(), 6u);
    MetaEvalOptions w2 = w;
    MetaRecordsWriter second;
    try {
      second.Open(path, header, &w2);
      ADD_FAILURE() << "a second writer opened a file in use";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("in use by another evaluation"), std::string::npos)
          << e.what();
    }
    ASSERT_TRUE(w.on_record);
    w.on_record(records[2]);
    std::ifstream in(path, std::ios::binary);
    const std::string now((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_EQ(now, text + records[2].ToJson().dump() + "\n");
  }
  {
    // Released (and its extra line gone), the file is refused for another seed's trials, naming the
    // field and both values, and left as it was.
    MetaEvalOptions w;
    w.trials = 7;
    Json other = header;
    other["seed"] = 12;
    { std::ofstream(path, std::ios::binary) << text; }
    const auto size = std::filesystem::file_size(path);
    MetaRecordsWriter writer;
    try {
      writer.Open(path, other, &w);
      ADD_FAILURE() << "records of another seed were resumed";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("another \"seed\" (11, now 12)"), std::string::npos)
          << e.what();
    }
    EXPECT_EQ(std::filesystem::file_size(path), size);
  }
  {
    // A header and no trial (a run refused before its first trial ended) holds nothing to keep:
    // another run's header replaces it.
    { std::ofstream(path, std::ios::binary) << MetaRecordsHeaderLine(header) << "\n"; }
    Json other = header;
    other["seed"] = 12;
    MetaEvalOptions w;
    w.trials = 6;
    MetaRecordsWriter writer;
    EXPECT_EQ(writer.Open(path, other, &w).resumed, 0);
    EXPECT_EQ(ReadMetaRecords(path).header, other);
  }
  { std::ofstream(path, std::ios::binary) << text << "{\"trial\": 9}\n"; }
  try {
    ReadMetaRecords(path);
    ADD_FAILURE() << "a record without its fields was read";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(path + ":8: missing required field 'success'"),
              std::string::npos)
        << e.what();
  }
  { std::ofstream(path, std::ios::binary) << "not json\n"; }
  EXPECT_THROW(ReadMetaRecords(path), ConfigError);
}

// The delivered meta policy in Zone 1: its saved env config, frozen subtasks and weights.
struct DeliveredMeta {
  TaskEnvConfig config;
  std::vector<FrozenPolicyData> frozen;
  proto::ModelWeights meta;
};
DeliveredMeta LoadDeliveredMeta() {
  const std::string model = ResolveProjectPath("models/sit_chair/policy.bin");
  DeliveredMeta d{TaskEnvConfig::FromJson(SavedConfig(model)["env"], "saved"),
                  FrozenPoliciesIn(model), LoadModelFile(model)};
  d.config.env.spawn = SpawnConfig();
  d.config.env.spawn.zone = 1;
  return d;
}

TEST(MetaEval, TheMetaPolicyWithLookaheadIsExactAndNoWorseThanAlone) {
  const DeliveredMeta d = LoadDeliveredMeta();
  const TaskEnvConfig& c = d.config;
  const std::vector<FrozenPolicyData>& frozen = d.frozen;
  ASSERT_EQ(frozen.size(), 4u);
  const proto::ModelWeights& meta = d.meta;
  MetaEvalOptions o;
  o.trials = 4;
  o.seed = 7;
  o.threads = 2;
  const Json alone = EvaluateMeta(c, meta, frozen, o);
  EXPECT_FALSE(alone.contains("lookahead"));
  o.policy_lookahead.lookahead_delays_s = {0.3, 0.8};
  const Json j = EvaluateMeta(c, meta, frozen, o);
  ASSERT_TRUE(j.contains("lookahead"));
  const Json& la = j["lookahead"];
  EXPECT_EQ(la["trials_predicted"].get<int>(), 4);  // every trial switches at least once
  EXPECT_EQ(la["trials_as_predicted"].get<int>(), 4);
  EXPECT_EQ(la["trials_not_worse_than_rules"].get<int>(), 4);
  // Three rollouts (now, +0.3 s, +0.8 s) at each switch.
  EXPECT_NEAR(la["rollouts_per_trial"].get<double>(), 3 * la["points_per_trial"].get<double>(),
              1e-9);
  EXPECT_EQ(j["lookahead_delays_s"], Json({0.3, 0.8}));
  EXPECT_EQ(j["lookahead_rank"], "sooner");
  EXPECT_EQ(j["decider"], "meta policy");
  ASSERT_GT(j["success_rate"].get<double>(), 0.0);
  // Seated, the pelvis (a capsule of radius 0.09 m) rests well above the seat surface's centre,
  // the paper's distance target, so no success comes much nearer than that height
  // (docs/journal/meta.md "Stop 40").
  EXPECT_GT(j["seated_height_cm_mean"].get<double>(), 5.0);
  EXPECT_LT(j["seated_height_cm_mean"].get<double>(), 15.0);
  EXPECT_GT(j["min_dist_success_mean_m"].get<double>(), 0.05);
  // With the other turn at its turn switches and a straight-on start, ranked by the nearer
  // success: still exact and no worse than the policy alone by that rank, and no success is lost.
  o.policy_lookahead.lookahead_sides = true;
  o.policy_lookahead.lookahead_straight_s = {0.5};
  o.policy_lookahead.lookahead_detour_deg = {-60.0, 60.0};
  o.policy_lookahead.lookahead_rank = "nearer";
  std::vector<MetaTrialRecord> records;  // the lookahead's counts survive the records too
  o.on_record = [&](const MetaTrialRecord& r) {
    records.push_back(MetaTrialRecord::FromJson(Json::parse(r.ToJson().dump()), "line"));
  };
  const Json near = EvaluateMeta(c, meta, frozen, o);
  ExpectSameResult(AggregateMeta(MetaEvalHeader(c, meta, frozen, o), records), near);
  EXPECT_EQ(near["lookahead_rank"], "nearer");
  EXPECT_EQ(near["lookahead_sides"], true);
  EXPECT_EQ(near["lookahead_straight_s"], Json({0.5}));
  EXPECT_EQ(near["lookahead_detour_deg"], Json({-60.0, 60.0}));
  EXPECT_EQ(near["lookahead"]["trials_predicted"].get<int>(), 4);
  EXPECT_GE(near["lookahead"]["points_per_trial"].get<double>(), 1.0);  // the start, at least
  // At the start: as the policy steers, and straight ahead, 60 deg left or right for 0.5 s.
  EXPECT_GE(near["lookahead"]["rollouts_per_trial"].get<double>(), 4.0);
  EXPECT_EQ(near["lookahead"]["trials_as_predicted"].get<int>(), 4);
  EXPECT_EQ(near["lookahead"]["trials_not_worse_than_rules"].get<int>(), 4);
  EXPECT_GE(near["success_rate"].get<double>(), alone["success_rate"].get<double>());
}

// perch eval --task sit_chair --push / --obs-noise / --act-noise / --restore (issue 49): each
// trial also runs unperturbed, and the result says how many outcomes the perturbation flipped.
// No perturbation of size zero flips anything; a 3 kN shove on the pelvis for 0.1 s at a random
// moment of every trial ends some that the policy alone completes; the records carry the
// unperturbed outcome, so a resumed or merged perturbed evaluation gives the same figures.
TEST(MetaEval, PerturbedTrialsReportTheirFlipRateAgainstTheSameTrialsUnperturbed) {
  const DeliveredMeta d = LoadDeliveredMeta();
  MetaEvalOptions o;
  o.trials = 8;
  o.seed = 21;
  o.threads = 2;
  const Json plain = EvaluateMeta(d.config, d.meta, d.frozen, o);
  EXPECT_FALSE(plain.contains("flip_rate"));
  EXPECT_FALSE(MetaEvalHeader(d.config, d.meta, d.frozen, o).contains("perturbation"));
  // A restore alone: the trial goes on from the same state (Bullet's caches rebuilt), so most
  // outcomes stay, and the unperturbed ones are the plain evaluation's.
  o.perturb.restore = true;
  const Json restored = EvaluateMeta(d.config, d.meta, d.frozen, o);
  EXPECT_EQ(restored["unperturbed_success_rate"], plain["success_rate"]);
  EXPECT_EQ(restored["perturbation"]["restore"], true);
  ASSERT_TRUE(restored.contains("flip_ci95"));
  EXPECT_LE(restored["flip_rate"].get<double>(), 0.5);
  o.perturb = Perturbation();
  o.perturb.push_n = 3000.0;
  std::vector<MetaTrialRecord> records;
  o.on_record = [&](const MetaTrialRecord& r) {
    records.push_back(MetaTrialRecord::FromJson(Json::parse(r.ToJson().dump()), "line"));
  };
  const Json pushed = EvaluateMeta(d.config, d.meta, d.frozen, o);
  EXPECT_EQ(pushed["unperturbed_success_rate"], plain["success_rate"]);
  ASSERT_GT(plain["success_rate"].get<double>(), 0.0);
  EXPECT_LT(pushed["success_rate"].get<double>(), plain["success_rate"].get<double>());
  EXPECT_GT(pushed["flip_rate"].get<double>(), 0.0);
  EXPECT_EQ(pushed["flips"].get<int>(),
            static_cast<int>(std::lround(pushed["flip_rate"].get<double>() * 8)));
  EXPECT_EQ(pushed["perturbation"]["push_n"], 3000.0);
  // Records hold both outcomes and aggregate to the same figures.
  ASSERT_EQ(records.size(), 8u);
  for (const MetaTrialRecord& r : records) EXPECT_GE(r.unperturbed_success, 0);
  ExpectSameResult(AggregateMeta(MetaEvalHeader(d.config, d.meta, d.frozen, o), records), pushed);
  // A record without the unperturbed outcome cannot join a perturbed evaluation.
  records[3].unperturbed_success = -1;
  EXPECT_THROW(AggregateMeta(MetaEvalHeader(d.config, d.meta, d.frozen, o), records), ConfigError);
}

// --record-routes: each trial's record holds its start observation and the outcome of every
// start route tried (the policy's own first), and the trial takes the best of them (only start
// routes here, ranked by the sooner success), so its outcome is theirs.
TEST(MetaEval, StartRoutesAreRecordedAndTheTrialTakesTheBest) {
  const DeliveredMeta d = LoadDeliveredMeta();
  const TaskEnvConfig& c = d.config;
  const std::vector<FrozenPolicyData>& frozen = d.frozen;
  const proto::ModelWeights& meta = d.meta;
  MetaEvalOptions o;
  o.trials = 3;
  o.seed = 7;
  o.threads = 2;
  o.policy_lookahead.lookahead_straight_s = {0.5};
  o.policy_lookahead.lookahead_detour_deg = {-60.0, 60.0};
  o.record_routes = true;
  std::vector<MetaTrialRecord> records;
  o.on_record = [&](const MetaTrialRecord& r) {
    records.push_back(MetaTrialRecord::FromJson(Json::parse(r.ToJson().dump()), "line"));
  };
  const Json j = EvaluateMeta(c, meta, frozen, o);
  ASSERT_EQ(records.size(), 3u);
  const MetaEnv probe(c);
  const double dt = probe.humanoid().spec().control_dt;
  for (const MetaTrialRecord& r : records) {
    SCOPED_TRACE(r.trial);
    EXPECT_EQ(static_cast<int>(r.start_obs.size()), probe.spec().obs_dim);
    ASSERT_EQ(r.routes.size(), 4u);  // its own, then ahead, 60 deg right and left for 0.5 s
    EXPECT_EQ(r.routes[0].straight_steps, 0);
    EXPECT_TRUE(std::isnan(r.routes[0].detour_deg));
    EXPECT_GT(r.routes[1].straight_steps, 0);
    EXPECT_TRUE(std::isnan(r.routes[1].detour_deg));
    EXPECT_NEAR(r.routes[2].detour_deg, -60.0, 1e-9);
    EXPECT_NEAR(r.routes[3].detour_deg, 60.0, 1e-9);
    // The policy's own route is what it would do alone (with the same restores).
    EXPECT_EQ(r.routes[0].success, r.la_rules_success);
    bool any = false;
    int sooner = std::numeric_limits<int>::max();
    for (const MetaTrialRecord::Route& route : r.routes) {
      any = any || route.success;
      if (route.success) sooner = std::min(sooner, route.success_step);
      if (route.success) {
        EXPECT_FALSE(route.fell);
      }
    }
    EXPECT_EQ(r.success, any);
    if (any) {
      EXPECT_NEAR(r.time_to_sit_s, sooner * dt, 1e-9);
    }
  }
  EXPECT_EQ(j["lookahead"]["rollouts_per_trial"].get<double>(), 4.0);
  // Without the option the records hold no routes.
  o.record_routes = false;
  o.trials = 1;
  records.clear();
  EvaluateMeta(c, meta, frozen, o);
  ASSERT_EQ(records.size(), 1u);
  EXPECT_TRUE(records[0].routes.empty());
  EXPECT_TRUE(records[0].start_obs.empty());
  EXPECT_FALSE(records[0].ToJson().contains("routes"));
}

// A saved episode restored into a second env goes on exactly as the env that saved it does after
// restoring it too (the lookahead planner's simulator, hierarchy/meta_lookahead.h): the same
// observations, rewards, subtask sequence and record, through hand-overs to a turn and the sit.
TEST(MetaEnv, ARestoredEpisodeGoesOnAsTheSavingEnvDoes) {
  TaskEnvConfig c = MetaConfigFor({"turn_left", "turn_right", "sit", "walk"}, 1, 4.0);
  c.MutableSection<SitChairTaskConfig>().meta.period = 10;
  const std::vector<FrozenPolicyData> p = LoadFrozenPolicies(c);
  MetaEnv a(c), b(c);
  a.SetFrozenPolicies(p);
  b.SetFrozenPolicies(p);
  std::vector<float> obs_a(57), obs_b(57);
  a.Seed(5);
  a.Reset(obs_a.data());
  b.Seed(99);  // another episode: everything it keeps must be replaced by the restore
  b.Reset(obs_b.data());
  std::vector<float> walk{3.0f, 0.2f, 2.0f};
  for (int t = 0; t < 6; ++t) b.Step(walk.data(), obs_b.data());
  for (int t = 0; t < 6; ++t) ASSERT_FALSE(a.Step(walk.data(), obs_a.data()).terminated);
  const MetaEnvState s = a.SaveState();
  a.RestoreState(s);
  b.RestoreState(s);
  // A turn, then the sit; the walker in between.
  const std::vector<float> classes{0, 0, 0, 3, 3, 2, 2, 2};
  int compared = 0;
  for (float cls : classes) {
    std::vector<float> act{cls, -0.3f, 1.5f};
    const StepResult ra = a.Step(act.data(), obs_a.data());
    const StepResult rb = b.Step(act.data(), obs_b.data());
    ASSERT_EQ(obs_a, obs_b) << "meta step " << compared;
    ASSERT_EQ(ra.reward, rb.reward);
    ASSERT_EQ(ra.terminated, rb.terminated);
    ++compared;
    if (ra.terminated) break;
  }
  EXPECT_GE(compared, 2);
  EXPECT_EQ(a.episode().sequence, b.episode().sequence);
  EXPECT_GE(a.episode().sequence.size(), 2u);
  EXPECT_EQ(a.episode().control_steps, b.episode().control_steps);
  EXPECT_EQ(a.episode().min_dist_m, b.episode().min_dist_m);
  EXPECT_EQ(a.active(), b.active());
}

// meta.blend_steps: after a switch the humanoid gets the cross-fade of the old subtask's action and
// the new one's, then the new one's alone; a restore in the middle of a fade goes on as the saver.
TEST(MetaEnv, ASwitchCrossFadesTheOldSubtasksActionIntoTheNewOnes) {
  auto config = [](int blend) {
    TaskEnvConfig c = MetaConfigFor({"turn_left", "turn_right", "sit", "walk"});
    auto& m = c.MutableSection<SitChairTaskConfig>().meta;
    m.period = 10;
    m.subtask_stochastic = false;  // mean actions: the fade is exact
    m.blend_steps = blend;
    return c;
  };
  const std::vector<FrozenPolicyData> p = Untrained();
  // keep: walks on; cut: switches to the left turn at once; fade: switches with a 4-step fade.
  struct Run {
    std::unique_ptr<MetaEnv> env;
    std::vector<std::array<double, HumanoidModel::kNumJoints>> tau;  // per control step [N m]
  };
  auto start = [&](int blend) {
    auto r = std::make_unique<Run>();
    r->env = std::make_unique<MetaEnv>(config(blend));
    r->env->SetFrozenPolicies(p);
    Run* raw = r.get();
    r->env->on_control_step = [raw](const HumanoidChairEnv& e, const StepResult&, int) {
      raw->tau.push_back(e.last_torques());
    };
    r->env->Seed(21);
    std::vector<float> obs(57), walk{3.0f, 0.1f, 2.0f};
    r->env->Reset(obs.data());
    r->env->Step(walk.data(), obs.data());
    return r;
  };
  auto keep = start(0), cut = start(0), fade = start(4);
  ASSERT_EQ(fade->tau, cut->tau);  // the walker alone so far
  std::vector<float> obs(57), walk{3.0f, 0.1f, 2.0f}, left{0.0f, 0.1f, 2.0f};
  keep->env->Step(walk.data(), obs.data());
  cut->env->Step(left.data(), obs.data());
  fade->env->Step(left.data(), obs.data());
  ASSERT_EQ(fade->tau.size(), 20u);
  // The first step after the switch starts from one state in all three: the fade's torque is
  // 1/5 of the turn's plus 4/5 of the walker's wherever neither saturates.
  const HumanoidModel& model = fade->env->humanoid().model();
  int linear = 0;
  for (int j = 0; j < model.num_joints(); ++j) {
    const double max = model.joint(j).max_torque;
    const double a = cut->tau[10][j], b = keep->tau[10][j];
    if (std::abs(a) >= max || std::abs(b) >= max) continue;
    EXPECT_NEAR(fade->tau[10][j], 0.2 * a + 0.8 * b, 1e-4 * max) << "joint " << j;
    ++linear;
  }
  EXPECT_GE(linear, 5);
  EXPECT_NE(fade->tau[10], cut->tau[10]);
  EXPECT_EQ(fade->env->episode().sequence, cut->env->episode().sequence);
  // A fade longer than a meta step: saved with 5 of its 15 steps to go, restored into another env.
  auto a = start(15), b = start(15);
  a->env->Step(left.data(), obs.data());
  const MetaEnvState s = a->env->SaveState();
  EXPECT_EQ(s.blend_left, 5);
  a->env->RestoreState(s);  // both restored: a restore empties Bullet's contact caches
  b->env->RestoreState(s);
  a->tau.clear();
  b->tau.clear();
  a->env->Step(left.data(), obs.data());
  b->env->Step(left.data(), obs.data());
  EXPECT_EQ(a->tau, b->tau);
  EXPECT_GE(a->tau.size(), 6u);  // past the fade's end (the untrained turn may fall after it)
  // Refused out of range, by name.
  Json bad{{"task", "sit_chair"}, {"sit_chair", {{"meta", {{"blend_steps", -1}}}}}};
  try {
    TaskEnvConfig::FromJson(bad, "t");
    ADD_FAILURE() << "blend_steps -1 accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("blend_steps"), std::string::npos);
  }
}

}  // namespace
}  // namespace perch
