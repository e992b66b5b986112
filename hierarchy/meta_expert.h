// A scripted meta controller (ours; issue 15): the planned hand-over of hierarchy/chain_plan.h
// decided at the meta controller's own rate, through MetaEnv's hybrid action. It is the teacher a
// meta policy is cloned from (learner/local/meta_clone.h) and a row of the evaluation ("planner").
//
// Each meta step: while walking, steer the walker so that the turn would end where the sit's clip
// starts, and choose the turn at the decision whose predicted turn end is nearest to it; while
// turning, choose sit at the decision nearest to the sit's heading; then keep sitting.
#pragma once

#include <array>
#include <memory>
#include <vector>

#include "common/env.h"
#include "common/json_util.h"
#include "common/rng.h"
#include "hierarchy/chain_plan.h"
#include "tasks/task_env.h"

namespace perch {

class MetaEnv;

MetaPlan BuildMetaPlan(const TaskEnvConfig& config, const std::vector<FrozenPolicyData>& frozen,
                       const PlannerConfig& planner);

// One per env (per thread): call Reset after each MetaEnv::Reset, then Act before each Step.
class MetaPlanner {
 public:
  explicit MetaPlanner(std::shared_ptr<const MetaPlan> plan) : plan_(std::move(plan)) {}
  void Reset();
  // action[3] = [class index in env.meta().choices, theta rad, dist m].
  void Act(const MetaEnv& env, float* action);
  // The turn's side (0 left, 1 right), -1 before the first decision; set_side fixes it (the
  // lookahead tries both, hierarchy/meta_lookahead.h).
  int side() const { return side_; }
  void set_side(int side) { side_ = side; }

 private:
  std::shared_ptr<const MetaPlan> plan_;
  int side_ = -1;  // 0 left, 1 right; chosen at the first decision
  // The subtask seen acting at the last decision and the control step it began (whoever chose
  // it: a cloned policy may drive while the planner labels, learner/local/meta_clone.h).
  int last_active_ = -1;
  int active_since_step_ = 0;
  // The value gate (PlannerConfig::turn_value_min): the control step at which the rule first
  // said "hand over" during the running subtask; -1: not yet.
  int ready_since_step_ = -1;
  // After a turn was handed back: the walker walks straight on until this control step.
  int recover_until_step_ = 0;
  // Whether the hand-over to `next` may happen now: its critic rates the state at least
  // value_min, or the wait is over (value_min 0: always).
  bool Gate(const MetaEnv& env, int next, double value_min);
  // Whether the walker takes over from a subtask whose critic reads `value`: it is below `below`
  // and the walker's critic is higher (and >= abort_walk_min); starts the walker's recovery then.
  bool HandBack(const MetaEnv& env, float value, double below);
};

}  // namespace perch
