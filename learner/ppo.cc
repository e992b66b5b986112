#include "learner/ppo.h"

#include <algorithm>
#include <cmath>

#include "common/proto/model.pb.h"

namespace perch {

namespace {
// A minibatch is split across threads only into parts at least this big: smaller ones cost more
// in hand-off than they save.
constexpr int kMinShardSamples = 16;
// V-trace: log pi/mu is capped here before exp, so that the ratio statistics stay finite.
constexpr float kMaxLogRatio = 20.0f;
}  // namespace

Json ToJson(const UpdateStats& s) {
  return Json{{"num_samples", s.num_samples},
              {"num_minibatch_steps", s.num_minibatch_steps},
              {"policy_loss", s.policy_loss},
              {"value_loss", s.value_loss},
              {"entropy", s.entropy},
              {"approx_kl", s.approx_kl},
              {"clip_fraction", s.clip_fraction},
              {"grad_norm", s.grad_norm},
              {"explained_variance", s.explained_variance},
              {"mean_reward", s.mean_reward},
              {"mean_scaled_reward", s.mean_scaled_reward},
              {"mean_advantage", s.mean_advantage},
              {"mean_return", s.mean_return},
              {"log_std_mean", s.log_std_mean},
              {"lagged_samples", s.lagged_samples},
              {"vtrace_ratio_mean", s.vtrace_ratio_mean},
              {"vtrace_rho_clipped", s.vtrace_rho_clipped}};
}

PpoLossTerms PpoLossFromEval(const PpoConfig& cfg, const Eigen::Ref<const VectorXf>& old_logp,
                             const Eigen::Ref<const VectorXf>& old_value,
                             const Eigen::Ref<const VectorXf>& adv,
                             const Eigen::Ref<const VectorXf>& ret, PpoLossWorkspace* ws,
                             int mean_over) {
  const int b = static_cast<int>(adv.size());
  const PolicyEvalCache& ev = ws->eval;
  ws->dlogp.resize(b);
  ws->dent.resize(b);
  ws->dval.resize(b);
  const float inv_b = 1.0f / (mean_over > 0 ? mean_over : b);
  const float clip = cfg.clip_range;
  const float vclip = cfg.value_clip_range;
  double pg = 0, vf = 0, kl = 0, cf = 0;
  for (int k = 0; k < b; ++k) {
    const float log_ratio = ev.log_prob[k] - old_logp[k];
    const float ratio = std::exp(log_ratio);
    const float a = adv[k];
    const float pg1 = -a * ratio;
    const float pg2 = -a * std::clamp(ratio, 1.0f - clip, 1.0f + clip);
    // The max's gradient: the unclipped term, or the clipped one (zero outside the range).
    const bool inside = ratio > 1.0f - clip && ratio < 1.0f + clip;
    ws->dlogp[k] = (pg1 >= pg2 || inside) ? -a * ratio * inv_b : 0.0f;
    pg += std::max(pg1, pg2);
    kl += 0.5 * log_ratio * log_ratio;
    cf += std::abs(ratio - 1.0f) > clip ? 1.0 : 0.0;

    const float v = ev.value[k];
    const float r = ret[k];
    float dv;
    if (cfg.clip_value) {
      const float dv_old = v - old_value[k];
      const float vc = old_value[k] + std::clamp(dv_old, -vclip, vclip);
      const float e1 = (v - r) * (v - r);
      const float e2 = (vc - r) * (vc - r);
      const bool v_inside = dv_old > -vclip && dv_old < vclip;
      dv = (e1 >= e2) ? v - r : (v_inside ? vc - r : 0.0f);
      vf += 0.5 * std::max(e1, e2);
    } else {
      dv = v - r;
      vf += 0.5 * (v - r) * (v - r);
    }
    ws->dval[k] = cfg.value_coef * dv * inv_b;
    ws->dent[k] = -cfg.entropy_coef * inv_b;
  }
  PpoLossTerms t;
  t.policy_loss = pg * inv_b;
  t.value_loss = vf * inv_b;
  t.entropy =
      mean_over > 0 ? ev.entropy.cast<double>().sum() * inv_b : ev.entropy.cast<double>().mean();
  t.approx_kl = kl * inv_b;
  t.clip_fraction = cf * inv_b;
  t.total = t.policy_loss - cfg.entropy_coef * t.entropy + cfg.value_coef * t.value_loss;
  return t;
}

PpoLossTerms PpoLoss(const ActorCritic& model, const float* params, const PpoConfig& cfg,
                     const Eigen::Ref<const MatrixXf>& obs,
                     const Eigen::Ref<const MatrixXf>& actions,
                     const Eigen::Ref<const VectorXf>& old_logp,
                     const Eigen::Ref<const VectorXf>& old_value,
                     const Eigen::Ref<const VectorXf>& adv, const Eigen::Ref<const VectorXf>& ret,
                     PpoLossWorkspace* ws, float* grad, int mean_over) {
  model.Evaluate(params, obs, actions, &ws->eval);
  const PpoLossTerms t = PpoLossFromEval(cfg, old_logp, old_value, adv, ret, ws, mean_over);
  if (grad != nullptr) model.Backward(params, ws->dlogp, ws->dent, ws->dval, &ws->eval, grad);
  return t;
}

PpoLearner::PpoLearner(const PolicyConfig& policy, const PpoConfig& ppo, uint64_t seed)
    : policy_config_(policy),
      ppo_(ppo),
      model_(policy, seed),
      obs_norm_(policy.obs_dim, ppo.obs_norm),
      reward_scaler_(ppo.reward_scaling, ppo.gamma),
      adam_(model_.num_params(), ppo.adam_beta1, ppo.adam_beta2, ppo.adam_eps),
      // A stream of its own so that shuffling does not depend on the init draws.
      rng_(seed ^ 0x5bd1e995a4f3c2e1ULL),
      grad_(VectorXf::Zero(model_.num_params())) {}

void PpoLearner::AddObsStats(const RunningMeanStd& delta) {
  if (delta.count() <= 0) return;
  obs_norm_.stats().Merge(delta);
  obs_norm_.Refresh();
}

void PpoLearner::SeedShuffle(uint64_t seed, int rank) {
  rng_ = Rng(seed ^ 0x5bd1e995a4f3c2e1ULL ^ (0x9e3779b97f4a7c15ULL * static_cast<uint64_t>(rank)));
}

std::vector<int> PpoLearner::CheckBatch(const std::vector<Rollout>& rollouts) const {
  const int obs_dim = model_.obs_dim();
  const int act_size = model_.action_size();
  int n = 0;
  std::string refused;
  try {
    for (size_t i = 0; i < rollouts.size(); ++i) {
      const std::string ctx = "rollout[" + std::to_string(i) + "]";
      const Rollout& r = rollouts[i];
      r.Validate(ctx);
      if (r.obs_dim != obs_dim || r.action_size != act_size) {
        throw ConfigError(ctx + ": obs_dim/action_size " + std::to_string(r.obs_dim) + "/" +
                          std::to_string(r.action_size) + ", model has " + std::to_string(obs_dim) +
                          "/" + std::to_string(act_size));
      }
      if (model_.config().kind == PolicyKind::kMeta) {
        // A bad choice would otherwise throw halfway through the epochs.
        const int c = model_.config().num_choices;
        for (int t = 0; t < r.size(); ++t) {
          const float ch = r.actions[static_cast<size_t>(t) * act_size];
          if (!(ch >= 0 && ch <= c - 1 && ch == std::round(ch))) {
            throw ConfigError(ctx + ".actions: meta choice " + std::to_string(ch) + " at step " +
                              std::to_string(t) + " is not in 0.." + std::to_string(c - 1));
          }
        }
      }
      n += r.size();
    }
  } catch (const ConfigError& e) {
    if (group_ == nullptr) throw;
    refused = e.what();
  }
  // A group learns whether every member's batch passed, and its size, before anything changes.
  std::vector<int> group_n(1, n);
  if (group_ != nullptr) {
    const std::vector<std::string> all =
        group_->AllGather(refused.empty() ? "ok " + std::to_string(n) : "refused " + refused);
    group_n.assign(all.size(), 0);
    for (size_t r = 0; r < all.size(); ++r) {
      if (all[r].rfind("ok ", 0) != 0) {
        if (static_cast<int>(r) == group_->rank()) throw ConfigError(refused);
        throw ConfigError("learner group: rank " + std::to_string(r) +
                          " refused its batch, every member drops its own: " + all[r]);
      }
      group_n[r] = std::stoi(all[r].substr(3));
    }
  }
  return group_n;
}

void PpoLearner::AssembleBatch(const std::vector<Rollout>& rollouts, int n, UpdateStats* st) {
  const int obs_dim = model_.obs_dim();
  const int act_size = model_.action_size();
  // A group merges every member's statistics after the batch, in rank order (below).
  RunningMeanStd obs_delta(obs_dim, 0.0), ret_delta(1, 0.0);
  const RunningMeanStd ret_before = reward_scaler_.return_stats();

  obs_.resize(obs_dim, n);
  actions_.resize(act_size, n);
  old_logp_.resize(n);
  old_value_.resize(n);
  adv_.resize(n);
  ret_.resize(n);
  double sum_r = 0.0, sum_sr = 0.0;
  double sum_ratio = 0.0;
  int lagged = 0, rho_clipped = 0;
  std::vector<uint8_t> done;
  int off = 0;
  for (const Rollout& r : rollouts) {
    const int t = r.size();
    if (t == 0) continue;
    if (group_ != nullptr) {
      obs_delta.Merge(r.obs_stats_delta);
    } else {
      AddObsStats(r.obs_stats_delta);
    }
    scaled_rewards_.assign(r.rewards.begin(), r.rewards.end());
    done.resize(t);
    for (int k = 0; k < t; ++k) done[k] = r.terminated[k] | r.truncated[k];
    reward_scaler_.ScaleInPlace(r.stream_id, scaled_rewards_.data(), done.data(), t,
                                group_ != nullptr ? &ret_delta : nullptr);
    seg_adv_.resize(t);
    seg_ret_.resize(t);
    obs_.middleCols(off, t) = Eigen::Map<const MatrixXf>(r.obs.data(), obs_dim, t);
    actions_.middleCols(off, t) = Eigen::Map<const MatrixXf>(r.actions.data(), act_size, t);
    const bool is_lagged = r.policy_version < static_cast<uint64_t>(num_updates_);
    if (is_lagged) lagged += t;
    if (ppo_.vtrace && is_lagged) {
      // Acted with older weights: the current policy and value network on the segment's steps.
      PolicyEvalCache& ev = ws_.eval;
      model_.Evaluate(model_.params().data(), obs_.middleCols(off, t), actions_.middleCols(off, t),
                      &ev);
      seg_rho_.resize(t);
      seg_c_.resize(t);
      for (int k = 0; k < t; ++k) {
        const float ratio = std::exp(std::min(ev.log_prob[k] - r.log_probs[k], kMaxLogRatio));
        seg_rho_[k] = std::min(ppo_.vtrace_rho_clip, ratio);
        seg_c_[k] = std::min(ppo_.vtrace_c_clip, ratio);
        sum_ratio += ratio;
        rho_clipped += ratio > ppo_.vtrace_rho_clip;
      }
      ComputeVtrace(r, scaled_rewards_.data(), ev.value.data(), seg_rho_.data(), seg_c_.data(),
                    ppo_.gamma, ppo_.gae_lambda, ppo_.bootstrap_on_truncation, seg_adv_.data(),
                    seg_ret_.data());
      // PPO's ratio and value clipping then measure against the learner's own start point.
      old_logp_.segment(off, t) = ev.log_prob.head(t);
      old_value_.segment(off, t) = ev.value.head(t);
    } else {
      ComputeGae(r, scaled_rewards_.data(), ppo_.gamma, ppo_.gae_lambda,
                 ppo_.bootstrap_on_truncation, seg_adv_.data(), seg_ret_.data());
      old_logp_.segment(off, t) = Eigen::Map<const VectorXf>(r.log_probs.data(), t);
      old_value_.segment(off, t) = Eigen::Map<const VectorXf>(r.values.data(), t);
    }
    adv_.segment(off, t) = Eigen::Map<const VectorXf>(seg_adv_.data(), t);
    ret_.segment(off, t) = Eigen::Map<const VectorXf>(seg_ret_.data(), t);
    for (int k = 0; k < t; ++k) {
      sum_r += r.rewards[k];
      sum_sr += scaled_rewards_[k];
    }
    off += t;
  }
  if (group_ != nullptr) MergeGroupStats(obs_delta, ret_delta, ret_before);
  st->lagged_samples = lagged;
  if (lagged > 0) {
    st->vtrace_ratio_mean = static_cast<float>(sum_ratio / lagged);
    st->vtrace_rho_clipped = static_cast<float>(rho_clipped) / lagged;
  }
  st->mean_reward = static_cast<float>(sum_r / n);
  st->mean_scaled_reward = static_cast<float>(sum_sr / n);
  st->mean_advantage = adv_.mean();
  st->mean_return = ret_.mean();
  const double var_ret = (ret_.array() - ret_.mean()).square().mean();
  const VectorXf resid = ret_ - old_value_;
  const double var_res = (resid.array() - resid.mean()).square().mean();
  st->explained_variance = var_ret > 0 ? static_cast<float>(1.0 - var_res / var_ret) : 0.0f;
}

void PpoLearner::MergeGroupStats(const RunningMeanStd& obs_delta, const RunningMeanStd& ret_delta,
                                 const RunningMeanStd& ret_before) {
  const int obs_dim = model_.obs_dim();
  proto::RunningStats po, pr;
  obs_delta.ToProto(&po);
  ret_delta.ToProto(&pr);
  const std::vector<std::string> all =
      group_->AllGather(PackStrings({po.SerializeAsString(), pr.SerializeAsString()}));
  RunningMeanStd ret_stats = ret_before;
  for (size_t r = 0; r < all.size(); ++r) {
    const std::string ctx = "learner group: rank " + std::to_string(r) + "'s statistics";
    const std::vector<std::string> two = UnpackStrings(all[r], ctx);
    if (two.size() != 2 || !po.ParseFromString(two[0]) || !pr.ParseFromString(two[1])) {
      throw ConfigError(ctx + ": malformed");
    }
    AddObsStats(RunningMeanStd::FromProto(po, obs_dim, ctx + ".obs"));
    ret_stats.Merge(RunningMeanStd::FromProto(pr, 1, ctx + ".returns"));
  }
  reward_scaler_.return_stats() = ret_stats;
}

void PpoLearner::RunEpochs(int n, const std::vector<int>& group_n, UpdateStats* st) {
  const int min_n = *std::min_element(group_n.begin(), group_n.end());
  const int num_mb = std::max(1, std::min(ppo_.num_minibatches, min_n));
  // Minibatch m of a group: every member's m-th part; the means are over their total size.
  auto part = [num_mb](int m, int size) {
    return static_cast<int>(static_cast<int64_t>(m + 1) * size / num_mb) -
           static_cast<int>(static_cast<int64_t>(m) * size / num_mb);
  };
  perm_.resize(n);
  for (int i = 0; i < n; ++i) perm_[i] = i;
  double acc_pg = 0, acc_vf = 0, acc_ent = 0, acc_kl = 0, acc_cf = 0, acc_gn = 0;
  int steps = 0;
  float* params = model_.params().data();
  for (int epoch = 0; epoch < ppo_.num_epochs; ++epoch) {
    // Fisher-Yates with our portable RNG: same seed, same minibatches everywhere.
    for (int i = n - 1; i > 0; --i) {
      std::swap(perm_[i], perm_[rng_.UniformInt(static_cast<uint64_t>(i) + 1)]);
    }
    for (int m = 0; m < num_mb; ++m) {
      const int begin = static_cast<int>(static_cast<int64_t>(m) * n / num_mb);
      const int end = static_cast<int>(static_cast<int64_t>(m + 1) * n / num_mb);
      int mean_over = end - begin;
      if (group_ != nullptr) {
        mean_over = 0;
        for (int nr : group_n) mean_over += part(m, nr);
      }
      float gn;
      const PpoLossTerms lt = MinibatchStep(begin, end - begin, mean_over, params, &gn);
      params = model_.params().data();
      acc_pg += lt.policy_loss;
      acc_vf += lt.value_loss;
      acc_ent += lt.entropy;
      acc_kl += lt.approx_kl;
      acc_cf += lt.clip_fraction;
      acc_gn += gn;
      ++steps;
    }
  }
  st->num_minibatch_steps = steps;
  st->policy_loss = static_cast<float>(acc_pg / steps);
  st->value_loss = static_cast<float>(acc_vf / steps);
  st->entropy = static_cast<float>(acc_ent / steps);
  st->approx_kl = static_cast<float>(acc_kl / steps);
  st->clip_fraction = static_cast<float>(acc_cf / steps);
  st->grad_norm = static_cast<float>(acc_gn / steps);
}

PpoLossTerms PpoLearner::MinibatchStep(int begin, int b, int mean_over, const float* params,
                                       float* grad_norm) {
  PpoLossTerms lt;
  if (ppo_.threads > 1) {
    // Parts of the minibatch on threads of their own (at least kMinShardSamples each).
    lt = ColumnLoss(begin, b, std::max(1, std::min(ppo_.threads, b / kMinShardSamples)), params,
                    mean_over);
    if (group_ != nullptr) {
      SumShards();
      ReduceOverGroup(&lt);
      *grad_norm = SerialStep(&grad_);
    } else {
      *grad_norm = ShardedStep();
    }
    return lt;
  }
  ResizeShard(&mb_, b);
  GatherColumns(&mb_, begin, 0, b);
  if (ppo_.normalize_advantages && b > 1) NormalizeAdvantages(&mb_.adv);
  grad_.setZero();
  lt = PpoLoss(model_, params, ppo_, mb_.obs, mb_.act, mb_.logp, mb_.value, mb_.adv, mb_.ret, &ws_,
               grad_.data(), mean_over);
  if (group_ != nullptr) ReduceOverGroup(&lt);
  *grad_norm = SerialStep(&grad_);
  return lt;
}

UpdateStats PpoLearner::Update(const std::vector<Rollout>& rollouts) {
  const std::vector<int> group_n = CheckBatch(rollouts);
  const int n = group_n[group_ != nullptr ? group_->rank() : 0];
  UpdateStats st;
  int min_n = n, group_total = 0;
  for (int nr : group_n) {
    min_n = std::min(min_n, nr);
    group_total += nr;
  }
  if (min_n == 0) return st;
  st.num_samples = n;
  st.group_samples = group_total;
  AssembleBatch(rollouts, n, &st);
  RunEpochs(n, group_n, &st);
  st.log_std_mean = model_.params().segment(model_.log_std_offset(), model_.act_dim()).mean();
  ++num_updates_;
  num_samples_ += n;
  return st;
}

void PpoLearner::ResizeShard(Shard* sh, int bs) const {
  sh->obs.resize(model_.obs_dim(), bs);
  sh->act.resize(model_.action_size(), bs);
  sh->logp.resize(bs);
  sh->value.resize(bs);
  sh->adv.resize(bs);
  sh->ret.resize(bs);
}

void PpoLearner::GatherColumns(Shard* sh, int lo, int k0, int k1) const {
  for (int k = k0; k < k1; ++k) {
    const int idx = perm_[lo + k];
    sh->obs.col(k) = obs_.col(idx);
    sh->act.col(k) = actions_.col(idx);
    sh->logp[k] = old_logp_[idx];
    sh->value[k] = old_value_[idx];
    sh->adv[k] = adv_[idx];
    sh->ret[k] = ret_[idx];
  }
}

void PpoLearner::NormalizeAdvantages(VectorXf* adv) const {
  const float mean = adv->mean();
  const float sd = std::sqrt((adv->array() - mean).square().mean());
  adv->array() = (adv->array() - mean) / (sd + ppo_.advantage_eps);
}

// One minibatch on `parts` threads, each with a contiguous part of its columns and both networks:
// gather, normalise (over the whole minibatch), evaluate, loss and backward in one round per
// minibatch; ShardedStep then sums the parts' gradients in part order (same bits every run).
PpoLossTerms PpoLearner::ColumnLoss(int begin, int b, int parts, const float* params,
                                    int mean_over) {
  if (!pool_ || pool_->threads() != ppo_.threads)
    pool_ = std::make_shared<WorkerPool>(ppo_.threads);
  if (static_cast<int>(shards_.size()) < parts) shards_.resize(parts);
  active_shards_ = parts;
  const bool normalize = ppo_.normalize_advantages && b > 1;
  float adv_mean = 0.0f, adv_scale = 1.0f;
  if (normalize) {
    double sum = 0.0;
    for (int k = 0; k < b; ++k) sum += adv_[perm_[begin + k]];
    const double mean = sum / b;
    double ss = 0.0;
    for (int k = 0; k < b; ++k) {
      const double d = adv_[perm_[begin + k]] - mean;
      ss += d * d;
    }
    adv_mean = static_cast<float>(mean);
    adv_scale = 1.0f / (static_cast<float>(std::sqrt(ss / b)) + ppo_.advantage_eps);
  }
  const int np = model_.num_params();
  pool_->Run(parts, [&](int s) {
    Shard& sh = shards_[s];
    const int lo = begin + static_cast<int>(static_cast<int64_t>(s) * b / parts);
    const int bs = begin + static_cast<int>(static_cast<int64_t>(s + 1) * b / parts) - lo;
    ResizeShard(&sh, bs);
    GatherColumns(&sh, lo, 0, bs);
    if (normalize) sh.adv.array() = (sh.adv.array() - adv_mean) * adv_scale;
    model_.EvaluatePolicy(params, sh.obs, sh.act, &sh.ws.eval);
    model_.EvaluateValue(params, sh.obs, &sh.ws.eval);
    sh.terms = PpoLossFromEval(ppo_, sh.logp, sh.value, sh.adv, sh.ret, &sh.ws, mean_over);
    sh.grad.setZero(np);
    model_.BackwardPolicy(params, sh.ws.dlogp, sh.ws.dent, &sh.ws.eval, sh.grad.data());
    model_.BackwardValue(params, sh.ws.dval, &sh.ws.eval, sh.grad.data());
  });
  PpoLossTerms t = shards_[0].terms;
  for (int s = 1; s < parts; ++s) {
    const PpoLossTerms& u = shards_[s].terms;
    t.total += u.total;
    t.policy_loss += u.policy_loss;
    t.value_loss += u.value_loss;
    t.entropy += u.entropy;
    t.approx_kl += u.approx_kl;
    t.clip_fraction += u.clip_fraction;
  }
  return t;
}

void PpoLearner::SumShards() {
  const int np = model_.num_params();
  const int ranges = std::min(ppo_.threads, std::max(1, np / 1024));
  const float* mask = model_.trainable_mask().data();
  pool_->Run(ranges, [&](int r) {
    const int lo = static_cast<int>(static_cast<int64_t>(r) * np / ranges);
    const int hi = static_cast<int>(static_cast<int64_t>(r + 1) * np / ranges);
    auto g = grad_.segment(lo, hi - lo);
    g = shards_[0].grad.segment(lo, hi - lo);
    for (int s = 1; s < active_shards_; ++s) g += shards_[s].grad.segment(lo, hi - lo);
    g.array() *= Eigen::Map<const VectorXf>(mask + lo, hi - lo).array();
  });
}

// One message per minibatch: the gradient and the loss terms (each member's already weighted by
// its share of the group's minibatch, so the sums are the group's means).
void PpoLearner::ReduceOverGroup(PpoLossTerms* t) {
  const int np = model_.num_params();
  reduce_buf_.resize(np + 6);
  std::copy(grad_.data(), grad_.data() + np, reduce_buf_.begin());
  const double terms[6] = {t->total,   t->policy_loss, t->value_loss,
                           t->entropy, t->approx_kl,   t->clip_fraction};
  for (int i = 0; i < 6; ++i) reduce_buf_[np + i] = static_cast<float>(terms[i]);
  group_->AllReduceSum(reduce_buf_.data(), np + 6);
  std::copy(reduce_buf_.begin(), reduce_buf_.begin() + np, grad_.data());
  t->total = reduce_buf_[np];
  t->policy_loss = reduce_buf_[np + 1];
  t->value_loss = reduce_buf_[np + 2];
  t->entropy = reduce_buf_[np + 3];
  t->approx_kl = reduce_buf_[np + 4];
  t->clip_fraction = reduce_buf_[np + 5];
}

// Mask, global-norm clip and the Adam step on one gradient, as the one-thread update does.
float PpoLearner::SerialStep(VectorXf* grad) {
  VectorXf& g = *grad;
  g.array() *= model_.trainable_mask().array();
  const float gn = g.norm();
  if (ppo_.max_grad_norm > 0 && gn > ppo_.max_grad_norm) g *= ppo_.max_grad_norm / gn;
  adam_.Step(model_.params(), g, ppo_.learning_rate);
  return gn;
}

// After ColumnLoss: the parts' gradients summed, masked, clipped to the global norm and the Adam
// step, each thread on its own range of the parameters (two rounds: the norm needs every range).
// Returns the gradient norm before clipping.
float PpoLearner::ShardedStep() {
  const int np = model_.num_params();
  const int ranges = std::min(ppo_.threads, std::max(1, np / 1024));
  range_sq_.assign(ranges, 0.0);
  const float* mask = model_.trainable_mask().data();
  auto range = [&](int r, int* lo, int* hi) {
    *lo = static_cast<int>(static_cast<int64_t>(r) * np / ranges);
    *hi = static_cast<int>(static_cast<int64_t>(r + 1) * np / ranges);
  };
  pool_->Run(ranges, [&](int r) {
    int lo, hi;
    range(r, &lo, &hi);
    auto g = grad_.segment(lo, hi - lo);
    g = shards_[0].grad.segment(lo, hi - lo);
    for (int s = 1; s < active_shards_; ++s) g += shards_[s].grad.segment(lo, hi - lo);
    g.array() *= Eigen::Map<const VectorXf>(mask + lo, hi - lo).array();
    range_sq_[r] = g.squaredNorm();
  });
  double sq = 0.0;
  for (double v : range_sq_) sq += v;
  const float gn = static_cast<float>(std::sqrt(sq));
  const float scale =
      ppo_.max_grad_norm > 0 && gn > ppo_.max_grad_norm ? ppo_.max_grad_norm / gn : 1.0f;
  const float lr_t = adam_.BeginStep(ppo_.learning_rate);
  float* params = model_.params().data();
  pool_->Run(ranges, [&](int r) {
    int lo, hi;
    range(r, &lo, &hi);
    if (scale != 1.0f) grad_.segment(lo, hi - lo) *= scale;
    adam_.ApplyRange(params, grad_.data(), lr_t, lo, hi);
  });
  return gn;
}

void PpoLearner::ExportWeights(proto::ModelWeights* w) const {
  w->Clear();
  model_.GetShape(w->mutable_shape());
  w->set_version(static_cast<uint64_t>(num_updates_));
  const VectorXf& p = model_.params();
  w->mutable_params()->Assign(p.data(), p.data() + p.size());
  obs_norm_.stats().ToProto(w->mutable_obs_stats());
  w->set_obs_clip(obs_norm_.config().obs_clip);
  w->set_obs_eps(obs_norm_.config().obs_eps);
  w->set_normalize_obs(obs_norm_.config().normalize_obs);
}

void PpoLearner::ExportState(proto::LearnerState* s) const {
  s->Clear();
  ExportWeights(s->mutable_model());
  adam_.ToProto(s->mutable_adam());
  reward_scaler_.return_stats().ToProto(s->mutable_return_stats());
  std::vector<std::pair<uint64_t, double>> streams(reward_scaler_.streams().begin(),
                                                   reward_scaler_.streams().end());
  std::sort(streams.begin(), streams.end());  // deterministic bytes
  for (const auto& [id, ret] : streams) {
    proto::ReturnStream* rs = s->add_return_streams();
    rs->set_stream_id(id);
    rs->set_ret(ret);
  }
  const Rng::State rs = rng_.GetState();
  for (uint64_t w : rs.s) s->mutable_rng()->add_s(w);
  s->mutable_rng()->set_has_spare(rs.has_spare);
  s->mutable_rng()->set_spare(rs.spare);
  s->set_num_updates(num_updates_);
  s->set_num_samples(num_samples_);
  s->set_ppo_config_json(ToJson(ppo_).dump());
  s->set_policy_config_json(ToJson(policy_config_).dump());
}

void PpoLearner::ImportWeights(const proto::ModelWeights& w, const std::string& ctx) {
  model_.CheckShape(w.shape(), ctx);
  if (w.params_size() != model_.num_params()) {
    throw ConfigError(ctx + ": params has " + std::to_string(w.params_size()) +
                      " values, the network needs " + std::to_string(model_.num_params()));
  }
  VectorXf p = Eigen::Map<const VectorXf>(w.params().data(), w.params_size());
  if (!p.allFinite()) throw ConfigError(ctx + ": params contain NaN/Inf");
  RunningMeanStd stats =
      RunningMeanStd::FromProto(w.obs_stats(), model_.obs_dim(), ctx + ".obs_stats");
  model_.params() = p;
  obs_norm_.stats() = stats;
  obs_norm_.Refresh();
  num_updates_ = static_cast<int64_t>(w.version());
}

void PpoLearner::ImportState(const proto::LearnerState& s, const std::string& ctx) {
  // Validate everything into temporaries first: a bad blob changes nothing.
  if (!s.has_model()) throw ConfigError(ctx + ": missing model");
  PpoLearner tmp = *this;
  tmp.ImportWeights(s.model(), ctx + ".model");
  tmp.adam_.FromProto(s.adam(), ctx + ".adam");
  tmp.reward_scaler_.return_stats() =
      RunningMeanStd::FromProto(s.return_stats(), 1, ctx + ".return_stats");
  tmp.reward_scaler_.streams().clear();
  for (const proto::ReturnStream& rs : s.return_streams()) {
    if (!std::isfinite(rs.ret())) throw ConfigError(ctx + ".return_streams: non-finite return");
    tmp.reward_scaler_.streams()[rs.stream_id()] = rs.ret();
  }
  if (s.rng().s_size() != 4) throw ConfigError(ctx + ".rng: expected 4 state words");
  Rng::State st{{s.rng().s(0), s.rng().s(1), s.rng().s(2), s.rng().s(3)},
                s.rng().has_spare(),
                s.rng().spare()};
  tmp.rng_.SetState(st);
  if (s.num_updates() < 0 || s.num_samples() < 0) throw ConfigError(ctx + ": negative counters");
  tmp.num_updates_ = s.num_updates();
  tmp.num_samples_ = s.num_samples();
  *this = std::move(tmp);
}

}  // namespace perch
