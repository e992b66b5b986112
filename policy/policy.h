// Actor-critic networks: a policy MLP with a Gaussian head (subtasks, paper §4) or a categorical +
// Gaussian head (meta controller, paper §5), and a separate value MLP (notes §8.1).
//
// Parameter vector layout (float32, one flat vector; ModelWeights.params on the wire):
//   [ policy MLP (obs_dim -> hidden -> head_dim) | log_std [act_dim] | value MLP (obs_dim -> hidden
//   -> 1) ] gaussian: head_dim = act_dim (the mean). meta:     head_dim = num_choices + act_dim
//   (logits, then the target mean).
//
// Action layout (what an actor applies and ships, action_size() floats per step):
//   gaussian: the act_dim sampled action (unclipped; the env clips).
//   meta:     [choice index as a float, target (act_dim)]. The target's log-probability counts only
//             when choice == target_choice (walk); otherwise the target is ignored.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "common/env.h"
#include "common/json_util.h"
#include "common/rng.h"
#include "policy/mlp.h"
#include "policy/normalizer.h"

namespace perch {

namespace proto {
class PolicyShape;
class ModelWeights;
}  // namespace proto

enum class PolicyKind { kGaussian, kMeta };
// kTrained: state-independent log-std trained with the policy (authors' code, notes §8.1).
// kFixed: sigma = exp(init_log_std), never trained (the paper's "fixed diagonal covariance", §4).
enum class StdMode { kTrained, kFixed };
std::string StdModeName(StdMode m);  // "trained" / "fixed", as in configs and shapes

struct PolicyConfig {
  PolicyKind kind = PolicyKind::kGaussian;
  int obs_dim = 57;       // sit / meta observation (walk and turn: 52), notes §2
  int act_dim = 21;       // joint torques (meta: the 2-d walk target (theta rad, dist m))
  int num_choices = 4;    // meta only: 0 left turn, 1 right turn, 2 sit, 3 walk (notes §4.7)
  int target_choice = 3;  // meta only: walk
  MlpConfig policy_net;   // 2 x 64 tanh
  MlpConfig value_net;    // 2 x 64 tanh
  StdMode std_mode = StdMode::kTrained;
  float init_log_std = 0.0f;  // sigma = 1 at start
  // Orthogonal init gains (notes §8.1).
  float hidden_gain = 1.41421356f;  // sqrt(2)
  float policy_out_gain = 0.01f;    // mean and logits
  float value_out_gain = 1.0f;

  static PolicyConfig Subtask(int obs_dim);    // gaussian over 21 torques
  static PolicyConfig Meta(int obs_dim = 57);  // 4 choices + 2-d target
  int action_size() const { return kind == PolicyKind::kMeta ? 1 + act_dim : act_dim; }
};
Json ToJson(const PolicyConfig& c);
// Strict: unknown field / wrong type / bad value -> ConfigError naming ctx.field.
PolicyConfig PolicyConfigFromJson(const Json& j, const std::string& ctx);
const FieldTable<PolicyConfig>& PolicyConfigFields();  // each field written once

// Per-sample results and caches of a batched evaluation (PPO update). Reused across minibatches.
struct PolicyEvalCache {
  MlpCache pi;
  MlpCache vf;
  VectorXf log_prob;        // [B] log pi(a | s)
  VectorXf entropy;         // [B]
  VectorXf value;           // [B] V(s)
  MatrixXf z;               // [act_dim x B] (a - mu) / sigma
  MatrixXf probs;           // meta: [num_choices x B] softmax
  std::vector<int> choice;  // meta: [B]
  std::vector<float> gate;  // meta: [B] 1 when the target counts
  MatrixXf grad_head;       // [head_dim x B] backward scratch
  MatrixXf grad_value;      // [1 x B]
};

// The networks and their parameters. Stateless apart from the parameter vector, so the learner
// can evaluate any parameter vector (gradient checks) through the const methods.
class ActorCritic {
 public:
  ActorCritic() = default;
  // Orthogonal init from `seed` (deterministic).
  ActorCritic(const PolicyConfig& config, uint64_t seed);

