#include "hierarchy/meta_expert.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "common/proto/model.pb.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/meta_env.h"
#include "tasks/imitation.h"

namespace perch {

MetaPlan BuildMetaPlan(const TaskEnvConfig& config, const std::vector<FrozenPolicyData>& frozen,
                       const PlannerConfig& planner) {
  if (config.env.task != "sit_chair") {
    throw ConfigError("planner: needs the sit_chair env task, got \"" + config.env.task + "\"");
  }
  std::array<proto::ModelWeights, kNumSubtasks> models;
  std::array<std::string, kNumSubtasks> names;
  std::array<Json, kNumSubtasks> saved;
  std::array<bool, kNumSubtasks> have{};
  for (const FrozenPolicyData& f : frozen) {
    const int id = SubtaskIdOf(f.name);
    if (id < 0 || id == kWalk) continue;
    const std::string ctx = "planner: frozen " + f.name + " policy " + f.source;
    if (!models[id].ParseFromString(f.model)) throw ConfigError(ctx + ": model does not parse");
    names[id] = f.source.empty() ? f.name : f.source;
    if (!f.saved_config.empty()) saved[id] = Json::parse(f.saved_config);
    have[id] = true;
  }
  for (int id : {kLeftTurn, kRightTurn, kSit}) {
    if (!have[id] && (id == kSit || PlannerTakesTurn(planner, id))) {
      throw ConfigError(std::string("planner: needs the ") + SubtaskName(id) +
                        " subtask among sit_chair.meta.choices (planner.side \"" + planner.side +
                        "\")");
    }
  }
  SubtaskPolicies policies(models, names, saved, {have[kLeftTurn], have[kRightTurn], true, false});
  std::unique_ptr<HumanoidChairEnv> env = MakeTaskHumanoidEnv(config);
  return MeasurePlan(*env, policies, saved[kSit], names[kSit], planner);
}

void MetaPlanner::Reset() {
  side_ = -1;
  last_active_ = -1;
  active_since_step_ = 0;
  ready_since_step_ = -1;
  recover_until_step_ = 0;
}

bool MetaPlanner::Gate(const MetaEnv& env, int next, double value_min) {
  if (value_min <= 0.0) return true;
  const int step = env.humanoid().episode_step();
  if (ready_since_step_ < 0) ready_since_step_ = step;
  const double waited = (step - ready_since_step_) * env.humanoid().spec().control_dt;
  return waited >= plan_->config.value_wait_s || env.SubtaskValue(next) >= value_min;
}

bool MetaPlanner::HandBack(const MetaEnv& env, float value, double below) {
  const float walk = env.SubtaskValue(kWalk);
  if (!(value < below && walk > value && walk >= plan_->config.abort_walk_min)) return false;
  const HumanoidChairEnv& h = env.humanoid();
  recover_until_step_ =
      h.episode_step() +
      static_cast<int>(std::lround(plan_->config.abort_recover_s / h.spec().control_dt));
  return true;
}

void MetaPlanner::Act(const MetaEnv& env, float* action) {
  const MetaPlan& p = *plan_;
  const PlannerConfig& c = p.config;
  const HumanoidChairEnv& h = env.humanoid();
  const double dt = h.spec().control_dt;
  const double period_s = env.meta().period * dt;
  const PlanarPose root{h.humanoid_state().root_pos.head<2>(), h.RootRpy().z()};
  if (side_ < 0) {
    side_ = c.side == "left"    ? 0
            : c.side == "right" ? 1
                                : (AngleDiff(p.sit_start.yaw, root.yaw) >= 0 ? 0 : 1);
  }
  const PlanRule rule = MakePlanRule(c, c.sit_yaw_deg);
  int want = env.active();
  if (want != last_active_) {
    // It began at the start of the last meta step (or at the reset).
    active_since_step_ = std::max(0, h.episode_step() - (last_active_ < 0 ? 0 : env.meta().period));
    last_active_ = want;
    ready_since_step_ = -1;
  }
  // Turns and sit ignore the target; keep it ahead so a later walk starts sensibly.
  const Eigen::Vector2d ahead =
      root.xy + c.lookahead_m * Eigen::Vector2d(std::cos(root.yaw), std::sin(root.yaw));
  Eigen::Vector2d target = ahead;
  if (want == kWalk) {
    const std::vector<double> features =
        c.regress_start_state ? TurnStartFeatures(h) : std::vector<double>();
    const PlanView v = PlanStep(root, p.sit_start, p.turns[side_], side_ == 0, rule,
                                c.regress_start_state ? &features : nullptr);
    // Around the chair when the way to the turn's start passes it (zones 2 and 3).
    const Eigen::Vector2d around =
        WalkAroundChair(root.xy, v.start_point, h.SeatTargetWorld().head<2>(), p.sit_start.yaw,
                        c.clearance_m, c.avoid_front_m);
    target = around == v.start_point ? v.walk_target : around;
    if (h.episode_step() < recover_until_step_) target = ahead;
    const int turn = side_ == 0 ? kLeftTurn : kRightTurn;
    if (HandOverNow(v, h.humanoid_state().root_lin_vel.head<2>(), period_s, p.sit_start.xy, rule) &&
        Gate(env, turn, c.turn_value_min) &&
        // A turn that would be handed back at once is not begun.
        (c.turn_begin_value <= 0 || env.SubtaskValue(turn) >= c.turn_begin_value) &&
        h.episode_step() >= recover_until_step_) {
      want = turn;
    }
  } else if (want == kLeftTurn || want == kRightTurn) {
    const double t = (h.episode_step() - active_since_step_) * dt;
    // A turn its own critic gives up on goes back to the walker (before it falls), which plans
    // the turn again at the next decision.
    const bool abort =
        c.turn_abort_value > 0 && HandBack(env, env.ActiveValue(), c.turn_abort_value);
    // The sit as soon as its critic rates the state highly, within a wider heading window.
    const bool early =
        c.sit_value_early > 0 && t >= c.turn_min_s &&
        std::abs(AngleDiff(root.yaw, p.sit_start.yaw)) <= c.sit_value_yaw_deg * M_PI / 180.0 &&
        env.SubtaskValue(kSit) >= c.sit_value_early;
    if (abort) {
      want = kWalk;
    } else if (t >= c.turn_max_s || early ||
               (t >= c.turn_min_s &&
                SitNow(root.yaw, h.humanoid_state().root_ang_vel.z(), p.sit_start.yaw,
                       rule.tolerance_rad, period_s) &&
                Gate(env, kSit, c.sit_value_min))) {
      want = kSit;
      if (c.sit_retry_value > 0 && HandBack(env, env.SubtaskValue(kSit), c.sit_retry_value)) {
        want = kWalk;
      }
    }
  }
  const std::vector<std::string>& choices = env.meta().choices;
  auto index_of = [&](int id) {
    const auto it = std::find(choices.begin(), choices.end(), SubtaskName(id));
    return it == choices.end() ? -1 : static_cast<int>(it - choices.begin());
  };
  int cls = index_of(want);
  if (cls < 0) cls = index_of(env.active());
  if (cls < 0) cls = env.meta().target_choice();
  const Eigen::Vector2d d = target - root.xy;
  action[0] = static_cast<float>(cls);
  action[1] = static_cast<float>(AngleDiff(std::atan2(d.y(), d.x()), root.yaw));
  action[2] = static_cast<float>(d.norm());
}

}  // namespace perch
