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
#include <vector>

#include "tasks/meta_env.h"
#include "tasks/meta_expert.h"

namespace perch {

// How a (simulated) episode ended.
struct LookaheadOutcome {
  bool success = false;
  int success_step = -1;  // control step of the success
  bool fell = false;
  double min_dist_m = 0.0;
  // Success, sooner; then no fall; then nearer (false when equal).
  bool BetterThan(const LookaheadOutcome& o) const;
  static LookaheadOutcome Of(const MetaEpisode& e);
};

class LookaheadPlanner {
 public:
  LookaheadPlanner(std::shared_ptr<const MetaPlan> plan, const TaskEnvConfig& config,
                   const std::vector<FrozenPolicyData>& frozen);
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
  };
  const Stats& stats() const { return stats_; }

 private:
  // One decision of the rules on `env` as the acting env and every rollout make it: at a switch
  // (or the first decision) the env's state is saved and restored first. `hold`: the running
  // subtask goes on whatever the rules say.
  static void RuleStep(MetaEnv& env, MetaPlanner& planner, bool hold, float* action);
  LookaheadOutcome Rollout(const MetaEnvState& s, const MetaPlanner& before, int side,
                           int hold_steps);
  std::shared_ptr<const MetaPlan> plan_;
  std::unique_ptr<MetaEnv> sim_;
  MetaPlanner base_;
  std::vector<int> delays_;  // [meta steps], each > 0
  int meta_step_ = 0;
  int hold_until_ = 0;  // the running subtask goes on while meta_step_ < hold_until_
  Stats stats_;
};

}  // namespace perch
