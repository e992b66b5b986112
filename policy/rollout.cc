#include "policy/rollout.h"

#include <cmath>

#include "common/proto/model.pb.h"

namespace perch {

void Rollout::Reserve(int steps) {
  obs.reserve(static_cast<size_t>(steps) * obs_dim);
  actions.reserve(static_cast<size_t>(steps) * action_size);
  log_probs.reserve(steps);
  values.reserve(steps);
  rewards.reserve(steps);
  terminated.reserve(steps);
  truncated.reserve(steps);
  bootstrap_values.reserve(steps);
}

void Rollout::Begin(int obs_dim_in, int action_size_in, uint64_t stream_id_in,
                    uint64_t policy_version_in, int steps) {
  if (obs_dim != obs_dim_in || action_size != action_size_in) {
    *this = Rollout(obs_dim_in, action_size_in);
  }
  Clear();
  stream_id = stream_id_in;
  policy_version = policy_version_in;
  Reserve(steps);
}

void Rollout::Clear() {
  obs.clear();
  actions.clear();
  log_probs.clear();
  values.clear();
  rewards.clear();
  terminated.clear();
  truncated.clear();
  bootstrap_values.clear();
  obs_stats_delta = RunningMeanStd(obs_dim, 0.0);
}

void Rollout::Add(const float* norm_obs, const float* action, float log_prob, float value,
                  float reward, bool term, bool trunc, float bootstrap_value) {
  obs.insert(obs.end(), norm_obs, norm_obs + obs_dim);
  actions.insert(actions.end(), action, action + action_size);
  log_probs.push_back(log_prob);
  values.push_back(value);
  rewards.push_back(reward);
  terminated.push_back(term ? 1 : 0);
  truncated.push_back(trunc && !term ? 1 : 0);
  bootstrap_values.push_back(bootstrap_value);
}

void Rollout::Validate(const std::string& ctx) const {
  const size_t t = rewards.size();
  auto check = [&](const char* name, size_t got, size_t want) {
    if (got != want) {
      throw ConfigError(ctx + "." + name + ": " + std::to_string(got) + " values, expected " +
                        std::to_string(want) + " (T = " + std::to_string(t) + ")");
    }
  };
  constexpr int kMaxDim = 1 << 16;  // far above any env here; guards against garbage sizes
  if (obs_dim <= 0 || action_size <= 0 || obs_dim > kMaxDim || action_size > kMaxDim) {
    throw ConfigError(ctx + ": obs_dim/action_size out of range (" + std::to_string(obs_dim) + "/" +
                      std::to_string(action_size) + ")");
  }
  check("obs", obs.size(), t * obs_dim);
  check("actions", actions.size(), t * action_size);
  check("log_probs", log_probs.size(), t);
  check("values", values.size(), t);
  check("terminated", terminated.size(), t);
  check("truncated", truncated.size(), t);
  check("bootstrap_values", bootstrap_values.size(), t);
  auto finite = [&](const char* name, const std::vector<float>& v) {
    for (size_t i = 0; i < v.size(); ++i) {
      if (!std::isfinite(v[i])) {
        throw ConfigError(ctx + "." + name + "[" + std::to_string(i) + "]: not finite");
      }
    }
  };
  finite("obs", obs);
  finite("actions", actions);
  finite("log_probs", log_probs);
  finite("values", values);
  finite("bootstrap_values", bootstrap_values);
  // Rewards may be NaN only for meta off-steps, which are never shipped: require finite.
  finite("rewards", rewards);
  if (obs_stats_delta.count() > 0 && obs_stats_delta.dim() != obs_dim) {
    throw ConfigError(ctx + ".obs_stats_delta: dimension " + std::to_string(obs_stats_delta.dim()) +
                      ", expected " + std::to_string(obs_dim));
  }
}

void Rollout::ToProto(proto::RolloutSegment* p) const {
  p->Clear();
  p->set_stream_id(stream_id);
  p->set_policy_version(policy_version);
  p->set_obs_dim(obs_dim);
  p->set_action_size(action_size);
  p->mutable_obs()->Add(obs.begin(), obs.end());
  p->mutable_actions()->Add(actions.begin(), actions.end());
  p->mutable_log_probs()->Add(log_probs.begin(), log_probs.end());
  p->mutable_values()->Add(values.begin(), values.end());
  p->mutable_rewards()->Add(rewards.begin(), rewards.end());
  p->set_terminated(std::string(terminated.begin(), terminated.end()));
  p->set_truncated(std::string(truncated.begin(), truncated.end()));
  p->mutable_bootstrap_values()->Add(bootstrap_values.begin(), bootstrap_values.end());
  obs_stats_delta.ToProto(p->mutable_obs_stats_delta());
}

Rollout Rollout::FromProto(const proto::RolloutSegment& p, const std::string& ctx) {
  Rollout r(p.obs_dim(), p.action_size());
  r.stream_id = p.stream_id();
  r.policy_version = p.policy_version();
  r.obs.assign(p.obs().begin(), p.obs().end());
  r.actions.assign(p.actions().begin(), p.actions().end());
  r.log_probs.assign(p.log_probs().begin(), p.log_probs().end());
  r.values.assign(p.values().begin(), p.values().end());
  r.rewards.assign(p.rewards().begin(), p.rewards().end());
  r.terminated.assign(p.terminated().begin(), p.terminated().end());
  r.truncated.assign(p.truncated().begin(), p.truncated().end());
  r.bootstrap_values.assign(p.bootstrap_values().begin(), p.bootstrap_values().end());
  for (size_t i = 0; i < r.terminated.size(); ++i) {
    if (r.terminated[i] > 1 || (i < r.truncated.size() && r.truncated[i] > 1)) {
      throw ConfigError(ctx + ": terminated/truncated must be 0 or 1 (step " + std::to_string(i) +
                        ")");
    }
  }
  r.obs_stats_delta = RunningMeanStd();
  r.Validate(ctx);  // sizes first: obs_dim is trusted only after this
  if (p.has_obs_stats_delta() && p.obs_stats_delta().count() > 0) {
    r.obs_stats_delta =
        RunningMeanStd::FromProto(p.obs_stats_delta(), p.obs_dim(), ctx + ".obs_stats_delta");
  } else {
    r.obs_stats_delta = RunningMeanStd(p.obs_dim(), 0.0);
  }
  return r;
}

void ComputeGae(const Rollout& r, const float* rewards, float gamma, float lambda,
                bool bootstrap_on_truncation, float* advantages, float* returns) {
  ComputeVtrace(r, rewards, nullptr, nullptr, nullptr, gamma, lambda, bootstrap_on_truncation,
                advantages, returns);
}

void ComputeVtrace(const Rollout& r, const float* rewards, const float* values, const float* rho,
                   const float* c, float gamma, float lambda, bool bootstrap_on_truncation,
                   float* advantages, float* returns) {
  const int n = r.size();
  if (rewards == nullptr) rewards = r.rewards.data();
  if (values == nullptr) values = r.values.data();
  float next_adv = 0.0f;
  for (int t = n - 1; t >= 0; --t) {
    const bool term = r.terminated[t] != 0;
    const bool trunc = r.truncated[t] != 0 && !term;
    const bool last = t == n - 1;
    float next_value;
    if (term) {
      next_value = 0.0f;
    } else if (trunc) {
      next_value = bootstrap_on_truncation ? r.bootstrap_values[t] : 0.0f;
    } else if (last) {
      next_value = r.bootstrap_values[t];
    } else {
      next_value = values[t + 1];
    }
    // The recursion continues only inside one episode and one segment.
    const float cont = (term || trunc || last) ? 0.0f : 1.0f;
    float delta = rewards[t] + gamma * next_value - values[t];
    float trace = gamma * lambda * cont;
    if (rho != nullptr) delta *= rho[t];
    if (c != nullptr) trace *= c[t];
    next_adv = delta + trace * next_adv;
    advantages[t] = next_adv;
    returns[t] = next_adv + values[t];
  }
}

RolloutCollector::RolloutCollector(Env* env, uint64_t stream_id)
    : env_(env), stream_id_(stream_id) {
  const EnvSpec& s = env->spec();
  obs_.resize(s.obs_dim);
  next_obs_.resize(s.obs_dim);
  norm_obs_.resize(s.obs_dim);
  action_.resize(s.act_dim);
}

void RolloutCollector::Collect(PolicyRunner* runner, Rng& rng, int steps, Rollout* out,
                               EpisodeStats* stats) {
  const EnvSpec& spec = env_->spec();
  const int action_size = runner->model().action_size();
  if (runner->model().obs_dim() != spec.obs_dim) {
    throw ConfigError("RolloutCollector: policy obs_dim " +
                      std::to_string(runner->model().obs_dim()) + " != env obs_dim " +
                      std::to_string(spec.obs_dim));
  }
  if (static_cast<int>(action_.size()) < action_size) action_.resize(action_size);
  out->Begin(spec.obs_dim, action_size, stream_id_, runner->version(), steps);
  runner->ClearObsStatsDelta();
  for (int t = 0; t < steps; ++t) {
    if (need_reset_) {
      env_->Reset(obs_.data());
      need_reset_ = false;
      episode_return_ = 0.0;
      episode_length_ = 0;
      episode_success_ = false;
    }
    const PolicyRunner::Output o =
        runner->Act(obs_.data(), rng, deterministic_, norm_obs_.data(), action_.data());
    const StepResult sr = env_->Step(action_.data(), next_obs_.data());
    ++episode_length_;
    episode_return_ += sr.reward;
    episode_success_ = episode_success_ || sr.success;
    const bool term = sr.terminated || sr.invalid;
    const bool trunc = !term && (sr.truncated || episode_length_ >= spec.max_episode_steps);
    const bool last = t == steps - 1;
    float bootstrap = 0.0f;
    if (!term && (trunc || last)) bootstrap = runner->Value(next_obs_.data());
    out->Add(norm_obs_.data(), action_.data(), o.log_prob, o.value, sr.reward, term, trunc,
             bootstrap);
    if (term || trunc) {
      need_reset_ = true;
      if (stats != nullptr) {
        stats->returns.push_back(episode_return_);
        stats->lengths.push_back(episode_length_);
        stats->succeeded.push_back(episode_success_ ? 1 : 0);
        (term ? stats->terminated : stats->truncated) += 1;
      }
    } else {
      std::swap(obs_, next_obs_);
    }
  }
  out->obs_stats_delta = runner->obs_stats_delta();
}

}  // namespace perch
