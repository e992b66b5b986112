#include "tasks/task_eval.h"

#include <algorithm>
#include <cmath>

#include "common/rng.h"
#include "policy/policy.h"
#include "tasks/sit.h"
#include "tasks/turn.h"

namespace perch {

std::array<double, 2> WilsonInterval95(int k, int n) {
  if (n <= 0) return {0.0, 1.0};
  const double z = 1.959963984540054, p = static_cast<double>(k) / n;
  const double denom = 1 + z * z / n;
  const double centre = (p + z * z / (2.0 * n)) / denom;
  const double half = z * std::sqrt(p * (1 - p) / n + z * z / (4.0 * n * n)) / denom;
  return {std::max(0.0, centre - half), std::min(1.0, centre + half)};
}

PolicyRunner MakeEvalPolicy(const proto::ModelWeights& weights, const EnvSpec& spec,
                            const std::string& task) {
  const PolicyConfig pc = PolicyConfigFromShape(weights.shape(), "model");
  if (pc.kind != PolicyKind::kGaussian || pc.obs_dim != spec.obs_dim ||
      pc.act_dim != spec.act_dim) {
    throw ConfigError("model: shape " + weights.shape().kind() + " obs " +
                      std::to_string(pc.obs_dim) + " act " + std::to_string(pc.act_dim) +
                      " does not fit the " + task + " env (gaussian obs " +
                      std::to_string(spec.obs_dim) + " act " + std::to_string(spec.act_dim) + ")");
  }
  PolicyRunner runner(pc, NormalizerConfig());
  runner.LoadWeights(weights);
  runner.set_update_obs_stats(false);  // evaluation must not move the normaliser
  return runner;
}

namespace {

// A subtask policy in the shared loop (tasks/episode_loop.h): its observer, the recorder, the
// frames of episode 0, and the totals over all episodes.
class PolicyDriver : public EpisodeDriver {
 public:
  PolicyDriver(HumanoidChairEnv* env, PolicyRunner* policy, const EvalOptions& o,
               const EpisodeLoop& loop, EpisodeObserver* observer, EvalRecording* rec,
               EpisodeTotals* totals)
      : env_(env),
        policy_(policy),
        o_(o),
        loop_(loop),
        observer_(observer),
        rec_(rec),
        t_(totals) {}

  void Begin(int episode, uint64_t env_seed, const float* /*obs*/) override {
    episode_ = episode;
    observer_->Begin(*env_);
    if (o_.recorder != nullptr) o_.recorder->Begin(*env_, episode, env_seed);
    Record(0);
  }
  bool Act(const float* obs, Rng& rng, float* action) override {
    policy_->Act(obs, rng, !o_.stochastic, nullptr, action);
    return true;
  }
  void Stepped(const StepResult& r, int steps) override {
    t_->sum_return += r.reward;
    if (r.invalid) ++t_->invalid;
    if (!r.invalid) observer_->Observe(*env_, r, steps);
    if (o_.recorder != nullptr) o_.recorder->Step(*env_, r);
    Record(steps);
  }

 private:
  void Record(int step) {
    if (episode_ != 0 || rec_ == nullptr) return;
    rec_->frames.push_back(PoseFrameOf(env_->humanoid_state(), step * env_->spec().control_dt));
    if (loop_.record_targets &&
        (rec_->targets.empty() || (rec_->targets.back() - env_->walk_target()).norm() > 1e-9)) {
      rec_->targets.push_back(env_->walk_target());
    }
  }
  HumanoidChairEnv* env_;
  PolicyRunner* policy_;
  const EvalOptions& o_;
  const EpisodeLoop& loop_;
  EpisodeObserver* observer_;
  EvalRecording* rec_;
  EpisodeTotals* t_;
  int episode_ = 0;
};

}  // namespace

EpisodeTotals RunEvalEpisodes(HumanoidChairEnv* env, PolicyRunner* policy, const EvalOptions& o,
                              const EpisodeLoop& loop, EpisodeObserver* observer,
                              EvalRecording* rec) {
  const double dt = env->spec().control_dt;
  EpisodeTotals t;
  PolicyDriver driver(env, policy, o, loop, observer, rec, &t);
  const EpisodeLimits limits{loop.max_steps, loop.stop_at_truncation};
  // The perturbations' random moments fall inside the episode's length.
  const int length = std::min(loop.max_steps, env->spec().max_episode_steps);
  PerturbedEnv perturbed(env, o.perturb, loop.judged_steps > 0 ? loop.judged_steps : length);
  Env* stepped = o.perturb.any() ? static_cast<Env*>(&perturbed) : env;
  for (int e = 0; e < o.episodes; ++e) {
    const EpisodeEnd end = RunEpisode(stepped, e, o.seed, limits, &driver);
    if (end.fell) {
      ++t.falls;
      t.fall_times.push_back(end.steps * dt);
      t.fall_episodes.push_back(e);
    }
    const bool success = observer->End(*env, e, end.steps, end.fell);
    if (o.recorder != nullptr) o.recorder->End(success, end.fell);
    t.steps += end.steps;
    t.outcomes.push_back(success);
  }
  return t;
}

namespace {

// An episode's outcome alone (AddFlipRate's unperturbed run).
class OutcomeObserver : public EpisodeObserver {
 public:
  explicit OutcomeObserver(int no_fall_steps) : no_fall_steps_(no_fall_steps) {}
  void Begin(const HumanoidChairEnv&) override { success_ = false; }
  void Observe(const HumanoidChairEnv&, const StepResult& r, int) override {
    success_ = success_ || r.success;
  }
  bool End(const HumanoidChairEnv& env, int, int steps, bool fell) override {
    if (env.spec().has_success) return success_;
    return !fell || steps >= no_fall_steps_;
  }

