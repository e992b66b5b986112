// Rollout segments (what PPO consumes), GAE, and a single-process collector over common/env.h.
#pragma once

#include <cstdint>
#include <vector>

#include "common/env.h"
#include "common/rng.h"
#include "policy/normalizer.h"
#include "policy/policy.h"

namespace perch {

namespace proto {
class RolloutSegment;
}

// T consecutive steps of one environment stream. Step t: the policy saw obs[t], took actions[t]
// (log_probs[t], values[t] = V(obs[t])), got rewards[t]; then
//   terminated[t]: the episode ended by a fall etc. -> no bootstrap (value of what follows is 0);
//   truncated[t]:  the episode ended by the time limit -> bootstrap with bootstrap_values[t] =
//                  V(final observation) (the observation the env returned before reset);
//   otherwise at t == T-1 (segment cut mid-episode): bootstrap_values[t] = V(next observation).
// bootstrap_values[t] is read only in those two cases (set 0 elsewhere). The next segment of the
// same stream continues where this one stopped.
struct Rollout {
  uint64_t stream_id = 0;       // env instance; keys the reward-scaling return accumulator
  uint64_t policy_version = 0;  // weights version that acted
  int obs_dim = 0;
  int action_size = 0;
  std::vector<float> obs;               // [T x obs_dim] normalized observations
  std::vector<float> actions;           // [T x action_size]
  std::vector<float> log_probs;         // [T]
  std::vector<float> values;            // [T]
  std::vector<float> rewards;           // [T] raw env rewards (scaling is the learner's)
  std::vector<uint8_t> terminated;      // [T]
  std::vector<uint8_t> truncated;       // [T]
  std::vector<float> bootstrap_values;  // [T]
  RunningMeanStd obs_stats_delta;       // raw-obs statistics of these steps (count 0 if unused)

  Rollout() = default;
  Rollout(int obs_dim, int action_size) : obs_dim(obs_dim), action_size(action_size) {}
  int size() const { return static_cast<int>(rewards.size()); }
  void Reserve(int steps);
  void Clear();  // keeps dims, stream id and capacity
  // Starts a segment of up to `steps` steps: resized (and emptied) for these dims, else cleared.
  void Begin(int obs_dim, int action_size, uint64_t stream_id, uint64_t policy_version, int steps);
  void Add(const float* norm_obs, const float* action, float log_prob, float value, float reward,
           bool terminated, bool truncated, float bootstrap_value);
  // Throws ConfigError naming ctx when array sizes disagree or values are not finite.
  void Validate(const std::string& ctx) const;

  void ToProto(proto::RolloutSegment* p) const;
  static Rollout FromProto(const proto::RolloutSegment& p, const std::string& ctx);  // validates
};

// Generalized advantage estimation over one segment (rewards already scaled if scaling is on).
//   delta_t = r_t + gamma * V_next_t - V_t, A_t = delta_t + gamma * lambda * c_t * A_{t+1},
// where V_next_t = 0 if terminated[t]; bootstrap_values[t] if truncated[t] (or 0 when
// !bootstrap_on_truncation, the authors' behaviour) or t == T-1; values[t+1] otherwise; and
// c_t = 0 at an episode end (terminated or truncated) or at t == T-1. returns = A + V.
// rewards may differ from r.rewards (scaled copy); pass nullptr to use r.rewards.
void ComputeGae(const Rollout& r, const float* rewards, float gamma, float lambda,
                bool bootstrap_on_truncation, float* advantages, float* returns);

// V-trace (Espeholt et al. 2018) in GAE's form, for a segment that acted with older weights:
//   delta_t = rho_t (r_t + gamma * V_next_t - V_t), A_t = delta_t + gamma * lambda * c_t * A_{t+1},
// with V_t = values[t] (the learner's current value network; V_next_t as for GAE but from values,
// except the bootstrap values at truncation and segment end, which stay the acting network's: the
// observation they came from is not in the segment), rho_t and c_t the truncated importance
// ratios. returns = A + V are V-trace's targets v_s. rho = c = 1 and values = r.values is
// ComputeGae, bit for bit.
void ComputeVtrace(const Rollout& r, const float* rewards, const float* values, const float* rho,
                   const float* c, float gamma, float lambda, bool bootstrap_on_truncation,
                   float* advantages, float* returns);

// Per-episode bookkeeping from a collector.
struct EpisodeStats {
  std::vector<double> returns;  // undiscounted, raw rewards, of episodes finished
  std::vector<int> lengths;
  int terminated = 0;
  int truncated = 0;
  std::vector<uint8_t> succeeded;  // [episodes] the task's success test passed (has_success)
};

// Steps one Env with a PolicyRunner, in process: what an actor does, without the sockets.
// Handles reset, termination vs truncation (bootstrap from the final observation) and segment
// ends. Keeps the episode going across Collect() calls.
class RolloutCollector {
 public:
  RolloutCollector(Env* env, uint64_t stream_id);
  // Appends `steps` steps to *out (cleared first). Deterministic given runner weights and rng.
  void Collect(PolicyRunner* runner, Rng& rng, int steps, Rollout* out, EpisodeStats* stats);
  // Mean actions / argmax choices instead of samples (evaluation).
  void set_deterministic(bool on) { deterministic_ = on; }

 private:
  bool deterministic_ = false;
  Env* env_;
  uint64_t stream_id_;
  bool need_reset_ = true;
  double episode_return_ = 0.0;
  int episode_length_ = 0;
  bool episode_success_ = false;
  std::vector<float> obs_, next_obs_, norm_obs_, action_;
};

}  // namespace perch
