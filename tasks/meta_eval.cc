#include "tasks/meta_eval.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <map>
#include <mutex>
#include <thread>

#include "learner/policy.h"
#include "tasks/meta_env.h"
#include "tasks/meta_expert.h"
#include "tasks/meta_lookahead.h"
#include "tasks/state_bank.h"
#include "tasks/task_eval.h"
#include "viz/canvas.h"

namespace perch {

static_assert(kSit == 2, "MetaEvalOptions::starts_subtask defaults to the sit");

namespace {

struct TrialResult {
  bool success = false;
  bool fell = false;
  double min_dist_m = 0.0;
  double time_to_sit_s = 0.0;
  double pos_err_m = 0.0, height_m = 0.0, yaw_err_rad = 0.0;
  double spawn_theta = 0.0;
  std::vector<int> sequence;
  std::vector<float> begin_value;            // [run] the subtask's critic when it began
  std::vector<proto::BankState> sit_starts;  // its hand-overs to o.starts_subtask (when asked)
  LookaheadPlanner::Stats lookahead;         // with the planner's lookahead
  bool lookahead_agreed = false;             // the outcome is what the last look ahead predicted
  bool lookahead_not_worse = false;  // ... and not worse than the rules' own from the first one
};

// Who decides in a trial: a meta policy (runner), the planner, or the planner with lookahead.
struct Decider {
  std::unique_ptr<PolicyRunner> runner;
  std::unique_ptr<MetaPlanner> planner;
  std::unique_ptr<LookaheadPlanner> lookahead;
};

uint64_t TrialSeed(uint64_t seed, int trial) {
  return seed * 1000003ULL + static_cast<uint64_t>(trial);
}

// One trial on `env` decided by `d` (both owned by the calling thread).
TrialResult RunTrial(MetaEnv& env, Decider& d, const MetaEvalOptions& o, int trial,
                     std::vector<PoseFrame>* frames) {
  const uint64_t s = TrialSeed(o.seed, trial);
  env.Seed(2 * s);
  Rng act_rng(2 * s + 1);
  std::vector<float> obs(env.spec().obs_dim), action(env.spec().act_dim);
  const double dt = env.humanoid().spec().control_dt;
  if (frames != nullptr) {
    env.on_control_step = [&](const HumanoidChairEnv& h, const StepResult&, int active) {
      const HumanoidState& st = h.humanoid_state();
      PoseFrame f;
      f.root_pos = st.root_pos;
      f.root_quat = st.root_quat;
      f.q.assign(st.q.begin(), st.q.end());
      f.time_s = h.episode_step() * dt;
      f.label = SubtaskName(active);
      frames->push_back(f);
    };
  }
  std::vector<proto::BankState> sit_starts;
  if (o.sit_starts != nullptr || o.failed_sit_starts != nullptr) {
    env.on_subtask_begin = [&](const HumanoidChairEnv& h, int sub) {
      // The episode's first run starts from the spawn, not from a hand-over.
      if (sub != o.starts_subtask || env.episode().sequence.size() < 2) return;
      sit_starts.push_back(CaptureState(h));
      sit_starts.back().set_episode(static_cast<uint64_t>(trial));
    };
  }
  env.Reset(obs.data());
  if (d.planner != nullptr) d.planner->Reset();
  if (d.lookahead != nullptr) d.lookahead->Reset(2 * s);
  for (int t = 0; t < env.spec().max_episode_steps; ++t) {
    if (d.lookahead != nullptr) {
      d.lookahead->Act(env, action.data());
    } else if (d.planner != nullptr) {
      d.planner->Act(env, action.data());
    } else {
      d.runner->Act(obs.data(), act_rng, !o.stochastic, nullptr, action.data());
    }
    const StepResult r = env.Step(action.data(), obs.data());
    if (r.terminated || r.truncated) break;
  }
  env.on_control_step = nullptr;
  env.on_subtask_begin = nullptr;
  const MetaEpisode& e = env.episode();
  TrialResult out;
  out.success = e.success_step >= 0;
  out.fell = e.fell;
  out.min_dist_m = e.min_dist_m;
  out.time_to_sit_s = out.success ? e.success_step * dt : 0.0;
  out.pos_err_m = e.seated_pos_err_m;
  out.height_m = e.seated_height_m;
  out.yaw_err_rad = e.seated_yaw_err_rad;
  out.spawn_theta = e.spawn_theta;
  out.sequence = e.sequence;
  out.begin_value = e.begin_value;
  out.sit_starts = std::move(sit_starts);
  if (d.lookahead != nullptr) {
    out.lookahead = d.lookahead->stats();
    const LookaheadOutcome& p = out.lookahead.predicted;
    out.lookahead_agreed = out.lookahead.predicted_any && p.success == out.success &&
                           (p.success ? p.success_step == e.success_step : p.fell == e.fell);
    out.lookahead_not_worse = out.lookahead.predicted_any &&
                              !d.lookahead->Better(out.lookahead.rules, LookaheadOutcome::Of(e));
  }
  return out;
}

// How well a subtask's own critic at its start tells the runs that went on from those that
// failed: per subtask, the runs, their share that went on (a turn or walk: not ended by a fall;
// sit: the trial succeeded with it), the mean value of each group, the AUC (the chance that a run
// that went on started with a higher value than one that failed; 0.5: no information) and the
// share that went on per value quartile (cut points in `quartile_cuts`).
Json HandoverValues(const std::vector<TrialResult>& results) {
  std::array<std::vector<std::pair<float, bool>>, kNumSubtasks> runs;
  for (const TrialResult& r : results) {
    for (size_t j = 0; j < r.sequence.size() && j < r.begin_value.size(); ++j) {
      const bool last = j + 1 == r.sequence.size();
      const int id = r.sequence[j];
      const bool ok = id == kSit ? (last && r.success) : !(last && r.fell);
      runs[id].push_back({r.begin_value[j], ok});
    }
  }
  Json out = Json::object();
  for (int id = 0; id < kNumSubtasks; ++id) {
    std::vector<std::pair<float, bool>>& v = runs[id];
    if (v.empty()) continue;
    std::sort(v.begin(), v.end());  // for the quartiles
    double sum_ok = 0.0, sum_bad = 0.0;
    int n_ok = 0;
    for (const auto& [value, ok] : v) {
      (ok ? sum_ok : sum_bad) += value;
      n_ok += ok;
    }
    const int n = static_cast<int>(v.size()), n_bad = n - n_ok;
    Json quart = Json::array(), cuts = Json::array();
    for (int q = 0; q < 4; ++q) {
      const size_t lo = v.size() * q / 4, hi = v.size() * (q + 1) / 4;
      int ok = 0;
      for (size_t m = lo; m < hi; ++m) ok += v[m].second;
      quart.push_back(hi > lo ? static_cast<double>(ok) / (hi - lo) : 0.0);
      if (q > 0) cuts.push_back(v[lo].first);
    }
    Json j{{"runs", n},
           {"went_on_rate", static_cast<double>(n_ok) / n},
           {"value_mean_went_on", n_ok ? sum_ok / n_ok : 0.0},
           {"value_mean_failed", n_bad ? sum_bad / n_bad : 0.0},
           {"quartile_cuts", cuts},
           {"went_on_by_quartile", quart}};
    j["auc"] = RankAuc(v);
    out[SubtaskName(id)] = j;
  }
  return out;
}

}  // namespace

double RankAuc(std::vector<std::pair<float, bool>> v) {
  std::sort(v.begin(), v.end());
  // Mann-Whitney: the positives' rank sum (ties share their mean rank).
  double rank_sum = 0.0;
  int64_t n_pos = 0;
  for (size_t i = 0; i < v.size();) {
    size_t k = i;
    while (k < v.size() && v[k].first == v[i].first) ++k;
    const double mean_rank = 0.5 * static_cast<double>(i + 1 + k);
    for (size_t m = i; m < k; ++m) {
      if (v[m].second) {
        rank_sum += mean_rank;
        ++n_pos;
      }
    }
    i = k;
  }
  const int64_t n_neg = static_cast<int64_t>(v.size()) - n_pos;
  if (n_pos == 0 || n_neg == 0) return 0.5;
  return (rank_sum - 0.5 * n_pos * (n_pos + 1.0)) / (static_cast<double>(n_pos) * n_neg);
}

Json EvaluateMeta(const TaskEnvConfig& config_in, const proto::ModelWeights& meta,
                  const std::vector<FrozenPolicyData>& frozen, const MetaEvalOptions& o,
                  MetaTrialFrames* first_success, MetaTrialFrames* first_failure) {
  if (o.trials < 1) throw ConfigError("eval: --trials must be >= 1");
  TaskEnvConfig config = config_in;
  config.MutableSection<SitChairTaskConfig>().meta.subtask_stochastic = o.stochastic;
  const bool planned = o.planner != nullptr;
  const PolicyConfig pc =
      planned ? PolicyConfig::Meta() : PolicyConfigFromShape(meta.shape(), "meta model");
  const MetaConfig& mc = config.Section<SitChairTaskConfig>().meta;
  const int obs_dim = mc.obs_dim();
  if (!planned && (pc.kind != PolicyKind::kMeta || pc.obs_dim != obs_dim ||
                   pc.num_choices != static_cast<int>(mc.choices.size()))) {
    throw ConfigError("eval: the model is not a meta policy over this config's " +
                      std::to_string(mc.choices.size()) + " subtask choices and " +
                      std::to_string(obs_dim) + " inputs (kind " + meta.shape().kind() + ", " +
                      std::to_string(pc.num_choices) + " classes, " + std::to_string(pc.obs_dim) +
                      " inputs)");
  }
  const bool lookahead = planned ? o.planner->config.lookahead() : o.policy_lookahead.lookahead();
  if (lookahead && !planned && o.stochastic) {
    // Its rollouts take the policy's mean action: a sampling policy would not do what they show.
    throw ConfigError("eval: a meta policy's lookahead needs its mean action (no --stochastic)");
  }
  auto MakeDecider = [&](Decider* d) {
    if (lookahead && planned) {
      d->lookahead = std::make_unique<LookaheadPlanner>(o.planner, config, frozen);
    } else if (lookahead) {
      auto runner = std::make_shared<PolicyRunner>(pc, NormalizerConfig());
      runner->LoadWeights(meta);
      runner->set_update_obs_stats(false);
      d->lookahead = std::make_unique<LookaheadPlanner>(runner, o.policy_lookahead, config, frozen);
    } else if (planned) {
      d->planner = std::make_unique<MetaPlanner>(o.planner);
    } else {
      d->runner = std::make_unique<PolicyRunner>(pc, NormalizerConfig());
      d->runner->LoadWeights(meta);
      d->runner->set_update_obs_stats(false);
    }
  };
  const int threads = std::clamp(o.threads, 1, o.trials);
  std::vector<TrialResult> results(o.trials);
  std::atomic<int> next{0}, done{0}, successes{0};
  std::mutex progress_mu;
  std::exception_ptr error;
  auto worker = [&]() {
    try {
      MetaEnv env(config);
      env.SetFrozenPolicies(frozen);
      Decider decider;
      MakeDecider(&decider);
      for (int i = next++; i < o.trials; i = next++) {
        results[i] = RunTrial(env, decider, o, i, nullptr);
        successes += results[i].success;
        const int d = ++done;
        if (o.progress) {
          std::lock_guard<std::mutex> lock(progress_mu);
          o.progress(d, successes.load());
        }
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(progress_mu);
      if (!error) error = std::current_exception();
      next = o.trials;  // the others stop too
    }
  };
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t) pool.emplace_back(worker);
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);