 private:
  int no_fall_steps_;
  bool success_ = false;
};

}  // namespace

void AddFlipRate(HumanoidChairEnv* env, PolicyRunner* policy, const EvalOptions& o,
                 const EpisodeLoop& loop, const EpisodeTotals& perturbed, int no_fall_steps,
                 Json* j) {
  if (!o.perturb.any()) return;
  EvalOptions plain = o;
  plain.perturb = Perturbation();
  plain.recorder = nullptr;
  OutcomeObserver observer(no_fall_steps);
  const EpisodeTotals t = RunEvalEpisodes(env, policy, plain, loop, &observer, nullptr);
  int successes = 0;
  for (bool s : t.outcomes) successes += s;
  (*j)["perturbation"] = o.perturb.ToJson();
  (*j)["unperturbed_success_rate"] = static_cast<double>(successes) / o.episodes;
  (*j).update(FlipRate(t.outcomes, perturbed.outcomes));
}

namespace {

// The clip tasks' metrics in the shared loop, and the imitation reward they report.
class MetricsObserver : public EpisodeObserver {
 public:
  explicit MetricsObserver(EpisodeMetrics* m) : m_(m) {}
  void Begin(const HumanoidChairEnv& env) override { m_->Start(env); }
  void Observe(const HumanoidChairEnv& env, const StepResult& r, int /*steps*/) override {
    sum_sim_ += m_->ImitationReward(env);
    m_->Observe(env, r);
  }
  bool End(const HumanoidChairEnv& env, int /*episode*/, int /*steps*/, bool fell) override {
    const bool success = m_->Finish(env, fell);
    successes_ += success;
    return success;
  }
  double sum_sim() const { return sum_sim_; }
  int successes() const { return successes_; }

 private:
  EpisodeMetrics* m_;
  double sum_sim_ = 0.0;
  int successes_ = 0;
};

}  // namespace

Json EvaluateEpisodes(const TaskEnvConfig& config, const proto::ModelWeights& weights,
                      const EvalOptions& o, EpisodeMetrics* metrics, EvalRecording* rec) {
  if (o.episodes < 1) throw ConfigError("eval: --episodes must be >= 1");
  std::unique_ptr<HumanoidChairEnv> env = MakeTaskHumanoidEnv(config);
  PolicyRunner policy = MakeEvalPolicy(weights, env->spec(), config.env.task);
  EpisodeLoop loop;
  // The task's time limit is lifted when the metric needs longer episodes.
  loop.max_steps = std::max(env->spec().max_episode_steps, metrics->MinEpisodeSteps(*env));
  MetricsObserver observer(metrics);
  const EpisodeTotals t = RunEvalEpisodes(env.get(), &policy, o, loop, &observer, rec);
  const double n = o.episodes;
  const int successes = observer.successes();
  const auto ci = WilsonInterval95(successes, o.episodes);
  Json j{{"task", config.env.task},
         {"chair", config.env.chair},
         {"model_version", weights.version()},
         {"episodes", o.episodes},
         {"seed", o.seed},
         {"stochastic", o.stochastic},
         {"episode_steps", loop.max_steps},
         {"successes", successes},
         {"success_rate", successes / n},
         {"success_ci95", {ci[0], ci[1]}},
         {"fall_rate", t.falls / n},
         {"invalid_episodes", t.invalid},
         {"mean_episode_steps", t.steps / n},
         {"mean_return", t.sum_return / n},
         {"mean_imitation_reward",
          observer.sum_sim() / static_cast<double>(std::max<int64_t>(1, t.steps))},
         {"fall_times_s", t.fall_times},
         {"fall_episodes", t.fall_episodes}};
  metrics->AddSummary(&j);
  AddFlipRate(env.get(), &policy, o, loop, t, 0, &j);
  return j;
}

double MeanOf(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0.0 : s / v.size();
}

double StdOf(const std::vector<double>& v) {
  const double m = MeanOf(v);
  double s = 0;
  for (double x : v) s += (x - m) * (x - m);
  return v.empty() ? 0.0 : std::sqrt(s / v.size());
}

namespace {

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * (v.size() - 1) + 0.5))];
}

