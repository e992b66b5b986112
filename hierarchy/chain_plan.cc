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

namespace {

// A list of at most 8 values, each in its range: the error says which of the two it broke.
FieldRule<std::vector<double>> ShortList(std::function<bool(double)> each, std::string each_rule,
                                         std::string too_many) {
  const std::string rule = too_many + "; " + each_rule;
  return {[each](const std::vector<double>& v) {
            if (v.size() > 8) return false;
            for (double x : v) {
              if (!each(x)) return false;
            }
            return true;
          },
          rule,
          [too_many, each_rule](const std::vector<double>& v) {
            return v.size() > 8 ? too_many : each_rule;
          }};
}

// A string among a few; the error names the value.
FieldRule<std::string> OneOf(std::vector<std::string> allowed, std::string rule,
                             std::function<std::string(const std::string&)> message) {
  return {[allowed](const std::string& v) {
            return std::find(allowed.begin(), allowed.end(), v) != allowed.end();
          },
          std::move(rule), std::move(message)};
}

FieldRule<double> OffOrPositive() {
  return Satisfies<double>([](const double& v) { return v >= 0; }, "must be >= 0 (0: off)");
}

}  // namespace

const FieldTable<PlannerConfig>& PlannerConfigFields() {
  using C = PlannerConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("pass_m", &C::pass_m, "hand over only when the predicted turn end is this close [m]",
               Satisfies<double>([](const double& v) { return v > 0 && v <= 3; },
                                 "must be in (0, 3] m"))
          .Add("reach_m", &C::reach_m, "... at once when this close [m] (in [0, pass_m])")
          .Add("lookahead_m", &C::lookahead_m, "walk targets are never nearer than this [m]",
               InRange<double>(0, 5, "must be in [0, 5] m"))
          .Add("aim_m", &C::aim_m, "turn end aim from the sit clip's start (chair frame) [m]",
               Satisfies<std::array<double, 2>>(
                   [](const std::array<double, 2>& v) {
                     return std::abs(v[0]) <= 1 && std::abs(v[1]) <= 1;
                   },
                   "each within +-1 m"))
          .Add("sit_yaw_deg", &C::sit_yaw_deg, "turn -> sit tolerance on the heading [deg]",
               Satisfies<double>([](const double& v) { return v > 0 && v <= 90; },
                                 "must be in (0, 90]"))
          .Add("turn_max_s", &C::turn_max_s, "turn -> sit at the latest [s]",
               Satisfies<double>([](const double& v) { return v > 0.3 && v <= 10; },
                                 "must be in (0.3, 10] s"))
          .Add("turn_min_s", &C::turn_min_s, "... and not before [s] (in [0, turn_max_s))")
          .Add("calibration_runs", &C::calibration_runs, "turn runs measured for the plan",
               InRange<int>(1, 1000, "must be in [1, 1000]"))
          .Custom(
              "calibration_allow_falls", "toy runs only: falling turns stand in for whole ones",
              [](const Json& j, C& c, const std::string& ctx) {
                GetOptional(j, "calibration_allow_falls", c.calibration_allow_falls, ctx);
              },
              // Written only when on, so that every other config resolves as before.
              [](const C& c, Json& j) {
                if (c.calibration_allow_falls) j["calibration_allow_falls"] = true;
              })
          .Add("calibration_seed", &C::calibration_seed, "seed of the calibration runs")
          .Add("side", &C::side, "which turn: short (by the first heading), left or right",
               OneOf({"short", "left", "right"}, "expected short, left or right",
                     [](const std::string& v) {
                       return "expected short, left or right, got \"" + v + "\"";
                     }))
          .Add("approach_deg", &C::approach_deg,
               "approach the turn along a line at this angle to the sit's facing [deg]; < 0: off",
               Satisfies<double>([](const double& v) { return v <= 90; }, "must be <= 90"))
          .Add("regress_start_state", &C::regress_start_state,
               "predict the turn's path from its start state")
          .Add("clearance_m", &C::clearance_m, "walk round the chair this far from its centre [m]",
               InRange<double>(0, 3, "must be in [0, 3] m"))
          .Add("avoid_front_m", &C::avoid_front_m,
               "... only while less than this far in front of the seat [m]",
               InRange<double>(-3, 3, "must be in [-3, 3] m"))
          .Add("turn_value_min", &C::turn_value_min, "value gate: turn's critic at least; 0: off")
          .Add("sit_value_min", &C::sit_value_min, "value gate: sit's critic at least; 0: off")
          .Add("value_wait_s", &C::value_wait_s, "value gate: wait at most [s]",
               InRange<double>(0, 3, "must be in [0, 3] s"))
          .Add("sit_value_early", &C::sit_value_early, "turn -> sit early at this sit value",
               OffOrPositive())
          .Add("sit_value_yaw_deg", &C::sit_value_yaw_deg, "... within this heading [deg]",
               Satisfies<double>([](const double& v) { return v > 0 && v <= 90; },
                                 "must be in (0, 90]"))
          .Add("turn_abort_value", &C::turn_abort_value, "turn -> walk below this turn value",
               OffOrPositive())
          .Add("sit_retry_value", &C::sit_retry_value, "turn -> walk when the sit rates below",
               OffOrPositive())
          .Add("abort_walk_min", &C::abort_walk_min, "hand-backs need the walker's critic at least")
          .CustomAlways(
              "turn_begin_value", "begin a turn only from this turn value (default: the abort's)",
              [](const Json& j, C& c, const std::string& ctx) {
                c.turn_begin_value = c.turn_abort_value;
                GetOptional(j, "turn_begin_value", c.turn_begin_value, ctx);
              },
              [](const C& c, Json& j) { j["turn_begin_value"] = c.turn_begin_value; })
          .Add("abort_recover_s", &C::abort_recover_s, "walk straight on after a hand-back [s]",
               InRange<double>(0, 5, "must be in [0, 5] s"))
          .Add("lookahead_delays_s", &C::lookahead_delays_s,
               "lookahead: switches delayed by each [s]",
               ShortList([](double d) { return d > 0 && d <= 3; }, "each must be in (0, 3] s",
                         "at most 8 times"))
          .Add("lookahead_sides", &C::lookahead_sides,
               "lookahead: both turns at the first decision")
          .Add("lookahead_straight_s", &C::lookahead_straight_s,
               "lookahead: walk straight on for each first [s]",
               ShortList([](double d) { return d > 0 && d <= 3; }, "each must be in (0, 3] s",
                         "at most 8 times"))
          .Add("lookahead_rank", &C::lookahead_rank, "how successes rank: sooner or nearer",
               OneOf({"sooner", "nearer"}, "must be \"sooner\" or \"nearer\"",
                     [](const std::string& v) {
                       return "must be \"sooner\" or \"nearer\", not \"" + v + "\"";
                     }))
          .Add("lookahead_detour_deg", &C::lookahead_detour_deg,
               "lookahead: each straight walk also heading this far off [deg]",
               ShortList([](double h) { return std::abs(h) > 0 && std::abs(h) <= 180; },
                         "each must be in [-180, 180] deg and not 0", "at most 8 headings"))
          .Rule([](const C& c, const std::string& ctx) {
            if (!c.lookahead_detour_deg.empty() && c.lookahead_straight_s.empty()) {
              return ctx + ".lookahead_detour_deg: needs lookahead_straight_s (how long)";
            }
            if (c.lookahead_sides && c.side != "short") {
              return ctx + ".lookahead_sides: needs side \"short\" (both turns)";
            }
            if (!(c.turn_value_min >= 0) || !(c.sit_value_min >= 0)) {
              return ctx + ".turn_value_min / sit_value_min: must be >= 0 (0: off)";
            }
            if (!(c.reach_m >= 0 && c.reach_m <= c.pass_m)) {
              return ctx + ".reach_m: must be in [0, pass_m]";
            }
            if (!(c.turn_min_s >= 0 && c.turn_min_s < c.turn_max_s)) {
              return ctx + ".turn_min_s: must be in [0, turn_max_s)";
            }
            return std::string();
          });
  return t;
}

PlannerConfig PlannerConfig::FromJson(const Json& j, const std::string& ctx) {
  return PlannerConfigFields().Read(j, ctx);
}

Json PlannerConfig::ToJson() const { return PlannerConfigFields().Write(*this); }

const std::vector<std::string>& LookaheadFieldNames() {
  static const std::vector<std::string> names = {"lookahead_delays_s", "lookahead_sides",
                                                 "lookahead_straight_s", "lookahead_detour_deg",
                                                 "lookahead_rank"};
  return names;
}

Json LookaheadJson(const PlannerConfig& c) {
  const Json all = c.ToJson();
  Json j = Json::object();
  for (const std::string& k : LookaheadFieldNames()) j[k] = all.at(k);
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
