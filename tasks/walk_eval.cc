#include "tasks/walk_eval.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>

#include "common/proto/wire.pb.h"
#include "tasks/foot_sliding.h"

namespace perch {
namespace {

// Reached / resolved targets by their distance when drawn, bins of 1 m from 0 m: a target farther
// than the walking speed times the re-draw time cannot be reached at all (docs/walk.md).
constexpr int kDistBins = 6;

// What walk measures in the shared episode loop: staying up, targets, heading, speed, sliding.
class WalkObserver : public EpisodeObserver {
 public:
  WalkObserver(const HumanoidChairEnv& env, const EvalOptions& o, int no_fall_steps,
               bool target_mode)
      : env_(env),
        task_(dynamic_cast<const WalkTask&>(env.task())),
        dt_(env.spec().control_dt),
        no_fall_steps_(no_fall_steps),
        target_mode_(target_mode),
        sliding_options_(o.foot_sliding),
        sliding_(env.model(), o.foot_sliding) {}

  void Begin(const HumanoidChairEnv& env) override {
    x0_ = env.humanoid_state().root_pos.x();
    open_bin_ = TargetBin();
    target_drawn_step_ = 0;
    heading_err_deg_ = 0.0;
    sliding_.Start(BodyPose());
  }
  void Observe(const HumanoidChairEnv& env, const StepResult& /*r*/, int steps) override {
    const WalkTerms& t = task_.last_terms();
    sum_sim_ += t.similarity;
    // A re-draw resolves the open target: reached, or its 2.5 s ran out.
    if (t.target_redrawn) {
      ++bin_resolved_[open_bin_];
      if (t.target_reached) ++bin_reached_[open_bin_];
      open_bin_ = TargetBin();
      target_drawn_step_ = steps;
    }
    if (target_mode_) {
      const Eigen::Vector2d to = env.walk_target() - env.BodyXyz().head<2>();
      const double err = AngleDiff(std::atan2(to.y(), to.x()), env.RootRpy().z());
      heading_err_deg_ = std::abs(err) * 180.0 / M_PI;
      sum_heading_ += heading_err_deg_;
    }
    sliding_.Observe(BodyPose(), dt_);
  }
  bool End(const HumanoidChairEnv& env, int /*episode*/, int steps, bool fell) override {
    // Where falls happen, to tell a balance problem from a steering one: the time since the
    // current target was drawn and the heading error to it at the falling step; and the reference
    // phase the episode started from (a bad start phase shows up as falls at similar times).
    if (fell) {
      fall_start_phase_.push_back(task_.start_time());
      if (target_mode_) {
        fall_since_target_.push_back((steps - target_drawn_step_) * dt_);
        fall_heading_.push_back(heading_err_deg_);
      }
    }
    const bool up = !fell || steps >= no_fall_steps_;
    no_fall_ += up;
    sum_forward_ += (env.humanoid_state().root_pos.x() - x0_) / (steps * dt_);
    return up;
  }

  // The walk's own keys over `t` (the loop's totals) and `n` episodes.
  void AddSummary(const EpisodeTotals& t, double n, Json* j) const {
    const double secs = t.steps * dt_;
    (*j)["no_fall_rate"] = no_fall_ / n;
    (*j)["mean_imitation_reward"] = sum_sim_ / static_cast<double>(t.steps);
    (*j)["mean_forward_speed_mps"] = sum_forward_ / n;
    (*j)["foot_sliding"] = sliding_.ToJson(secs);
    (*j)["fall_start_phase_s"] = fall_start_phase_;
    // The same meter on the imitated clip over the mean episode length: sliding a clean reference
    // walk itself scores (the swing foot counts while it is low).
    const double ref_s = std::max(dt_, secs / n);
    const FootSlidingMeter ref =
        ReferenceFootSliding(env_.model(), task_.motion(), ref_s, dt_, sliding_options_);
    (*j)["foot_sliding"]["reference"] = ref.ToJson(ref_s);
    if (!target_mode_) return;
    const int targets = std::accumulate(bin_reached_.begin(), bin_reached_.end(), 0);
    const int targets_missed =
        std::accumulate(bin_resolved_.begin(), bin_resolved_.end(), 0) - targets;
    (*j)["targets_reached"] = targets;
    (*j)["targets_reached_per_min"] = targets / (secs / 60.0);
    // Of the targets that were reached or ran out of time (not the one open at episode end).
    (*j)["targets_missed"] = targets_missed;
    (*j)["target_reach_fraction"] =
        targets + targets_missed ? static_cast<double>(targets) / (targets + targets_missed) : 0.0;
    (*j)["mean_heading_error_deg"] = sum_heading_ / static_cast<double>(t.steps);
    (*j)["fall_seconds_since_target"] = fall_since_target_;
    Json by_dist = Json::array();
    for (int b = 0; b < kDistBins; ++b) {
      if (bin_resolved_[b] == 0) continue;
      by_dist.push_back(
          {{"from_m", b},
           {"to_m", b + 1 < kDistBins ? Json(b + 1) : Json(nullptr)},
           {"resolved", bin_resolved_[b]},
           {"reached", bin_reached_[b]},
           {"reach_fraction", static_cast<double>(bin_reached_[b]) / bin_resolved_[b]}});
    }
    (*j)["target_reach_by_distance"] = by_dist;
    (*j)["fall_heading_error_deg"] = fall_heading_;
  }

