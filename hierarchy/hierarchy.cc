#include "hierarchy/hierarchy.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <mutex>

#include "common/paths.h"
#include "envs/spawn.h"
#include "hierarchy/chain_plan.h"
#include "tasks/config_fields.h"
#include "tasks/episode_loop.h"
#include "tasks/imitation.h"
#include "tasks/perturbation.h"
#include "tasks/registry.h"
#include "tasks/state_bank.h"
#include "tasks/task_env.h"
#include "tasks/task_eval.h"
#include "tasks/turn.h"

namespace perch {

const FieldTable<MetaConfig>& MetaConfigFields() {
  using C = MetaConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("choices", &C::choices,
               "the switch's classes in order (SubtaskId names; must contain walk)")
          .Add("period", &C::period, "control steps per meta decision (30: about 2 Hz)",
               Satisfies<int>([](const int& v) { return v >= 1; }, "must be >= 1"))
          .Add("subtask_stochastic", &C::subtask_stochastic, "subtasks sample their actions")
          .Add("fixed_order", &C::fixed_order, "Table 3 baselines: keep or trigger the next")
          .Add("observe_active", &C::observe_active,
               "ours: observe the acting subtask and its time")
          .Add("active_time_scale_s", &C::active_time_scale_s, "the acting time's scale [s]",
               Positive<double>())
          .Add("observe_values", &C::observe_values, "ours: observe the subtasks' critics")
          .Add("blend_steps", &C::blend_steps, "ours: cross-fade after a switch [control steps]",
               InRange<int>(0, 120, "must be in [0, 120] control steps"))
          .Nested("planner", &C::planner, PlannerConfigFields(),
                  "the scripted planner (perch meta-clone, perch eval --planner)")
          .Custom(
              "subtasks", "frozen subtask checkpoints by name",
              [](const Json& j, C& c, const std::string& ctx) {
                const Json& s = j["subtasks"];
                const std::string sc = ctx + ".subtasks";
                if (!s.is_object()) throw ConfigError(sc + ": expected an object");
                CheckKnownKeys(s, SubtaskNames(), sc);
                for (int id = 0; id < kNumSubtasks; ++id) {
                  GetOptional(s, SubtaskName(id), c.subtasks[id], sc);
                }
              },
              [](const C& c, Json& j) {
                Json subs = Json::object();
                for (int id = 0; id < kNumSubtasks; ++id) subs[SubtaskName(id)] = c.subtasks[id];
                j["subtasks"] = subs;
              })
          .Rule([](const C& c, const std::string& ctx) {
            if (c.choices.empty()) return ctx + ".choices: must not be empty";
            for (size_t i = 0; i < c.choices.size(); ++i) {
              if (SubtaskIdOf(c.choices[i]) < 0) {
                return ctx + ".choices[" + std::to_string(i) + "]: unknown subtask \"" +
                       c.choices[i] + "\" (turn_left, turn_right, sit, walk)";
              }
              for (size_t k = 0; k < i; ++k) {
                if (c.choices[k] == c.choices[i]) {
                  return ctx + ".choices: \"" + c.choices[i] + "\" twice";
                }
              }
            }
            if (c.target_choice() < 0) {
              return ctx + ".choices: must contain walk (the meta's target head drives it)";
            }
            for (int id : c.choice_ids()) {
              if (c.subtasks[id].empty()) {
                return ctx + ".subtasks." + SubtaskName(id) +
                       ": no checkpoint for a chosen subtask";
              }
            }
            return std::string();
          });
  return t;
}

MetaConfig MetaConfig::FromJson(const Json& j, const std::string& ctx) {
  return MetaConfigFields().Read(j, ctx);
}

Json MetaConfig::ToJson() const { return MetaConfigFields().Write(*this); }

int MetaConfig::obs_dim() const {
  return ObsLayoutDim(ObsLayout::kProprioChair) + (observe_active ? kNumSubtasks + 1 : 0) +
         (observe_values ? kNumSubtasks + 1 : 0);
}

int MetaConfig::target_choice() const {
  for (size_t i = 0; i < choices.size(); ++i) {
    if (choices[i] == "walk") return static_cast<int>(i);
  }
  return -1;
}

std::vector<int> MetaConfig::choice_ids() const {
  std::vector<int> ids;
  for (const std::string& c : choices) ids.push_back(SubtaskIdOf(c));
  return ids;
}

const FieldTable<SitChairTaskConfig>& SitChairTaskConfigFields() {
  using C = SitChairTaskConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("support_reward", &C::support_reward, "Eq. 8: while the pelvis is on the seat")
          .Add("approach_weight", &C::approach_weight, "Eq. 8: x (-V_sit) otherwise")
          .Add("fall_penalty", &C::fall_penalty, "ours: on the meta step that ends in a fall",
               NonNegative<double>())
          .Add("min_root_z", &C::min_root_z, "early termination below [m]")
          .Add("sit_min_root_z", &C::sit_min_root_z, "... while the sit acts [m]")
          .Add("max_episode_steps", &C::max_episode_steps, "time limit [control steps]",
               Satisfies<int>([](const int& v) { return v >= 1; }, "must be >= 1"))
          .With(StartField<C>)
          .Add("success_contact_s", &C::success_contact_s, "seated this long: success [s]",
               Positive<double>())
          .Nested("meta", &C::meta, MetaConfigFields(), "the meta controller");
  return t;
}

SitChairTaskConfig SitChairTaskConfig::FromJson(const Json& j, const std::string& ctx) {
  return SitChairTaskConfigFields().Read(j, ctx);
}

Json SitChairTaskConfig::ToJson() const { return SitChairTaskConfigFields().Write(*this); }

SitChairTask::SitChairTask(const SitChairTaskConfig& c, double control_dt)
    : c_(c), dt_(control_dt) {}

bool SitChairTask::InitialState(const HumanoidChairEnv& env, Rng& rng, HumanoidState* s) {
  const SpawnPose spawn = SampleSpawn(env.config().spawn, rng);
  spawn_theta_ = spawn.theta;
  if (c_.start.banks.empty()) return false;  // the env's own spawn of its init pose
  if (!bank_) bank_ = LoadStartBanks(c_.start.banks, env.model());
  HumanoidState h = HumanoidStateOf(bank_->states[rng.UniformInt(bank_->states.size())]);
  // Heading 0 first, so that PlaceAtSpawn's yaw_added (theta + pi) faces the zone's centre.
  h = TransformHorizontally(h, -RpyFromQuat(h.root_quat).z(), 0.0, 0.0);
  *s = PlaceAtSpawn(h, spawn, env.config().chair_placement);
  if (c_.start.zero_root_ang_vel) s->root_ang_vel.setZero();
  return true;
}

void SitChairTask::OnReset(HumanoidChairEnv& env, Rng& rng) {
  active_ = kWalk;
  seated_ = Seated();
  prev_distance_ = env.PelvisSeatDistance();
  // At reset the walk target is the chair's origin until the first meta decision (notes 4.7).
  env.SetWalkTarget(env.SeatTargetWorld().head<2>());
}

TaskStep SitChairTask::OnStep(const HumanoidChairEnv& env, const float* action) {
  const double d = env.PelvisSeatDistance();
  TaskStep r;
  r.reward = static_cast<float>(env.PelvisSeatContact()
                                    ? c_.support_reward
                                    : ApproachReward(prev_distance_, d, dt_, c_.approach_weight));
  prev_distance_ = d;
  const double min_z = active_ == kSit ? c_.sit_min_root_z : c_.min_root_z;
  r.terminated = env.humanoid_state().root_pos.z() < min_z;
  seated_.run = env.PelvisSeatContact() ? seated_.run + 1 : 0;
  const int need = static_cast<int>(std::ceil(c_.success_contact_s / dt_ - 1e-9));
  if (!seated_.succeeded && seated_.run >= need) {
    seated_.succeeded = true;
    r.success = true;
  }
  return r;
}

Json SitChairTask::SaveMemory() const {
  return Json{
      {"active", active_}, {"prev_distance", prev_distance_}, {"spawn_theta", spawn_theta_}};
}

void SitChairTask::LoadMemory(const Json& j) {
  GetRequired(j, "active", active_, "sit_chair task memory");
  GetRequired(j, "prev_distance", prev_distance_, "sit_chair task memory");
  GetRequired(j, "spawn_theta", spawn_theta_, "sit_chair task memory");
}

// ---- subtask policies -------------------------------------------------------------------------

double TurnHeadingSource::GoalYaw(double yaw0, double t) const {
  const double f =
      std::clamp((t + lookahead_s) / frame_time, 0.0, static_cast<double>(clip_yaw.size() - 1));
  const int i = std::min(static_cast<int>(f), static_cast<int>(clip_yaw.size()) - 2);
  const double w = f - i;
  return yaw0 + (1.0 - w) * clip_yaw[i] + w * clip_yaw[i + 1] - clip_yaw[0];
}

std::unique_ptr<TurnHeadingSource> TurnHeadingSource::FromSavedConfig(const Json& experiment,
                                                                      const std::string& ctx) {
  if (!experiment.is_object() || !experiment.contains("env")) return nullptr;
  const TaskEnvConfig c = TaskEnvConfig::FromJson(experiment["env"], ctx + ": saved config env");
  if (c.env.task != "turn_left" && c.env.task != "turn_right") return nullptr;
  const TurnTaskConfig& t = c.Section<TurnTaskConfig>();
  if (!t.heading_goal) return nullptr;
  const ReferenceMotion m = ReferenceMotion::Load(ResolveProjectPath(t.motion_file));
  auto h = std::make_unique<TurnHeadingSource>();
  h->frame_time = m.frame_time();
  h->lookahead_s = t.heading_lookahead_s;
  for (int i = 0; i < m.num_frames(); ++i) {
    const double y = RpyFromQuat(m.frame(i).root_rot).z();
    h->clip_yaw.push_back(i == 0 ? y : h->clip_yaw.back() + AngleDiff(y, h->clip_yaw.back()));
  }
  if (h->clip_yaw.size() < 2)
    throw ConfigError(ctx + ": turn clip " + t.motion_file + " too short");
  return h;
}

ObsLayout SubtaskPolicies::Layout(int id) const {
  if (id == kSit) return sit_sees_shape_ ? ObsLayout::kProprioChairShape : ObsLayout::kProprioChair;
  return id == kWalk || heading_[id] != nullptr ? ObsLayout::kProprioGoal : ObsLayout::kProprio;
}

SubtaskPolicies::SubtaskPolicies(const std::array<proto::ModelWeights, kNumSubtasks>& models,
                                 const std::array<std::string, kNumSubtasks>& names,
                                 const std::array<Json, kNumSubtasks>& saved_configs,
                                 const std::array<bool, kNumSubtasks>& needed) {
  for (int id = 0; id < kNumSubtasks; ++id) {
    if (!needed[id]) continue;
    const std::string ctx = std::string(SubtaskName(id)) + " policy " + names[id];
    if (id == kLeftTurn || id == kRightTurn) {
      heading_[id] = TurnHeadingSource::FromSavedConfig(saved_configs[id], ctx);
    }
    const PolicyConfig pc = PolicyConfigFromShape(models[id].shape(), ctx);
    // A sit trained with observe_chair_shape says so by its input count.
    if (id == kSit) sit_sees_shape_ = pc.obs_dim == ObsLayoutDim(ObsLayout::kProprioChairShape);
    const int want = ObsLayoutDim(Layout(id));
    if (pc.kind != PolicyKind::kGaussian || pc.obs_dim != want || pc.act_dim != 21) {
      std::string why = "the " + std::string(SubtaskName(id)) +
                        " subtask needs a gaussian policy over " + std::to_string(want) +
                        " observations and 21 torques";
      if ((id == kLeftTurn || id == kRightTurn) && pc.obs_dim == 52 && heading_[id] == nullptr) {
        why +=
            " (a 52-input turn needs its saved config with heading_goal: a checkpoint, not a "
            "bare policy file)";
      }
      throw ConfigError(ctx + ": observes " + std::to_string(pc.obs_dim) + " and acts " +
                        std::to_string(pc.act_dim) + ", " + why);
    }
    runners_[id] = std::make_unique<PolicyRunner>(pc, NormalizerConfig());
    runners_[id]->LoadWeights(models[id]);
    runners_[id]->set_update_obs_stats(
        false);  // frozen normalisers (notes 9.5: the cleaner choice)
  }
  obs_.resize(ObsLayoutDim(ObsLayout::kProprioChairShape));  // the largest layout
}

void SubtaskPolicies::Begin(int id, const HumanoidChairEnv& env) {
  begin_step_[id] = env.episode_step();
  begin_yaw_[id] = env.RootRpy().z();
}

void SubtaskPolicies::Act(int id, const HumanoidChairEnv& env, Rng& rng, bool deterministic,
                          float* action, const std::pair<double, Rng*>* obs_noise) {
  WriteObservation(id, env, /*running=*/true);
  if (obs_noise != nullptr && obs_noise->first > 0.0) {
    AddGaussianNoise(obs_.data(), static_cast<int>(obs_.size()), obs_noise->first,
                     *obs_noise->second);
  }
  runners_[id]->Act(obs_.data(), rng, deterministic, nullptr, action);
}

void SubtaskPolicies::WriteObservation(int id, const HumanoidChairEnv& env, bool running) {
  if (runners_[id] == nullptr) {
    throw std::logic_error(std::string("SubtaskPolicies: no policy for ") + SubtaskName(id));
  }
  env.WriteObservation(Layout(id), obs_.data());
  if (heading_[id] != nullptr) {
    // The goal slots read the turn's reference heading instead of the walk target.
    const double t = running ? (env.episode_step() - begin_step_[id]) * env.spec().control_dt : 0.0;
    const double yaw0 = running ? begin_yaw_[id] : env.RootRpy().z();
    const double rel = AngleDiff(heading_[id]->GoalYaw(yaw0, t), env.RootRpy().z());
    obs_[50] = static_cast<float>(std::sin(rel));
    obs_[51] = static_cast<float>(std::cos(rel));
  }
}

float SubtaskPolicies::Value(int id, const HumanoidChairEnv& env) {
  WriteObservation(id, env, /*running=*/false);
  return runners_[id]->Value(obs_.data());
}

float SubtaskPolicies::RunningValue(int id, const HumanoidChairEnv& env) {
  WriteObservation(id, env, /*running=*/true);
  return runners_[id]->Value(obs_.data());
}

// ---- the scripted chain ------------------------------------------------------------------------

namespace {

// What the chain's rules did over all episodes: turns and sits begun, and (planned hand-over)
// where the sits began relative to the sit clip's start (chair frame) [m], [deg] and the
// predicted hand-over error when each turn began [m].
struct ChainTally {
  int left_turns = 0, right_turns = 0, sits = 0;
  std::vector<double> start_along, start_across, start_yaw_deg, handover_err;
};

// The scripted chain's fixed switching rules over one episode (docs/subtasks.md "The scripted
// chain"): walk to a point in front of the seat (or, planned, where the turn will end at the
// sit's start), turn to the side that faces away from the chair, sit.
class ChainRules {
 public:
  ChainRules(const ChainOptions& o, const MetaPlan& plan, const PlanRule& rule, double chair_yaw,
             double dt, ChainTally* tally)
      : o_(o),
        plan_(plan),
        rule_(rule),
        chair_yaw_(chair_yaw),
        facing_(std::cos(chair_yaw), std::sin(chair_yaw)),
        sit_yaw_(o.plan ? plan.sit_start.yaw : chair_yaw),
        dt_(dt),
        tally_(tally) {}

