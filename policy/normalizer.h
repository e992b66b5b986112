// Running observation statistics and reward scaling, as the authors' VecNormalize (notes §2,
// §8.1): obs_n = clip((obs - mean) / sqrt(var + eps), -clip, clip); reward / sqrt(var_ret + eps)
// clipped, where var_ret is the running variance of the discounted return.
//
// In the cluster, the learner owns the master statistics and broadcasts them with the weights.
// An actor keeps a local copy (master + what it has seen since) to normalize, and accumulates what
// it has seen into a delta (starts at count 0) that it ships with each rollout; the learner
// Merge()s the deltas. The merge is exact (parallel mean/variance formula).
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

#include "common/field_table.h"
#include "common/json_util.h"

namespace perch {

namespace proto {
class RunningStats;
}

// Mean and population variance over a stream of vectors, in double (as numpy in the original).
class RunningMeanStd {
 public:
  RunningMeanStd() = default;
  // initial_count 1e-4 with mean 0, var 1 is the authors' prior; use 0 for deltas.
  explicit RunningMeanStd(int dim, double initial_count = 1e-4);

  int dim() const { return static_cast<int>(mean_.size()); }
  double count() const { return count_; }
  const std::vector<double>& mean() const { return mean_; }
  const std::vector<double>& var() const { return var_; }

  // Adds one sample x[dim].
  void Update(const float* x);
  // Adds n samples, x [n x dim] row-major, as one batch (the authors' batch update).
  void UpdateBatch(const float* x, int n);
  // Adds another accumulator's samples (its prior count included). No-op for count 0.
  void Merge(const RunningMeanStd& other);
  // Forgets all samples: count = initial_count, mean 0, var 1 (0 when initial_count == 0).
  void Reset(double initial_count);

  void ToProto(proto::RunningStats* p) const;
  // Throws ConfigError naming ctx when the dimension differs from expected_dim (>= 0) or the
  // values are not finite/non-negative.
  static RunningMeanStd FromProto(const proto::RunningStats& p, int expected_dim,
                                  const std::string& ctx);

 private:
  void MergeMoments(double n, const double* mean, const double* var);
  double count_ = 0.0;
  std::vector<double> mean_;
  std::vector<double> var_;
};

struct NormalizerConfig {
  bool normalize_obs = true;  // off: observations pass through unchanged
  float obs_clip = 10.0f;     // notes §2
  float obs_eps = 1e-8f;      // added to var
  double initial_count = 1e-4;
};
const FieldTable<NormalizerConfig>& NormalizerConfigFields();
Json ToJson(const NormalizerConfig& c);
NormalizerConfig NormalizerConfigFromJson(const Json& j, const std::string& ctx);

// Observation normalizer: statistics plus the transform. Normalize() does not update.
class ObsNormalizer {
 public:
  ObsNormalizer() = default;
  ObsNormalizer(int dim, const NormalizerConfig& config);

  const NormalizerConfig& config() const { return config_; }
  void set_config(const NormalizerConfig& c) {
    config_ = c;
    Refresh();
  }
  RunningMeanStd& stats() { return stats_; }
  const RunningMeanStd& stats() const { return stats_; }
  int dim() const { return stats_.dim(); }

  // out[dim] = clip((raw - mean) / sqrt(var + eps)); raw and out may alias. No allocation.
  void Normalize(const float* raw, float* out) const;
  // Recomputes the cached float mean / inverse std after the stats changed.
  void Refresh();

 private:
  NormalizerConfig config_;
  RunningMeanStd stats_;
  std::vector<float> mean_f_;     // [dim]
  std::vector<float> inv_std_f_;  // [dim]
};

struct RewardScalingConfig {
  bool enabled = true;  // authors' VecNormalize(ret=True)
  float clip = 10.0f;   // scaled rewards clipped to +-clip
  float eps = 1e-8f;
  bool reset_at_episode_end = false;  // authors never reset the return estimate (notes §9.6)
  double initial_count = 1e-4;        // prior of the return statistics (mean 0, var 1)
};
const FieldTable<RewardScalingConfig>& RewardScalingConfigFields();
Json ToJson(const RewardScalingConfig& c);
RewardScalingConfig RewardScalingConfigFromJson(const Json& j, const std::string& ctx);

// Divides rewards by the running std of the discounted return. Each environment stream
// (Rollout::stream_id) has its own return accumulator ret = ret * gamma + r; the variance is
// shared. Applied by the learner to each incoming rollout in step order, update-then-scale per
// step as the authors. NaN rewards are passed through unchanged and skipped.
class RewardScaler {
 public:
  RewardScaler() = default;
  RewardScaler(const RewardScalingConfig& config, float gamma);

  // Scales rewards[n] in place; done[t] (terminated or truncated) resets the accumulator after
  // step t only when reset_at_episode_end.
  // delta (optional, 1-d): also receives the returns added to the statistics (a learner group
  // merges every member's delta into the same statistics).
  void ScaleInPlace(uint64_t stream_id, float* rewards, const uint8_t* done, int n,
                    RunningMeanStd* delta = nullptr);

  const RunningMeanStd& return_stats() const { return return_stats_; }
  RunningMeanStd& return_stats() { return return_stats_; }
  std::unordered_map<uint64_t, double>& streams() { return streams_; }
  const std::unordered_map<uint64_t, double>& streams() const { return streams_; }

 private:
  RewardScalingConfig config_;
  float gamma_ = 0.99f;
  RunningMeanStd return_stats_{1};
  std::unordered_map<uint64_t, double> streams_;
};

}  // namespace perch
