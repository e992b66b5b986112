// PPO (clipped surrogate) as the authors ran it (OpenAI Baselines PPO2, notes §8.1), on Eigen.
//
//   learner = PpoLearner(PolicyConfig::Subtask(57), PpoConfig::Subtask(), seed);
//   loop: rollouts from actors (PolicyRunner + Rollout) ->
//         stats = learner.Update(rollouts)   (also merges each rollout's obs_stats_delta) ->
//         learner.ExportWeights(&msg) and broadcast.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/json_util.h"
#include "common/rng.h"
#include "common/worker_pool.h"
#include "learner/adam.h"
#include "learner/collective.h"
#include "policy/normalizer.h"
#include "policy/policy.h"
#include "policy/rollout.h"
#include "protocol/ppo_config.h"

namespace perch {

namespace proto {
class ModelWeights;
class LearnerState;
}  // namespace proto

// Means over all minibatches of all epochs of one update, except where noted.
struct UpdateStats {
  int num_samples = 0;
  int num_minibatch_steps = 0;
  float policy_loss = 0.0f;  // clipped surrogate (to minimize)
  float value_loss = 0.0f;   // 0.5 * mean of (clipped) squared error, before value_coef
  float entropy = 0.0f;
  float approx_kl = 0.0f;           // 0.5 * mean (log ratio)^2, as Baselines
  float clip_fraction = 0.0f;       // fraction with |ratio - 1| > clip_range
  float grad_norm = 0.0f;           // before clipping
  float explained_variance = 0.0f;  // of the values before the update vs returns
  float mean_reward = 0.0f;         // raw rewards of the batch
  float mean_scaled_reward = 0.0f;
  float mean_advantage = 0.0f;  // before normalization
  float mean_return = 0.0f;     // GAE targets
  float log_std_mean = 0.0f;    // after the update
  // Samples from segments older than the learner (policy lag >= 1); with ppo.vtrace, over those,
  // the mean importance ratio pi/mu before truncation and the fraction truncated by
  // vtrace_rho_clip.
  int lagged_samples = 0;
  float vtrace_ratio_mean = 0.0f;
  float vtrace_rho_clipped = 0.0f;
  // In a learner group: the samples of this update over all members (else num_samples).
  int group_samples = 0;
};
Json ToJson(const UpdateStats& s);

// The PPO objective on one minibatch (advantages already normalized):
//   total = policy_loss - entropy_coef * entropy + value_coef * value_loss
//   policy_loss = mean max(-A r, -A clip(r, 1 +- clip_range)), r = exp(logp - old_logp)
//   value_loss = 0.5 mean max((v - R)^2, (old_v + clip(v - old_v, +-value_clip_range) - R)^2)
//                (without the clipped term when !clip_value)
struct PpoLossTerms {
  double total = 0, policy_loss = 0, value_loss = 0, entropy = 0, approx_kl = 0, clip_fraction = 0;
};
struct PpoLossWorkspace {
  PolicyEvalCache eval;
  VectorXf dlogp, dent, dval;  // [B]
};
// The loss terms from an evaluated ws->eval (ActorCritic::Evaluate), and ws->dlogp, dent, dval
// for ActorCritic::Backward. mean_over as for PpoLoss.
PpoLossTerms PpoLossFromEval(const PpoConfig& cfg, const Eigen::Ref<const VectorXf>& old_logp,
                             const Eigen::Ref<const VectorXf>& old_value,
                             const Eigen::Ref<const VectorXf>& adv,
                             const Eigen::Ref<const VectorXf>& ret, PpoLossWorkspace* ws,
                             int mean_over = 0);
// Evaluates the loss at `params`; when grad != nullptr adds d total / d params into grad.
// mean_over > 0: the means are over that many samples (a part of a minibatch split across threads:
// the parts' terms and gradients then add up to the whole minibatch's); 0: over obs.cols().
PpoLossTerms PpoLoss(const ActorCritic& model, const float* params, const PpoConfig& cfg,
                     const Eigen::Ref<const MatrixXf>& obs,
                     const Eigen::Ref<const MatrixXf>& actions,
                     const Eigen::Ref<const VectorXf>& old_logp,
                     const Eigen::Ref<const VectorXf>& old_value,
                     const Eigen::Ref<const VectorXf>& adv, const Eigen::Ref<const VectorXf>& ret,
                     PpoLossWorkspace* ws, float* grad, int mean_over = 0);

class PpoLearner {
 public:
  PpoLearner(const PolicyConfig& policy, const PpoConfig& ppo, uint64_t seed);

  const PpoConfig& config() const { return ppo_; }
  // The rate of the next updates (the service follows ppo.lr_schedule by samples).
  void SetLearningRate(float lr) { ppo_.learning_rate = lr; }
  const ActorCritic& model() const { return model_; }
  ActorCritic& model() { return model_; }
  ObsNormalizer& obs_normalizer() { return obs_norm_; }
  const ObsNormalizer& obs_normalizer() const { return obs_norm_; }
  RewardScaler& reward_scaler() { return reward_scaler_; }
  const Adam& optimizer() const { return adam_; }
  int64_t num_updates() const { return num_updates_; }
  int64_t num_samples() const { return num_samples_; }