  // After the episode's Reset: walk towards the point in front of the seat.
  void Begin(HumanoidChairEnv& env) {
    target_ = env.SeatTargetWorld().head<2>() + o_.approach_dist_m * facing_;
    env.SetWalkTarget(target_);
    phase_ = kWalk;
    phase_start_ = 0;
    turn_taken_.clear();
    sit_from_ = nullptr;
    plan_left_ = o_.side == "left"    ? true
                 : o_.side == "right" ? false
                                      : AngleDiff(plan_.sit_start.yaw, env.RootRpy().z()) >= 0;
  }

  // Before control step k of episode e: switches the subtask when the rules say so. False when
  // the episode ends here (at the switch to sit, with stop_at_sit).
  bool Decide(HumanoidChairEnv& env, int k, int e) {
    const bool decide = k % o_.decision_period == 0;
    const bool walk_timeout = (k - phase_start_) * dt_ >= o_.max_walk_s;
    if (phase_ == kWalk && o_.plan) {
      if (decide) PlannedWalk(env, k, walk_timeout);
    } else if (phase_ == kWalk) {
      const bool reached = (env.BodyXyz().head<2>() - target_).norm() < o_.reach_m;
      if (decide && (reached || walk_timeout)) {
        // Turn towards the chair's facing direction the short way round.
        const double err = AngleDiff(chair_yaw_, env.RootRpy().z());
        phase_ = o_.side == "left"    ? kLeftTurn
                 : o_.side == "right" ? kRightTurn
                 : err >= 0           ? kLeftTurn
                                      : kRightTurn;
        (phase_ == kLeftTurn ? tally_->left_turns : tally_->right_turns) += 1;
        turn_taken_ = SubtaskName(phase_);
        phase_start_ = k;
      }
    } else if (phase_ != kSit && decide && TurnDone(env, k)) {
      BeginSit(env, k, e);
      if (o_.stop_at_sit) return false;
    }
    return true;
  }

