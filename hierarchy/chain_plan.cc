#include "hierarchy/chain_plan.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <utility>

#include "common/rng.h"
#include "hierarchy/hierarchy.h"
#include "tasks/imitation.h"
#include "tasks/sit.h"
#include "tasks/task_env.h"

namespace perch {

namespace {

Eigen::Vector2d Rotate(double yaw, const Eigen::Vector2d& v) {
  const double c = std::cos(yaw), s = std::sin(yaw);
  return {c * v.x() - s * v.y(), s * v.x() + c * v.y()};
}

}  // namespace

PlannerConfig PlannerConfig::FromJson(const Json& j, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected an object");
  CheckKnownKeys(j,
                 {"pass_m",
                  "reach_m",
                  "lookahead_m",
                  "aim_m",
                  "sit_yaw_deg",
                  "turn_max_s",
                  "turn_min_s",
                  "calibration_runs",
                  "calibration_allow_falls",
                  "calibration_seed",
                  "side",
                  "approach_deg",
                  "regress_start_state",
                  "clearance_m",
                  "avoid_front_m",
                  "turn_value_min",
                  "sit_value_min",
                  "value_wait_s",
                  "sit_value_early",
                  "sit_value_yaw_deg",
                  "turn_abort_value",
                  "sit_retry_value",
                  "abort_walk_min",
                  "turn_begin_value",
                  "abort_recover_s",
                  "lookahead_delays_s",
                  "lookahead_sides",
                  "lookahead_straight_s",
                  "lookahead_rank",
                  "lookahead_detour_deg"},
                 ctx);
  PlannerConfig c;
  GetOptional(j, "pass_m", c.pass_m, ctx);
  GetOptional(j, "reach_m", c.reach_m, ctx);
  GetOptional(j, "lookahead_m", c.lookahead_m, ctx);
  GetOptional(j, "aim_m", c.aim_m, ctx);
  GetOptional(j, "sit_yaw_deg", c.sit_yaw_deg, ctx);
  GetOptional(j, "turn_max_s", c.turn_max_s, ctx);
  GetOptional(j, "turn_min_s", c.turn_min_s, ctx);
  GetOptional(j, "calibration_runs", c.calibration_runs, ctx);
  GetOptional(j, "calibration_allow_falls", c.calibration_allow_falls, ctx);
  GetOptional(j, "calibration_seed", c.calibration_seed, ctx);
  GetOptional(j, "side", c.side, ctx);
  GetOptional(j, "approach_deg", c.approach_deg, ctx);
  GetOptional(j, "regress_start_state", c.regress_start_state, ctx);
  GetOptional(j, "clearance_m", c.clearance_m, ctx);
  GetOptional(j, "avoid_front_m", c.avoid_front_m, ctx);
  GetOptional(j, "turn_value_min", c.turn_value_min, ctx);
  GetOptional(j, "sit_value_min", c.sit_value_min, ctx);
  GetOptional(j, "value_wait_s", c.value_wait_s, ctx);
  GetOptional(j, "sit_value_early", c.sit_value_early, ctx);
  GetOptional(j, "sit_value_yaw_deg", c.sit_value_yaw_deg, ctx);
  GetOptional(j, "turn_abort_value", c.turn_abort_value, ctx);
  GetOptional(j, "sit_retry_value", c.sit_retry_value, ctx);
  GetOptional(j, "abort_walk_min", c.abort_walk_min, ctx);
  c.turn_begin_value = c.turn_abort_value;
  GetOptional(j, "turn_begin_value", c.turn_begin_value, ctx);
  GetOptional(j, "abort_recover_s", c.abort_recover_s, ctx);
  GetOptional(j, "lookahead_delays_s", c.lookahead_delays_s, ctx);
  GetOptional(j, "lookahead_sides", c.lookahead_sides, ctx);
  GetOptional(j, "lookahead_straight_s", c.lookahead_straight_s, ctx);
  GetOptional(j, "lookahead_rank", c.lookahead_rank, ctx);
  GetOptional(j, "lookahead_detour_deg", c.lookahead_detour_deg, ctx);
  if (c.lookahead_detour_deg.size() > 8) {
    throw ConfigError(ctx + ".lookahead_detour_deg: at most 8 headings");
  }
  for (double h : c.lookahead_detour_deg) {
    if (!(std::abs(h) > 0 && std::abs(h) <= 180)) {
      throw ConfigError(ctx + ".lookahead_detour_deg: each must be in [-180, 180] deg and not 0");
    }
  }
  if (!c.lookahead_detour_deg.empty() && c.lookahead_straight_s.empty()) {
    throw ConfigError(ctx + ".lookahead_detour_deg: needs lookahead_straight_s (how long)");
  }
  if (c.lookahead_rank != "sooner" && c.lookahead_rank != "nearer") {
    throw ConfigError(ctx + ".lookahead_rank: must be \"sooner\" or \"nearer\", not \"" +
                      c.lookahead_rank + "\"");
  }
  for (const auto& [name, list] : {std::pair<const char*, const std::vector<double>*>{
                                       "lookahead_delays_s", &c.lookahead_delays_s},
                                   {"lookahead_straight_s", &c.lookahead_straight_s}}) {
    if (list->size() > 8) throw ConfigError(ctx + "." + name + ": at most 8 times");
    for (double d : *list) {
      if (!(d > 0 && d <= 3)) throw ConfigError(ctx + "." + name + ": each must be in (0, 3] s");
    }
  }
  if (c.lookahead_sides && c.side != "short") {
    throw ConfigError(ctx + ".lookahead_sides: needs side \"short\" (both turns)");
  }
  if (!(c.abort_recover_s >= 0 && c.abort_recover_s <= 5)) {
    throw ConfigError(ctx + ".abort_recover_s: must be in [0, 5] s");
  }
  if (!(c.sit_retry_value >= 0)) {
    throw ConfigError(ctx + ".sit_retry_value: must be >= 0 (0: off)");
  }
  if (!(c.turn_abort_value >= 0)) {
    throw ConfigError(ctx + ".turn_abort_value: must be >= 0 (0: off)");
  }
  if (!(c.sit_value_early >= 0)) throw ConfigError(ctx + ".sit_value_early: must be >= 0 (0: off)");
  if (!(c.sit_value_yaw_deg > 0 && c.sit_value_yaw_deg <= 90)) {
    throw ConfigError(ctx + ".sit_value_yaw_deg: must be in (0, 90]");
  }
  if (!(c.turn_value_min >= 0) || !(c.sit_value_min >= 0)) {
    throw ConfigError(ctx + ".turn_value_min / sit_value_min: must be >= 0 (0: off)");
  }
  if (!(c.value_wait_s >= 0 && c.value_wait_s <= 3)) {
    throw ConfigError(ctx + ".value_wait_s: must be in [0, 3] s");
  }
  if (!(c.avoid_front_m >= -3 && c.avoid_front_m <= 3)) {
    throw ConfigError(ctx + ".avoid_front_m: must be in [-3, 3] m");
  }
  if (!(c.clearance_m >= 0 && c.clearance_m <= 3)) {
    throw ConfigError(ctx + ".clearance_m: must be in [0, 3] m");
  }
  if (!(c.approach_deg <= 90)) throw ConfigError(ctx + ".approach_deg: must be <= 90");
  if (!(c.pass_m > 0 && c.pass_m <= 3)) throw ConfigError(ctx + ".pass_m: must be in (0, 3] m");
  if (!(c.reach_m >= 0 && c.reach_m <= c.pass_m)) {
    throw ConfigError(ctx + ".reach_m: must be in [0, pass_m]");
  }
  if (!(c.lookahead_m >= 0 && c.lookahead_m <= 5)) {
    throw ConfigError(ctx + ".lookahead_m: must be in [0, 5] m");
  }
  if (!(std::abs(c.aim_m[0]) <= 1 && std::abs(c.aim_m[1]) <= 1)) {
    throw ConfigError(ctx + ".aim_m: each within +-1 m");
  }
  if (!(c.sit_yaw_deg > 0 && c.sit_yaw_deg <= 90)) {
    throw ConfigError(ctx + ".sit_yaw_deg: must be in (0, 90]");
  }
  if (!(c.turn_max_s > 0.3 && c.turn_max_s <= 10)) {
    throw ConfigError(ctx + ".turn_max_s: must be in (0.3, 10] s");
  }
  if (!(c.turn_min_s >= 0 && c.turn_min_s < c.turn_max_s)) {
    throw ConfigError(ctx + ".turn_min_s: must be in [0, turn_max_s)");
  }
  if (c.calibration_runs < 1 || c.calibration_runs > 1000) {
    throw ConfigError(ctx + ".calibration_runs: must be in [1, 1000]");
  }
  if (c.side != "short" && c.side != "left" && c.side != "right") {
    throw ConfigError(ctx + ".side: expected short, left or right, got \"" + c.side + "\"");
  }
  return c;
}

Json PlannerConfig::ToJson() const {
  Json j{{"pass_m", pass_m},
         {"reach_m", reach_m},
         {"lookahead_m", lookahead_m},
         {"aim_m", aim_m},
         {"sit_yaw_deg", sit_yaw_deg},
         {"turn_max_s", turn_max_s},
         {"turn_min_s", turn_min_s},
         {"calibration_runs", calibration_runs},
         {"calibration_seed", calibration_seed},
         {"side", side},
         {"approach_deg", approach_deg},
         {"regress_start_state", regress_start_state},
         {"clearance_m", clearance_m},
         {"avoid_front_m", avoid_front_m},
         {"turn_value_min", turn_value_min},
         {"sit_value_min", sit_value_min},
         {"value_wait_s", value_wait_s},
         {"sit_value_early", sit_value_early},
         {"sit_value_yaw_deg", sit_value_yaw_deg},
         {"turn_abort_value", turn_abort_value},
         {"sit_retry_value", sit_retry_value},
         {"abort_walk_min", abort_walk_min},
         {"turn_begin_value", turn_begin_value},
         {"abort_recover_s", abort_recover_s},
         {"lookahead_delays_s", lookahead_delays_s},
         {"lookahead_sides", lookahead_sides},
         {"lookahead_straight_s", lookahead_straight_s},
         {"lookahead_rank", lookahead_rank},
         {"lookahead_detour_deg", lookahead_detour_deg}};
  // Written only when on, so that every other config resolves as before.
  if (calibration_allow_falls) j["calibration_allow_falls"] = true;
  return j;
}

Eigen::Vector2d TurnCalibration::DisplacementAt(double rotation) const {
  for (size_t k = 0; k < rotation_rad.size(); ++k) {
    if (rotation_rad[k] >= rotation) return disp[k];
  }
  return disp.empty() ? Eigen::Vector2d::Zero() : disp.back();
}

Eigen::Vector2d TurnCalibration::PredictDisplacement(const std::vector<double>& features,
                                                     double rotation) const {
  const int n = static_cast<int>(run_features.size());
  const int f = static_cast<int>(features.size());
  if (n < 4 * (f + 1) || f == 0) return DisplacementAt(rotation);
  // Standardised features, an intercept, ridge lambda 1 (in units of runs).
  Eigen::VectorXd mean = Eigen::VectorXd::Zero(f), sd = Eigen::VectorXd::Zero(f);
  for (const auto& r : run_features) mean += Eigen::Map<const Eigen::VectorXd>(r.data(), f);
  mean /= n;
  for (const auto& r : run_features) {
    sd += (Eigen::Map<const Eigen::VectorXd>(r.data(), f) - mean).cwiseAbs2();
  }
  sd = (sd / n).cwiseSqrt().cwiseMax(1e-6);
  Eigen::MatrixXd x(n, f + 1), y(n, 2);
  for (int i = 0; i < n; ++i) {
    x(i, 0) = 1.0;
    x.row(i).tail(f) =
        ((Eigen::Map<const Eigen::VectorXd>(run_features[i].data(), f) - mean).array() / sd.array())
            .matrix()
            .transpose();
    const std::vector<double>& rot = run_rotation[i];
    size_t k = 0;
    while (k + 1 < rot.size() && rot[k] < rotation) ++k;
    y.row(i) = run_disp[i][k].transpose();
  }
  Eigen::MatrixXd a = x.transpose() * x;
  a.diagonal().tail(f).array() += 1.0;
  const Eigen::MatrixXd w = a.ldlt().solve(x.transpose() * y);
  Eigen::VectorXd q(f + 1);
  q(0) = 1.0;
  q.tail(f) = ((Eigen::Map<const Eigen::VectorXd>(features.data(), f) - mean).array() / sd.array())
                  .matrix();
  return (q.transpose() * w).transpose();
}

std::vector<double> TurnStartFeatures(const HumanoidChairEnv& env) {
  const HumanoidState& s = env.humanoid_state();
  const double yaw = env.RootRpy().z();
  const Eigen::Vector2d v = Rotate(-yaw, s.root_lin_vel.head<2>());
  const int rh = env.model().FindJoint("right_hip_y"), lh = env.model().FindJoint("left_hip_y");
  const double hip = rh >= 0 && lh >= 0 ? s.q[rh] - s.q[lh] : 0.0;
  const double hip_rate = rh >= 0 && lh >= 0 ? s.qd[rh] - s.qd[lh] : 0.0;
  return {v.x(),
          v.y(),
          s.root_ang_vel.z(),
          env.contacts().foot_floor[0] ? 1.0 : 0.0,
          env.contacts().foot_floor[1] ? 1.0 : 0.0,
          hip,
          hip_rate};
}

Json TurnCalibration::ToJson() const {
  Json path = Json::array();
  // Every 10th step is enough to read the shape of the turn.
  for (size_t k = 0; k < disp.size(); k += 10) {
    path.push_back({{"t_steps", k},
                    {"rotation_deg", rotation_rad[k] * 180.0 / M_PI},
                    {"forward_m", disp[k].x()},
                    {"left_m", disp[k].y()},
                    {"forward_std_m", disp_std[k].x()},
                    {"left_std_m", disp_std[k].y()}});
  }
  Json all_starts = Json::array();
  for (const Start& st : starts) {
    all_starts.push_back({{"features", st.features},
                          {"fell", st.fell},
                          {"end_step", st.end_step},
                          {"end_rotation_deg", st.end_rotation_rad * 180.0 / M_PI}});
  }
  return Json{{"runs", runs}, {"fell", fell}, {"path", path}, {"starts", all_starts}};
}

TurnCalibration CalibrateTurn(HumanoidChairEnv& env, SubtaskPolicies& policies, int id, int runs,
                              uint64_t seed, double max_s, bool allow_falls) {
  const int steps = static_cast<int>(std::ceil(max_s / env.spec().control_dt));
  std::vector<float> obs(env.spec().obs_dim), action(21);
  std::vector<double> rot_sum(steps, 0.0);
  std::vector<Eigen::Vector2d> disp_sum(steps, Eigen::Vector2d::Zero());
  std::vector<Eigen::Vector2d> disp_sq(steps, Eigen::Vector2d::Zero());
  TurnCalibration c;
  for (int r = 0; r < runs; ++r) {
    env.Seed(seed * 7919ULL + static_cast<uint64_t>(r));
    Rng rng(seed * 7919ULL + static_cast<uint64_t>(r) + 1);
    env.Reset(obs.data());
    const std::vector<double> features = TurnStartFeatures(env);
    policies.Begin(id, env);
    const Eigen::Vector2d xy0 = env.humanoid_state().root_pos.head<2>();
    const double yaw0 = env.RootRpy().z();
    double yaw = yaw0, unwrapped = 0.0;
    std::vector<double> rot(steps);
    std::vector<Eigen::Vector2d> d(steps);
    bool fell = false;
    int ran = 0;
    for (int k = 0; k < steps; ++k, ++ran) {
      policies.Act(id, env, rng, true, action.data());
      if (env.Step(action.data(), obs.data()).terminated) {
        fell = true;
        break;
      }
      const double y = env.RootRpy().z();
      unwrapped += AngleDiff(y, yaw);
      yaw = y;
      rot[k] = std::abs(unwrapped);
      d[k] = Rotate(-yaw0, env.humanoid_state().root_pos.head<2>() - xy0);
    }
    c.starts.push_back({features, fell, ran, std::abs(unwrapped)});
    if (fell && allow_falls) {
      // Held where it fell (toy runs only, PlannerConfig::calibration_allow_falls).
      for (int k = ran; k < steps; ++k) {
        rot[k] = k > 0 ? rot[k - 1] : 0.0;
        d[k] = k > 0 ? d[k - 1] : Eigen::Vector2d::Zero();
      }
      fell = false;
    }
    if (fell) {
      ++c.fell;
      continue;
    }
    ++c.runs;
    c.run_features.push_back(features);
    c.run_rotation.push_back(rot);
    c.run_disp.push_back(d);
    for (int k = 0; k < steps; ++k) {
      rot_sum[k] += rot[k];
      disp_sum[k] += d[k];
      disp_sq[k] += d[k].cwiseProduct(d[k]);
    }
  }
  if (c.runs == 0) {
    throw std::runtime_error(std::string("chain plan: every calibration run of ") +
                             SubtaskName(id) + " fell");
  }
  for (int k = 0; k < steps; ++k) {
    c.rotation_rad.push_back(rot_sum[k] / c.runs);
    c.disp.push_back(disp_sum[k] / c.runs);
    const Eigen::Vector2d var = disp_sq[k] / c.runs - c.disp.back().cwiseProduct(c.disp.back());
    c.disp_std.push_back(var.cwiseMax(0.0).cwiseSqrt());
  }
  return c;
}

PlanarPose SitClipStart(const Json& saved, const EnvConfig& chain_env, const std::string& ctx) {
  if (!saved.is_object() || !saved.contains("env")) {
    throw ConfigError(ctx +
                      ": the sit model has no saved config (a checkpoint is needed to know "
                      "where its clip starts)");
  }
  TaskEnvConfig c = TaskEnvConfig::FromJson(saved["env"], ctx + ": saved config env");
  if (c.env.task != "sit") {
    throw ConfigError(ctx + ": the sit model was trained on task \"" + c.env.task + "\"");
  }
  c.env.chair = chain_env.chair;
  c.env.chair_placement = chain_env.chair_placement;
  c.env.chair_random = chain_env.chair_random;
  SitTaskConfig& s = c.MutableSection<SitTaskConfig>();
  s.start.banks.clear();
  s.reference_state_init = false;
  std::unique_ptr<HumanoidChairEnv> env = MakeTaskHumanoidEnv(c);
  std::vector<float> obs(env->spec().obs_dim);
  env->Seed(0);
  env->Reset(obs.data());
  PlanarPose p;
  p.xy = env->humanoid_state().root_pos.head<2>();
  p.yaw = env->RootRpy().z();
  return p;
}

Eigen::Vector2d AvoidChair(const Eigen::Vector2d& root, const Eigen::Vector2d& target,
                           const Eigen::Vector2d& chair_xy, double clearance_m) {
  const Eigen::Vector2d seg = target - root;
  const double len2 = seg.squaredNorm();
  if (clearance_m <= 0 || len2 < 1e-12) return target;
  const double t = std::clamp((chair_xy - root).dot(seg) / len2, 0.0, 1.0);
  if ((root + t * seg - chair_xy).norm() >= clearance_m) return target;
  const Eigen::Vector2d from = root - chair_xy;
  if (from.norm() < clearance_m) return target;  // already beside it: go on
  const Eigen::Vector2d u = from / from.norm();
  const Eigen::Vector2d side(-u.y(), u.x());
  // The point beside the chair on the target's side, a little toward the root so that the
  // walker passes it rather than circles it.
  const double s = (target - chair_xy).dot(side) >= 0 ? 1.0 : -1.0;
  return chair_xy + clearance_m * (s * side + 0.3 * u).normalized();
}

Eigen::Vector2d WalkAroundChair(const Eigen::Vector2d& root, const Eigen::Vector2d& target,
                                const Eigen::Vector2d& chair_xy, double facing_yaw,
                                double clearance_m, double avoid_front_m) {
  const double in_front =
      (root - chair_xy).dot(Eigen::Vector2d(std::cos(facing_yaw), std::sin(facing_yaw)));
  return in_front < avoid_front_m ? AvoidChair(root, target, chair_xy, clearance_m) : target;
}

PlanRule MakePlanRule(const PlannerConfig& c, double sit_yaw_deg) {
  PlanRule rule;
  rule.reach_m = c.reach_m;
  rule.pass_m = c.pass_m;
  rule.lookahead_m = c.lookahead_m;
  rule.tolerance_rad = sit_yaw_deg * M_PI / 180.0;
  rule.approach_rad = c.approach_deg < 0 ? -1.0 : c.approach_deg * M_PI / 180.0;
  return rule;
}

Json MetaPlan::ToJson() const {
  return Json{{"config", config.ToJson()},
              {"sit_start",
               {{"x_m", sit_start.xy.x()},
                {"y_m", sit_start.xy.y()},
                {"yaw_deg", sit_start.yaw * 180.0 / M_PI}}},
              {"turn_left_calibration", turns[0].ToJson()},
              {"turn_right_calibration", turns[1].ToJson()}};
}

MetaPlan MeasurePlan(HumanoidChairEnv& env, SubtaskPolicies& policies, const Json& sit_saved,
                     const std::string& sit_name, const PlannerConfig& planner) {
  auto& task = const_cast<SitChairTask&>(dynamic_cast<const SitChairTask&>(env.task()));
  MetaPlan plan;
  plan.config = planner;
  for (int side = 0; side < 2; ++side) {
    const int id = side == 0 ? kLeftTurn : kRightTurn;
    if (!PlannerTakesTurn(planner, id)) continue;
    task.set_active(id);
    plan.turns[side] =
        CalibrateTurn(env, policies, id, planner.calibration_runs, planner.calibration_seed,
                      planner.turn_max_s, planner.calibration_allow_falls);
  }
  plan.sit_start = SitClipStart(sit_saved, env.config(), "planner: sit policy " + sit_name);
  plan.sit_start.xy += Eigen::Rotation2Dd(env.config().chair_placement.yaw) *
                       Eigen::Vector2d(planner.aim_m[0], planner.aim_m[1]);
  return plan;
}

bool PlannerTakesTurn(const PlannerConfig& planner, int turn_id) {
  if (planner.side == "left") return turn_id == kLeftTurn;
  if (planner.side == "right") return turn_id == kRightTurn;
  return turn_id == kLeftTurn || turn_id == kRightTurn;
}

bool SitNow(double yaw, double yaw_rate, double sit_yaw, double tol, double period_s) {
  const double now = std::abs(AngleDiff(sit_yaw, yaw));
  if (now < tol) return true;
  if (period_s <= 0.05) return false;  // deciding every control step: the tolerance is enough
  const double next = std::abs(AngleDiff(sit_yaw, yaw + yaw_rate * period_s));
  return now < 3.0 * tol && now <= next;
}

bool HandOverNow(const PlanView& v, const Eigen::Vector2d& root_vel, double period_s,
                 const Eigen::Vector2d& sit_xy, const PlanRule& rule) {
  if (v.error_m <= rule.reach_m) return true;
  const double next_err = (v.predicted_end + root_vel * period_s - sit_xy).norm();
  return v.error_m < rule.pass_m && v.error_m <= next_err;
}

PlanView PlanStep(const PlanarPose& root, const PlanarPose& sit, const TurnCalibration& turn,
                  bool left, const PlanRule& rule, const std::vector<double>* features) {
  PlanView v;
  double rot = AngleDiff(sit.yaw, root.yaw);  // > 0: counter-clockwise (left)
  if (!left) rot = -rot;
  if (rot < 0) rot += 2.0 * M_PI;
  v.rotation_rad = rot;
  const double cut = std::max(0.0, rot - rule.tolerance_rad);
  const Eigen::Vector2d disp =
      features != nullptr ? turn.PredictDisplacement(*features, cut) : turn.DisplacementAt(cut);
  v.predicted_end = root.xy + Rotate(root.yaw, disp);
  const Eigen::Vector2d d = sit.xy - v.predicted_end;
  v.error_m = d.norm();
  v.start_point = root.xy + d;
  // Walk where the root must be for the turn to end on the sit start, never nearer than the
  // look-ahead (the walker circles a target it has reached).
  Eigen::Vector2d dir = d.norm() > 1e-6 ? Eigen::Vector2d(d / d.norm())
                                        : Eigen::Vector2d(std::cos(root.yaw), std::sin(root.yaw));
  v.walk_target = d.norm() >= rule.lookahead_m ? Eigen::Vector2d(root.xy + d)
                                               : Eigen::Vector2d(root.xy + rule.lookahead_m * dir);
  if (rule.approach_rad >= 0) {
    // Follow the line into the turn's start for that approach heading: a point on it ahead of
    // the root's projection (pure pursuit), while the root is still behind the start point.
    const double rot_a = M_PI - rule.approach_rad;
    const double heading = sit.yaw - (left ? rot_a : -rot_a);
    const Eigen::Vector2d u(std::cos(heading), std::sin(heading));
    const Eigen::Vector2d start =
        sit.xy - Rotate(heading, turn.DisplacementAt(std::max(0.0, rot_a - rule.tolerance_rad)));
    const double along = (root.xy - start).dot(u);
    if (along < 0.0) {
      v.walk_target = start + u * (along + std::max(rule.lookahead_m, 0.5));
    }
  }
  return v;
}

}  // namespace perch
