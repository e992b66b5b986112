// Perturbations of an evaluation (issue 49; perch eval --push, --obs-noise, --act-noise,
// --restore): each episode gets them at moments drawn from its own seed, so the same episode can
// be run with and without them and the pair differs only by the perturbation (flip_rate).
#pragma once

#include <cstdint>
#include <vector>

#include "common/json_util.h"
#include "common/rng.h"
#include "envs/humanoid_env.h"

namespace perch {

// The perturbations' RNG is seeded with the episode's seed XOR this, a stream of its own
// (Rng::Seed scrambles), so the episode's other draws are the unperturbed episode's.
constexpr uint64_t kPerturbationRngSalt = 0x5eed0f9e57b0a710ULL;

// x[0 .. n) += Gaussian noise of std `std`, drawn in order from `rng`.
void AddGaussianNoise(float* x, int n, double std, Rng& rng);

struct Perturbation {
  double push_n = 0.0;     // [N] a horizontal force on the pelvis, in a random direction ...
  double push_s = 0.1;     // [s] ... for this long, from a random step of the episode
  double obs_noise = 0.0;  // std of Gaussian noise added to every observation entry (its units)
  double act_noise = 0.0;  // std of Gaussian noise added to every action entry (before clipping)
  bool restore = false;    // save and restore the simulator's state at a random step
  bool any() const { return push_n > 0.0 || obs_noise > 0.0 || act_noise > 0.0 || restore; }
  Json ToJson() const;
};

// An evaluation env with its perturbations: forwards to `env`, pushes and restores it at steps
// drawn uniformly in [0, horizon_steps) per episode, and adds the noises. The draws come from an
// RNG of their own seeded from the episode's seed, so the env's and the policy's streams are the
// unperturbed episode's.
class PerturbedEnv : public Env {
 public:
  PerturbedEnv(HumanoidChairEnv* env, const Perturbation& p, int horizon_steps);
  const EnvSpec& spec() const override { return env_->spec(); }
  void Seed(uint64_t seed) override;
  void Reset(float* obs) override;
  StepResult Step(const float* action, float* obs) override;

  int push_step() const { return push_step_; }        // this episode's (-1: none)
  int restore_step() const { return restore_step_; }  // this episode's (-1: none)

 private:
  void AddObsNoise(float* obs);
  HumanoidChairEnv* env_;
  Perturbation p_;
  int horizon_;
  Rng rng_;
  int step_ = 0, push_step_ = -1, restore_step_ = -1;
  std::vector<float> action_;
};

// The share of episodes whose outcome differs between two runs of the same episodes, with its
// Wilson 95% interval: {"flip_rate", "flip_ci95", "flips"}.
Json FlipRate(const std::vector<bool>& unperturbed, const std::vector<bool>& perturbed);

}  // namespace perch
