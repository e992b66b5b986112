// A multilayer perceptron over a flat float32 parameter vector, with batched forward/backward in
// Eigen. Batches are column-major [features x B]: B observations stored one after another (a
// row-major [B x features] array) map onto it without a copy.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "common/field_table.h"
#include "common/json_util.h"
#include "common/rng.h"

namespace perch {

using MatrixXf = Eigen::MatrixXf;  // column-major float32
using VectorXf = Eigen::VectorXf;

enum class Activation { kTanh, kRelu };

std::string ActivationName(Activation a);
Activation ParseActivation(const std::string& name, const std::string& ctx);  // ConfigError

// Hidden layers of one MLP. The paper: two hidden layers of 64, tanh (notes §8.1).
struct MlpConfig {
  std::vector<int> hidden = {64, 64};
  Activation activation = Activation::kTanh;
};
Json ToJson(const MlpConfig& c);
MlpConfig MlpConfigFromJson(const Json& j, const std::string& ctx);
const FieldTable<MlpConfig>& MlpConfigFields();  // each field written once (common/field_table.h)

// Activations of one batched forward pass, kept for the backward pass. Reused across calls:
// buffers are resized only when the batch size changes.
struct MlpCache {
  std::vector<MatrixXf> act;   // act[0] = input copy [in x B], act[l] = layer l output
  std::vector<MatrixXf> grad;  // backward scratch, one per layer output
  const MatrixXf& out() const { return act.back(); }
};

// Layout inside the parameter vector, layer by layer: W_l [out x in] column-major, then b_l [out].
// The last layer is linear; the others apply the activation.
class Mlp {
 public:
  Mlp() = default;
  Mlp(int in_dim, const MlpConfig& config, int out_dim);

  int in_dim() const { return sizes_.front(); }
  int out_dim() const { return sizes_.back(); }
  int num_layers() const { return static_cast<int>(sizes_.size()) - 1; }
  int num_params() const { return num_params_; }
  int max_width() const;
  const std::vector<int>& sizes() const { return sizes_; }  // [in, h1, ..., out]
  // Where layer l's W_l starts in this MLP's parameters (its b_l follows W_l).
  int weight_offset(int l) const { return w_offset_[l]; }

  // Orthogonal weights (as the authors: gain `hidden_gain` on hidden layers, `out_gain` on the
  // output rows [out_row_begin, out_row_end) ), zero biases. Call once per output block to give
  // heads their own orthogonal init; the hidden layers are initialised by the first call only
  // when init_hidden is true.
  void Init(float* params, Rng& rng, float hidden_gain, float out_gain, bool init_hidden = true,
            int out_row_begin = 0, int out_row_end = -1) const;

  // Batched forward: x [in_dim x B]. Result in cache->out() [out_dim x B].
  void Forward(const float* params, const Eigen::Ref<const MatrixXf>& x, MlpCache* cache) const;

  // Backward of the last Forward with this cache: grad_out = dL/d out [out_dim x B]. Adds dL/d
  // params into grad_params (same layout as params). Overwrites cache->grad. If grad_in is given,
  // writes dL/d x [in_dim x B].
  void Backward(const float* params, const Eigen::Ref<const MatrixXf>& grad_out, MlpCache* cache,
                float* grad_params, MatrixXf* grad_in = nullptr) const;

  // One input, no allocation: x [in_dim] -> out [out_dim]. scratch needs 2 * max_width() floats.
  void ForwardOne(const float* params, const float* x, float* out, float* scratch) const;

  // Net2WiderNet (Chen et al. 2016): writes into params (this MLP's layout, already initialised)
  // the function of `narrow` (same activation, depth, input and output sizes; no hidden layer
  // wider than ours): its weights and biases in the leading rows and columns, zero weights out of
  // the extra units. The extra units keep their initial incoming weights, so they start to learn
  // at once while the output stays what `narrow` computes. ConfigError naming ctx otherwise.
  void EmbedNarrower(const Mlp& narrow, const float* narrow_params, float* params,
                     const std::string& ctx) const;

 private:
  std::vector<int> sizes_;
  std::vector<int> w_offset_;  // per layer, into params
  std::vector<int> b_offset_;
  Activation activation_ = Activation::kTanh;
  int num_params_ = 0;
};

}  // namespace perch
