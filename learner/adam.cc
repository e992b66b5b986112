#include "learner/adam.h"

#include <cmath>

#include "common/json_util.h"
#include "common/proto/model.pb.h"

namespace perch {

Adam::Adam(int num_params, float beta1, float beta2, float eps)
    : beta1_(beta1),
      beta2_(beta2),
      eps_(eps),
      m_(Eigen::VectorXf::Zero(num_params)),
      v_(Eigen::VectorXf::Zero(num_params)) {}

void Adam::Step(Eigen::VectorXf& params, const Eigen::VectorXf& grad, float lr) {
  ++step_;
  const double t = static_cast<double>(step_);
  const float lr_t =
      static_cast<float>(lr * std::sqrt(1.0 - std::pow(beta2_, t)) / (1.0 - std::pow(beta1_, t)));
  m_ = beta1_ * m_ + (1.0f - beta1_) * grad;
  v_ = beta2_ * v_ + (1.0f - beta2_) * grad.cwiseAbs2();
  params.array() -= lr_t * m_.array() / (v_.array().sqrt() + eps_);
}

float Adam::BeginStep(float lr) {
  ++step_;
  const double t = static_cast<double>(step_);
  return static_cast<float>(lr * std::sqrt(1.0 - std::pow(beta2_, t)) / (1.0 - std::pow(beta1_, t)));
}

void Adam::ApplyRange(float* params, const float* grad, float lr_t, int begin, int end) {
  const int n = end - begin;
  Eigen::Map<Eigen::VectorXf> p(params + begin, n);
  Eigen::Map<const Eigen::VectorXf> g(grad + begin, n);
  auto m = m_.segment(begin, n);
  auto v = v_.segment(begin, n);
  m = beta1_ * m + (1.0f - beta1_) * g;
  v = beta2_ * v + (1.0f - beta2_) * g.cwiseAbs2();
  p.array() -= lr_t * m.array() / (v.array().sqrt() + eps_);
}

void Adam::ToProto(proto::AdamState* p) const {
  p->set_step(step_);
  p->mutable_m()->Assign(m_.data(), m_.data() + m_.size());
  p->mutable_v()->Assign(v_.data(), v_.data() + v_.size());
}

void Adam::FromProto(const proto::AdamState& p, const std::string& ctx) {
  if (p.m_size() != m_.size() || p.v_size() != v_.size()) {
    throw ConfigError(ctx + ": optimizer state has " + std::to_string(p.m_size()) + "/" +
                      std::to_string(p.v_size()) + " moments, model has " +
                      std::to_string(m_.size()) + " parameters");
  }
  if (p.step() < 0) throw ConfigError(ctx + ".step: negative");
  Eigen::VectorXf m = Eigen::Map<const Eigen::VectorXf>(p.m().data(), p.m_size());
  Eigen::VectorXf v = Eigen::Map<const Eigen::VectorXf>(p.v().data(), p.v_size());
  if (!m.allFinite() || !v.allFinite() || (v.array() < 0).any()) {
    throw ConfigError(ctx + ": optimizer moments contain NaN/Inf or negative variances");
  }
  m_ = m;
  v_ = v;
  step_ = p.step();
}

}  // namespace perch
