// The planned hand-over for the scripted chain (ours; issue 15): where each subtask must start so
// that the next one starts where it was trained to.
//  * The sit starts where its own clip starts on this chair (SitClipStart): root xy and heading
//    of the placed clip's first frame, the pose its transition fine-tuning placed turn end poses.
//  * A turn's mean motion is measured once (CalibrateTurn): from the walker's states it is run
//    and its root displacement in its start frame recorded against the rotation so far.
//  * While walking, the chain predicts where the turn would end if it began now (the current
//    root plus the calibrated displacement for the rotation still needed, rotated by the current
//    heading), steers the walker so that this prediction moves onto the sit start, and hands over
//    when it is there (PlanStep).
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "common/field_table.h"
#include "common/json_util.h"
#include "envs/env_config.h"
#include "envs/humanoid_env.h"

namespace perch {

class SubtaskPolicies;

// A subtask's start pose in the world: root xy [m] and heading [rad].
struct PlanarPose {
  Eigen::Vector2d xy = Eigen::Vector2d::Zero();
  double yaw = 0.0;
};

// The mean path of a turn run from walking states, per control step k since it began.
struct TurnCalibration {
  std::vector<double> rotation_rad;  // [k] |yaw change| so far, mean over the surviving runs
  std::vector<Eigen::Vector2d>
      disp;  // [k] root displacement (forward, left) in the start frame [m]
  std::vector<Eigen::Vector2d> disp_std;  // [k] its spread over the runs [m]
  int runs = 0, fell = 0;
  // Per surviving run: its start features (TurnStartFeatures) and its own path.
  std::vector<std::vector<double>> run_features;
  std::vector<std::vector<double>> run_rotation;       // [run][k] [rad]
  std::vector<std::vector<Eigen::Vector2d>> run_disp;  // [run][k] [m]
  // Every run, fallen or not (what a fall depends on, and when it comes).
  struct Start {
    std::vector<double> features;  // TurnStartFeatures
    bool fell = false;
    int end_step = 0;               // control steps run (to the fall, or all)
    double end_rotation_rad = 0.0;  // |yaw change| then
  };
  std::vector<Start> starts;
  // The displacement when the turn has rotated by `rotation_rad` (first step that reaches it;
  // the last one when the turn never does).
  Eigen::Vector2d DisplacementAt(double rotation_rad) const;
  // The same for a turn that starts from a state with these features: a ridge regression of the
  // runs' own displacements at that rotation on their start features (gait phase, speed). The
  // mean path when there are too few runs. Measured: it does not narrow the hand-over's spread
  // (docs/meta.md), so the planner's default is the mean path.
  Eigen::Vector2d PredictDisplacement(const std::vector<double>& features,
                                      double rotation_rad) const;
  Json ToJson() const;
};

// What a turn's path depends on, read at its start (its start frame): forward and lateral speed
// [m/s], yaw rate [rad/s], foot contacts (right, left), hip flexion difference right - left [rad]
// and its rate [rad/s].
std::vector<double> TurnStartFeatures(const HumanoidChairEnv& env);

// Runs turn `id` of `policies` for `runs` episodes of `env` (each from the env's own reset, a
// walking state) for up to max_s seconds, deterministic actions. allow_falls: a run that falls
// counts, held where it fell (PlannerConfig::calibration_allow_falls).
TurnCalibration CalibrateTurn(HumanoidChairEnv& env, SubtaskPolicies& policies, int id, int runs,
                              uint64_t seed, double max_s, bool allow_falls = false);

// Where the sit subtask's clip starts on chain_env's chair: its saved experiment config (the one
// stored with the sit checkpoint), with no start banks and no reference state initialisation.
PlanarPose SitClipStart(const Json& sit_saved_config, const EnvConfig& chain_env,
                        const std::string& ctx);

// The planner's rules (env.sit_chair.meta.planner; the chain's --chain-plan-* flags).
struct PlannerConfig {
  double pass_m = 0.5;       // hand over only when the predicted turn end is this close [m]
  double reach_m = 0.08;     // ... at once when this close [m]
  double lookahead_m = 1.5;  // walk targets are never nearer than this [m]
  std::array<double, 2> aim_m{0.1, 0.0};  // turn end aim from the sit clip's start (chair frame)
  double sit_yaw_deg = 15.0;              // turn -> sit tolerance on the heading
  double turn_max_s = 3.2;                // turn -> sit at the latest
  double turn_min_s = 0.3;                // ... and not before [s]
  int calibration_runs = 20;
  // Toy runs (perch recipe run --scale): untrained turns fall in every calibration run; with this
  // the paths up to each fall stand in for whole turns (held at the fall), so the rest of the
  // pipeline can be exercised. Never on for a real plan.
  bool calibration_allow_falls = false;
  uint64_t calibration_seed = 17;
  std::string side = "short";  // "short" (by the heading at the first decision), "left", "right"
  // Approach the turn's start along a line that meets the sit's facing at this angle [deg]
  // (90: walking past the front of the chair; 0: straight at it), so that the turn's forward
  // travel does not carry the humanoid into the seat; < 0: no line, the turn begins from
  // whatever heading the walker has.
  double approach_deg = -1.0;
  // Predict the turn's path from the state it would start in (TurnCalibration::
  // PredictDisplacement) rather than its mean path.
  bool regress_start_state = false;
  // Walk around the chair: a walk target behind it (seen from the root) is replaced by a point
  // this far from the seat centre, beside it (zones 2 and 3 start behind the chair) [m]; 0: off.
  double clearance_m = 0.6;
  // ... only while the root is less than this far in front of the seat centre, along the
  // chair's facing [m] (ours, stop 34): a start in front (Zone 1) walks straight to its turn, one
  // beside or behind the chair (zones 2, 3) rounds it first. 3: everywhere (the rule before).
  double avoid_front_m = 3.0;
  // The value gate (ours, 2026-12-05): hand over to a turn (sit) only from a state its own critic
  // values at least this much (SubtaskPolicies::Value, the model's value units; `perch eval --task
  // sit_chair` reports them per hand-over as `handover_values`), waiting at most value_wait_s
  // after the rule above first says "now". 0: off.
  double turn_value_min = 0.0;
  double sit_value_min = 0.0;
  double value_wait_s = 0.25;  // [s]
  // Turn -> sit early (ours, 2026-12-05): as soon as the sit's critic values the state at least
  // sit_value_early and the heading is within sit_value_yaw_deg of the sit's, before the heading
  // rule above would (the turn often stalls 30-40 deg short and the sit's chance decays). 0: off.
  double sit_value_early = 0.0;
  double sit_value_yaw_deg = 45.0;  // [deg]
  // Turn -> walk (ours, 2026-12-05): a turn whose own critic (on its clock) drops below this, and
  // below the walker's critic, hands back to the walker, which then plans the turn again. Its
  // value falls 0.5-1 s before the fall in most falling turns and stays high in the others. 0: off.
  double turn_abort_value = 0.0;
  // Turn -> walk instead of sit (ours, 2026-12-05): when the sit's critic rates the hand-over
  // below this (and below the walker's critic), the walker takes over and the approach is planned
  // again; a sit begun from such a state falls in most trials. 0: off.
  double sit_retry_value = 0.0;
  // Both hand-backs to the walker also need the walker's critic at least this high (it falls
  // after many of them otherwise). 0: no bound beyond "higher than the subtask's".
  double abort_walk_min = 0.0;
  // A turn is begun only from a state its critic rates at least this (so that it is not handed
  // back at once); defaults to turn_abort_value when that is given. 0: off.
  double turn_begin_value = 0.0;
  // After a hand-back, the walker walks straight on for this long before the turn is planned
  // again [s]. 0: plans at once.
  double abort_recover_s = 0.0;
  // Lookahead (ours, stop 39; hierarchy/meta_lookahead.h): at every decision where the rules above
  // switch subtasks, the switch now and the switch delayed by each of these times (the running
  // subtask goes on meanwhile) are each simulated to the episode's end with the rules above, and
  // the best outcome is taken [s]. Empty: off.
  std::vector<double> lookahead_delays_s;
  // ... and at the first decision, the episode simulated with either turn (side "short" only).
  bool lookahead_sides = false;
  // ... and at the first decision, the walker walking straight on for each of these times before
  // the rules steer it [s]. Empty: only the rules' steering.
  std::vector<double> lookahead_straight_s;
  // ... each also with the walker heading this far off its facing at that decision (a fixed
  // direction, + left) instead of straight ahead, e.g. a detour round the chair [deg]. Empty: only
  // straight ahead.
  std::vector<double> lookahead_detour_deg;
  // How two successful outcomes are ranked: "sooner" (the earlier success) or "nearer" (the
  // smaller minimum pelvis - seat distance, the paper's second metric; then sooner). Failures
  // rank alike either way: no fall, then nearer.
  std::string lookahead_rank = "sooner";
  bool lookahead() const {
    return !lookahead_delays_s.empty() || lookahead_sides || !lookahead_straight_s.empty();
  }