  int phase() const { return phase_; }
  const std::string& turn_taken() const { return turn_taken_; }
  const Json& sit_from() const { return sit_from_; }

 private:
  // The planned walk: the walk target from the plan, and the hand-over to the planned turn.
  void PlannedWalk(HumanoidChairEnv& env, int k, bool walk_timeout) {
    const PlanarPose root{env.humanoid_state().root_pos.head<2>(), env.RootRpy().z()};
    const std::vector<double> features =
        o_.planner.regress_start_state ? TurnStartFeatures(env) : std::vector<double>();
    const PlanView v = PlanStep(root, plan_.sit_start, plan_.turns[plan_left_ ? 0 : 1], plan_left_,
                                rule_, o_.planner.regress_start_state ? &features : nullptr);
    env.SetWalkTarget(v.walk_target);
    const bool now = HandOverNow(v, env.humanoid_state().root_lin_vel.head<2>(),
                                 o_.decision_period * dt_, plan_.sit_start.xy, rule_);
    if (!now && !walk_timeout) return;
    phase_ = plan_left_ ? kLeftTurn : kRightTurn;
    turn_taken_ = SubtaskName(phase_);
    (plan_left_ ? tally_->left_turns : tally_->right_turns) += 1;
    phase_start_ = k;
    tally_->handover_err.push_back(v.error_m);
  }

