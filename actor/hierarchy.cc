#include "actor/hierarchy.h"

#include <algorithm>
#include <cmath>

#include "common/json_util.h"

namespace perch {

HierarchicalCollector::HierarchicalCollector(Env* env, uint64_t stream_id, int meta_period)
    : env_(env),
      henv_(dynamic_cast<HierarchyEnv*>(env)),
      stream_id_(stream_id),
      meta_period_(meta_period),
      single_(env, stream_id) {}

void HierarchicalCollector::Collect(PolicyRunner* trained,
                                    const std::vector<PolicyRunner*>& subtasks, Rng& rng, int steps,
                                    Rollout* out, EpisodeStats* stats) {
  if (trained->model().config().kind == PolicyKind::kMeta) {
    CollectMeta(trained, subtasks, rng, steps, out, stats);
    return;
  }
  single_.Collect(trained, rng, steps, out, stats);
  control_steps_ += steps;
}

void HierarchicalCollector::CollectMeta(PolicyRunner* meta,
                                        const std::vector<PolicyRunner*>& subtasks, Rng& rng,
                                        int steps, Rollout* out, EpisodeStats* stats) {
  if (henv_ == nullptr) {
    throw ConfigError("cluster.task meta: env '" + env_->spec().name +
                      "' does not implement HierarchyEnv");
  }
  const PolicyConfig& mc = meta->model().config();
  if (static_cast<int>(subtasks.size()) != mc.num_choices ||
      henv_->num_subtasks() != mc.num_choices) {
    throw ConfigError("meta policy has " + std::to_string(mc.num_choices) + " choices, env has " +
                      std::to_string(henv_->num_subtasks()) + " subtasks, actor has " +
                      std::to_string(subtasks.size()) + " subtask policies");
  }
  if (mc.act_dim != 2) {
    throw ConfigError("meta policy act_dim must be 2 (walk target theta, dist), got " +
                      std::to_string(mc.act_dim));
  }
  const EnvSpec& spec = env_->spec();
  obs_.resize(spec.obs_dim);
  next_obs_.resize(spec.obs_dim);
  norm_obs_.resize(spec.obs_dim);
  meta_action_.resize(mc.action_size());
  out->Begin(spec.obs_dim, mc.action_size(), stream_id_, meta->version(), steps);
  meta->ClearObsStatsDelta();
  for (int t = 0; t < steps; ++t) {
    if (need_reset_) {
      env_->Reset(obs_.data());
      need_reset_ = false;
      episode_return_ = 0.0;
      episode_length_ = 0;
    }
    const PolicyRunner::Output o =
        meta->Act(obs_.data(), rng, /*deterministic=*/false, norm_obs_.data(), meta_action_.data());
    ++meta_decisions_;
    const int choice = std::clamp(static_cast<int>(meta_action_[0]), 0, mc.num_choices - 1);
    henv_->SetWalkTarget(meta_action_[1], meta_action_[2]);
    PolicyRunner* sub = subtasks[choice];
    sub_obs_.resize(henv_->subtask_obs_dim(choice));
    sub_norm_.resize(sub_obs_.size());
    sub_action_.resize(spec.act_dim);
    double reward = 0.0;
    bool term = false, trunc = false;
    for (int k = 0; k < meta_period_ && !term && !trunc; ++k) {
      henv_->SubtaskObservation(choice, sub_obs_.data());
      sub->Act(sub_obs_.data(), rng, /*deterministic=*/false, sub_norm_.data(), sub_action_.data());
      const StepResult sr = env_->Step(sub_action_.data(), next_obs_.data());
      ++control_steps_;
      ++episode_length_;
      if (std::isfinite(sr.reward)) reward += sr.reward;  // NaN: no meta reward on this step
      term = sr.terminated || sr.invalid;
      trunc = !term && (sr.truncated || episode_length_ >= spec.max_episode_steps);
      if (!term && !trunc) std::swap(obs_, next_obs_);
    }
    episode_return_ += reward;
    const bool last = t == steps - 1;
    float bootstrap = 0.0f;
    if (!term && (trunc || last)) bootstrap = meta->Value(trunc ? next_obs_.data() : obs_.data());
    out->Add(norm_obs_.data(), meta_action_.data(), o.log_prob, o.value, static_cast<float>(reward),
             term, trunc, bootstrap);
    if (term || trunc) {
      need_reset_ = true;
      if (stats != nullptr) {
        stats->returns.push_back(episode_return_);
        stats->lengths.push_back(episode_length_);
        stats->succeeded.push_back(0);  // the meta task's success is not judged here yet
        (term ? stats->terminated : stats->truncated) += 1;
      }
    }
  }
  out->obs_stats_delta = meta->obs_stats_delta();
}

}  // namespace perch
