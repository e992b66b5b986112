// The planner with lookahead (ours, stop 39): MetaPlanner's rules, but wherever they switch
// subtasks (and at the first decision, which turn to take) the alternatives are simulated to the
// episode's end on a second MetaEnv with the same config, frozen subtasks, spawn and chair, each
// continued by the same rules, and the best outcome is taken (success first, sooner; then no
// fall; then a nearer approach). This is the rollout algorithm: with an exact simulator it never
// does worse on a trial than the rules alone.
//
// The simulator is exact: at every decision where the rules switch, the acting env and every
// rollout save their state and restore it (MetaEnv::RestoreState rebuilds the physics world), so
// the acting env goes on exactly as the chosen rollout did up to the next such decision, whose
// own choice includes that rollout's continuation. PlannerConfig::lookahead_delays_s and
// lookahead_sides switch it on; perch eval --task sit_chair --planner uses it then.
#pragma once

#include <memory>
#include <optional>
#include <vector>

#include "hierarchy/meta_env.h"
#include "hierarchy/meta_expert.h"

namespace perch {

// How a (simulated) episode ended.
struct LookaheadOutcome {
  bool success = false;
  int success_step = -1;  // control step of the success
  bool fell = false;
  double min_dist_m = 0.0;
  // Success, sooner (`nearer`: success, nearer, then sooner); then no fall; then nearer (false
  // when equal).
  bool BetterThan(const LookaheadOutcome& o, bool nearer = false) const;
  static LookaheadOutcome Of(const MetaEpisode& e);
};

class PolicyRunner;

// What the lookahead improves on: the planner's rules, or a meta policy acting on the meta
// observation (its mean action; a policy has no state of its own to copy).
class MetaDecider {
 public:
  explicit MetaDecider(std::shared_ptr<const MetaPlan> plan);
  explicit MetaDecider(std::shared_ptr<PolicyRunner> policy);
  void Reset();
  void Act(const MetaEnv& env, float* action);
  // The rules' turn side (-1 before their first decision); a policy has none to choose (0).
  int side() const { return rules_ ? rules_->side() : 0; }
  bool is_policy() const { return !rules_; }
  void set_side(int side) {
    if (rules_) rules_->set_side(side);
  }

 private:
  std::optional<MetaPlanner> rules_;
  std::shared_ptr<PolicyRunner> policy_;
  std::vector<float> obs_;
};

class LookaheadPlanner {
 public:
  // The planner's rules improved as its config's lookahead_* fields say.
  LookaheadPlanner(std::shared_ptr<const MetaPlan> plan, const TaskEnvConfig& config,
                   const std::vector<FrozenPolicyData>& frozen);
  // A meta policy improved as `lookahead`'s lookahead_* fields say: its switches delayed by each
  // of lookahead_delays_s; with lookahead_sides, each switch into a turn also simulated into the
  // other turn; at its first step, the walker walking straight on for each of
  // lookahead_straight_s before the policy steers it; outcomes ranked by lookahead_rank.
  LookaheadPlanner(std::shared_ptr<PolicyRunner> policy, const PlannerConfig& lookahead,
                   const TaskEnvConfig& config, const std::vector<FrozenPolicyData>& frozen);
  ~LookaheadPlanner();
  // After env.Seed(seed) and env.Reset: the simulator is seeded and reset alike (the same spawn
  // and chair).
  void Reset(uint64_t seed);
  // Before each env.Step: action[3] as MetaPlanner::Act. May restore `env` to the state it just
  // saved (see above).
  void Act(MetaEnv& env, float* action);

  // This episode so far: decisions looked ahead at, rollouts run, decisions whose choice differs
  // from the rules' own, and the outcome the last choice predicted.
  struct Stats {
    int points = 0, rollouts = 0, changed = 0;
    bool predicted_any = false;
    LookaheadOutcome predicted;
    // What the rules alone (with the same saves and restores) did from the first look ahead on:
    // the outcome the lookahead must not fall below.
    LookaheadOutcome rules;
    // A meta policy's start routes (its first step, with straight-on starts): each one's outcome,
    // in the order tried (the policy's own first, straight_steps 0). For learning which start
    // to take without the simulator (docs/journal/meta.md "Stop 42").
    struct Route {
      int straight_steps = 0;  // [meta steps] walked straight on before the policy steers
      double detour_deg = 0;   // off the facing at the start [deg] (NaN: straight ahead)
      LookaheadOutcome outcome;
    };
    std::vector<Route> routes;
  };
  const Stats& stats() const { return stats_; }
  // Whether `a` ranks above `b` as this lookahead ranks outcomes.
  bool Better(const LookaheadOutcome& a, const LookaheadOutcome& b) const {
    return a.BetterThan(b, config_.lookahead_rank == "nearer");
  }

 private:
  // One decision of the rules on `env` as the acting env and every rollout make it: at a switch
  // (or the first decision) the env's state is saved and restored first. `hold`: the running
  // subtask goes on whatever the rules say.
  // `straight`: the walker's target is straight ahead instead (the first decision's alternatives).
  // `straight_yaw`: the world direction it walks then [rad] (NaN: straight ahead each step).
  void RuleStep(MetaEnv& env, MetaDecider& planner, bool hold, bool straight, double straight_yaw,
                float* action) const;
  // `side`: the rules' turn (>= 0), kOtherTurn (a policy's switch goes into the other turn
  // instead) or -1 (as decided).
  LookaheadOutcome Rollout(const MetaEnvState& s, const MetaDecider& before, int side,
                           int hold_steps, int straight_steps, double straight_yaw);
  static constexpr int kOtherTurn = 2;
  // A policy's switch into a turn turned into the other turn.
  static void OtherTurn(const MetaEnv& env, float* action);
  void Straight(const MetaEnv& env, double yaw, float* action) const;
  void Init(const TaskEnvConfig& config, const std::vector<FrozenPolicyData>& frozen);
  PlannerConfig config_;  // the lookahead_* fields and lookahead_m
  std::unique_ptr<MetaEnv> sim_;
  MetaDecider base_;
  std::vector<int> delays_;      // [meta steps], each > 0
  std::vector<int> straights_;   // [meta steps], each > 0
  std::vector<double> detours_;  // [rad], off the facing at the decision
  int meta_step_ = 0;
  int hold_until_ = 0;       // the running subtask goes on while meta_step_ < hold_until_
  int straight_until_ = 0;   // the walker walks straight on while meta_step_ < straight_until_
  double straight_yaw_ = 0;  // ... in this world direction [rad] (NaN: ahead)
  Stats stats_;
};

}  // namespace perch