  // Turn -> sit: after turn_s, or once the heading is within sit_yaw_deg after turn_min_s.
  bool TurnDone(const HumanoidChairEnv& env, int k) const {
    const double t = (k - phase_start_) * dt_;
    return t >= o_.turn_s ||
           (o_.sit_yaw_deg > 0 && t >= o_.turn_min_s &&
            SitNow(env.RootRpy().z(), env.humanoid_state().root_ang_vel.z(), sit_yaw_,
                   o_.sit_yaw_deg * M_PI / 180.0, o_.decision_period * dt_));
  }

  void BeginSit(const HumanoidChairEnv& env, int k, int e) {
    phase_ = kSit;
    ++tally_->sits;
    phase_start_ = k;
    if (o_.plan) {
      const Eigen::Vector2d rel =
          Eigen::Rotation2Dd(-chair_yaw_) *
          Eigen::Vector2d(env.humanoid_state().root_pos.head<2>() - plan_.sit_start.xy);
      tally_->start_along.push_back(rel.x());
      tally_->start_across.push_back(rel.y());
      tally_->start_yaw_deg.push_back(AngleDiff(env.RootRpy().z(), plan_.sit_start.yaw) * 180.0 /
                                      M_PI);
      sit_from_ = Json::array({rel.x(), rel.y(), tally_->start_yaw_deg.back()});
    }
    if (o_.sit_starts != nullptr) {
      o_.sit_starts->push_back(CaptureState(env));
      o_.sit_starts->back().set_episode(static_cast<uint64_t>(e));
    }
  }