  // Data parallelism over a learner group (ours, issue 20, DD-PPO style; not owned, nullptr:
  // alone). Each member updates on its own batch; every minibatch's gradient and loss terms are
  // summed over the group (each member's share weighted by its samples), the observation and
  // return statistics merged in rank order, so every member takes the same steps and keeps the
  // same weights, Adam moments and normalizers. Advantages are normalized per member (DD-PPO).
  // A member whose batch is refused makes every member drop its batch (ConfigError everywhere).
  void SetCollective(Collective* group) { group_ = group; }
  Collective* collective() const { return group_; }
  // A member's own minibatch shuffling (rank > 0): the same seed would draw the same
  // permutations on every member. Resuming restores the saved stream instead.
  void SeedShuffle(uint64_t seed, int rank);

  // Merges an actor's raw-observation statistics into the master ones (Update() does this for
  // each rollout's obs_stats_delta; call it only for statistics that travel otherwise).
  void AddObsStats(const RunningMeanStd& delta);

  // One PPO update: merges the rollouts' obs_stats_delta, reward scaling (in place on a copy, per
  // stream in order), GAE per segment, then num_epochs passes over shuffled minibatches. Segments
  // are validated first (ConfigError). Any total size works; minibatches split it as evenly as
  // possible.
  UpdateStats Update(const std::vector<Rollout>& rollouts);

  // Weights + obs stats for actors (version = num_updates()).
  void ExportWeights(proto::ModelWeights* w) const;
  // Everything: weights, Adam, reward-scaler, RNG, counters. Resuming gives identical updates.
  void ExportState(proto::LearnerState* s) const;
  // ConfigError "ctx: ..." on another network shape or inconsistent sizes; nothing changes then.
  void ImportWeights(const proto::ModelWeights& w, const std::string& ctx);
  void ImportState(const proto::LearnerState& s, const std::string& ctx);

 private:
  PolicyConfig policy_config_;
  PpoConfig ppo_;
  ActorCritic model_;
  ObsNormalizer obs_norm_;
  RewardScaler reward_scaler_;
  Adam adam_;
  Rng rng_;
  int64_t num_updates_ = 0;
  int64_t num_samples_ = 0;

  // Flattened batch and minibatch buffers, reused across updates (no allocation once warm).
  MatrixXf obs_, actions_;  // [obs_dim x N], [action_size x N]
  VectorXf old_logp_, old_value_, adv_, ret_;
  std::vector<int> perm_;
  // A minibatch, or with ppo.threads > 1 one part of it per thread.
  struct Shard {
    MatrixXf obs, act;
    VectorXf logp, value, adv, ret, grad;
    PpoLossWorkspace ws;
    PpoLossTerms terms;
  };
  Shard mb_;  // the one-thread path's minibatch
  VectorXf grad_;
  PpoLossWorkspace ws_;
  std::vector<float> scaled_rewards_, seg_adv_, seg_ret_, seg_rho_, seg_c_;

  // Update's steps. Each rollout is valid and fits the model (ConfigError otherwise; a group
  // agrees first, every member refusing together); returns every member's sample count by rank.
  std::vector<int> CheckBatch(const std::vector<Rollout>& rollouts) const;
  // The flattened batch: observation statistics, scaled rewards, GAE (V-trace for lagged
  // segments), the old log-probs and values; the batch's figures into st.
  void AssembleBatch(const std::vector<Rollout>& rollouts, int n, UpdateStats* st);
  // A group's observation and return statistics merged in rank order.
  void MergeGroupStats(const RunningMeanStd& obs_delta, const RunningMeanStd& ret_delta,
                       const RunningMeanStd& ret_before);
  // The epochs over shuffled minibatches; their mean losses into st.
  void RunEpochs(int n, const std::vector<int>& group_n, UpdateStats* st);
  // One minibatch (columns perm_[begin, begin + b)): loss, gradient, Adam step.
  PpoLossTerms MinibatchStep(int begin, int b, int mean_over, const float* params,
                             float* grad_norm);
  void ResizeShard(Shard* sh, int bs) const;
  void GatherColumns(Shard* sh, int lo, int k0, int k1) const;  // columns [k0, k1) of perm_[lo..]
  void NormalizeAdvantages(VectorXf* adv) const;  // (A - mean) / (std + eps) over the vector
  PpoLossTerms ColumnLoss(int begin, int b, int parts, const float* params, int mean_over);
  void SumShards();                           // the parts' gradients into grad_, masked
  void ReduceOverGroup(PpoLossTerms* terms);  // grad_ and terms summed over the group
  Collective* group_ = nullptr;
  std::vector<float> reduce_buf_;
  float ShardedStep();
  float SerialStep(VectorXf* grad);
  int active_shards_ = 0;
  std::vector<double> range_sq_;
  std::vector<Shard> shards_;
  std::shared_ptr<WorkerPool> pool_;  // shared by copies (ImportState works on a copy)
};

}  // namespace perch
