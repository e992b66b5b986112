// The environment interface the actor loop sees. It knows nothing about humanoids or Bullet:
// an env publishes a static spec and implements Reset/Step on flat float arrays.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace perch {

// A named contiguous range of the observation vector, e.g. {"joint_angles", 7, 21}.
struct ObsSlice {
  std::string name;
  int offset = 0;
  int size = 0;
};

// The env's left/right symmetry (world y -> -y) on its flat arrays: the mirror image of a state
// observes obs'[i] = obs_scale[i] * obs[obs_src[i]] + obs_offset[i], and the mirror image of an
// action is act'[i] = act_scale[i] * act[act_src[i]] + act_offset[i]. A policy for the mirrored
// task (turn right from turn left) is then pi'(o) = M_act(pi(M_obs(o))) (policy/policy.h,
// MirrorModelWeights). Empty when the env has no such symmetry.
struct MirrorMap {
  std::vector<int> obs_src;       // [obs_dim] a permutation
  std::vector<float> obs_scale;   // [obs_dim] nonzero
  std::vector<float> obs_offset;  // [obs_dim]
  std::vector<int> act_src;       // [act_dim] a permutation
  std::vector<float> act_scale;   // [act_dim] nonzero
  std::vector<float> act_offset;  // [act_dim]
  bool empty() const { return obs_src.empty(); }
};

struct EnvSpec {
  std::string name;
  int obs_dim = 0;                   // length of the observation vector
  int act_dim = 0;                   // length of the action vector
  std::vector<float> obs_low;        // [obs_dim] bounds observations are clipped to
  std::vector<float> obs_high;       // [obs_dim]
  std::vector<float> act_low;        // [act_dim] the env clips actions to these
  std::vector<float> act_high;       // [act_dim]
  std::vector<ObsSlice> obs_slices;  // which slices are which
  double control_dt = 1.0 / 60.0;    // seconds per Step()
  int max_episode_steps = 1000;      // truncation limit, in Step() calls
  bool has_success = false;          // the task has a success test (StepResult::success)
  MirrorMap mirror;                  // left/right symmetry of obs and actions (may be empty)
};

// Result of one Step(). `terminated` (e.g. fell) and `truncated` (time limit) are distinct:
// PPO bootstraps on truncation, not on termination.
struct StepResult {
  float reward = 0.0f;
  bool terminated = false;
  bool truncated = false;
  bool invalid = false;  // NaN/Inf or exploding state detected; also sets terminated
  bool success = false;  // the task's success test passed at this step (once per episode)
};

// A policy an env runs inside its own Step (the hierarchy's frozen subtasks, paper Sec. 5): the
// env's concern, shipped to actors by the learner, so the actor loop only passes bytes along.
struct FrozenPolicyData {
  std::string name;          // the subtask: "walk", "turn_left", "turn_right", "sit"
  std::string model;         // serialized proto::ModelWeights
  std::string saved_config;  // the experiment config saved with the model (JSON; may be empty)
  std::string source;        // where it came from (file and sha256), for records
};

class Env;

// Implemented by envs that need frozen policies before they can step (the meta env).
class FrozenPolicyEnv {
 public:
  virtual ~FrozenPolicyEnv() = default;
  virtual std::vector<std::string> frozen_policy_names() const = 0;  // the ones it needs
  virtual bool has_frozen_policies() const = 0;
  // ConfigError naming the policy when one is missing or does not fit.
  virtual void SetFrozenPolicies(const std::vector<FrozenPolicyData>& policies) = 0;
};

class Env {
 public:
  virtual ~Env() = default;
  virtual const EnvSpec& spec() const = 0;
  // Reseeds the env's RNG; the next Reset() starts a new reproducible stream.
  virtual void Seed(uint64_t seed) = 0;
  // Starts an episode and writes the first observation into obs[spec().obs_dim].
  virtual void Reset(float* obs) = 0;
  // Applies action[spec().act_dim] for one control step and writes the next observation.
  virtual StepResult Step(const float* action, float* obs) = 0;
};

}  // namespace perch
