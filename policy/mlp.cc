#include "policy/mlp.h"

#include <Eigen/QR>
#include <algorithm>
#include <cmath>

#include "policy/dense_kernels.h"

namespace perch {

std::string ActivationName(Activation a) { return a == Activation::kTanh ? "tanh" : "relu"; }

Activation ParseActivation(const std::string& name, const std::string& ctx) {
  if (name == "tanh") return Activation::kTanh;
  if (name == "relu") return Activation::kRelu;
  throw ConfigError(ctx + ": unknown activation '" + name + "' (expected tanh or relu)");
}

const FieldTable<MlpConfig>& MlpConfigFields() {
  using C = MlpConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("hidden", &C::hidden, "hidden layer widths",
               FieldRule<std::vector<int>>{[](const std::vector<int>& v) {
                                             for (int h : v) {
                                               if (h <= 0) return false;
                                             }
                                             return true;
                                           },
                                           "widths must be positive",
                                           [](const std::vector<int>& v) {
                                             for (int h : v) {
                                               if (h <= 0)
                                                 return "widths must be positive, got " +
                                                        std::to_string(h);
                                             }
                                             return std::string();
                                           }})
          .CustomAlways(
              "activation", "tanh or relu",
              [](const Json& j, C& c, const std::string& ctx) {
                std::string act = ActivationName(c.activation);
                GetOptional(j, "activation", act, ctx);
                c.activation = ParseActivation(act, ctx + ".activation");
              },
              [](const C& c, Json& j) { j["activation"] = ActivationName(c.activation); });
  return t;
}

Json ToJson(const MlpConfig& c) { return MlpConfigFields().Write(c); }

MlpConfig MlpConfigFromJson(const Json& j, const std::string& ctx) {
  return MlpConfigFields().Read(j, ctx);
}

Mlp::Mlp(int in_dim, const MlpConfig& config, int out_dim) : activation_(config.activation) {
  sizes_.push_back(in_dim);
  for (int h : config.hidden) sizes_.push_back(h);
  sizes_.push_back(out_dim);
  int off = 0;
  for (int l = 0; l < num_layers(); ++l) {
    w_offset_.push_back(off);
    off += sizes_[l + 1] * sizes_[l];
    b_offset_.push_back(off);
    off += sizes_[l + 1];
  }
  num_params_ = off;
}

void Mlp::EmbedNarrower(const Mlp& narrow, const float* narrow_params, float* params,
                        const std::string& ctx) const {
  auto sizes = [](const std::vector<int>& v) {
    std::string s;
    for (int x : v) s += (s.empty() ? "" : "-") + std::to_string(x);
    return s;
  };
  bool fits = narrow.activation_ == activation_ && narrow.sizes_.size() == sizes_.size() &&
              narrow.in_dim() == in_dim() && narrow.out_dim() == out_dim();
  for (size_t i = 0; fits && i < sizes_.size(); ++i) fits = narrow.sizes_[i] <= sizes_[i];
  if (!fits) {
    throw ConfigError(ctx + ": cannot widen a " + sizes(narrow.sizes_) + " " +
                      ActivationName(narrow.activation_) + " MLP into " + sizes(sizes_) + " " +
                      ActivationName(activation_) +
                      " (same activation, depth, input and output needed, no layer narrower)");
  }
  for (int l = 0; l < num_layers(); ++l) {
    const int n_out = narrow.sizes_[l + 1], n_in = narrow.sizes_[l];
    Eigen::Map<MatrixXf> w(params + w_offset_[l], sizes_[l + 1], sizes_[l]);
    Eigen::Map<const MatrixXf> nw(narrow_params + narrow.w_offset_[l], n_out, n_in);
    w.topLeftCorner(n_out, n_in) = nw;
    w.topRightCorner(n_out, sizes_[l] - n_in).setZero();  // from the extra units below
    Eigen::Map<VectorXf>(params + b_offset_[l], n_out) =
        Eigen::Map<const VectorXf>(narrow_params + narrow.b_offset_[l], n_out);
  }
}

int Mlp::max_width() const { return *std::max_element(sizes_.begin(), sizes_.end()); }

namespace {

// rows x cols matrix with orthonormal rows (rows <= cols) or columns, times gain: the QR of a
// Gaussian matrix with the sign fix that makes it uniformly distributed (Baselines uses the SVD,
// which has the same distribution).
Eigen::MatrixXd Orthogonal(int rows, int cols, float gain, Rng& rng) {
  const bool tall = rows >= cols;
  const int n = tall ? rows : cols, k = tall ? cols : rows;
  Eigen::MatrixXd a(n, k);
  for (int j = 0; j < k; ++j)
    for (int i = 0; i < n; ++i) a(i, j) = rng.Normal();
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(a);
  Eigen::MatrixXd q = qr.householderQ() * Eigen::MatrixXd::Identity(n, k);
  const Eigen::MatrixXd r = qr.matrixQR();
  for (int j = 0; j < k; ++j) {
    if (r(j, j) < 0) q.col(j) *= -1.0;
  }
  q *= gain;
  if (tall) return q;
  return q.transpose();
}

DenseAct DenseActOf(Activation a) {
  return a == Activation::kTanh ? DenseAct::kTanh : DenseAct::kRelu;
}

}  // namespace

void Mlp::Init(float* params, Rng& rng, float hidden_gain, float out_gain, bool init_hidden,
               int out_row_begin, int out_row_end) const {
  const int last = num_layers() - 1;
  if (init_hidden) {
    for (int l = 0; l < last; ++l) {
      Eigen::Map<MatrixXf> w(params + w_offset_[l], sizes_[l + 1], sizes_[l]);
      w = Orthogonal(sizes_[l + 1], sizes_[l], hidden_gain, rng).cast<float>();
      Eigen::Map<VectorXf>(params + b_offset_[l], sizes_[l + 1]).setZero();
    }
  }
  if (out_row_end < 0) out_row_end = out_dim();
  const int rows = out_row_end - out_row_begin;
  if (rows <= 0) return;
  Eigen::Map<MatrixXf> w(params + w_offset_[last], sizes_[last + 1], sizes_[last]);
  w.middleRows(out_row_begin, rows) = Orthogonal(rows, sizes_[last], out_gain, rng).cast<float>();
  Eigen::Map<VectorXf>(params + b_offset_[last], sizes_[last + 1])
      .segment(out_row_begin, rows)
      .setZero();
}

void Mlp::Forward(const float* params, const Eigen::Ref<const MatrixXf>& x, MlpCache* cache) const {
  const int n_layers = num_layers();
  const Eigen::Index batch = x.cols();
  const DenseKernels& k = ActiveDenseKernels();
  cache->act.resize(n_layers + 1);
  cache->act[0] = x;
  for (int l = 0; l < n_layers; ++l) {
    MatrixXf& out = cache->act[l + 1];
    out.resize(sizes_[l + 1], batch);
    k.forward(params + w_offset_[l], params + b_offset_[l], sizes_[l + 1], sizes_[l],
              cache->act[l].data(), static_cast<int>(batch), out.data(),
              l + 1 < n_layers ? DenseActOf(activation_) : DenseAct::kNone);
  }
}

void Mlp::Backward(const float* params, const Eigen::Ref<const MatrixXf>& grad_out, MlpCache* cache,
                   float* grad_params, MatrixXf* grad_in) const {
  const int n_layers = num_layers();
  const DenseKernels& k = ActiveDenseKernels();
  cache->grad.resize(n_layers);
  cache->grad[n_layers - 1] = grad_out;
  for (int l = n_layers - 1; l >= 0; --l) {
    const MatrixXf& g = cache->grad[l];  // dL/d(pre-activation of layer l) [out x B]
    const MatrixXf& in = cache->act[l];
    const int batch = static_cast<int>(g.cols());
    float* gin = nullptr;
    if (l > 0) {
      cache->grad[l - 1].resize(sizes_[l], batch);
      gin = cache->grad[l - 1].data();
    } else if (grad_in != nullptr) {
      grad_in->resize(sizes_[0], batch);
      gin = grad_in->data();
    }
    k.backward(params + w_offset_[l], sizes_[l + 1], sizes_[l], in.data(), batch, g.data(),
               grad_params + w_offset_[l], grad_params + b_offset_[l], gin,
               l > 0 ? DenseActOf(activation_) : DenseAct::kNone);
  }
}

void Mlp::ForwardOne(const float* params, const float* x, float* out, float* scratch) const {
  const int n_layers = num_layers();
  const int width = max_width();
  const float* in = x;
  for (int l = 0; l < n_layers; ++l) {
    Eigen::Map<const MatrixXf> w(params + w_offset_[l], sizes_[l + 1], sizes_[l]);
    Eigen::Map<const VectorXf> b(params + b_offset_[l], sizes_[l + 1]);
    Eigen::Map<const VectorXf> vin(in, sizes_[l]);
    float* dst = (l + 1 == n_layers) ? out : scratch + (l % 2) * width;
    Eigen::Map<VectorXf> vout(dst, sizes_[l + 1]);
    vout.noalias() = w * vin;
    vout += b;
    if (l + 1 < n_layers) {
      if (activation_ == Activation::kTanh) {
        vout.array() = vout.array().tanh();
      } else {
        vout.array() = vout.array().max(0.0f);
      }
    }
    in = dst;
  }
}

}  // namespace perch