// Turn: success (the task's, TurnTask::OnStep) = no early termination until success_after_end_s
// after the clip ends, and the yaw then within success_yaw_tol_deg of the reference's last frame.
class TurnMetrics : public EpisodeMetrics {
 public:
  int MinEpisodeSteps(const HumanoidChairEnv& env) const override {
    return Task(env).SuccessStep();
  }
  void Start(const HumanoidChairEnv& env) override {
    judged_ = false;
    ok_ = false;
    start_xy_ = env.humanoid_state().root_pos.head<2>();
  }
  void Observe(const HumanoidChairEnv& env, const StepResult& r) override {
    const TurnTask& t = Task(env);
    last_xy_ = env.humanoid_state().root_pos.head<2>();
    last_speed_ = env.humanoid_state().root_lin_vel.head<2>().norm();
    if (r.terminated) {
      // Which early-termination rule ended it: the root height (a fall) or the yaw rule.
      const bool low = env.humanoid_state().root_pos.z() < t.config().min_root_z;
      (low ? ended_low_ : ended_yaw_) += 1;
    }
    if (judged_ || env.episode_step() < t.SuccessStep()) return;
    judged_ = true;
    const double err_deg = std::abs(t.last_terms().yaw_error_rad) * 180.0 / M_PI;
    yaw_err_deg_.push_back(err_deg);
    ok_ = r.success;  // the task judges this step (tasks/turn.cc)
  }
  bool Finish(const HumanoidChairEnv& env, bool fell) override {
    if (!fell) {
      // Where the next subtask would start: how far the turn carried the torso, how fast it
      // still moves at the episode's end.
      end_speed_.push_back(last_speed_);
      travel_m_.push_back((last_xy_ - start_xy_).norm());
    }
    if (!judged_) unjudged_ += 1;  // fell before the judging step
    return judged_ && ok_;
  }
  double ImitationReward(const HumanoidChairEnv& env) const override {
    return Task(env).last_terms().similarity;
  }
  void AddSummary(Json* j) const override {
    (*j)["final_yaw_error_deg_mean"] = MeanOf(yaw_err_deg_);
    (*j)["final_yaw_error_deg_p90"] = Percentile(yaw_err_deg_, 0.9);
    (*j)["end_speed_mps_mean"] = MeanOf(end_speed_);  // episodes that did not fall
    (*j)["end_speed_mps_p90"] = Percentile(end_speed_, 0.9);
    (*j)["travel_m_mean"] = MeanOf(travel_m_);
    (*j)["episodes_fell_before_judging"] = unjudged_;
    (*j)["terminations_by_rule"] = Json{{"root_height", ended_low_}, {"yaw", ended_yaw_}};
  }

 private:
  static const TurnTask& Task(const HumanoidChairEnv& env) {
    return dynamic_cast<const TurnTask&>(env.task());
  }
  bool judged_ = false, ok_ = false;
  int unjudged_ = 0;
  int ended_low_ = 0, ended_yaw_ = 0;  // early terminations by rule, over all episodes
  std::vector<double> yaw_err_deg_;
  Eigen::Vector2d start_xy_ = Eigen::Vector2d::Zero(), last_xy_ = Eigen::Vector2d::Zero();
  double last_speed_ = 0.0;
  std::vector<double> end_speed_, travel_m_;  // [m/s], [m] per episode that did not fall
};