  const ChainOptions& o_;
  const MetaPlan& plan_;
  const PlanRule& rule_;
  double chair_yaw_;
  Eigen::Vector2d facing_;
  double sit_yaw_;
  double dt_;
  ChainTally* tally_;
  Eigen::Vector2d target_ = Eigen::Vector2d::Zero();
  int phase_ = kWalk, phase_start_ = 0;
  bool plan_left_ = true;
  std::string turn_taken_;
  Json sit_from_ = nullptr;  // where this episode's sit began (plan only)
};

// The planned hand-over's figures: the sit's start, the turns' calibration, where the sits began.
Json PlanSummary(const MetaPlan& plan, const ChainTally& t, const PlannerConfig& planner) {
  return Json{{"sit_start",
               {{"x_m", plan.sit_start.xy.x()},
                {"y_m", plan.sit_start.xy.y()},
                {"yaw_deg", plan.sit_start.yaw * 180.0 / M_PI}}},
              {"turn_left_calibration", plan.turns[0].ToJson()},
              {"turn_right_calibration", plan.turns[1].ToJson()},
              {"handover_pred_err_m_mean", MeanOf(t.handover_err)},
              {"sit_start_along_m_mean", MeanOf(t.start_along)},
              {"sit_start_along_m_std", StdOf(t.start_along)},
              {"sit_start_across_m_mean", MeanOf(t.start_across)},
              {"sit_start_across_m_std", StdOf(t.start_across)},
              {"sit_start_yaw_deg_mean", MeanOf(t.start_yaw_deg)},
              {"sit_start_yaw_deg_std", StdOf(t.start_yaw_deg)},
              {"planner", planner.ToJson()}};
}

// The chain in the shared episode loop (tasks/episode_loop.h): its rules pick the subtask at each
// control step, the subtask's frozen policy acts; success is the task's (SitChairTask::OnStep).
class ChainDriver : public EpisodeDriver {
 public:
  ChainDriver(HumanoidChairEnv* env, SitChairTask* task, SubtaskPolicies* policies,
              ChainRules* rules, const ChainOptions& o, std::vector<PoseFrame>* frames)
      : env_(env), task_(task), policies_(policies), rules_(rules), o_(o), frames_(frames) {}

