#include "tasks/meta_lookahead.h"

#include <algorithm>
#include <cmath>

namespace perch {

namespace {

// The switch class of subtask `id` in the env's choices (-1: not among them).
int ClassOf(const MetaEnv& env, int id) {
  const std::vector<std::string>& c = env.meta().choices;
  const auto it = std::find(c.begin(), c.end(), SubtaskName(id));
  return it == c.end() ? -1 : static_cast<int>(it - c.begin());
}

// Whether `action` hands over to another subtask than the one acting.
bool Switches(const MetaEnv& env, const float* action) {
  const int cls = static_cast<int>(std::lround(action[0]));
  return cls != ClassOf(env, env.active());
}

}  // namespace

bool LookaheadOutcome::BetterThan(const LookaheadOutcome& o) const {
  if (success != o.success) return success;
  if (success) return success_step < o.success_step;
  if (fell != o.fell) return !fell;
  return min_dist_m < o.min_dist_m;
}

LookaheadOutcome LookaheadOutcome::Of(const MetaEpisode& e) {
  LookaheadOutcome out;
  out.success = e.success_step >= 0;
  out.success_step = e.success_step;
  out.fell = e.fell;
  out.min_dist_m = e.min_dist_m;
  return out;
}

LookaheadPlanner::LookaheadPlanner(std::shared_ptr<const MetaPlan> plan,
                                   const TaskEnvConfig& config,
                                   const std::vector<FrozenPolicyData>& frozen)
    : plan_(plan), sim_(std::make_unique<MetaEnv>(config)), base_(plan) {
  sim_->SetFrozenPolicies(frozen);
  const double period_s = sim_->meta().period * sim_->humanoid().spec().control_dt;
  for (double d : plan_->config.lookahead_delays_s) {
    delays_.push_back(std::max(1, static_cast<int>(std::lround(d / period_s))));
  }
}

LookaheadPlanner::~LookaheadPlanner() = default;

void LookaheadPlanner::Reset(uint64_t seed) {
  std::vector<float> obs(sim_->spec().obs_dim);
  sim_->Seed(seed);
  sim_->Reset(obs.data());
  base_.Reset();
  meta_step_ = 0;
  hold_until_ = 0;
  stats_ = Stats();
}

void LookaheadPlanner::RuleStep(MetaEnv& env, MetaPlanner& planner, bool hold, float* action) {
  const MetaPlanner before = planner;
  planner.Act(env, action);
  if (before.side() < 0 || Switches(env, action)) {
    env.RestoreState(env.SaveState());
    planner = before;
    planner.Act(env, action);
  }
  if (hold) action[0] = static_cast<float>(ClassOf(env, env.active()));
}

LookaheadOutcome LookaheadPlanner::Rollout(const MetaEnvState& s, const MetaPlanner& before,
                                           int side, int hold_steps) {
  ++stats_.rollouts;
  sim_->RestoreState(s);
  MetaPlanner p = before;
  if (side >= 0) p.set_side(side);
  std::vector<float> obs(sim_->spec().obs_dim), a(sim_->spec().act_dim);
  p.Act(*sim_, a.data());
  if (hold_steps > 0) a[0] = static_cast<float>(ClassOf(*sim_, sim_->active()));
  for (int k = 1;; ++k) {
    const StepResult r = sim_->Step(a.data(), obs.data());
    if (r.terminated || r.truncated || sim_->episode().success_step >= 0) break;
    RuleStep(*sim_, p, k < hold_steps, a.data());
  }
  return LookaheadOutcome::Of(sim_->episode());
}

void LookaheadPlanner::Act(MetaEnv& env, float* action) {
  const int step = meta_step_++;
  const bool hold = step < hold_until_;
  const MetaPlanner before = base_;
  base_.Act(env, action);
  const bool first = before.side() < 0;
  const bool switches = Switches(env, action);
  if (!first && !switches) {
    if (hold) action[0] = static_cast<float>(ClassOf(env, env.active()));
    return;
  }
  // As RuleStep: save and restore, so that what follows is what a rollout from here simulates.
  const MetaEnvState s = env.SaveState();
  env.RestoreState(s);
  base_ = before;
  base_.Act(env, action);
  if (hold) {
    action[0] = static_cast<float>(ClassOf(env, env.active()));
    return;
  }
  std::vector<int> sides{-1};
  if (first && plan_->config.lookahead_sides) sides = {base_.side(), 1 - base_.side()};
  std::vector<int> holds{0};
  if (Switches(env, action)) holds.insert(holds.end(), delays_.begin(), delays_.end());
  if (sides.size() * holds.size() < 2) return;
  ++stats_.points;
  int best_side = sides[0], best_hold = 0;
  LookaheadOutcome best;
  bool have = false;
  for (int side : sides) {
    for (int h : holds) {
      const LookaheadOutcome o = Rollout(s, before, side, h);
      if (!stats_.predicted_any && !have) stats_.rules = o;
      if (!have || o.BetterThan(best)) {
        best = o;
        best_side = side;
        best_hold = h;
        have = true;
      }
    }
  }
  stats_.predicted_any = true;
  stats_.predicted = best;
  if (best_side != sides[0] || best_hold != 0) ++stats_.changed;
  if (best_side >= 0 && best_side != base_.side()) {
    base_ = before;
    base_.set_side(best_side);
    base_.Act(env, action);
  }
  if (best_hold > 0) {
    hold_until_ = step + best_hold;
    action[0] = static_cast<float>(ClassOf(env, env.active()));
  }
}

}  // namespace perch