  const PolicyConfig& config() const { return config_; }
  int obs_dim() const { return config_.obs_dim; }
  int act_dim() const { return config_.act_dim; }
  int action_size() const { return config_.action_size(); }
  int head_dim() const { return pi_.out_dim(); }
  int num_params() const { return num_params_; }
  int log_std_offset() const { return log_std_offset_; }
  int value_offset() const { return value_offset_; }
  const Mlp& policy_mlp() const { return pi_; }
  const Mlp& value_mlp() const { return vf_; }

  VectorXf& params() { return params_; }
  const VectorXf& params() const { return params_; }
  // 1 for trained parameters, 0 for the fixed log-std: the learner multiplies gradients by it.
  const VectorXf& trainable_mask() const { return mask_; }

  // Batched: obs [obs_dim x B] (normalized), actions [action_size x B]. Fills cache->log_prob,
  // entropy, value.
  void Evaluate(const float* params, const Eigen::Ref<const MatrixXf>& obs,
                const Eigen::Ref<const MatrixXf>& actions, PolicyEvalCache* cache) const;
  // Backward of the last Evaluate: adds into grad_params the gradient of
  //   sum_b dlogp[b] * log_prob[b] + dent[b] * entropy[b] + dval[b] * value[b].
  void Backward(const float* params, const Eigen::Ref<const VectorXf>& dlogp,
                const Eigen::Ref<const VectorXf>& dent, const Eigen::Ref<const VectorXf>& dval,
                PolicyEvalCache* cache, float* grad_params) const;
  // The two independent halves of Evaluate and Backward: the policy network (log_prob, entropy;
  // its weights and log_std) and the value network (value; its weights). They read and write
  // disjoint parts of the cache and of grad_params, so two threads may run one each.
  void EvaluatePolicy(const float* params, const Eigen::Ref<const MatrixXf>& obs,
                      const Eigen::Ref<const MatrixXf>& actions, PolicyEvalCache* cache) const;
  void EvaluateValue(const float* params, const Eigen::Ref<const MatrixXf>& obs,
                     PolicyEvalCache* cache) const;
  void BackwardPolicy(const float* params, const Eigen::Ref<const VectorXf>& dlogp,
                      const Eigen::Ref<const VectorXf>& dent, PolicyEvalCache* cache,
                      float* grad_params) const;
  void BackwardValue(const float* params, const Eigen::Ref<const VectorXf>& dval,
                     PolicyEvalCache* cache, float* grad_params) const;

  // Shape as on the wire; CheckShape throws ConfigError "ctx: <field> differs (blob X, model Y)".
  void GetShape(proto::PolicyShape* shape) const;
  void CheckShape(const proto::PolicyShape& shape, const std::string& ctx) const;

