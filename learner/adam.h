// Adam over a flat float32 parameter vector, in TensorFlow's form (Baselines PPO2 used
// tf.train.AdamOptimizer): lr_t = lr * sqrt(1 - b2^t) / (1 - b1^t); p -= lr_t * m / (sqrt(v) +
// eps).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>

namespace perch {

namespace proto {
class AdamState;
}

class Adam {
 public:
  Adam() = default;
  Adam(int num_params, float beta1, float beta2, float eps);

  // One step; grad is not modified.
  void Step(Eigen::VectorXf& params, const Eigen::VectorXf& grad, float lr);
  // The same step in parts, for threads that own disjoint ranges of the parameters: BeginStep
  // once (counts the step, returns the bias-corrected rate), then ApplyRange over ranges that
  // cover [0, num_params) once each.
  float BeginStep(float lr);
  void ApplyRange(float* params, const float* grad, float lr_t, int begin, int end);

  int64_t step() const { return step_; }
  const Eigen::VectorXf& m() const { return m_; }
  const Eigen::VectorXf& v() const { return v_; }

  void ToProto(proto::AdamState* p) const;
  // ConfigError naming ctx when the sizes differ from num_params.
  void FromProto(const proto::AdamState& p, const std::string& ctx);

 private:
  float beta1_ = 0.9f, beta2_ = 0.999f, eps_ = 1e-5f;
  int64_t step_ = 0;
  Eigen::VectorXf m_, v_;
};

}  // namespace perch