  static PlannerConfig FromJson(const Json& j, const std::string& ctx);
  Json ToJson() const;
};

// PlannerConfig's fields, each written once (common/field_table.h).
const FieldTable<PlannerConfig>& PlannerConfigFields();

// The test-time lookahead's fields of PlannerConfig: a meta policy's --lookahead-* flags, the keys
// of a --lookahead FILE and of an evaluation's header. LookaheadJson: those fields of c.
const std::vector<std::string>& LookaheadFieldNames();
Json LookaheadJson(const PlannerConfig& c);

struct PlanRule {
  double reach_m = 0.08;     // hand over when the predicted turn end is this close to the sit start
  double pass_m = 0.35;      // ... or when it has come this close and starts moving away again
  double lookahead_m = 0.8;  // the walk target is never nearer than this [m]
  double tolerance_rad = 0.0;  // the turn is cut this much before its full rotation (sit rule)
  double approach_rad = -1.0;  // PlannerConfig::approach_deg; < 0: off
};

// The rule of a planner config, with the turn -> sit tolerance `sit_yaw_deg` [deg].
PlanRule MakePlanRule(const PlannerConfig& c, double sit_yaw_deg);

// What the planner knows, measured once for a chair and its frozen subtasks (immutable; shared
// by the threads of an evaluation): where to aim the turn's end, and each turn's path.
struct MetaPlan {
  PlannerConfig config;
  PlanarPose sit_start;                  // the aim point (sit clip start + aim_m)
  std::array<TurnCalibration, 2> turns;  // left, right
  Json ToJson() const;
};

// Measures a plan on `env` (a sit_chair env; its resets are the calibration runs' starts) with
// the turns of `policies` (run for up to planner.turn_max_s) and the sit model's saved config.
// Only the turns planner.side can take are measured (both for "short"; the other one's
// calibration stays empty), so a one-turn meta (Table 3's baselines) can be planned for.
MetaPlan MeasurePlan(HumanoidChairEnv& env, SubtaskPolicies& policies, const Json& sit_saved,
                     const std::string& sit_name, const PlannerConfig& planner);
// Whether planner.side takes this turn (kLeftTurn / kRightTurn).
bool PlannerTakesTurn(const PlannerConfig& planner, int turn_id);

struct PlanView {
  Eigen::Vector2d walk_target = Eigen::Vector2d::Zero();    // world [m]
  Eigen::Vector2d start_point = Eigen::Vector2d::Zero();    // where the turn should begin [m]
  Eigen::Vector2d predicted_end = Eigen::Vector2d::Zero();  // where the turn would end [m]
  double error_m = 0.0;                                     // |predicted_end - sit start| [m]
  double rotation_rad = 0.0;                                // the rotation the turn needs (>= 0)
};

// The plan for the current root pose with turn calibration `turn` turning left (left = true) or
// right towards sit start `sit`.
// features: TurnStartFeatures of the current state (the prediction then uses the regression),
// or null (the mean path).
PlanView PlanStep(const PlanarPose& root, const PlanarPose& sit, const TurnCalibration& turn,
                  bool left, const PlanRule& rule, const std::vector<double>* features = nullptr);

// `target` unless the straight walk from `root` to it passes within clearance_m of `chair_xy`:
// then the tangent-side point clearance_m from the chair (the side nearer the target).
Eigen::Vector2d AvoidChair(const Eigen::Vector2d& root, const Eigen::Vector2d& target,
                           const Eigen::Vector2d& chair_xy, double clearance_m);
// AvoidChair while the root is less than `avoid_front_m` in front of `chair_xy` along the
// chair's facing `facing_yaw` [rad]; `target` unchanged once it is further in front.
Eigen::Vector2d WalkAroundChair(const Eigen::Vector2d& root, const Eigen::Vector2d& target,
                                const Eigen::Vector2d& chair_xy, double facing_yaw,
                                double clearance_m, double avoid_front_m);

// Walk -> turn now: the predicted end is within reach_m, or within pass_m and the next decision
// (period_s later, the root moving at root_vel with its heading held) would find it further.
bool HandOverNow(const PlanView& v, const Eigen::Vector2d& root_vel, double period_s,
                 const Eigen::Vector2d& sit_xy, const PlanRule& rule);

// Turn -> sit now: the heading is within `tol` of the sit's, or (deciding only every period_s)
// within 3 tol and the next decision would find it further away at the present yaw rate.
bool SitNow(double yaw, double yaw_rate, double sit_yaw, double tol, double period_s);

}  // namespace perch
