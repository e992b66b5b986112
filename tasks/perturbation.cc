#include "tasks/perturbation.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "tasks/task_eval.h"

namespace perch {

void AddGaussianNoise(float* x, int n, double std, Rng& rng) {
  for (int i = 0; i < n; ++i) x[i] += static_cast<float>(rng.Normal(0.0, std));
}

Json Perturbation::ToJson() const {
  return Json{{"push_n", push_n},
              {"push_s", push_s},
              {"obs_noise", obs_noise},
              {"act_noise", act_noise},
              {"restore", restore}};
}

PerturbedEnv::PerturbedEnv(HumanoidChairEnv* env, const Perturbation& p, int horizon_steps)
    : env_(env), p_(p), horizon_(std::max(1, horizon_steps)), action_(env->spec().act_dim) {}

void PerturbedEnv::Seed(uint64_t seed) {
  env_->Seed(seed);
  rng_.Seed(seed ^ kPerturbationRngSalt);
}

void PerturbedEnv::Reset(float* obs) {
  env_->Reset(obs);
  step_ = 0;
  push_step_ = p_.push_n > 0.0 ? static_cast<int>(rng_.UniformInt(horizon_)) : -1;
  restore_step_ = p_.restore ? static_cast<int>(rng_.UniformInt(horizon_)) : -1;
  AddObsNoise(obs);
}

StepResult PerturbedEnv::Step(const float* action, float* obs) {
  if (step_ == restore_step_) env_->SetState(env_->GetState());
  if (step_ == push_step_) {
    const double angle = rng_.Uniform(-M_PI, M_PI);
    const int steps = std::max(1, static_cast<int>(std::lround(p_.push_s / spec().control_dt)));
    env_->StartPush(p_.push_n * Eigen::Vector3d(std::cos(angle), std::sin(angle), 0.0), steps);
  }
  const float* a = action;
  if (p_.act_noise > 0.0) {
    std::copy(action, action + action_.size(), action_.begin());
    AddGaussianNoise(action_.data(), static_cast<int>(action_.size()), p_.act_noise, rng_);
    a = action_.data();
  }
  const StepResult r = env_->Step(a, obs);
  ++step_;
  AddObsNoise(obs);
  return r;
}

void PerturbedEnv::AddObsNoise(float* obs) {
  if (p_.obs_noise > 0.0) AddGaussianNoise(obs, spec().obs_dim, p_.obs_noise, rng_);
}

Json FlipRate(const std::vector<bool>& unperturbed, const std::vector<bool>& perturbed) {
  if (unperturbed.size() != perturbed.size()) {
    throw std::logic_error("flip rate: runs of different lengths");
  }
  int flips = 0;
  for (size_t i = 0; i < unperturbed.size(); ++i) flips += unperturbed[i] != perturbed[i];
  const int n = static_cast<int>(unperturbed.size());
  const auto ci = WilsonInterval95(flips, n);
  return Json{{"flip_rate", n > 0 ? static_cast<double>(flips) / n : 0.0},
              {"flip_ci95", {ci[0], ci[1]}},
              {"flips", flips}};
}

}  // namespace perch
