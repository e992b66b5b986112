#include "hierarchy/meta_env.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/paths.h"
#include "common/proto/model.pb.h"
#include "tasks/imitation.h"
#include "tasks/model_source.h"

namespace perch {

namespace {

constexpr uint64_t kSubtaskRngSalt = 0x6A09E667F3BCC909ULL;

float FiniteOr0(float x) { return std::isfinite(x) ? x : 0.0f; }

}  // namespace

MetaEnv::MetaEnv(const TaskEnvConfig& config) : config_(config) {
  if (config.env.task != "sit_chair") {
    throw ConfigError("meta env: needs env.task \"sit_chair\", got \"" + config.env.task + "\"");
  }
  task_config_ = config.Section<SitChairTaskConfig>();
  meta_ = task_config_.meta;
  choice_ids_ = meta_.choice_ids();
  env_ = MakeTaskHumanoidEnv(config);
  task_ = const_cast<SitChairTask*>(dynamic_cast<const SitChairTask*>(&env_->task()));
  if (task_ == nullptr) throw std::logic_error("meta env: the sit_chair env has another task");
  const EnvSpec& inner = env_->spec();
  // The meta observes the sit state (+ the active subtask and its time, when configured).
  const int obs_dim = meta_.obs_dim();
  spec_.name = "meta_sit_chair";
  spec_.obs_dim = obs_dim;
  spec_.act_dim = 3;  // [switch class, theta, dist]
  const float clip = static_cast<float>(config.env.obs.clip);
  spec_.obs_low.assign(obs_dim, -clip);
  spec_.obs_high.assign(obs_dim, clip);
  const float classes = static_cast<float>(choice_ids_.size() - 1);
  // The target is unbounded in the authors' env; these bounds only document it.
  spec_.act_low = {0.0f, -1e6f, -1e6f};
  spec_.act_high = {classes, 1e6f, 1e6f};
  spec_.obs_slices = {{"more", 0, 6}, {"joints", 6, 42}, {"feet", 48, 2}, {"chair", 50, 7}};
  int at = ObsLayoutDim(ObsLayout::kProprioChair);
  if (meta_.observe_active) {
    spec_.obs_slices.push_back({"active", at, kNumSubtasks + 1});
    at += kNumSubtasks + 1;
  }
  if (meta_.observe_values) spec_.obs_slices.push_back({"values", at, kNumSubtasks + 1});
  spec_.control_dt = inner.control_dt * meta_.period;
  spec_.max_episode_steps = (inner.max_episode_steps + meta_.period - 1) / meta_.period;
  spec_.has_success = true;
  inner_obs_.resize(inner.obs_dim);
  action_.resize(inner.act_dim);
  blend_action_.resize(inner.act_dim);
}

MetaEnv::~MetaEnv() = default;

void MetaEnv::Seed(uint64_t seed) {
  env_->Seed(seed);
  rng_.Seed(seed ^ kSubtaskRngSalt);
  perturb_rng_.Seed(seed ^ kPerturbationRngSalt);
}

void MetaEnv::SetPerturbation(const Perturbation& p, int horizon_steps) {
  perturb_ = p;
  perturb_horizon_ = std::max(1, horizon_steps);
}

void MetaEnv::Perturb() {
  const int t = episode_.control_steps;
  if (t == restore_step_) RestoreState(SaveState());
  if (t == push_step_) {
    const double angle = perturb_rng_.Uniform(-M_PI, M_PI);
    push_force_ = perturb_.push_n * Eigen::Vector3d(std::cos(angle), std::sin(angle), 0.0);
    push_left_ =
        std::max(1, static_cast<int>(std::lround(perturb_.push_s / env_->spec().control_dt)));
  }
  if (push_left_ > 0) {
    env_->StartPush(push_force_, 1);  // this control step
    --push_left_;
  }
}

void MetaEnv::AddObsNoise(float* obs) {
  if (perturb_.obs_noise > 0.0) {
    AddGaussianNoise(obs, spec_.obs_dim, perturb_.obs_noise, perturb_rng_);
  }
}

std::vector<std::string> MetaEnv::frozen_policy_names() const {
  std::vector<std::string> names;
  for (int id : choice_ids_) names.push_back(SubtaskName(id));
  return names;
}

void MetaEnv::SetFrozenPolicies(const std::vector<FrozenPolicyData>& policies) {
  std::array<proto::ModelWeights, kNumSubtasks> models;
  std::array<std::string, kNumSubtasks> names;
  std::array<Json, kNumSubtasks> saved;
  std::array<bool, kNumSubtasks> needed{};
  for (int id : choice_ids_) needed[id] = true;
  std::array<bool, kNumSubtasks> have{};
  for (const FrozenPolicyData& p : policies) {
    const int id = SubtaskIdOf(p.name);
    if (id < 0 || !needed[id]) continue;  // a subtask this env does not choose
    const std::string ctx = "frozen " + p.name + " policy " + p.source;
    if (!models[id].ParseFromString(p.model)) throw ConfigError(ctx + ": model does not parse");
    names[id] = p.source.empty() ? p.name : p.source;
    if (!p.saved_config.empty()) {
      try {
        saved[id] = Json::parse(p.saved_config);
      } catch (const std::exception& e) {
        throw ConfigError(ctx + ": saved config does not parse: " + e.what());
      }
    }
    have[id] = true;
  }
  for (int id : choice_ids_) {
    if (!have[id]) {
      throw ConfigError(std::string("meta env: no frozen policy for the ") + SubtaskName(id) +
                        " subtask (sit_chair.meta.choices names it)");
    }
  }
  policies_ = std::make_unique<SubtaskPolicies>(models, names, saved, needed);
}

void MetaEnv::Reset(float* obs) {
  env_->Reset(inner_obs_.data());  // SitChairTask: walk active, target = the chair's origin
  // Fixed order: the first of `choices` runs first (walk in the authors' baselines).
  active_ = meta_.fixed_order ? choice_ids_[0] : kWalk;
  order_pos_ = 0;
  begun_ = false;
  prev_dist_ = env_->PelvisSeatDistance();
  episode_ = MetaEpisode();
  episode_.min_dist_m = prev_dist_;
  episode_.spawn_theta = task_->spawn_theta();
  active_steps_ = 0;
  blend_left_ = 0;
  push_left_ = 0;
  push_step_ =
      perturb_.push_n > 0.0 ? static_cast<int>(perturb_rng_.UniformInt(perturb_horizon_)) : -1;
  restore_step_ =
      perturb_.restore ? static_cast<int>(perturb_rng_.UniformInt(perturb_horizon_)) : -1;
  WriteObservation(obs);
  AddObsNoise(obs);
}

void MetaEnv::WriteObservation(float* obs) const {
  env_->WriteObservation(ObsLayout::kProprioChair, obs);
  float* extra = obs + ObsLayoutDim(ObsLayout::kProprioChair);
  if (meta_.observe_active) {
    for (int id = 0; id < kNumSubtasks; ++id) extra[id] = id == active_ ? 1.0f : 0.0f;
    const double s = active_steps_ * env_->spec().control_dt / meta_.active_time_scale_s;
    extra[kNumSubtasks] = static_cast<float>(std::min(s, 2.0));
    extra += kNumSubtasks + 1;
  }
  if (meta_.observe_values) {
    // Before the subtasks arrive (a probe's reset) there is nothing to rate: zeros.
    const bool have = policies_ != nullptr;
    for (int id = 0; id < kNumSubtasks; ++id) {
      extra[id] = have && policies_->has(id) ? policies_->Value(id, *env_) : 0.0f;
    }
    extra[kNumSubtasks] = have && begun_ ? policies_->RunningValue(active_, *env_) : 0.0f;
  }
}

StepResult MetaEnv::Step(const float* action, float* obs) {
  if (policies_ == nullptr) {
    throw std::logic_error("meta env: Step before the frozen subtask policies were set");
  }
  // Absurd or non-finite actions cannot stop the env: the class is clamped, NaN reads as 0.
  const float a0 = FiniteOr0(action[0]);
  const int cls = std::clamp(static_cast<int>(std::lround(std::clamp(a0, -1e6f, 1e6f))), 0,
                             static_cast<int>(choice_ids_.size()) - 1);
  if (meta_.fixed_order && cls == order_pos_ + 1) ++order_pos_;  // only "next" moves on
  const int sub = choice_ids_[meta_.fixed_order ? order_pos_ : cls];
  // The walk target, whatever was chosen (only walk reads it): dist along the heading turned by
  // theta, from the torso (notes 4.7).
  const double theta = FiniteOr0(action[1]);
  const double dist = FiniteOr0(action[2]);
  const double yaw = env_->RootRpy().z() + theta;
  const Eigen::Vector3d root = env_->humanoid_state().root_pos;
  env_->SetWalkTarget(
      Eigen::Vector2d(root.x() + dist * std::cos(yaw), root.y() + dist * std::sin(yaw)));
  const double dt = env_->spec().control_dt;
  StepResult out;
  bool term = false, trunc = false;
  for (int k = 0; k < meta_.period && !term && !trunc; ++k) {
    if (!begun_ || sub != active_) {
      if (begun_ && meta_.blend_steps > 0) {
        blend_from_ = active_;
        blend_left_ = meta_.blend_steps;
      }
      // A subtask (re)starts: a turn's reference clock begins now.
      policies_->Begin(sub, *env_);
      active_ = sub;
      begun_ = true;
      active_steps_ = 0;
      episode_.sequence.push_back(sub);
      episode_.begin_value.push_back(policies_->Value(sub, *env_));
      if (on_subtask_begin) on_subtask_begin(*env_, sub);
    }
    task_->set_active(sub);
    if (perturb_.any()) Perturb();
    const std::pair<double, Rng*> obs_noise{perturb_.obs_noise, &perturb_rng_};
    const auto* noise = perturb_.obs_noise > 0.0 ? &obs_noise : nullptr;
    policies_->Act(sub, *env_, rng_, !meta_.subtask_stochastic, action_.data(), noise);
    if (blend_left_ > 0) {
      // The previous subtask acts on its own clock, as if it had kept running.
      policies_->Act(blend_from_, *env_, rng_, !meta_.subtask_stochastic, blend_action_.data(),
                     noise);
      const float w = static_cast<float>(meta_.blend_steps - blend_left_ + 1) /
                      static_cast<float>(meta_.blend_steps + 1);
      for (size_t i = 0; i < action_.size(); ++i) {
        action_[i] = w * action_[i] + (1.0f - w) * blend_action_[i];
      }
      --blend_left_;
    }
    if (perturb_.act_noise > 0.0) {
      AddGaussianNoise(action_.data(), static_cast<int>(action_.size()), perturb_.act_noise,
                       perturb_rng_);
    }
    const StepResult r = env_->Step(action_.data(), inner_obs_.data());
    ++episode_.control_steps;
    ++active_steps_;
    episode_.min_dist_m = std::min(episode_.min_dist_m, env_->PelvisSeatDistance());
    if (r.success) {  // the task's rule (SitChairTask::OnStep), once per episode
      episode_.success_step = episode_.control_steps;
      const Eigen::Vector3d d = env_->PelvisPosition() - env_->SeatTargetWorld();
      episode_.seated_pos_err_m = d.head<2>().norm();
      episode_.seated_height_m = d.z();
      episode_.seated_yaw_err_rad =
          std::abs(AngleDiff(env_->RootRpy().z(), config_.env.chair_placement.yaw));
      out.success = true;
    }
    if (on_control_step) on_control_step(*env_, r, sub);
    term = r.terminated || r.invalid;
    trunc = !term && r.truncated;
    out.invalid = out.invalid || r.invalid;
  }
  // Eq. 8 per meta step (notes 4.7): on support at the step's end, else the approach speed
  // toward the seat averaged over the meta step.
  const double d = env_->PelvisSeatDistance();
  if (env_->PelvisSeatContact()) {
    out.reward = static_cast<float>(task_config_.support_reward);
  } else {
    out.reward = static_cast<float>(
        ApproachReward(prev_dist_, d, dt * meta_.period, task_config_.approach_weight));
  }
  prev_dist_ = d;
  if (term) out.reward -= static_cast<float>(task_config_.fall_penalty);
  out.terminated = term;
  out.truncated = trunc;
  episode_.fell = term;
  WriteObservation(obs);
  AddObsNoise(obs);
  return out;
}

MetaEnvState MetaEnv::SaveState() const {
  if (policies_ == nullptr) {
    throw std::logic_error("meta env: SaveState before the frozen subtask policies were set");
  }
  MetaEnvState s;
  s.env = env_->GetState();
  s.task_memory = task_->SaveMemory();
  s.clocks = policies_->clocks();
  s.rng = rng_;
  s.active = active_;
  s.order_pos = order_pos_;
  s.begun = begun_;
  s.active_steps = active_steps_;
  s.blend_from = blend_from_;
  s.blend_left = blend_left_;
  s.seated = task_->seated();
  s.prev_dist = prev_dist_;
  s.episode = episode_;
  return s;
}

void MetaEnv::RestoreState(const MetaEnvState& s) {
  if (policies_ == nullptr) {
    throw std::logic_error("meta env: RestoreState before the frozen subtask policies were set");
  }
  env_->SetState(s.env);
  task_->LoadMemory(s.task_memory);
  policies_->set_clocks(s.clocks);
  rng_ = s.rng;
  active_ = s.active;
  order_pos_ = s.order_pos;
  begun_ = s.begun;
  active_steps_ = s.active_steps;
  blend_from_ = s.blend_from;
  blend_left_ = s.blend_left;
  task_->set_seated(s.seated);
  prev_dist_ = s.prev_dist;
  episode_ = s.episode;
}

float MetaEnv::SubtaskValue(int id) const {
  if (policies_ == nullptr) {
    throw std::logic_error("meta env: SubtaskValue before the frozen subtask policies were set");
  }
  return policies_->Value(id, *env_);
}

float MetaEnv::ActiveValue() const {
  if (policies_ == nullptr) {
    throw std::logic_error("meta env: ActiveValue before the frozen subtask policies were set");
  }
  return policies_->RunningValue(active_, *env_);
}

std::vector<FrozenPolicyData> LoadFrozenPolicies(const TaskEnvConfig& config) {
  const MetaConfig& m = config.Section<SitChairTaskConfig>().meta;
  std::vector<FrozenPolicyData> out;
  for (int id : m.choice_ids()) {
    const std::string path = ResolveProjectPath(m.subtasks[id]);
    try {
      out.push_back(LoadFrozenPolicy(SubtaskName(id), path));
    } catch (const ConfigError& e) {
      throw ConfigError(std::string("sit_chair.meta.subtasks.") + SubtaskName(id) + ": " +
                        e.what());
    }
  }
  // Each must observe its layout: building the runners says which does not.
  MetaEnv probe(config);
  probe.SetFrozenPolicies(out);
  return out;
}

}  // namespace perch
