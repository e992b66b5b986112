#include "hierarchy/meta_lookahead.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "policy/policy.h"
#include "tasks/imitation.h"

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

bool LookaheadOutcome::BetterThan(const LookaheadOutcome& o, bool nearer) const {
  if (success != o.success) return success;
  if (success && nearer && min_dist_m != o.min_dist_m) return min_dist_m < o.min_dist_m;
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

MetaDecider::MetaDecider(std::shared_ptr<const MetaPlan> plan) : rules_(MetaPlanner(plan)) {}

MetaDecider::MetaDecider(std::shared_ptr<PolicyRunner> policy) : policy_(std::move(policy)) {}

void MetaDecider::Reset() {
  if (rules_) rules_->Reset();
}

void MetaDecider::Act(const MetaEnv& env, float* action) {
  if (rules_) {
    rules_->Act(env, action);
    return;
  }
  obs_.resize(env.spec().obs_dim);
  env.Observe(obs_.data());
  Rng unused(0);  // the mean action draws nothing
  policy_->Act(obs_.data(), unused, /*deterministic=*/true, nullptr, action);
}

LookaheadPlanner::LookaheadPlanner(std::shared_ptr<const MetaPlan> plan,
                                   const TaskEnvConfig& config,
                                   const std::vector<FrozenPolicyData>& frozen)
    : config_(plan->config), base_(plan) {
  Init(config, frozen);
}

LookaheadPlanner::LookaheadPlanner(std::shared_ptr<PolicyRunner> policy,
                                   const PlannerConfig& lookahead, const TaskEnvConfig& config,
                                   const std::vector<FrozenPolicyData>& frozen)
    : config_(lookahead), base_(std::move(policy)) {
  Init(config, frozen);
}

void LookaheadPlanner::Init(const TaskEnvConfig& config,
                            const std::vector<FrozenPolicyData>& frozen) {
  sim_ = std::make_unique<MetaEnv>(config);
  sim_->SetFrozenPolicies(frozen);
  const double period_s = sim_->meta().period * sim_->humanoid().spec().control_dt;
  for (double d : config_.lookahead_delays_s) {
    delays_.push_back(std::max(1, static_cast<int>(std::lround(d / period_s))));
  }
  for (double d : config_.lookahead_straight_s) {
    straights_.push_back(std::max(1, static_cast<int>(std::lround(d / period_s))));
  }
  for (double h : config_.lookahead_detour_deg) detours_.push_back(h * M_PI / 180.0);
}

LookaheadPlanner::~LookaheadPlanner() = default;

void LookaheadPlanner::Reset(uint64_t seed) {
  std::vector<float> obs(sim_->spec().obs_dim);
  sim_->Seed(seed);
  sim_->Reset(obs.data());
  base_.Reset();
  meta_step_ = 0;
  hold_until_ = 0;
  straight_until_ = 0;
  stats_ = Stats();
}

void LookaheadPlanner::OtherTurn(const MetaEnv& env, float* action) {
  const int cls = static_cast<int>(std::lround(action[0]));
  const std::vector<std::string>& c = env.meta().choices;
  if (cls < 0 || cls >= static_cast<int>(c.size())) return;
  const int id = SubtaskIdOf(c[cls]);
  if (id != kLeftTurn && id != kRightTurn) return;
  const int other = ClassOf(env, id == kLeftTurn ? kRightTurn : kLeftTurn);
  if (other >= 0) action[0] = static_cast<float>(other);
}

void LookaheadPlanner::Straight(const MetaEnv& env, double yaw, float* action) const {
  if (env.active() != kWalk) return;
  // Ahead (as MetaPlanner keeps the target while not walking), or toward `yaw`.
  action[1] =
      std::isnan(yaw) ? 0.0f : static_cast<float>(AngleDiff(yaw, env.humanoid().RootRpy().z()));
  action[2] = static_cast<float>(config_.lookahead_m);
}

void LookaheadPlanner::RuleStep(MetaEnv& env, MetaDecider& planner, bool hold, bool straight,
                                double straight_yaw, float* action) const {
  const MetaDecider before = planner;
  planner.Act(env, action);
  if (before.side() < 0 || Switches(env, action)) {
    env.RestoreState(env.SaveState());
    planner = before;
    planner.Act(env, action);
  }
  if (hold) action[0] = static_cast<float>(ClassOf(env, env.active()));
  if (straight) Straight(env, straight_yaw, action);
}

LookaheadOutcome LookaheadPlanner::Rollout(const MetaEnvState& s, const MetaDecider& before,
                                           int side, int hold_steps, int straight_steps,
                                           double straight_yaw) {
  ++stats_.rollouts;
  sim_->RestoreState(s);
  MetaDecider p = before;
  if (side >= 0 && side != kOtherTurn) p.set_side(side);
  std::vector<float> obs(sim_->spec().obs_dim), a(sim_->spec().act_dim);
  p.Act(*sim_, a.data());
  if (side == kOtherTurn) OtherTurn(*sim_, a.data());
  if (hold_steps > 0) a[0] = static_cast<float>(ClassOf(*sim_, sim_->active()));
  if (straight_steps > 0) Straight(*sim_, straight_yaw, a.data());
  for (int k = 1;; ++k) {
    const StepResult r = sim_->Step(a.data(), obs.data());
    if (r.terminated || r.truncated || sim_->episode().success_step >= 0) break;
    RuleStep(*sim_, p, k < hold_steps, k < straight_steps, straight_yaw, a.data());
  }
  return LookaheadOutcome::Of(sim_->episode());
}

void LookaheadPlanner::Act(MetaEnv& env, float* action) {
  const int step = meta_step_++;
  const bool hold = step < hold_until_;
  const bool straight = step < straight_until_;
  const MetaDecider before = base_;
  base_.Act(env, action);
  // A policy's first decision is its first step, looked at only for straight-on starts (the
  // rules' is their choice of side).
  const bool first = before.is_policy() ? step == 0 && !straights_.empty() : before.side() < 0;
  const bool switches = Switches(env, action);
  if (!first && !switches) {
    if (hold) action[0] = static_cast<float>(ClassOf(env, env.active()));
    if (straight) Straight(env, straight_yaw_, action);
    return;
  }
  // As RuleStep: save and restore, so that what follows is what a rollout from here simulates.
  const MetaEnvState s = env.SaveState();
  env.RestoreState(s);
  base_ = before;
  base_.Act(env, action);
  if (hold || straight) {
    if (hold) action[0] = static_cast<float>(ClassOf(env, env.active()));
    if (straight) Straight(env, straight_yaw_, action);
    return;
  }
  std::vector<int> sides{-1};
  if (config_.lookahead_sides) {
    if (!base_.is_policy() && first) {
      sides = {base_.side(), 1 - base_.side()};
    } else if (base_.is_policy() && Switches(env, action)) {
      // Into the other turn, when it switches into a turn.
      std::vector<float> other(action, action + env.spec().act_dim);
      OtherTurn(env, other.data());
      if (other[0] != action[0]) sides = {-1, kOtherTurn};
    }
  }
  std::vector<int> holds{0};
  if (Switches(env, action)) holds.insert(holds.end(), delays_.begin(), delays_.end());
  // Straight-on starts: [meta steps, world direction (NaN: ahead)].
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<std::pair<int, double>> straights{{0, nan}};
  const double facing = env.humanoid().RootRpy().z();
  if (first) {
    for (int st : straights_) {
      straights.emplace_back(st, nan);
      for (double d : detours_) straights.emplace_back(st, facing + d);
    }
  }
  if (sides.size() * holds.size() * straights.size() < 2) return;
  ++stats_.points;
  int best_side = sides[0], best_hold = 0, best_straight = 0;
  double best_yaw = nan;
  LookaheadOutcome best;
  bool have = false;
  for (int side : sides) {
    for (const auto& [st, yaw] : straights) {
      for (int h : holds) {
        const LookaheadOutcome o = Rollout(s, before, side, h, st, yaw);
        if (!stats_.predicted_any && !have) stats_.rules = o;
        if (first && before.is_policy() && side == sides[0] && h == 0) {
          stats_.routes.push_back(
              {st, std::isnan(yaw) ? nan : AngleDiff(yaw, facing) * 180.0 / M_PI, o});
        }
        if (!have || Better(o, best)) {
          best = o;
          best_side = side;
          best_hold = h;
          best_straight = st;
          best_yaw = yaw;
          have = true;
        }
      }
    }
  }
  stats_.predicted_any = true;
  stats_.predicted = best;
  if (best_side != sides[0] || best_hold != 0 || best_straight != 0) ++stats_.changed;
  if (best_side == kOtherTurn) {
    OtherTurn(env, action);
  } else if (best_side >= 0 && best_side != base_.side()) {
    base_ = before;
    base_.set_side(best_side);
    base_.Act(env, action);
  }
  if (best_hold > 0) {
    hold_until_ = step + best_hold;
    action[0] = static_cast<float>(ClassOf(env, env.active()));
  }
  if (best_straight > 0) {
    straight_until_ = step + best_straight;
    straight_yaw_ = best_yaw;
    Straight(env, straight_yaw_, action);
  }
}

}  // namespace perch