 private:
  int TargetBin() const {
    return std::clamp(static_cast<int>(task_.target_drawn_distance_m()), 0, kDistBins - 1);
  }
  FootSlidingMeter::BodyPoseFn BodyPose() const {
    return [this](int b) { return env_.world().BodyPose(b); };
  }

  const HumanoidChairEnv& env_;
  const WalkTask& task_;
  double dt_;
  int no_fall_steps_;
  bool target_mode_;
  FootSlidingOptions sliding_options_;
  FootSlidingMeter sliding_;
  int no_fall_ = 0;
  double sum_sim_ = 0, sum_heading_ = 0, sum_forward_ = 0;
  double x0_ = 0, heading_err_deg_ = 0;
  int open_bin_ = 0, target_drawn_step_ = 0;
  std::array<int, kDistBins> bin_reached_{}, bin_resolved_{};
  Json fall_since_target_ = Json::array(), fall_heading_ = Json::array();
  Json fall_start_phase_ = Json::array();
};

}  // namespace

Json EvaluateWalk(const TaskEnvConfig& config_in, const proto::ModelWeights& weights,
                  const EvalOptions& o, EvalRecording* rec) {
  if (config_in.env.task != "walk")
    throw ConfigError("eval: config task is \"" + config_in.env.task + "\", not walk");
  if (o.episodes < 1) throw ConfigError("eval: --episodes must be >= 1");
  TaskEnvConfig config = config_in;
  const double dt = config.env.physics.physics_dt * config.env.physics.substeps;
  const int no_fall_steps = static_cast<int>(std::ceil(o.no_fall_s / dt - 1e-9));
  config.walk.max_episode_steps = std::max(config.walk.max_episode_steps, no_fall_steps);

  std::unique_ptr<HumanoidChairEnv> env = MakeTaskHumanoidEnv(config);
  PolicyRunner policy = MakeEvalPolicy(weights, env->spec(), "walk");
  const bool target_mode = config.walk.stage == WalkStage::kTarget;
  EpisodeLoop loop;
  loop.max_steps = std::numeric_limits<int>::max();  // to the task's time limit
  loop.stop_at_truncation = true;
  loop.record_targets = target_mode;
  loop.judged_steps = no_fall_steps;
  WalkObserver observer(*env, o, no_fall_steps, target_mode);
  const EpisodeTotals t = RunEvalEpisodes(env.get(), &policy, o, loop, &observer, rec);
  const double n = o.episodes;
  Json j{{"task", "walk"},
         {"stage", target_mode ? "target" : "forward"},
         {"reward_variant", config.walk.reward_variant},
         {"model_version", weights.version()},
         {"episodes", o.episodes},
         {"seed", o.seed},
         {"stochastic", o.stochastic},
         {"max_episode_steps", config.walk.max_episode_steps},
         {"no_fall_seconds", o.no_fall_s},
         {"fall_rate", t.falls / n},
         {"invalid_episodes", t.invalid},
         {"mean_episode_steps", t.steps / n},
         {"mean_return", t.sum_return / n},
         {"mean_reward", t.sum_return / static_cast<double>(t.steps)},
         {"fall_times_s", t.fall_times},
         {"fall_episodes", t.fall_episodes}};
  observer.AddSummary(t, n, &j);
  AddFlipRate(env.get(), &policy, o, loop, t, no_fall_steps, &j);
  return j;
}

}  // namespace perch