  // Aggregates, in trial order (independent of the threads).
  int n_success = 0, n_fell = 0;
  std::vector<double> min_d, t_sit, pos_cm, yaw_deg, height_cm, min_d_success, min_d_failure;
  // Transition counts per start side (the chair faces +x: theta > 0 is its left, +y).
  std::map<std::string, std::map<std::string, std::map<std::string, int>>> trans;
  std::map<std::string, int> seq_count;
  std::map<std::string, std::array<int, 2>> seq_ends;      // sequence -> {successes, falls}
  std::map<std::string, std::array<int, 2>> side_success;  // side -> {successes, trials}
  for (const TrialResult& r : results) {
    if (o.sit_starts != nullptr) {
      o.sit_starts->insert(o.sit_starts->end(), r.sit_starts.begin(), r.sit_starts.end());
    }
    if (o.failed_sit_starts != nullptr && !r.success) {
      o.failed_sit_starts->insert(o.failed_sit_starts->end(), r.sit_starts.begin(),
                                  r.sit_starts.end());
    }
  }
  for (const TrialResult& r : results) {
    n_success += r.success;
    n_fell += r.fell;
    min_d.push_back(r.min_dist_m);
    (r.success ? min_d_success : min_d_failure).push_back(r.min_dist_m);
    if (r.success) {
      t_sit.push_back(r.time_to_sit_s);
      pos_cm.push_back(100.0 * r.pos_err_m);
      height_cm.push_back(100.0 * r.height_m);
      yaw_deg.push_back(r.yaw_err_rad * 180.0 / M_PI);
    }
    const std::string side = r.spawn_theta >= 0 ? "left" : "right";
    side_success[side][0] += r.success;
    side_success[side][1] += 1;
    std::string prev = "start", seq;
    for (int id : r.sequence) {
      trans[side][prev][SubtaskName(id)] += 1;
      prev = SubtaskName(id);
      seq += (seq.empty() ? "" : ">") + prev;
    }
    trans[side][prev]["end"] += 1;
    seq_count[seq] += 1;
    seq_ends[seq][0] += r.success;
    seq_ends[seq][1] += r.fell;
  }
  const double n = o.trials;
  const auto ci = WilsonInterval95(n_success, o.trials);
  std::vector<std::pair<int, std::string>> seqs;
  for (const auto& [s, c] : seq_count) seqs.push_back({c, s});
  std::sort(seqs.begin(), seqs.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : a.second < b.second;
  });
  Json top = Json::array();
  for (size_t i = 0; i < seqs.size() && i < 10; ++i) {
    const std::array<int, 2>& ends = seq_ends[seqs[i].second];
    top.push_back({{"sequence", seqs[i].second},
                   {"trials", seqs[i].first},
                   {"successes", ends[0]},
                   {"falls", ends[1]}});
  }
  Json sides = Json::object();
  for (const auto& [side, c] : side_success) {
    sides[side] = {{"trials", c[1]}, {"success_rate", c[1] ? double(c[0]) / c[1] : 0.0}};
  }
  Json j{{"task", "sit_chair"},
         {"zone", config.env.spawn.zone},
         {"chair", config.env.chair},
         {"trials", o.trials},
         {"seed", o.seed},
         {"stochastic", o.stochastic},
         {"threads", threads},
         {"success_rate", n_success / n},
         {"success_ci95", {ci[0], ci[1]}},
         {"min_dist_mean_m", MeanOf(min_d)},
         {"min_dist_std_m", StdOf(min_d)},
         {"fall_rate", n_fell / n},
         {"seated_position_error_cm_mean", MeanOf(pos_cm)},
         {"seated_height_cm_mean", MeanOf(height_cm)},
         {"min_dist_success_mean_m", MeanOf(min_d_success)},
         {"min_dist_failure_mean_m", MeanOf(min_d_failure)},
         {"seated_orientation_error_deg_mean", MeanOf(yaw_deg)},
         {"time_to_sit_s_mean", MeanOf(t_sit)},
         {"by_side", sides},
         {"transitions", trans},
         {"sequences", top},
         {"choices", config.Section<SitChairTaskConfig>().meta.choices},
         {"decider", planned ? "planner" : "meta policy"}};
  j["handover_values"] = HandoverValues(results);
  if (planned) j["planner"] = o.planner->ToJson();
  if (!planned && lookahead) {
    const PlannerConfig& la = o.policy_lookahead;
    j["lookahead_delays_s"] = la.lookahead_delays_s;
    j["lookahead_sides"] = la.lookahead_sides;
    j["lookahead_straight_s"] = la.lookahead_straight_s;
    j["lookahead_rank"] = la.lookahead_rank;
    j["lookahead_detour_deg"] = la.lookahead_detour_deg;
  }
  if (lookahead) {
    // How much looking ahead was done and changed, and whether the simulator was exact (the
    // outcome is the one the last look ahead predicted).
    int points = 0, rollouts = 0, changed = 0, predicted = 0, agreed = 0, not_worse = 0;
    int rules_success = 0;
    for (const TrialResult& r : results) {
      points += r.lookahead.points;
      rollouts += r.lookahead.rollouts;
      changed += r.lookahead.changed;
      predicted += r.lookahead.predicted_any;
      agreed += r.lookahead_agreed;
      not_worse += r.lookahead_not_worse;
      rules_success += r.lookahead.predicted_any ? r.lookahead.rules.success : r.success;
    }
    j["lookahead"] = {{"points_per_trial", points / n},
                      {"rollouts_per_trial", rollouts / n},
                      {"changed_per_trial", changed / n},
                      {"trials_predicted", predicted},
                      {"trials_as_predicted", agreed},
                      {"trials_not_worse_than_rules", not_worse},
                      // The rules alone on the same trials (from the first look ahead on, with
                      // the same restores): what looking ahead bought.
                      {"rules_success_rate", rules_success / n}};
  }

  // Filmstrip material: the first success and the first failure, replayed (trials are
  // deterministic for their seed).
  auto replay = [&](bool want_success, MetaTrialFrames* out) {
    if (out == nullptr) return;
    for (int i = 0; i < o.trials; ++i) {
      if (results[i].success != want_success) continue;
      MetaEnv env(config);
      env.SetFrozenPolicies(frozen);
      Decider d;
      MakeDecider(&d);
      out->trial = i;
      out->success = want_success;
      RunTrial(env, d, o, i, &out->frames);
      return;
    }
  };
  replay(true, first_success);
  replay(false, first_failure);
  return j;
}

