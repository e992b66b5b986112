#include "learner/local/meta_clone.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <mutex>
#include <numeric>
#include <thread>

#include "common/rng.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/meta_env.h"
#include "hierarchy/meta_lookahead.h"
#include "learner/adam.h"
#include "policy/normalizer.h"
#include "tasks/task_eval.h"

namespace perch {

namespace {

// What one episode adds: observations [obs_dim] and the planner's labels [3] per meta step.
struct Episode {
  std::vector<float> obs, labels;
  std::vector<uint8_t> changes;  // [step] the label's subtask is not the acting one
  int steps = 0;
  bool success = false;
};

// The teacher: the planner's rules, or the rules with lookahead when the plan's config asks for
// it (hierarchy/meta_lookahead.h; it may restore the env to the state it saved).
struct Teacher {
  std::unique_ptr<MetaPlanner> rules;
  std::unique_ptr<LookaheadPlanner> ahead;
  Teacher(std::shared_ptr<const MetaPlan> plan, const TaskEnvConfig& config,
          const std::vector<FrozenPolicyData>& frozen) {
    if (plan->config.lookahead()) {
      ahead = std::make_unique<LookaheadPlanner>(plan, config, frozen);
    } else {
      rules = std::make_unique<MetaPlanner>(plan);
    }
  }
  void Reset(uint64_t env_seed) {
    if (ahead) {
      ahead->Reset(env_seed);
    } else {
      rules->Reset();
    }
  }
  void Act(MetaEnv& env, float* label) {
    if (ahead) {
      ahead->Act(env, label);
    } else {
      rules->Act(env, label);
    }
  }
};

// One episode on `env`: the planner labels every meta step; it also acts with probability
// `beta`, the clone (`runner`, may be null when beta is 1) otherwise.
Episode Collect(MetaEnv& env, Teacher& planner, PolicyRunner* runner, double beta, uint64_t seed) {
  Episode e;
  env.Seed(2 * seed);
  Rng rng(2 * seed + 1);
  const int od = env.spec().obs_dim;
  std::vector<float> obs(od), label(3), action(3);
  const std::vector<int> ids = env.meta().choice_ids();
  env.Reset(obs.data());
  planner.Reset(2 * seed);
  for (int t = 0; t < env.spec().max_episode_steps; ++t) {
    planner.Act(env, label.data());
    e.obs.insert(e.obs.end(), obs.begin(), obs.end());
    e.labels.insert(e.labels.end(), label.begin(), label.end());
    const int cls =
        std::clamp(static_cast<int>(std::lround(label[0])), 0, static_cast<int>(ids.size()) - 1);
    e.changes.push_back(ids[cls] != env.active());
    ++e.steps;
    const bool expert = runner == nullptr || rng.Uniform(0.0, 1.0) < beta;
    if (expert) {
      action = label;
    } else {
      runner->Act(obs.data(), rng, true, nullptr, action.data());
    }
    const StepResult r = env.Step(action.data(), obs.data());
    if (r.terminated || r.truncated) break;
  }
  e.success = env.episode().success_step >= 0;
  return e;
}

}  // namespace

void CheckCloneInit(const PolicyConfig& pc, const NormalizerConfig& norm,
                    const proto::ModelWeights& init) {
  PolicyRunner runner(pc, norm);
  try {
    runner.LoadWeights(init);  // shape, parameter count, finite values
  } catch (const ConfigError& e) {
    throw ConfigError(std::string("meta-clone --init-from: ") + e.what());
  }
}

namespace {

// The samples of every round so far: observations [obs_dim] and labels (class, target theta,
// target dist) per meta step, and whether the label hands over to another subtask.
struct CloneData {
  std::vector<float> obs, labels;
  std::vector<uint8_t> changes;
  int size() const { return static_cast<int>(labels.size() / 3); }
};

// One round's episodes, spread over threads; episode i of a round always gets the same seed.
// With a policy (DAgger) it acts with probability 1 - beta, the planner otherwise.
std::vector<Episode> CollectRound(const TaskEnvConfig& config,
                                  const std::vector<FrozenPolicyData>& frozen,
                                  const PolicyConfig& pc, const NormalizerConfig& norm,
                                  const std::shared_ptr<const MetaPlan>& plan,
                                  const CloneOptions& o, const proto::ModelWeights& weights,
                                  int round, bool dagger, double beta) {
  std::vector<Episode> eps(o.episodes);
  std::atomic<int> next{0};
  std::exception_ptr error;
  std::mutex mu;
  auto worker = [&]() {
    try {
      MetaEnv env(config);
      env.SetFrozenPolicies(frozen);
      Teacher planner(plan, config, frozen);
      std::unique_ptr<PolicyRunner> runner;
      if (dagger) {
        runner = std::make_unique<PolicyRunner>(pc, norm);
        runner->LoadWeights(weights);
        runner->set_update_obs_stats(false);
      }
      for (int i = next++; i < o.episodes; i = next++) {
        const uint64_t seed = (o.seed * 1000003ULL + static_cast<uint64_t>(round)) * 1000003ULL +
                              static_cast<uint64_t>(i);
        eps[i] = Collect(env, planner, runner.get(), beta, seed);
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(mu);
      if (!error) error = std::current_exception();
      next = o.episodes;
    }
  };
  std::vector<std::thread> pool;
  for (int t = 0; t < std::clamp(o.threads, 1, o.episodes); ++t) pool.emplace_back(worker);
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
  return eps;
}

// Fits the model to all data so far: the normaliser from the data, then maximum likelihood
// (hand-over steps weighted by switch_weight). Returns the last epoch's mean NLL.
double FitRound(const CloneData& d, const PolicyConfig& pc, const NormalizerConfig& norm,
                const CloneOptions& o, int round, ActorCritic* model, Adam* adam,
                RunningMeanStd* stats) {
  const int n = d.size();
  *stats = RunningMeanStd(pc.obs_dim, norm.initial_count);
  stats->UpdateBatch(d.obs.data(), n);
  ObsNormalizer normalizer(pc.obs_dim, norm);
  normalizer.stats() = *stats;
  normalizer.Refresh();
  MatrixXf x(pc.obs_dim, n);
  MatrixXf a(3, n);
  for (int i = 0; i < n; ++i) {
    normalizer.Normalize(d.obs.data() + static_cast<size_t>(i) * pc.obs_dim, x.col(i).data());
    for (int k = 0; k < 3; ++k) a(k, i) = d.labels[3 * static_cast<size_t>(i) + k];
  }
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  Rng shuffle(o.seed * 7919ULL + static_cast<uint64_t>(round));
  PolicyEvalCache cache;
  VectorXf grad(model->num_params());
  double last_nll = 0.0;
  for (int epoch = 0; epoch < o.epochs; ++epoch) {
    for (int i = n - 1; i > 0; --i) std::swap(order[i], order[shuffle.UniformInt(i + 1)]);
    double nll = 0.0;
    for (int start = 0; start < n; start += o.minibatch) {
      const int b = std::min(o.minibatch, n - start);
      MatrixXf xb(pc.obs_dim, b), ab(3, b);
      VectorXf w(b);
      for (int k = 0; k < b; ++k) {
        xb.col(k) = x.col(order[start + k]);
        ab.col(k) = a.col(order[start + k]);
        w[k] = d.changes[order[start + k]] ? static_cast<float>(o.switch_weight) : 1.0f;
      }
      model->Evaluate(model->params().data(), xb, ab, &cache);
      nll -= cache.log_prob.sum();
      grad.setZero();
      // Ascend the weighted mean log-likelihood: Adam descends -grad.
      const VectorXf dlogp = -w / w.sum();
      model->Backward(model->params().data(), dlogp, VectorXf::Zero(b), VectorXf::Zero(b), &cache,
                      grad.data());
      grad.array() *= model->trainable_mask().array();
      adam->Step(model->params(), grad, o.learning_rate);
    }
    last_nll = nll / n;
  }
  return last_nll;
}

// How well the clone (its deterministic actions) matches the labels: switch accuracy overall and
// at hand-overs, walk-target error.
struct CloneScore {
  double accuracy = 0.0, handover_accuracy = 0.0, target_err_m = 0.0;
  int handovers = 0, walk_samples = 0;
};
CloneScore ScoreClone(const CloneData& d, const PolicyConfig& pc, const NormalizerConfig& norm,
                      const proto::ModelWeights& weights) {
  const int n = d.size();
  PolicyRunner runner(pc, norm);
  runner.LoadWeights(weights);
  runner.set_update_obs_stats(false);
  Rng unused(0);
  std::vector<float> act(3);
  int right = 0, changes_right = 0;
  CloneScore s;
  std::vector<double> target_err;
  for (int i = 0; i < n; ++i) {
    const float* label = d.labels.data() + 3 * static_cast<size_t>(i);
    runner.Act(d.obs.data() + static_cast<size_t>(i) * pc.obs_dim, unused, true, nullptr,
               act.data());
    const bool ok = static_cast<int>(std::lround(act[0])) == static_cast<int>(label[0]);
    right += ok;
    s.handovers += d.changes[i];
    changes_right += d.changes[i] && ok;
    if (static_cast<int>(label[0]) == pc.target_choice) {
      ++s.walk_samples;
      const double ex = label[2] * std::cos(label[1]), ey = label[2] * std::sin(label[1]);
      const double cx = act[2] * std::cos(act[1]), cy = act[2] * std::sin(act[1]);
      target_err.push_back(std::hypot(ex - cx, ey - cy));
    }
  }
  s.accuracy = static_cast<double>(right) / n;
  s.handover_accuracy = s.handovers ? static_cast<double>(changes_right) / s.handovers : 0.0;
  s.target_err_m = MeanOf(target_err);
  return s;
}

}  // namespace

CloneResult CloneMeta(const TaskEnvConfig& config, const std::vector<FrozenPolicyData>& frozen,
                      const PolicyConfig& pc, const NormalizerConfig& norm,
                      std::shared_ptr<const MetaPlan> plan, const CloneOptions& o) {
  if (pc.kind != PolicyKind::kMeta)
    throw ConfigError("meta-clone: the policy is not a meta policy");
  if (o.episodes < 1 || o.rounds < 1 || o.epochs < 1 || o.minibatch < 1) {
    throw ConfigError("meta-clone: episodes, rounds, epochs and minibatch must be >= 1");
  }
  if (!(o.switch_weight >= 1 && o.switch_weight <= 1000)) {
    throw ConfigError("meta-clone: switch weight must be in [1, 1000]");
  }
  if (!(o.dagger_beta >= 0 && o.dagger_beta <= 1)) {
    throw ConfigError("meta-clone: dagger beta must be in [0, 1]");
  }
  ActorCritic model(pc, o.seed);
  if (o.init) {
    CheckCloneInit(pc, norm, *o.init);
    std::copy(o.init->params().begin(), o.init->params().end(), model.params().data());
  }
  RunningMeanStd stats(pc.obs_dim, norm.initial_count);
  Adam adam(model.num_params(), 0.9f, 0.999f, 1e-5f);
  CloneData data;
  Json rounds = Json::array();
  proto::ModelWeights weights;
  auto export_weights = [&]() {
    weights.Clear();
    model.GetShape(weights.mutable_shape());
    weights.set_version(0);
    weights.mutable_params()->Assign(model.params().data(),
                                     model.params().data() + model.params().size());
    stats.ToProto(weights.mutable_obs_stats());
    weights.set_obs_clip(norm.obs_clip);
    weights.set_obs_eps(norm.obs_eps);
    weights.set_normalize_obs(norm.normalize_obs);
  };
  if (o.init) weights = *o.init;
  for (int round = 0; round < o.rounds; ++round) {
    // --- collect (episodes spread over threads; episode i always gets the same seed) ---
    // Round 1 is plain cloning, unless a previous stage's policy is there to drive it.
    const bool dagger = round > 0 || o.init.has_value();
    const double beta = dagger ? o.dagger_beta : 1.0;
    const std::vector<Episode> eps =
        CollectRound(config, frozen, pc, norm, plan, o, weights, round, dagger, beta);
    int successes = 0, steps = 0;
    for (const Episode& e : eps) {
      data.obs.insert(data.obs.end(), e.obs.begin(), e.obs.end());
      data.labels.insert(data.labels.end(), e.labels.begin(), e.labels.end());
      data.changes.insert(data.changes.end(), e.changes.begin(), e.changes.end());
      successes += e.success;
      steps += e.steps;
    }
    const int n = data.size();
    if (o.progress) {
      o.progress("meta-clone: round " + std::to_string(round + 1) + "/" + std::to_string(o.rounds) +
                 ": " + std::to_string(o.episodes) + " episodes (" +
                 (!dagger ? std::string("planner") : "planner with p " + std::to_string(beta)) +
                 "), success " + std::to_string(static_cast<double>(successes) / o.episodes) +
                 ", " + std::to_string(n) + " samples in all");
    }

    // --- fit: normaliser from all data so far, then maximum likelihood ---
    const double last_nll = FitRound(data, pc, norm, o, round, &model, &adam, &stats);
    // Exploration for PPO: the target head's spread set to target_log_std.
    if (pc.std_mode == StdMode::kTrained) {
      for (int k = 0; k < pc.act_dim; ++k) {
        model.params()[model.log_std_offset() + k] = o.target_log_std;
      }
    }
    export_weights();

    const CloneScore score = ScoreClone(data, pc, norm, weights);
    rounds.push_back({{"round", round + 1},
                      {"episodes", o.episodes},
                      {"planner_acts_prob", beta},
                      {"success_rate", static_cast<double>(successes) / o.episodes},
                      {"meta_steps", steps},
                      {"samples_total", n},
                      {"nll_last_epoch", last_nll},
                      {"switch_accuracy", score.accuracy},
                      {"handover_samples", score.handovers},
                      {"handover_accuracy", score.handover_accuracy},
                      {"walk_target_err_m_mean", score.target_err_m},
                      {"walk_samples", score.walk_samples}});
    if (o.progress) {
      o.progress("meta-clone: round " + std::to_string(round + 1) + " fitted: switch accuracy " +
                 std::to_string(score.accuracy) + " (hand-overs " +
                 std::to_string(score.handover_accuracy) + " of " +
                 std::to_string(score.handovers) + "), walk target error " +
                 std::to_string(score.target_err_m) + " m (mean over " +
                 std::to_string(score.walk_samples) + ")");
    }
  }
  CloneResult r;
  r.weights = weights;
  r.summary = Json{{"rounds", rounds},
                   {"epochs", o.epochs},
                   {"minibatch", o.minibatch},
                   {"learning_rate", o.learning_rate},
                   {"target_log_std", o.target_log_std},
                   {"dagger_beta", o.dagger_beta},
                   {"switch_weight", o.switch_weight},
                   {"init_from_stage", o.init.has_value()},
                   {"seed", o.seed},
                   {"planner", plan->ToJson()}};
  return r;
}

}  // namespace perch
