#include "policy/policy.h"

#include <algorithm>
#include <cmath>

#include "common/proto/model.pb.h"

namespace perch {

namespace {

constexpr float kLog2Pi = 1.8378770664093453f;  // log(2 pi)

std::string KindName(PolicyKind k) { return k == PolicyKind::kMeta ? "meta" : "gaussian"; }

// `field` names where the value came from, for the error.
PolicyKind ParseKind(const std::string& s, const std::string& field) {
  if (s == "gaussian") return PolicyKind::kGaussian;
  if (s == "meta") return PolicyKind::kMeta;
  throw ConfigError(field + ": unknown policy kind '" + s + "' (expected gaussian or meta)");
}
StdMode ParseStdMode(const std::string& s, const std::string& field) {
  if (s == "trained") return StdMode::kTrained;
  if (s == "fixed") return StdMode::kFixed;
  throw ConfigError(field + ": unknown '" + s + "' (expected trained or fixed)");
}

// Index of the largest entry (first on ties).
int ArgMax(const float* x, int n) { return static_cast<int>(std::max_element(x, x + n) - x); }

}  // namespace

std::string StdModeName(StdMode m) { return m == StdMode::kFixed ? "fixed" : "trained"; }

PolicyConfig PolicyConfig::Subtask(int obs_dim) {
  PolicyConfig c;
  c.obs_dim = obs_dim;
  return c;
}

PolicyConfig PolicyConfig::Meta(int obs_dim) {
  PolicyConfig c;
  c.kind = PolicyKind::kMeta;
  c.obs_dim = obs_dim;
  c.act_dim = 2;
  c.num_choices = 4;
  c.target_choice = 3;
  return c;
}

const FieldTable<PolicyConfig>& PolicyConfigFields() {
  using C = PolicyConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          // First: a meta policy starts from PolicyConfig::Meta()'s defaults.
          .CustomAlways(
              "kind", "gaussian (a subtask) or meta",
              [](const Json& j, C& c, const std::string& ctx) {
                std::string kind = KindName(c.kind);
                GetOptional(j, "kind", kind, ctx);
                if (ParseKind(kind, ctx + ".kind") == PolicyKind::kMeta) c = PolicyConfig::Meta();
              },
              [](const C& c, Json& j) { j["kind"] = KindName(c.kind); })
          .Add("obs_dim", &C::obs_dim, "observation size (set from the env)", Positive<int>())
          .Add("act_dim", &C::act_dim, "action size (meta: the 2-d walk target)", Positive<int>())
          .Add("num_choices", &C::num_choices, "meta: the switch's classes")
          .Add("target_choice", &C::target_choice, "meta: the class the target head drives")
          .Nested("policy_net", &C::policy_net, MlpConfigFields(), "the policy's hidden layers")
          .Nested("value_net", &C::value_net, MlpConfigFields(), "the critic's hidden layers")
          .CustomAlways(
              "std_mode", "trained (authors) or fixed (the paper's fixed covariance)",
              [](const Json& j, C& c, const std::string& ctx) {
                std::string std_mode = StdModeName(c.std_mode);
                GetOptional(j, "std_mode", std_mode, ctx);
                c.std_mode = ParseStdMode(std_mode, ctx + ".std_mode");
              },
              [](const C& c, Json& j) { j["std_mode"] = StdModeName(c.std_mode); })
          .Add("init_log_std", &C::init_log_std, "log sigma at start")
          .Add("hidden_gain", &C::hidden_gain, "orthogonal init gain, hidden layers")
          .Add("policy_out_gain", &C::policy_out_gain, "orthogonal init gain, mean and logits")
          .Add("value_out_gain", &C::value_out_gain, "orthogonal init gain, value")
          .Rule([](const C& c, const std::string& ctx) {
            if (c.kind != PolicyKind::kMeta) return std::string();
            // 1: the walk-only pre-training (notes 4.7), whose switch has one class.
            if (c.num_choices < 1) return ctx + ".num_choices: must be >= 1";
            if (c.target_choice < 0 || c.target_choice >= c.num_choices) {
              return ctx + ".target_choice: must be in [0, num_choices)";
            }
            return std::string();
          });
  return t;
}

Json ToJson(const PolicyConfig& c) { return PolicyConfigFields().Write(c); }

PolicyConfig PolicyConfigFromJson(const Json& j, const std::string& ctx) {
  return PolicyConfigFields().Read(j, ctx);
}

ActorCritic::ActorCritic(const PolicyConfig& config, uint64_t seed) : config_(config) {
  if (config.obs_dim <= 0 || config.act_dim <= 0) {
    throw ConfigError("policy: obs_dim and act_dim must be > 0");
  }
  const bool meta = config.kind == PolicyKind::kMeta;
  if (meta && (config.num_choices < 1 || config.target_choice < 0 ||
               config.target_choice >= config.num_choices)) {
    throw ConfigError("policy: meta needs num_choices >= 1 and target_choice in range");
  }
  if (!meta) config_.num_choices = 0, config_.target_choice = 0;
  const int head = meta ? config.num_choices + config.act_dim : config.act_dim;
  pi_ = Mlp(config.obs_dim, config.policy_net, head);
  vf_ = Mlp(config.obs_dim, config.value_net, 1);
  log_std_offset_ = pi_.num_params();
  value_offset_ = log_std_offset_ + config.act_dim;
  num_params_ = value_offset_ + vf_.num_params();
  params_ = VectorXf::Zero(num_params_);
  mask_ = VectorXf::Ones(num_params_);
  if (config.std_mode == StdMode::kFixed) mask_.segment(log_std_offset_, config.act_dim).setZero();

  Rng rng(seed);
  float* p = params_.data();
  if (meta) {
    // Separate orthogonal heads, as Baselines' separate dense layers.
    pi_.Init(p, rng, config.hidden_gain, config.policy_out_gain, true, 0, config.num_choices);
    pi_.Init(p, rng, config.hidden_gain, config.policy_out_gain, false, config.num_choices, head);
  } else {
    pi_.Init(p, rng, config.hidden_gain, config.policy_out_gain);
  }
  params_.segment(log_std_offset_, config.act_dim).setConstant(config.init_log_std);
  vf_.Init(p + value_offset_, rng, config.hidden_gain, config.value_out_gain);
}

void ActorCritic::Evaluate(const float* params, const Eigen::Ref<const MatrixXf>& obs,
                           const Eigen::Ref<const MatrixXf>& actions,
                           PolicyEvalCache* cache) const {
  EvaluatePolicy(params, obs, actions, cache);
  EvaluateValue(params, obs, cache);
}

void ActorCritic::EvaluatePolicy(const float* params, const Eigen::Ref<const MatrixXf>& obs,
                                 const Eigen::Ref<const MatrixXf>& actions,
                                 PolicyEvalCache* cache) const {
  const int k = config_.act_dim;
  const Eigen::Index batch = obs.cols();
  const bool meta = config_.kind == PolicyKind::kMeta;
  const int c = config_.num_choices;
  pi_.Forward(params, obs, &cache->pi);
  const MatrixXf& head = cache->pi.out();
  Eigen::Map<const VectorXf> log_std(params + log_std_offset_, k);
  const VectorXf inv_sigma = (-log_std.array()).exp().matrix();
  const float log_std_sum = log_std.sum();
  const float gauss_const = -log_std_sum - 0.5f * k * kLog2Pi;
  const float gauss_entropy = log_std_sum + 0.5f * k * (1.0f + kLog2Pi);

  const int mu_row = meta ? c : 0;
  const int a_row = meta ? 1 : 0;
  cache->z.resize(k, batch);
  cache->z.array() = (actions.middleRows(a_row, k) - head.middleRows(mu_row, k)).array().colwise() *
                     inv_sigma.array();
  cache->log_prob.resize(batch);
  cache->log_prob.noalias() = (-0.5f * cache->z.colwise().squaredNorm()).transpose();
  cache->log_prob.array() += gauss_const;
  cache->entropy.setConstant(batch, gauss_entropy);

  if (meta) {
    cache->probs.resize(c, batch);
    cache->choice.resize(batch);
    cache->gate.resize(batch);
    for (Eigen::Index b = 0; b < batch; ++b) {
      const float raw_choice = actions(0, b);
      const int ch = static_cast<int>(std::lround(raw_choice));
      if (!(ch >= 0 && ch < c)) {
        throw ConfigError("policy: meta action choice " + std::to_string(raw_choice) +
                          " out of range [0, " + std::to_string(c) + ")");
      }
      const float mx = head.col(b).head(c).maxCoeff();
      float sum = 0.0f;
      for (int j = 0; j < c; ++j) {
        const float e = std::exp(head(j, b) - mx);
        cache->probs(j, b) = e;
        sum += e;
      }
      const float log_sum = std::log(sum);
      float h = 0.0f;
      for (int j = 0; j < c; ++j) {
        cache->probs(j, b) /= sum;
        const float logp_j = head(j, b) - mx - log_sum;
        h -= cache->probs(j, b) * logp_j;
      }
      const float gate = ch == config_.target_choice ? 1.0f : 0.0f;
      cache->choice[b] = ch;
      cache->gate[b] = gate;
      cache->log_prob[b] = (head(ch, b) - mx - log_sum) + gate * cache->log_prob[b];
      cache->entropy[b] += h;
    }
  }
}

void ActorCritic::EvaluateValue(const float* params, const Eigen::Ref<const MatrixXf>& obs,
                                PolicyEvalCache* cache) const {
  vf_.Forward(params + value_offset_, obs, &cache->vf);
  cache->value = cache->vf.out().row(0).transpose();
}

void ActorCritic::Backward(const float* params, const Eigen::Ref<const VectorXf>& dlogp,
                           const Eigen::Ref<const VectorXf>& dent,
                           const Eigen::Ref<const VectorXf>& dval, PolicyEvalCache* cache,
                           float* grad_params) const {
  BackwardPolicy(params, dlogp, dent, cache, grad_params);
  BackwardValue(params, dval, cache, grad_params);
}

void ActorCritic::BackwardPolicy(const float* params, const Eigen::Ref<const VectorXf>& dlogp,
                                 const Eigen::Ref<const VectorXf>& dent, PolicyEvalCache* cache,
                                 float* grad_params) const {
  const int k = config_.act_dim;
  const Eigen::Index batch = dlogp.size();
  const bool meta = config_.kind == PolicyKind::kMeta;
  const int c = config_.num_choices;
  const int mu_row = meta ? c : 0;
  Eigen::Map<const VectorXf> log_std(params + log_std_offset_, k);
  const VectorXf inv_sigma = (-log_std.array()).exp().matrix();
  Eigen::Map<VectorXf> g_log_std(grad_params + log_std_offset_, k);

  cache->grad_head.resize(head_dim(), batch);
  // Gaussian part: d logp / d mu = z / sigma, d logp / d log_std = z^2 - 1, d H / d log_std = 1.
  VectorXf w = dlogp;
  if (meta) w.array() *= Eigen::Map<const VectorXf>(cache->gate.data(), batch).array();
  auto g_mu = cache->grad_head.middleRows(mu_row, k);
  g_mu.array() = cache->z.array().colwise() * inv_sigma.array();
  g_mu.array().rowwise() *= w.transpose().array();
  g_log_std.noalias() += (cache->z.array().square() - 1.0f).matrix() * w;
  g_log_std.array() += dent.sum();

  if (meta) {
    for (Eigen::Index b = 0; b < batch; ++b) {
      // H = -sum p log p; dH/dl_j = -p_j (log p_j + H).
      float h = 0.0f;
      for (int j = 0; j < c; ++j) {
        const float p = cache->probs(j, b);
        if (p > 0) h -= p * std::log(p);
      }
      for (int j = 0; j < c; ++j) {
        const float p = cache->probs(j, b);
        const float logp = p > 0 ? std::log(p) : 0.0f;
        const float onehot = j == cache->choice[b] ? 1.0f : 0.0f;
        cache->grad_head(j, b) = dlogp[b] * (onehot - p) - dent[b] * p * (logp + h);
      }
    }
  }
  pi_.Backward(params, cache->grad_head, &cache->pi, grad_params);
}

void ActorCritic::BackwardValue(const float* params, const Eigen::Ref<const VectorXf>& dval,
                                PolicyEvalCache* cache, float* grad_params) const {
  const Eigen::Index batch = dval.size();
  cache->grad_value.resize(1, batch);
  cache->grad_value.row(0) = dval.transpose();
  vf_.Backward(params + value_offset_, cache->grad_value, &cache->vf, grad_params + value_offset_);
}

void ActorCritic::GetShape(proto::PolicyShape* shape) const {
  shape->Clear();
  shape->set_kind(KindName(config_.kind));
  shape->set_obs_dim(config_.obs_dim);
  shape->set_act_dim(config_.act_dim);
  shape->set_num_choices(config_.num_choices);
  shape->set_target_choice(config_.target_choice);
  for (int h : config_.policy_net.hidden) shape->add_policy_hidden(h);
  for (int h : config_.value_net.hidden) shape->add_value_hidden(h);
  // Both nets share the activation field on the wire only when equal; else "policy/value".
  std::string act = ActivationName(config_.policy_net.activation);
  if (config_.value_net.activation != config_.policy_net.activation) {
    act += "/" + ActivationName(config_.value_net.activation);
  }
  shape->set_activation(act);
  shape->set_std_mode(StdModeName(config_.std_mode));
  shape->set_num_params(num_params_);
}

namespace {

std::string JoinInts(const google::protobuf::RepeatedField<int32_t>& v) {
  std::string s = "[";
  for (int i = 0; i < v.size(); ++i) s += (i ? "," : "") + std::to_string(v.Get(i));
  return s + "]";
}

}  // namespace

void ActorCritic::CheckShape(const proto::PolicyShape& blob, const std::string& ctx) const {
  proto::PolicyShape mine;
  GetShape(&mine);
  auto differs = [&](const std::string& field, const std::string& theirs, const std::string& ours) {
    if (theirs != ours) {
      throw ConfigError(ctx + ": network shape differs: " + field + " is " + theirs +
                        " in the blob, " + ours + " in this model");
    }
  };
  differs("kind", blob.kind(), mine.kind());
  differs("obs_dim", std::to_string(blob.obs_dim()), std::to_string(mine.obs_dim()));
  differs("act_dim", std::to_string(blob.act_dim()), std::to_string(mine.act_dim()));
  differs("num_choices", std::to_string(blob.num_choices()), std::to_string(mine.num_choices()));
  differs("target_choice", std::to_string(blob.target_choice()),
          std::to_string(mine.target_choice()));
  differs("policy_hidden", JoinInts(blob.policy_hidden()), JoinInts(mine.policy_hidden()));
  differs("value_hidden", JoinInts(blob.value_hidden()), JoinInts(mine.value_hidden()));
  differs("activation", blob.activation(), mine.activation());
  differs("std_mode", blob.std_mode(), mine.std_mode());
  differs("num_params", std::to_string(blob.num_params()), std::to_string(mine.num_params()));
}

PolicyConfig PolicyConfigFromShape(const proto::PolicyShape& s, const std::string& ctx) {
  PolicyConfig c;
  c.kind = ParseKind(s.kind(), ctx + ".shape.kind");
  c.obs_dim = s.obs_dim();
  c.act_dim = s.act_dim();
  c.num_choices = s.num_choices();
  c.target_choice = s.target_choice();
  c.policy_net.hidden.assign(s.policy_hidden().begin(), s.policy_hidden().end());
  c.value_net.hidden.assign(s.value_hidden().begin(), s.value_hidden().end());
  c.policy_net.activation = c.value_net.activation =
      ParseActivation(s.activation(), ctx + ".shape.activation");
  c.std_mode = ParseStdMode(s.std_mode(), ctx + ".shape.std_mode");
  return c;
}

namespace {

// A weights blob whose parameter vector does not fit the network its shape describes.
void CheckParamCount(const proto::ModelWeights& w, const ActorCritic& net, const std::string& ctx) {
  if (w.params_size() != net.num_params()) {
    throw ConfigError(ctx + ": params has " + std::to_string(w.params_size()) +
                      " values, its shape needs " + std::to_string(net.num_params()));
  }
}

}  // namespace

proto::ModelWeights WidenModelWeights(const proto::ModelWeights& narrow, const PolicyConfig& wide,
                                      uint64_t seed, const std::string& ctx) {
  const PolicyConfig nc = PolicyConfigFromShape(narrow.shape(), ctx);
  const ActorCritic small(nc, 0);
  CheckParamCount(narrow, small, ctx);
  ActorCritic big(wide, seed);
  // Everything but the hidden widths must agree.
  proto::PolicyShape a, b;
  small.GetShape(&a);
  big.GetShape(&b);
  for (proto::PolicyShape* s : {&a, &b}) {
    s->clear_policy_hidden();
    s->clear_value_hidden();
    s->clear_num_params();
  }
  if (a.SerializeAsString() != b.SerializeAsString()) {
    throw ConfigError(ctx + ": cannot widen: the networks differ in more than hidden widths (" +
                      a.ShortDebugString() + " vs " + b.ShortDebugString() + ")");
  }
  const float* np = narrow.params().data();
  float* p = big.params().data();
  big.policy_mlp().EmbedNarrower(small.policy_mlp(), np, p, ctx + ": policy");
  big.value_mlp().EmbedNarrower(small.value_mlp(), np + small.value_offset(),
                                p + big.value_offset(), ctx + ": value");
  std::copy(np + small.log_std_offset(), np + small.log_std_offset() + nc.act_dim,
            p + big.log_std_offset());
  proto::ModelWeights out = narrow;
  big.GetShape(out.mutable_shape());
  out.mutable_params()->Assign(big.params().data(), big.params().data() + big.num_params());
  return out;
}

namespace {

// The first layers of both networks re-sized to `obs_dim` inputs: the first min(old, new) input
// columns kept, new ones zero (W_0 [hidden x in] is column-major: input i is one column);
// normaliser statistics truncated, or extended with mean 0, var 1.
proto::ModelWeights ResizeInputs(const proto::ModelWeights& w, int obs_dim,
                                 const std::string& ctx) {
  const PolicyConfig src_c = PolicyConfigFromShape(w.shape(), ctx);
  const ActorCritic src(src_c, 0);
  CheckParamCount(w, src, ctx);
  PolicyConfig dst_c = src_c;
  dst_c.obs_dim = obs_dim;
  ActorCritic dst(dst_c, 0);
  const float* sp = w.params().data();
  float* dp = dst.params().data();
  const int keep = std::min(obs_dim, src_c.obs_dim);
  auto copy_mlp = [&](const Mlp& s_mlp, const float* s, float* d) {
    const int h = s_mlp.sizes()[1];
    std::copy(s, s + h * keep, d);
    std::fill(d + h * keep, d + h * obs_dim, 0.0f);
    const int rest = s_mlp.num_params() - h * src_c.obs_dim;
    std::copy(s + h * src_c.obs_dim, s + h * src_c.obs_dim + rest, d + h * obs_dim);
  };
  copy_mlp(src.policy_mlp(), sp, dp);
  copy_mlp(src.value_mlp(), sp + src.value_offset(), dp + dst.value_offset());
  std::copy(sp + src.log_std_offset(), sp + src.log_std_offset() + src_c.act_dim,
            dp + dst.log_std_offset());
  proto::ModelWeights out = w;
  dst.GetShape(out.mutable_shape());
  out.mutable_params()->Assign(dst.params().data(), dst.params().data() + dst.num_params());
  if (w.obs_stats().mean_size() == src_c.obs_dim && w.obs_stats().var_size() == src_c.obs_dim) {
    proto::RunningStats* st = out.mutable_obs_stats();
    st->mutable_mean()->Truncate(keep);
    st->mutable_var()->Truncate(keep);
    for (int i = keep; i < obs_dim; ++i) {
      st->add_mean(0.0);
      st->add_var(1.0);
    }
  }
  return out;
}

}  // namespace

proto::ModelWeights DropTrailingInputs(const proto::ModelWeights& w, int obs_dim,
                                       const std::string& ctx) {
  const int have = w.shape().obs_dim();
  if (obs_dim < 1 || obs_dim >= have) {
    throw ConfigError(ctx + ": cannot map " + std::to_string(have) + " inputs onto " +
                      std::to_string(obs_dim) + " (only dropping trailing inputs is supported)");
  }
  return ResizeInputs(w, obs_dim, ctx);
}

proto::ModelWeights AppendZeroInputs(const proto::ModelWeights& w, int obs_dim,
                                     const std::string& ctx) {
  const int have = w.shape().obs_dim();
  if (obs_dim <= have) {
    throw ConfigError(ctx + ": cannot append inputs to go from " + std::to_string(have) + " to " +
                      std::to_string(obs_dim));
  }
  return ResizeInputs(w, obs_dim, ctx);
}

proto::ModelWeights WidenMetaChoices(const proto::ModelWeights& w, const PolicyConfig& mine,
                                     uint64_t seed, const std::string& ctx) {
  const PolicyConfig src_c = PolicyConfigFromShape(w.shape(), ctx);
  if (src_c.kind != PolicyKind::kMeta || mine.kind != PolicyKind::kMeta ||
      src_c.num_choices >= mine.num_choices) {
    throw ConfigError(ctx + ": only a meta policy with fewer switch classes can start this one");
  }
  PolicyConfig same = mine;  // the source as it would be with this run's classes
  same.num_choices = src_c.num_choices;
  same.target_choice = src_c.target_choice;
  if (ToJson(same) != ToJson(src_c)) {
    throw ConfigError(ctx +
                      ": differs from this run's meta policy in more than its switch classes");
  }
  const ActorCritic src(src_c, 0);
  CheckParamCount(w, src, ctx);
  ActorCritic dst(mine, seed);  // fresh switch head
  const float* sp = w.params().data();
  float* dp = dst.params().data();
  const std::vector<int>& sizes = src.policy_mlp().sizes();
  // Hidden layers: identical shapes, one contiguous block before the output layer.
  const int hidden_params = src.policy_mlp().weight_offset(src.policy_mlp().num_layers() - 1);
  std::copy(sp, sp + hidden_params, dp);
  // Output layer W [head x h] column-major, then b [head]: the target rows follow the logits.
  const int h = sizes[sizes.size() - 2];
  const int sh = src.head_dim(), dh = dst.head_dim(), k = mine.act_dim;
  const int sc = src_c.num_choices, dc = mine.num_choices;
  for (int col = 0; col < h; ++col) {
    for (int r = 0; r < k; ++r) {
      dp[hidden_params + col * dh + dc + r] = sp[hidden_params + col * sh + sc + r];
    }
  }
  for (int r = 0; r < k; ++r)
    dp[hidden_params + h * dh + dc + r] = sp[hidden_params + h * sh + sc + r];
  std::copy(sp + src.log_std_offset(), sp + src.log_std_offset() + k, dp + dst.log_std_offset());
  std::copy(sp + src.value_offset(), sp + src.num_params(), dp + dst.value_offset());
  proto::ModelWeights out = w;
  dst.GetShape(out.mutable_shape());
  out.mutable_params()->Assign(dst.params().data(), dst.params().data() + dst.num_params());
  return out;
}

proto::ModelWeights MirrorModelWeights(const proto::ModelWeights& w, const MirrorMap& m,
                                       const std::string& ctx) {
  const PolicyConfig c = PolicyConfigFromShape(w.shape(), ctx);
  if (c.kind != PolicyKind::kGaussian) {
    throw ConfigError(ctx + ": only a Gaussian (subtask) policy can be mirrored");
  }
  const ActorCritic net(c, 0);
  CheckParamCount(w, net, ctx);
  auto check = [&](const std::vector<int>& src, const std::vector<float>& scale,
                   const std::vector<float>& offset, int n, const char* what) {
    if (static_cast<int>(src.size()) != n || static_cast<int>(scale.size()) != n ||
        static_cast<int>(offset.size()) != n) {
      throw ConfigError(ctx + ": the env's mirror map has " + std::to_string(src.size()) + " " +
                        what + " entries, the policy " + std::to_string(n));
    }
    std::vector<bool> used(n, false);
    for (int i = 0; i < n; ++i) {
      if (src[i] < 0 || src[i] >= n || used[src[i]] || scale[i] == 0.0f) {
        throw ConfigError(ctx + ": the env's mirror map of " + what +
                          " is not a signed permutation at " + std::to_string(i));
      }
      used[src[i]] = true;
    }
  };
  const int od = c.obs_dim, ad = c.act_dim;
  if (m.empty()) throw ConfigError(ctx + ": the env has no mirror map");
  check(m.obs_src, m.obs_scale, m.obs_offset, od, "observation");
  check(m.act_src, m.act_scale, m.act_offset, ad, "action");
  const float* sp = w.params().data();
  std::vector<float> dp(sp, sp + net.num_params());
  // First layers: the original reads x_i = a_i o_p(i) + b_i; normalised, that is
  // sign(a_i) (o_p(i) - mean'_p(i)) / std'_p(i), so column i moves to p(i) with sign(a_i).
  auto mirror_inputs = [&](const Mlp& mlp, int off) {
    const int h = mlp.sizes()[1];
    for (int i = 0; i < od; ++i) {
      const float sg = m.obs_scale[i] > 0 ? 1.0f : -1.0f;
      for (int r = 0; r < h; ++r) dp[off + m.obs_src[i] * h + r] = sg * sp[off + i * h + r];
    }
  };
  mirror_inputs(net.policy_mlp(), 0);
  mirror_inputs(net.value_mlp(), net.value_offset());
  // Mean head (the last layer, linear): row k = s_k row q(k), bias s_k b_q(k) + t_k.
  const std::vector<int>& sizes = net.policy_mlp().sizes();
  const int h = sizes[sizes.size() - 2];
  const int last = net.policy_mlp().weight_offset(net.policy_mlp().num_layers() - 1);
  for (int k = 0; k < ad; ++k) {
    const int q = m.act_src[k];
    const float sk = m.act_scale[k];
    for (int col = 0; col < h; ++col) dp[last + col * ad + k] = sk * sp[last + col * ad + q];
    dp[last + h * ad + k] = sk * sp[last + h * ad + q] + m.act_offset[k];
    dp[net.log_std_offset() + k] = sp[net.log_std_offset() + q] + std::log(std::abs(sk));
  }
  proto::ModelWeights out = w;
  out.mutable_params()->Assign(dp.begin(), dp.end());
  if (w.obs_stats().mean_size() == od && w.obs_stats().var_size() == od) {
    const double eps = w.obs_eps();
    proto::RunningStats* st = out.mutable_obs_stats();
    for (int i = 0; i < od; ++i) {
      const double a = m.obs_scale[i];
      st->set_mean(m.obs_src[i], (w.obs_stats().mean(i) - m.obs_offset[i]) / a);
      // (var' + eps) = (var + eps) / a^2: the same standard deviation in the normaliser.
      st->set_var(m.obs_src[i], std::max(0.0, (w.obs_stats().var(i) + eps) / (a * a) - eps));
    }
  }
  return out;
}

proto::ModelWeights ConvertStdMode(const proto::ModelWeights& w, const PolicyConfig& mine,
                                   const std::string& ctx) {
  proto::ModelWeights out = w;
  out.mutable_shape()->set_std_mode(StdModeName(mine.std_mode));
  if (mine.std_mode != StdMode::kFixed) return out;
  const ActorCritic src(PolicyConfigFromShape(w.shape(), ctx), 0);
  CheckParamCount(w, src, ctx);
  for (int i = 0; i < src.act_dim(); ++i) {
    out.set_params(src.log_std_offset() + i, mine.init_log_std);
  }
  return out;
}

PolicyRunner::PolicyRunner(const PolicyConfig& config, const NormalizerConfig& norm_config)
    : model_(config, 0),
      normalizer_(config.obs_dim, norm_config),
      delta_(config.obs_dim, 0.0),
      norm_(config.obs_dim),
      head_(model_.head_dim()),
      scratch_(2 * std::max(model_.policy_mlp().max_width(), model_.value_mlp().max_width())) {}

void PolicyRunner::SetWeights(const VectorXf& params, const RunningMeanStd& obs_stats,
                              uint64_t version) {
  if (params.size() != model_.num_params()) {
    throw ConfigError("PolicyRunner::SetWeights: " + std::to_string(params.size()) +
                      " parameters, model has " + std::to_string(model_.num_params()));
  }
  if (obs_stats.dim() != model_.obs_dim()) {
    throw ConfigError("PolicyRunner::SetWeights: obs stats dimension " +
                      std::to_string(obs_stats.dim()) + ", model has " +
                      std::to_string(model_.obs_dim()));
  }
  model_.params() = params;
  normalizer_.stats() = obs_stats;
  normalizer_.Refresh();
  version_ = version;
}

void PolicyRunner::LoadWeights(const proto::ModelWeights& w) {
  const std::string ctx = "model weights v" + std::to_string(w.version());
  model_.CheckShape(w.shape(), ctx);
  if (w.params_size() != model_.num_params()) {
    throw ConfigError(ctx + ": params has " + std::to_string(w.params_size()) +
                      " values, shape says " + std::to_string(model_.num_params()));
  }
  RunningMeanStd stats =
      RunningMeanStd::FromProto(w.obs_stats(), model_.obs_dim(), ctx + ".obs_stats");
  VectorXf p = Eigen::Map<const VectorXf>(w.params().data(), w.params_size());
  if (!p.allFinite()) throw ConfigError(ctx + ": params contain NaN/Inf");
  SetWeights(p, stats, w.version());
  // The learner's transform settings win over the runner's own.
  NormalizerConfig nc = normalizer_.config();
  nc.normalize_obs = w.normalize_obs();
  if (w.obs_clip() > 0) nc.obs_clip = w.obs_clip();
  if (w.obs_eps() >= 0) nc.obs_eps = w.obs_eps();
  normalizer_.set_config(nc);
}

void PolicyRunner::ClearObsStatsDelta() { delta_.Reset(0.0); }

PolicyRunner::Output PolicyRunner::Act(const float* raw_obs, Rng& rng, bool deterministic,
                                       float* norm_obs, float* action) {
  if (update_obs_stats_ && normalizer_.config().normalize_obs) {
    normalizer_.stats().Update(raw_obs);
    normalizer_.Refresh();
    delta_.Update(raw_obs);
  }
  normalizer_.Normalize(raw_obs, norm_.data());
  if (norm_obs != nullptr) std::copy(norm_.begin(), norm_.end(), norm_obs);
  const PolicyConfig& cfg = model_.config();
  const float* p = model_.params().data();
  model_.policy_mlp().ForwardOne(p, norm_.data(), head_.data(), scratch_.data());

  const int k = cfg.act_dim;
  const float* log_std = p + model_.log_std_offset();
  const bool meta = cfg.kind == PolicyKind::kMeta;
  const float* mu = head_.data() + (meta ? cfg.num_choices : 0);
  float* target = action + (meta ? 1 : 0);
  float gauss_logp = 0.0f;
  for (int i = 0; i < k; ++i) {
    const float z = deterministic ? 0.0f : static_cast<float>(rng.Normal());
    target[i] = mu[i] + std::exp(log_std[i]) * z;
    gauss_logp += -0.5f * z * z - log_std[i];
  }
  gauss_logp -= 0.5f * k * kLog2Pi;

  Output out;
  if (meta) {
    const int c = cfg.num_choices;
    const float mx = *std::max_element(head_.data(), head_.data() + c);
    float sum = 0.0f;
    for (int j = 0; j < c; ++j) sum += std::exp(head_[j] - mx);
    int ch = c - 1;
    if (deterministic) {
      ch = ArgMax(head_.data(), c);
    } else {
      const double u = rng.Uniform() * sum;
      double acc = 0.0;
      for (int j = 0; j < c; ++j) {
        acc += std::exp(head_[j] - mx);
        if (u < acc) {
          ch = j;
          break;
        }
      }
    }
    action[0] = static_cast<float>(ch);
    out.log_prob = head_[ch] - mx - std::log(sum) + (ch == cfg.target_choice ? gauss_logp : 0.0f);
  } else {
    out.log_prob = gauss_logp;
  }
  float v = 0.0f;
  model_.value_mlp().ForwardOne(p + model_.value_offset(), norm_.data(), &v, scratch_.data());
  out.value = v;
  return out;
}

float PolicyRunner::Value(const float* raw_obs) {
  normalizer_.Normalize(raw_obs, norm_.data());
  float v = 0.0f;
  model_.value_mlp().ForwardOne(model_.params().data() + model_.value_offset(), norm_.data(), &v,
                                scratch_.data());
  return v;
}

}  // namespace perch