// Sit: success (the task's, SitTask::OnStep) = pelvis continuously on the seat (contact rule of the
// env) for success_contact_s; for successes, the horizontal pelvis - seat target error and the
// torso heading error to the chair's facing direction at the moment success is reached.
class SitMetrics : public EpisodeMetrics {
 public:
  int MinEpisodeSteps(const HumanoidChairEnv& env) const override {
    const SitTask& t = Task(env);
    return static_cast<int>(std::ceil(t.config().eval_episode_s / t.control_dt() - 1e-9));
  }
  void Start(const HumanoidChairEnv& env) override {
    run_ = 0;
    longest_run_ = 0;
    success_ = false;
    min_dist_ = env.PelvisSeatDistance();
    first_contact_s_ = -1;
  }
  void Observe(const HumanoidChairEnv& env, const StepResult& r) override {
    const SitTask& t = Task(env);
    min_dist_ = std::min(min_dist_, env.PelvisSeatDistance());
    const bool contact = env.PelvisSeatContact();
    run_ = contact ? run_ + 1 : 0;
    longest_run_ = std::max(longest_run_, run_);
    if (contact && first_contact_s_ < 0) first_contact_s_ = env.episode_step() * t.control_dt();
    if (!success_ && r.success) {  // the task's contact rule (tasks/sit.cc)
      success_ = true;
      const Eigen::Vector3d d = env.PelvisPosition() - env.SeatTargetWorld();
      pos_err_cm_.push_back(100.0 * d.head<2>().norm());
      // Signed, in the chair frame (x along the chair's facing direction, y to its left).
      const double cy = SitTask::ChairYaw(env);
      offset_x_cm_.push_back(100.0 * (std::cos(cy) * d.x() + std::sin(cy) * d.y()));
      offset_y_cm_.push_back(100.0 * (-std::sin(cy) * d.x() + std::cos(cy) * d.y()));
      const double yaw = env.RootRpy().z();
      rot_err_deg_.push_back(std::abs(AngleDiff(yaw, SitTask::ChairYaw(env))) * 180.0 / M_PI);
      time_to_sit_s_.push_back(first_contact_s_);
      // The torso's pitch against the clip's seated pitch (+: tilted forward, more upright than
      // the clip): the pose reward tracks joint angles only, so the whole body may tilt.
      const MotionPose end = t.ReferenceAt(t.ClipEndStep());
      const double pitch_ref = RpyFromQuat(end.root_rot).y();
      pitch_dev_deg_.push_back(AngleDiff(env.RootRpy().y(), pitch_ref) * 180.0 / M_PI);
    }
  }
  bool Finish(const HumanoidChairEnv& env, bool fell) override {
    min_dists_.push_back(min_dist_);
    if (!success_) {
      // How a failure failed: never on the seat, or on it but not for the whole 3 s.
      failed_longest_contact_s_.push_back(longest_run_ * Task(env).control_dt());
      if (longest_run_ == 0) ++failed_never_in_contact_;
      if (fell) ++failed_fell_;
    }
    return success_;
  }
  double ImitationReward(const HumanoidChairEnv& env) const override {
    return Task(env).last_terms().similarity;
  }
  void AddSummary(Json* j) const override {
    (*j)["seat_position_error_cm_mean"] = MeanOf(pos_err_cm_);
    (*j)["seat_position_error_cm_p90"] = Percentile(pos_err_cm_, 0.9);
    (*j)["seat_offset_cm_mean"] = {MeanOf(offset_x_cm_), MeanOf(offset_y_cm_)};
    (*j)["seat_orientation_error_deg_mean"] = MeanOf(rot_err_deg_);
    (*j)["seat_orientation_error_deg_p90"] = Percentile(rot_err_deg_, 0.9);
    (*j)["seat_torso_pitch_vs_clip_deg_mean"] = MeanOf(pitch_dev_deg_);
    (*j)["first_contact_s_mean"] = MeanOf(time_to_sit_s_);
    (*j)["min_dist_mean_m"] = MeanOf(min_dists_);
    (*j)["min_dist_std_m"] = StdOf(min_dists_);
    (*j)["failures"] = Json{{"fell", failed_fell_},
                            {"never_in_seat_contact", failed_never_in_contact_},
                            {"longest_contact_s_mean", MeanOf(failed_longest_contact_s_)}};
  }

 private:
  static const SitTask& Task(const HumanoidChairEnv& env) {
    return dynamic_cast<const SitTask&>(env.task());
  }
  int run_ = 0;
  bool success_ = false;
  double min_dist_ = 0, first_contact_s_ = -1;
  std::vector<double> pos_err_cm_, rot_err_deg_, time_to_sit_s_, min_dists_;
  std::vector<double> pitch_dev_deg_;  // [deg] per success
  int longest_run_ = 0;                // this episode's longest seat contact [control steps]
  int failed_fell_ = 0, failed_never_in_contact_ = 0;
  std::vector<double> failed_longest_contact_s_;   // [s] per failed episode
  std::vector<double> offset_x_cm_, offset_y_cm_;  // [cm] chair frame
};

}  // namespace

std::unique_ptr<EpisodeMetrics> MakeTurnMetrics() { return std::make_unique<TurnMetrics>(); }
std::unique_ptr<EpisodeMetrics> MakeSitMetrics() { return std::make_unique<SitMetrics>(); }

}  // namespace perch