  void Begin(int episode, uint64_t env_seed, const float* /*obs*/) override {
    episode_ = episode;
    step_ = 0;
    begun_ = -1;
    success_step_ = 0;
    rules_->Begin(*env_);
    if (o_.recorder != nullptr) {
      RecordingExtras x;
      x.active_subtask = rules_->phase();
      o_.recorder->Begin(*env_, episode, env_seed, x);
    }
    min_dist_ = env_->PelvisSeatDistance();
  }
  bool Act(const float* /*obs*/, Rng& rng, float* action) override {
    if (!rules_->Decide(*env_, step_, episode_)) return false;
    const int phase = rules_->phase();
    task_->set_active(phase);
    if (phase != begun_) {
      policies_->Begin(phase, *env_);
      begun_ = phase;
    }
    if (episode_ == 0 && frames_ != nullptr) {
      frames_->push_back(
          PoseFrameOf(env_->humanoid_state(), step_ * env_->spec().control_dt, SubtaskName(phase)));
    }
    policies_->Act(phase, *env_, rng, !o_.stochastic, action);
    return true;
  }
  void Stepped(const StepResult& r, int steps) override {
    step_ = steps;
    if (o_.recorder != nullptr) {
      RecordingExtras x;
      x.active_subtask = rules_->phase();
      o_.recorder->Step(*env_, r, x);
    }
    min_dist_ = std::min(min_dist_, env_->PelvisSeatDistance());
    if (r.success) success_step_ = steps;
  }
  int success_step() const { return success_step_; }  // 0: not (yet) seated
  double min_dist() const { return min_dist_; }       // [m] pelvis - seat target, this episode