void SaveTransitionMatrixPng(const Json& result, const std::string& path) {
  const std::vector<std::string> rows = {"start", "turn_left", "turn_right", "sit", "walk"};
  const std::vector<std::string> cols = {"turn_left", "turn_right", "sit", "walk", "end"};
  const int cell = 90, label_w = 110, head_h = 60, gap = 30;
  const std::vector<std::string> sides = {"left", "right"};
  const int panel_w = label_w + cell * static_cast<int>(cols.size());
  Canvas c(gap + sides.size() * (panel_w + gap), head_h + cell * rows.size() + gap,
           Rgb{255, 255, 255});
  const Json& t = result.contains("transitions") ? result["transitions"] : Json::object();
  for (size_t p = 0; p < sides.size(); ++p) {
    const int x0 = gap + static_cast<int>(p) * (panel_w + gap);
    c.DrawText(x0, 8, "start side: " + sides[p], Rgb{0, 0, 0}, 3);
    for (size_t j = 0; j < cols.size(); ++j) {
      c.DrawText(x0 + label_w + static_cast<int>(j) * cell + 4, head_h - 18, cols[j], Rgb{0, 0, 0});
    }
    const Json side = t.contains(sides[p]) ? t[sides[p]] : Json::object();
    for (size_t i = 0; i < rows.size(); ++i) {
      const int y = head_h + static_cast<int>(i) * cell;
      c.DrawText(x0, y + cell / 2 - 5, rows[i], Rgb{0, 0, 0});
      const Json row = side.contains(rows[i]) ? side[rows[i]] : Json::object();
      int total = 0;
      for (const auto& [k, v] : row.items()) total += v.get<int>();
      for (size_t j = 0; j < cols.size(); ++j) {
        const int n = row.contains(cols[j]) ? row[cols[j]].get<int>() : 0;
        const double share = total > 0 ? static_cast<double>(n) / total : 0.0;
        const uint8_t shade = static_cast<uint8_t>(255 - 200 * share);
        const int x = x0 + label_w + static_cast<int>(j) * cell;
        c.FillRect(x, y, x + cell - 2, y + cell - 2, Rgb{shade, shade, 255});
        c.DrawText(x + 8, y + cell / 2 - 5, std::to_string(n),
                   share > 0.6 ? Rgb{255, 255, 255} : Rgb{0, 0, 0});
      }
    }
  }
  c.SavePng(path);
}

}  // namespace perch
