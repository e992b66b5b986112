#include "bench/ppo_bench.h"

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <thread>
#include <vector>

#include "learner/ppo.h"
#include "policy/dense_kernels.h"
#include "policy/policy.h"
#include "policy/rollout.h"

namespace perch {
namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

Json RunPpoBench(const PpoBenchOptions& o) {
  if (o.obs_dim <= 0 || o.batch <= 0 || o.minibatches <= 0 || o.repeats <= 0 || o.threads <= 0 ||
      o.epochs <= 0) {
    throw ConfigError(
        "bench ppo: --obs-dim, --batch, --minibatches, --repeats, --threads and --epochs must be "
        "> 0");
  }
  Eigen::setNbThreads(1);
  const PolicyConfig pc = PolicyConfig::Subtask(o.obs_dim);
  PpoConfig cfg = PpoConfig::Subtask();
  cfg.steps_per_update = o.batch;
  cfg.num_minibatches = o.minibatches;
  cfg.num_epochs = o.epochs;  // one timed Update call: the batch's preparation, then the epochs
  PpoConfig cfg_n = cfg;
  cfg_n.threads = o.threads;
  PpoLearner learner(pc, cfg, o.seed);
  PpoLearner learner_n(pc, cfg_n, o.seed);

  // A batch with realistic log-probs: actions sampled by the policy on random observations.
  PolicyRunner runner(pc, cfg.obs_norm);
  runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(), 0);
  runner.set_update_obs_stats(false);
  Rng rng(o.seed + 1);
  Rollout r(pc.obs_dim, pc.action_size());
  r.Reserve(o.batch);
  std::vector<float> raw(pc.obs_dim), norm(pc.obs_dim), act(pc.action_size());
  const auto t_act0 = Clock::now();
  for (int t = 0; t < o.batch; ++t) {
    for (float& x : raw) x = static_cast<float>(rng.Normal());
    const PolicyRunner::Output out = runner.Act(raw.data(), rng, false, norm.data(), act.data());
    const bool trunc = (t + 1) % 1000 == 0;
    r.Add(norm.data(), act.data(), out.log_prob, out.value, static_cast<float>(rng.Normal()), false,
          trunc, trunc || t + 1 == o.batch ? out.value : 0.0f);
  }
  const double act_s = Seconds(t_act0, Clock::now());
  r.obs_stats_delta = RunningMeanStd(pc.obs_dim, 0.0);
  const std::vector<Rollout> batch{r};

  const bool compare = o.threads > 1;
  learner.Update(batch);  // warm-up: buffers reach their size, threads start
  if (compare) learner_n.Update(batch);
  std::vector<double> times, times_n;
  for (int i = 0; i < o.repeats; ++i) {
    auto t0 = Clock::now();
    learner.Update(batch);
    times.push_back(Seconds(t0, Clock::now()));
    if (!compare || o.blocks) continue;
    t0 = Clock::now();
    learner_n.Update(batch);
    times_n.push_back(Seconds(t0, Clock::now()));
  }
  // The machine's own ceiling: N independent one-thread updates at once, against one alone. A VM's
  // cores may share a physical core, caches or a power budget; N threads cannot beat this.
  std::vector<double> times_conc;
  std::vector<PpoLearner> copies;
  if (compare && o.ceiling) {
    copies.assign(o.threads - 1, learner);
    for (PpoLearner& c : copies) c.Update(batch);
  }
  for (int i = 0; compare && o.ceiling && i < o.repeats; ++i) {
    const auto t0 = Clock::now();
    std::vector<std::thread> others;
    for (PpoLearner& c : copies) others.emplace_back([&c, &batch] { c.Update(batch); });
    learner.Update(batch);
    for (std::thread& t : others) t.join();
    times_conc.push_back(Seconds(t0, Clock::now()));
  }
  for (int i = 0; compare && o.blocks && i < o.repeats; ++i) {
    const auto t0 = Clock::now();
    learner_n.Update(batch);
    times_n.push_back(Seconds(t0, Clock::now()));
  }
  const double med = Median(times);
  const double best = *std::min_element(times.begin(), times.end());
  Json j{{"bench", "ppo"},
         // Per epoch of one sample pass (an update with --epochs E counts E passes).
         {"samples_per_s", o.batch * o.epochs / med},
         {"samples_per_s_best", o.batch * o.epochs / best},
         {"epoch_ms_median", 1e3 * med / o.epochs},
         {"epoch_ms_min", 1e3 * best / o.epochs},
         {"update_ms_median", 1e3 * med},
         {"batch", o.batch},
         {"minibatch", o.batch / o.minibatches},
         {"repeats", o.repeats},
         {"epochs", o.epochs},
         {"obs_dim", pc.obs_dim},
         {"act_dim", pc.act_dim},
         {"hidden", pc.policy_net.hidden},
         {"activation", "tanh"},
         {"num_params", learner.model().num_params()},
         {"threads", 1},
         {"act_steps_per_s", o.batch / act_s},
         {"eigen_simd", Eigen::SimdInstructionSetsInUse()},
         {"dense_kernels", ActiveDenseKernels().name},
         {"impl", "eigen"}};
  if (compare) {
    const double med_n = Median(times_n);
    j["threads_n"] = o.threads;
    j["samples_per_s_threads_n"] = o.batch * o.epochs / med_n;
    j["epoch_ms_median_threads_n"] = 1e3 * med_n / o.epochs;
    j["update_ms_median_threads_n"] = 1e3 * med_n;
    // Per repeat, one thread's time over N threads' (adjacent epochs share the machine's load).
    std::vector<double> ratios;
    for (size_t i = 0; i < times.size(); ++i) ratios.push_back(times[i] / times_n[i]);
    j["speedup_threads_n"] = Median(ratios);
    std::vector<double> ms1, msn;
    for (double t : times) ms1.push_back(1e3 * t);
    for (double t : times_n) msn.push_back(1e3 * t);
    j["update_ms_runs"] = ms1;
    j["update_ms_runs_threads_n"] = msn;
    j["speedup_threads_n_min"] = *std::min_element(ratios.begin(), ratios.end());
    j["speedup_threads_n_max"] = *std::max_element(ratios.begin(), ratios.end());
    if (!times_conc.empty()) {
      // N updates' worth of work in the time N concurrent one-thread learners took, over one alone.
      j["ceiling_threads_n"] = o.threads * med / Median(times_conc);
      j["speedup_of_ceiling"] =
          j["speedup_threads_n"].get<double>() / j["ceiling_threads_n"].get<double>();
    }
  }
  return j;
}

}  // namespace perch