 private:
  HumanoidChairEnv* env_;
  SitChairTask* task_;
  SubtaskPolicies* policies_;
  ChainRules* rules_;
  const ChainOptions& o_;
  std::vector<PoseFrame>* frames_;
  int episode_ = 0, step_ = 0, begun_ = -1, success_step_ = 0;
  double min_dist_ = 0.0;
};

}  // namespace

Json EvaluateChain(const TaskEnvConfig& config,
                   const std::array<proto::ModelWeights, kNumSubtasks>& models,
                   const std::array<std::string, kNumSubtasks>& paths,
                   const std::array<Json, kNumSubtasks>& saved_configs, const ChainOptions& o,
                   std::vector<PoseFrame>* frames) {
  if (config.env.task != "sit_chair") {
    throw ConfigError("chain: needs the sit_chair env task, got \"" + config.env.task + "\"");
  }
  SubtaskPolicies policies(models, paths, saved_configs);
  std::unique_ptr<HumanoidChairEnv> env = MakeTaskHumanoidEnv(config);
  auto& task = const_cast<SitChairTask&>(dynamic_cast<const SitChairTask&>(env->task()));
  const double dt = env->spec().control_dt;
  const int max_steps = env->spec().max_episode_steps;
  if (o.decision_period < 1) throw ConfigError("chain: decision period must be >= 1");
  // The planned hand-over: where the sit starts, how each turn moves (hierarchy/chain_plan.h).
  MetaPlan plan;
  PlanRule rule;
  if (o.plan) {
    // The chain's own turn limit and sit tolerance rule its turns.
    PlannerConfig pc = o.planner;
    pc.turn_max_s = o.turn_s;
    plan = MeasurePlan(*env, policies, saved_configs[kSit], paths[kSit], pc);
    rule = MakePlanRule(o.planner, o.sit_yaw_deg);
  }
  ChainTally tally;
  ChainRules rules(o, plan, rule, config.env.chair_placement.yaw, dt, &tally);
  ChainDriver driver(env.get(), &task, &policies, &rules, o, frames);
  int successes = 0, falls = 0;
  std::array<int, kNumSubtasks> falls_in{};  // by the subtask acting when the episode ended
  // Per episode: spawn azimuth [deg], the turn taken, the subtask it fell in ("" none), success.
  Json per_episode = Json::array();
  std::vector<double> min_dists, sit_times;
  for (int e = 0; e < o.episodes; ++e) {
    const EpisodeEnd end = RunEpisode(env.get(), e, o.seed, {max_steps, false}, &driver);
    const bool success = driver.success_step() > 0;
    if (success) sit_times.push_back(driver.success_step() * dt);
    if (end.fell) falls_in[rules.phase()] += 1;
    successes += success;
    per_episode.push_back({task.spawn_theta() * 180.0 / M_PI, rules.turn_taken(),
                           end.fell ? SubtaskName(rules.phase()) : "", success, rules.sit_from()});
    if (o.recorder != nullptr) o.recorder->End(success, end.fell);
    falls += end.fell;
    min_dists.push_back(driver.min_dist());
  }
  const double n = o.episodes;
  const auto ci = WilsonInterval95(successes, o.episodes);
  return Json{{"task", "chain"},
              {"plan", o.plan ? PlanSummary(plan, tally, o.planner) : Json(nullptr)},
              {"decision_period", o.decision_period},
              {"zone", config.env.spawn.zone},
              {"chair", config.env.chair},
              {"episodes", o.episodes},
              {"seed", o.seed},
              {"stochastic", o.stochastic},
              {"success_rate", successes / n},
              {"success_ci95", {ci[0], ci[1]}},
              {"min_dist_mean_m", MeanOf(min_dists)},
              {"min_dist_std_m", StdOf(min_dists)},
              {"fall_rate", falls / n},
              {"falls_by_subtask",
               {{"walk", falls_in[kWalk]},
                {"turn_left", falls_in[kLeftTurn]},
                {"turn_right", falls_in[kRightTurn]},
                {"sit", falls_in[kSit]}}},
              {"left_turns", tally.left_turns},
              {"right_turns", tally.right_turns},
              {"reached_sit", tally.sits},
              {"time_to_success_s_mean", MeanOf(sit_times)},
              {"episodes_detail", per_episode},
              {"models",
               {{"walk", paths[kWalk]},
                {"turn_left", paths[kLeftTurn]},
                {"turn_right", paths[kRightTurn]},
                {"sit", paths[kSit]}}},
              {"rules",
               {{"approach_dist_m", o.approach_dist_m},
                {"reach_m", o.reach_m},
                {"max_walk_s", o.max_walk_s},
                {"turn_s", o.turn_s},
                {"sit_yaw_deg", o.sit_yaw_deg},
                {"turn_min_s", o.turn_min_s},
                {"side", o.side}}}};
}

namespace {

TaskDef SitChairDef() {
  TaskDef d;
  d.name = "sit_chair";
  d.description =
      "sit_chair: the main task, sit down from a spawn zone around the chair (the meta "
      "controller's env; no single-policy evaluation: perch eval --task chain)";
  d.obs_layout = ObsLayout::kProprioChair;
  d.needs_chair = true;
  d.read = [](const Json* j, const std::string& ctx, TaskEnvConfig* c) {
    c->section = std::make_shared<TaskSectionOf<SitChairTaskConfig>>(
        SitChairTaskConfig::FromJson(j != nullptr ? *j : Json::object(), ctx));
  };
  d.write = [](const TaskEnvConfig& c) { return c.Section<SitChairTaskConfig>().ToJson(); };
  d.fields = [] { return SitChairTaskConfigFields().Describe(); };
  d.check = [](const TaskEnvConfig& c, const std::string& ctx) {
    CheckStartBanks(c.Section<SitChairTaskConfig>().start, c, ctx + ".sit_chair");
  };
  d.make = [](const TaskEnvConfig& c) -> std::unique_ptr<Task> {
    return std::make_unique<SitChairTask>(c.Section<SitChairTaskConfig>(), c.control_dt());
  };
  return d;
}

}  // namespace

void RegisterHierarchyTasks() {
  static std::once_flag once;
  std::call_once(once, [] { RegisterTask(SitChairDef()); });
}

}  // namespace perch