 private:
  PolicyConfig config_;
  Mlp pi_;
  Mlp vf_;
  int log_std_offset_ = 0;
  int value_offset_ = 0;
  int num_params_ = 0;
  VectorXf params_;
  VectorXf mask_;
};

// The network config a ModelWeights' shape describes (ConfigError naming ctx on bad values).
PolicyConfig PolicyConfigFromShape(const proto::PolicyShape& shape, const std::string& ctx);

// The policy of `narrow` in a network with wider hidden layers (`wide`; the extra units
// initialised from `seed`): the same actions, log-std, value and observation statistics, so
// fine-tuning goes on from where `narrow` was with more capacity (Mlp::EmbedNarrower). ConfigError
// naming ctx when `wide` differs in anything but hidden widths, or is narrower anywhere.
proto::ModelWeights WidenModelWeights(const proto::ModelWeights& narrow, const PolicyConfig& wide,
                                      uint64_t seed, const std::string& ctx);

// `w` observing only its first `obs_dim` inputs (the trailing ones dropped from the first layer of
// both MLPs and from the observation statistics): e.g. the walk policy (50-d proprioceptive + 2-d
// goal) as the start of a turn policy (50-d), as the authors fine-tuned turns from walk (notes
// 8.2). A dropped input then acts as if at its running mean (normalised 0). ConfigError when
// obs_dim is not smaller than w's.
proto::ModelWeights DropTrailingInputs(const proto::ModelWeights& w, int obs_dim,
                                       const std::string& ctx);
// The inverse: `extra` inputs appended with zero weights in both networks' first layers (the
// function is unchanged) and normaliser statistics mean 0, var 1 for them (a meta controller that
// observes more, e.g. sit_chair.meta.observe_active, starts from one that did not).
proto::ModelWeights AppendZeroInputs(const proto::ModelWeights& w, int obs_dim,
                                     const std::string& ctx);

// The policy of the mirror-image task (turn right from turn left, MirrorMap in common/env.h):
// pi'(o) = M_act(pi(M_obs(o))) and V'(o) = V(M_obs(o)) exactly, by permuting and signing both
// networks' input columns, moving the observation statistics (mean, var) to where the mirrored
// inputs come from, and permuting, scaling and shifting the mean head's rows and the log-std.
// ConfigError naming ctx for a meta policy, sizes that differ from the map, or a map that is not
// a signed permutation (a source used twice, a zero scale).
proto::ModelWeights MirrorModelWeights(const proto::ModelWeights& w, const MirrorMap& m,
                                       const std::string& ctx);

// `w` with the std mode of `mine` (a fine-tune that freezes or frees sigma): into a fixed-sigma
// network the log-std becomes mine.init_log_std for every action dimension (what fixed means);
// into a trained one the source's log-std is kept as the starting point. Other shape fields are
// left for CheckShape / WidenModelWeights to judge.
proto::ModelWeights ConvertStdMode(const proto::ModelWeights& w, const PolicyConfig& mine,
                                   const std::string& ctx);

// A meta policy with fewer switch classes (the walk-only pre-training: {walk}) as the start of one
// with more (`mine`): trunk, target head, log-std, value network and observation statistics
// copied; the switch head newly initialised from `seed` (its shape differs), as the authors
// warm-started the full meta controller (notes 6). ConfigError when the two differ otherwise.
proto::ModelWeights WidenMetaChoices(const proto::ModelWeights& w, const PolicyConfig& mine,
                                     uint64_t seed, const std::string& ctx);

// What an actor runs every control step: one observation in, action + log-prob + value out,
// no allocation per step. One runner per thread (it owns scratch buffers).
//
// Observation normalization: the runner normalizes raw observations with its local statistics
// (the learner's broadcast ones, updated with every observation it has seen since, as the authors
// update before normalizing), and accumulates the raw observations into obs_stats_delta() for the
// learner. Ship the normalized observation (norm_obs) in the rollout: PPO trains on exactly what
// the policy saw.
class PolicyRunner {
 public:
  struct Output {
    float log_prob = 0.0f;
    float value = 0.0f;
  };

  PolicyRunner() = default;
  PolicyRunner(const PolicyConfig& config, const NormalizerConfig& norm_config);

  // Takes the learner's weights and statistics (ConfigError on a shape mismatch, nothing changed
  // then). Resets local statistics to the broadcast ones; the delta is kept (not yet shipped).
  void LoadWeights(const proto::ModelWeights& weights);
  // Same, in process (tests, single-process training).
  void SetWeights(const VectorXf& params, const RunningMeanStd& obs_stats, uint64_t version);

  // raw_obs [obs_dim] -> norm_obs [obs_dim] (may be null), action [action_size]. Samples with rng
  // unless deterministic (mean / argmax). Updates the local stats and the delta first when
  // update_obs_stats (default true).
  Output Act(const float* raw_obs, Rng& rng, bool deterministic, float* norm_obs, float* action);
  // V(raw_obs) without updating statistics: the bootstrap value at truncation / segment end.
  float Value(const float* raw_obs);

  void set_update_obs_stats(bool on) { update_obs_stats_ = on; }
  const RunningMeanStd& obs_stats_delta() const { return delta_; }
  void ClearObsStatsDelta();
  uint64_t version() const { return version_; }
  const ActorCritic& model() const { return model_; }
  const ObsNormalizer& normalizer() const { return normalizer_; }

 private:
  ActorCritic model_;
  ObsNormalizer normalizer_;
  RunningMeanStd delta_;
  bool update_obs_stats_ = true;
  uint64_t version_ = 0;
  std::vector<float> norm_;     // [obs_dim]
  std::vector<float> head_;     // [head_dim]
  std::vector<float> scratch_;  // [2 * max width]
};

}  // namespace perch
