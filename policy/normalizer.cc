#include "policy/normalizer.h"

#include <algorithm>
#include <cmath>

#include "common/proto/model.pb.h"

namespace perch {

RunningMeanStd::RunningMeanStd(int dim, double initial_count)
    : mean_(dim, 0.0), var_(dim, initial_count > 0 ? 1.0 : 0.0) {
  count_ = initial_count;
}

void RunningMeanStd::Reset(double initial_count) {
  count_ = initial_count;
  std::fill(mean_.begin(), mean_.end(), 0.0);
  std::fill(var_.begin(), var_.end(), initial_count > 0 ? 1.0 : 0.0);
}

// The parallel merge of (count_, mean_, var_) with a batch (n, mean, var), as the authors'
// update_mean_var_count_from_moments.
void RunningMeanStd::MergeMoments(double n, const double* mean, const double* var) {
  if (n <= 0) return;
  const double tot = count_ + n;
  for (size_t i = 0; i < mean_.size(); ++i) {
    const double delta = mean[i] - mean_[i];
    const double m2 = var_[i] * count_ + var[i] * n + delta * delta * count_ * n / tot;
    mean_[i] += delta * n / tot;
    var_[i] = m2 / tot;
  }
  count_ = tot;
}

void RunningMeanStd::Update(const float* x) {
  const double tot = count_ + 1.0;
  for (size_t i = 0; i < mean_.size(); ++i) {
    const double delta = static_cast<double>(x[i]) - mean_[i];
    const double m2 = var_[i] * count_ + delta * delta * count_ / tot;
    mean_[i] += delta / tot;
    var_[i] = m2 / tot;
  }
  count_ = tot;
}

void RunningMeanStd::UpdateBatch(const float* x, int n) {
  if (n <= 0) return;
  const size_t d = mean_.size();
  std::vector<double> bm(d, 0.0), bv(d, 0.0);
  for (int r = 0; r < n; ++r)
    for (size_t i = 0; i < d; ++i) bm[i] += x[r * d + i];
  for (size_t i = 0; i < d; ++i) bm[i] /= n;
  for (int r = 0; r < n; ++r)
    for (size_t i = 0; i < d; ++i) {
      const double e = x[r * d + i] - bm[i];
      bv[i] += e * e;
    }
  for (size_t i = 0; i < d; ++i) bv[i] /= n;
  MergeMoments(n, bm.data(), bv.data());
}

void RunningMeanStd::Merge(const RunningMeanStd& other) {
  if (other.count_ <= 0) return;
  if (other.dim() != dim()) {
    throw ConfigError("RunningMeanStd::Merge: dimension " + std::to_string(other.dim()) +
                      " differs from " + std::to_string(dim()));
  }
  MergeMoments(other.count_, other.mean_.data(), other.var_.data());
}

void RunningMeanStd::ToProto(proto::RunningStats* p) const {
  p->set_count(count_);
  p->clear_mean();
  p->clear_var();
  for (double m : mean_) p->add_mean(m);
  for (double v : var_) p->add_var(v);
}

RunningMeanStd RunningMeanStd::FromProto(const proto::RunningStats& p, int expected_dim,
                                         const std::string& ctx) {
  if (p.mean_size() != p.var_size()) {
    throw ConfigError(ctx + ": mean has " + std::to_string(p.mean_size()) + " entries, var " +
                      std::to_string(p.var_size()));
  }
  if (expected_dim >= 0 && p.mean_size() != expected_dim) {
    throw ConfigError(ctx + ": dimension " + std::to_string(p.mean_size()) + ", expected " +
                      std::to_string(expected_dim));
  }
  if (!std::isfinite(p.count()) || p.count() < 0) {
    throw ConfigError(ctx + ".count: invalid value " + std::to_string(p.count()));
  }
  RunningMeanStd r(p.mean_size(), 0.0);
  r.count_ = p.count();
  for (int i = 0; i < p.mean_size(); ++i) {
    if (!std::isfinite(p.mean(i)) || !std::isfinite(p.var(i)) || p.var(i) < 0) {
      throw ConfigError(ctx + ": invalid mean/var at index " + std::to_string(i));
    }
    r.mean_[i] = p.mean(i);
    r.var_[i] = p.var(i);
  }
  return r;
}

const FieldTable<NormalizerConfig>& NormalizerConfigFields() {
  using C = NormalizerConfig;
  static const FieldTable<NormalizerConfig> t =
      FieldTable<C>()
          .Add("normalize_obs", &C::normalize_obs, "off: observations pass through unchanged")
          .Add("obs_clip", &C::obs_clip, "normalized observations clipped to +-obs_clip",
               Positive<float>())
          .Add("obs_eps", &C::obs_eps, "added to the variance", NonNegative<float>())
          .Add("initial_count", &C::initial_count, "prior count of the statistics (mean 0, var 1)",
               NonNegative<double>());
  return t;
}

Json ToJson(const NormalizerConfig& c) { return NormalizerConfigFields().Write(c); }

NormalizerConfig NormalizerConfigFromJson(const Json& j, const std::string& ctx) {
  return NormalizerConfigFields().Read(j, ctx);
}

ObsNormalizer::ObsNormalizer(int dim, const NormalizerConfig& config)
    : config_(config), stats_(dim, config.initial_count), mean_f_(dim), inv_std_f_(dim) {
  Refresh();
}

void ObsNormalizer::Refresh() {
  const int d = stats_.dim();
  mean_f_.resize(d);
  inv_std_f_.resize(d);
  for (int i = 0; i < d; ++i) {
    mean_f_[i] = static_cast<float>(stats_.mean()[i]);
    inv_std_f_[i] = static_cast<float>(1.0 / std::sqrt(stats_.var()[i] + config_.obs_eps));
  }
}

void ObsNormalizer::Normalize(const float* raw, float* out) const {
  const int d = dim();
  if (!config_.normalize_obs) {
    if (out != raw) std::copy(raw, raw + d, out);
    return;
  }
  const float c = config_.obs_clip;
  for (int i = 0; i < d; ++i) {
    out[i] = std::clamp((raw[i] - mean_f_[i]) * inv_std_f_[i], -c, c);
  }
}

const FieldTable<RewardScalingConfig>& RewardScalingConfigFields() {
  using C = RewardScalingConfig;
  static const FieldTable<RewardScalingConfig> t =
      FieldTable<C>()
          .Add("enabled", &C::enabled, "scale rewards by the running std of the return")
          .Add("clip", &C::clip, "scaled rewards clipped to +-clip", Positive<float>())
          .Add("eps", &C::eps, "added to the variance", NonNegative<float>())
          .Add("reset_at_episode_end", &C::reset_at_episode_end,
               "reset the return estimate at episode ends (the authors never did)")
          .Add("initial_count", &C::initial_count, "prior count of the return statistics",
               NonNegative<double>());
  return t;
}

Json ToJson(const RewardScalingConfig& c) { return RewardScalingConfigFields().Write(c); }

RewardScalingConfig RewardScalingConfigFromJson(const Json& j, const std::string& ctx) {
  return RewardScalingConfigFields().Read(j, ctx);
}

RewardScaler::RewardScaler(const RewardScalingConfig& config, float gamma)
    : config_(config), gamma_(gamma), return_stats_(1, config.initial_count) {}

void RewardScaler::ScaleInPlace(uint64_t stream_id, float* rewards, const uint8_t* done, int n,
                                RunningMeanStd* delta) {
  if (!config_.enabled) return;
  double& ret = streams_[stream_id];
  for (int t = 0; t < n; ++t) {
    if (std::isnan(rewards[t])) continue;  // meta off-steps
    ret = ret * gamma_ + rewards[t];
    const float r = static_cast<float>(ret);
    return_stats_.Update(&r);
    if (delta != nullptr) delta->Update(&r);
    const double s = std::sqrt(return_stats_.var()[0] + config_.eps);
    rewards[t] = std::clamp(static_cast<float>(rewards[t] / s), -config_.clip, config_.clip);
    if (config_.reset_at_episode_end && done != nullptr && done[t]) ret = 0.0;
  }
}

}  // namespace perch
