#include "hierarchy/meta_eval.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "common/file_util.h"
#include "hierarchy/meta_env.h"
#include "hierarchy/meta_expert.h"
#include "hierarchy/meta_lookahead.h"
#include "policy/policy.h"
#include "tasks/episode_loop.h"
#include "tasks/recording.h"
#include "tasks/state_bank.h"
#include "tasks/task_eval.h"

namespace perch {

static_assert(kSit == 2, "MetaEvalOptions::starts_subtask defaults to the sit");

namespace {

struct TrialResult {
  MetaTrialRecord rec;
  std::vector<proto::BankState> sit_starts;  // its hand-overs to o.starts_subtask (when asked)
};

// Who decides in a trial: a meta policy (runner), the planner, or the planner with lookahead.
struct Decider {
  std::unique_ptr<PolicyRunner> runner;
  std::unique_ptr<MetaPlanner> planner;
  std::unique_ptr<LookaheadPlanner> lookahead;
};

// The meta policy (or the planner, or the lookahead) in the shared episode loop
// (tasks/episode_loop.h).
class MetaDriver : public EpisodeDriver {
 public:
  MetaDriver(MetaEnv* env, Decider* d, const MetaEvalOptions& o) : env_(env), d_(d), o_(o) {}
  void Begin(int /*episode*/, uint64_t env_seed, const float* obs) override {
    if (o_.record_routes) start_obs.assign(obs, obs + env_->spec().obs_dim);
    if (d_->planner != nullptr) d_->planner->Reset();
    if (d_->lookahead != nullptr) d_->lookahead->Reset(env_seed);
  }
  bool Act(const float* obs, Rng& rng, float* action) override {
    if (d_->lookahead != nullptr) {
      d_->lookahead->Act(*env_, action);
    } else if (d_->planner != nullptr) {
      d_->planner->Act(*env_, action);
    } else {
      d_->runner->Act(obs, rng, !o_.stochastic, nullptr, action);
    }
    return true;
  }
  std::vector<float> start_obs;  // --record-routes: the trial's first observation

 private:
  MetaEnv* env_;
  Decider* d_;
  const MetaEvalOptions& o_;
};

// One trial on `env` decided by `d` (both owned by the calling thread).
TrialResult RunTrial(MetaEnv& env, Decider& d, const MetaEvalOptions& o, int trial,
                     std::vector<PoseFrame>* frames) {
  const double dt = env.humanoid().spec().control_dt;
  if (frames != nullptr) {
    env.on_control_step = [&](const HumanoidChairEnv& h, const StepResult&, int active) {
      frames->push_back(
          PoseFrameOf(h.humanoid_state(), h.episode_step() * dt, SubtaskName(active)));
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
  int unperturbed = -1;
  if (o.perturb.any()) {
    // The same trial without the perturbations first: its outcome for the flip rate, and the span
    // its outcome was decided in (to its success, else to its end: the trial goes on seated
    // after a success) the horizon the perturbations' moments are drawn in. Hooks see only the
    // perturbed run.
    auto on_step = std::move(env.on_control_step);
    auto on_begin = std::move(env.on_subtask_begin);
    env.on_control_step = nullptr;
    env.on_subtask_begin = nullptr;
    env.SetPerturbation(Perturbation(), 1);
    MetaDriver plain(&env, &d, o);
    RunEpisode(&env, trial, o.seed, {env.spec().max_episode_steps, true}, &plain);
    const MetaEpisode& u = env.episode();
    unperturbed = u.success_step >= 0 ? 1 : 0;
    env.SetPerturbation(o.perturb, u.success_step >= 0 ? u.success_step : u.control_steps);
    env.on_control_step = std::move(on_step);
    env.on_subtask_begin = std::move(on_begin);
  }
  MetaDriver driver(&env, &d, o);
  RunEpisode(&env, trial, o.seed, {env.spec().max_episode_steps, true}, &driver);
  env.SetPerturbation(Perturbation(), 1);
  std::vector<float> start_obs = std::move(driver.start_obs);
  env.on_control_step = nullptr;
  env.on_subtask_begin = nullptr;
  const MetaEpisode& e = env.episode();
  TrialResult out;
  MetaTrialRecord& rec = out.rec;
  rec.trial = trial;
  rec.success = e.success_step >= 0;
  rec.fell = e.fell;
  rec.min_dist_m = e.min_dist_m;
  rec.time_to_sit_s = rec.success ? e.success_step * dt : 0.0;
  rec.pos_err_m = e.seated_pos_err_m;
  rec.height_m = e.seated_height_m;
  rec.yaw_err_rad = e.seated_yaw_err_rad;
  rec.spawn_theta = e.spawn_theta;
  rec.sequence = e.sequence;
  rec.begin_value = e.begin_value;
  rec.build = PerchVersion();
  rec.unperturbed_success = unperturbed;
  out.sit_starts = std::move(sit_starts);
  if (d.lookahead != nullptr) {
    const LookaheadPlanner::Stats& st = d.lookahead->stats();
    const LookaheadOutcome& p = st.predicted;
    rec.has_lookahead = true;
    rec.la_points = st.points;
    rec.la_rollouts = st.rollouts;
    rec.la_changed = st.changed;
    rec.la_predicted_any = st.predicted_any;
    // Before the first look ahead nothing differed: the decider alone did what the trial did.
    rec.la_rules_success = st.predicted_any ? st.rules.success : rec.success;
    rec.la_as_predicted = st.predicted_any && p.success == rec.success &&
                          (p.success ? p.success_step == e.success_step : p.fell == e.fell);
    rec.la_not_worse = st.predicted_any && !d.lookahead->Better(st.rules, LookaheadOutcome::Of(e));
    if (o.record_routes) {
      rec.start_obs = std::move(start_obs);
      for (const LookaheadPlanner::Stats::Route& r : st.routes) {
        rec.routes.push_back({r.straight_steps, r.detour_deg, r.outcome.success, r.outcome.fell,
                              r.outcome.success_step, r.outcome.min_dist_m});
      }
    }
  }
  return out;
}

// How well a subtask's own critic at its start tells the runs that went on from those that
// failed: per subtask, the runs, their share that went on (a turn or walk: not ended by a fall;
// sit: the trial succeeded with it), the mean value of each group, the AUC (the chance that a run
// that went on started with a higher value than one that failed; 0.5: no information) and the
// share that went on per value quartile (cut points in `quartile_cuts`).
Json HandoverValues(const std::vector<MetaTrialRecord>& results) {
  std::array<std::vector<std::pair<float, bool>>, kNumSubtasks> runs;
  for (const MetaTrialRecord& r : results) {
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

Json MetaTrialRecord::ToJson() const {
  Json j{{"trial", trial},
         {"success", success},
         {"fell", fell},
         {"min_dist_m", min_dist_m},
         {"time_to_sit_s", time_to_sit_s},
         {"pos_err_m", pos_err_m},
         {"height_m", height_m},
         {"yaw_err_rad", yaw_err_rad},
         {"spawn_theta", spawn_theta},
         {"sequence", sequence},
         {"begin_value", begin_value}};
  if (!build.empty()) j["build"] = build;
  if (unperturbed_success >= 0) j["unperturbed_success"] = unperturbed_success == 1;
  if (!start_obs.empty()) j["start_obs"] = start_obs;
  if (!routes.empty()) {
    Json rs = Json::array();
    for (const Route& r : routes) {
      rs.push_back({{"straight_steps", r.straight_steps},
                    {"detour_deg", std::isnan(r.detour_deg) ? Json() : Json(r.detour_deg)},
                    {"success", r.success},
                    {"fell", r.fell},
                    {"success_step", r.success_step},
                    {"min_dist_m", r.min_dist_m}});
    }
    j["routes"] = rs;
  }
  if (has_lookahead) {
    j["lookahead"] = {{"points", la_points},
                      {"rollouts", la_rollouts},
                      {"changed", la_changed},
                      {"predicted_any", la_predicted_any},
                      {"rules_success", la_rules_success},
                      {"as_predicted", la_as_predicted},
                      {"not_worse", la_not_worse}};
  }
  return j;
}

MetaTrialRecord MetaTrialRecord::FromJson(const Json& j, const std::string& where) {
  if (!j.is_object()) throw ConfigError(where + ": not a JSON object");
  MetaTrialRecord r;
  GetRequired(j, "trial", r.trial, where);
  if (r.trial < 0) throw ConfigError(where + ": \"trial\" " + std::to_string(r.trial) + " < 0");
  GetRequired(j, "success", r.success, where);
  GetRequired(j, "fell", r.fell, where);
  GetRequired(j, "min_dist_m", r.min_dist_m, where);
  GetRequired(j, "time_to_sit_s", r.time_to_sit_s, where);
  GetRequired(j, "pos_err_m", r.pos_err_m, where);
  GetRequired(j, "height_m", r.height_m, where);
  GetRequired(j, "yaw_err_rad", r.yaw_err_rad, where);
  GetRequired(j, "spawn_theta", r.spawn_theta, where);
  GetRequired(j, "sequence", r.sequence, where);
  GetRequired(j, "begin_value", r.begin_value, where);
  GetOptional(j, "build", r.build, where);
  if (j.contains("unperturbed_success")) {
    bool u = false;
    GetRequired(j, "unperturbed_success", u, where);
    r.unperturbed_success = u ? 1 : 0;
  }
  GetOptional(j, "start_obs", r.start_obs, where);
  if (j.contains("routes")) {
    const Json& rs = j.at("routes");
    if (!rs.is_array()) throw ConfigError(where + ".routes: not an array");
    for (size_t i = 0; i < rs.size(); ++i) {
      const std::string w = where + ".routes[" + std::to_string(i) + "]";
      if (!rs[i].is_object()) throw ConfigError(w + ": not a JSON object");
      Route route;
      GetRequired(rs[i], "straight_steps", route.straight_steps, w);
      const Json& d = rs[i].contains("detour_deg") ? rs[i].at("detour_deg") : Json();
      if (!d.is_null() && !d.is_number()) throw ConfigError(w + ".detour_deg: not a number");
      route.detour_deg = d.is_null() ? std::nan("") : d.get<double>();
      GetRequired(rs[i], "success", route.success, w);
      GetRequired(rs[i], "fell", route.fell, w);
      GetRequired(rs[i], "success_step", route.success_step, w);
      GetRequired(rs[i], "min_dist_m", route.min_dist_m, w);
      r.routes.push_back(route);
    }
  }
  for (int id : r.sequence) {
    if (id < 0 || id >= kNumSubtasks) {
      throw ConfigError(where + ": \"sequence\" holds " + std::to_string(id) + ", not a subtask");
    }
  }
  if (j.contains("lookahead")) {
    const Json& l = j.at("lookahead");
    const std::string w = where + ".lookahead";
    if (!l.is_object()) throw ConfigError(w + ": not a JSON object");
    r.has_lookahead = true;
    GetRequired(l, "points", r.la_points, w);
    GetRequired(l, "rollouts", r.la_rollouts, w);
    GetRequired(l, "changed", r.la_changed, w);
    GetRequired(l, "predicted_any", r.la_predicted_any, w);
    GetRequired(l, "rules_success", r.la_rules_success, w);
    GetRequired(l, "as_predicted", r.la_as_predicted, w);
    GetRequired(l, "not_worse", r.la_not_worse, w);
  }
  return r;
}

Json MetaEvalHeader(const TaskEnvConfig& config, const proto::ModelWeights& meta,
                    const std::vector<FrozenPolicyData>& frozen, const MetaEvalOptions& o) {
  const bool planned = o.planner != nullptr;
  const bool lookahead = planned ? o.planner->config.lookahead() : o.policy_lookahead.lookahead();
  Json h{{"task", "sit_chair"},
         {"zone", config.env.spawn.zone},
         {"chair", config.env.chair},
         {"seed", o.seed},
         {"stochastic", o.stochastic},
         {"choices", config.Section<SitChairTaskConfig>().meta.choices},
         {"decider", planned ? "planner" : "meta policy"},
         {"looks_ahead", lookahead},
         {"env", config.ToJson()}};
  if (planned) {
    h["planner"] = o.planner->ToJson();
  } else {
    h["meta_sha256"] = Sha256Hex(meta.SerializeAsString());
  }
  if (!planned && lookahead) {
    h.update(LookaheadJson(o.policy_lookahead));
  }
  // Only when on, so that the records of unperturbed evaluations keep their headers.
  if (o.perturb.any()) h["perturbation"] = o.perturb.ToJson();
  Json subs = Json::object();
  for (const FrozenPolicyData& f : frozen) subs[f.name] = Sha256Hex(f.model);
  h["frozen_sha256"] = subs;
  Json banks = Json::array();
  for (const std::string& b : config.Section<SitChairTaskConfig>().start.banks) {
    banks.push_back(std::filesystem::exists(b) ? FileSha256(b) : std::string("missing"));
  }
  h["start_banks_sha256"] = banks;
  return h;
}

Json AggregateMeta(const Json& header, std::vector<MetaTrialRecord> results) {
  if (results.empty()) throw ConfigError("eval: no trials to aggregate");
  std::sort(results.begin(), results.end(),
            [](const MetaTrialRecord& a, const MetaTrialRecord& b) { return a.trial < b.trial; });
  for (size_t i = 1; i < results.size(); ++i) {
    if (results[i].trial == results[i - 1].trial) {
      throw ConfigError("eval: trial " + std::to_string(results[i].trial) + " twice");
    }
  }
  // Aggregates, in trial order (independent of the threads and the shards).
  int n_success = 0, n_fell = 0;
  std::vector<double> min_d, t_sit, pos_cm, yaw_deg, height_cm, min_d_success, min_d_failure;
  // Transition counts per start side (the chair faces +x: theta > 0 is its left, +y).
  std::map<std::string, std::map<std::string, std::map<std::string, int>>> trans;
  std::map<std::string, int> seq_count;
  std::map<std::string, std::array<int, 2>> seq_ends;      // sequence -> {successes, falls}
  std::map<std::string, std::array<int, 2>> side_success;  // side -> {successes, trials}
  std::map<std::string, int> builds;                       // build -> trials it ran
  for (const MetaTrialRecord& r : results) {
    builds[r.build.empty() ? "(not recorded)" : r.build] += 1;
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
  const int trials = static_cast<int>(results.size());
  const double n = trials;
  const auto ci = WilsonInterval95(n_success, trials);
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
  Json j = Json::object();
  std::vector<std::string> keys = {"task",    "zone",    "chair",   "seed",        "stochastic",
                                   "choices", "decider", "planner", "perturbation"};
  keys.insert(keys.end(), LookaheadFieldNames().begin(), LookaheadFieldNames().end());
  for (const std::string& k : keys) {
    if (header.contains(k)) j[k] = header[k];
  }
  j.update(Json{{"trials", trials},
                {"first_trial", results.front().trial},
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
                // Which program ran the trials: more than one when a resumed evaluation spans
                // builds (the header cannot see a code change).
                {"builds", builds}});
  j["handover_values"] = HandoverValues(results);
  if (header.contains("perturbation")) {
    std::vector<bool> plain, perturbed;
    for (const MetaTrialRecord& r : results) {
      if (r.unperturbed_success < 0) {
        throw ConfigError("eval: trial " + std::to_string(r.trial) +
                          " of a perturbed evaluation has no unperturbed outcome");
      }
      plain.push_back(r.unperturbed_success == 1);
      perturbed.push_back(r.success);
    }
    int u = 0;
    for (bool b : plain) u += b;
    j["unperturbed_success_rate"] = u / n;
    j.update(FlipRate(plain, perturbed));
  }
  if (header.value("looks_ahead", false)) {
    // How much looking ahead was done and changed, and whether the simulator was exact (the
    // outcome is the one the last look ahead predicted).
    int points = 0, rollouts = 0, changed = 0, predicted = 0, agreed = 0, not_worse = 0;
    int rules_success = 0;
    for (const MetaTrialRecord& r : results) {
      points += r.la_points;
      rollouts += r.la_rollouts;
      changed += r.la_changed;
      predicted += r.la_predicted_any;
      agreed += r.la_as_predicted;
      not_worse += r.la_not_worse;
      rules_success += r.la_rules_success;
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
  return j;
}

std::string MetaRecordsHeaderLine(const Json& header) {
  return Json{{"perch_meta_eval_records", 1}, {"header", header}}.dump();
}

MetaRecordsFile ReadMetaRecords(const std::string& path) {
  return ParseMetaRecords(ReadFileBytes(path, "the records file"), path);
}

MetaRecordsFile ParseMetaRecords(const std::string& text, const std::string& path) {
  std::vector<std::string> lines;
  std::vector<size_t> ends;  // the byte after each complete line's newline
  size_t at = 0;
  while (at < text.size()) {
    const size_t nl = text.find('\n', at);
    lines.push_back(text.substr(at, nl == std::string::npos ? std::string::npos : nl - at));
    ends.push_back(nl == std::string::npos ? std::string::npos : nl + 1);
    at = nl == std::string::npos ? text.size() : nl + 1;
  }
  MetaRecordsFile out;
  if (lines.empty()) throw ConfigError(path + ": empty, not a records file (perch eval --records)");
  Json head;
  try {
    head = Json::parse(lines[0]);
  } catch (const Json::exception&) {
    throw ConfigError(path + ":1: not a records file (perch eval --records): no JSON header");
  }
  if (!head.is_object() || head.value("perch_meta_eval_records", 0) != 1 ||
      !head.contains("header") || !head["header"].is_object()) {
    throw ConfigError(path +
                      ":1: not a records file (perch eval --records): the header lacks "
                      "\"perch_meta_eval_records\": 1 and its \"header\"");
  }
  if (ends[0] == std::string::npos) {
    throw ConfigError(path + ":1: the header line has no end (a records file is one per line)");
  }
  out.header = head["header"];
  // The env config as this build reads it: a field added since the file was made takes its
  // default, so the file resumes and merges while that field stays at its default.
  if (out.header.contains("env") && out.header["env"].is_object()) {
    try {
      out.header["env"] = TaskEnvConfig::FromJson(out.header["env"], "header.env").ToJson();
    } catch (const ConfigError&) {
      // Not a config this build reads (a field since removed): compared as written, and refused.
    }
  }
  out.complete_bytes = ends[0];
  std::set<int> seen;
  for (size_t i = 1; i < lines.size(); ++i) {
    const std::string where = path + ":" + std::to_string(i + 1);
    // A run killed mid-write leaves its last line without its newline: that trial runs again.
    if (ends[i] == std::string::npos) {
      out.torn_tail = true;
      break;
    }
    Json j;
    try {
      j = Json::parse(lines[i]);
    } catch (const Json::exception&) {
      throw ConfigError(where + ": not JSON (a records file is corrupt; nothing was changed)");
    }
    MetaTrialRecord r = MetaTrialRecord::FromJson(j, where);
    if (!seen.insert(r.trial).second) {
      throw ConfigError(where + ": trial " + std::to_string(r.trial) + " twice");
    }
    out.records.push_back(std::move(r));
    out.complete_bytes = ends[i];
  }
  return out;
}

namespace {

// The value at a dotted path of `h` ("env.spawn.zone"), shortened, for a refusal.
std::string BriefAt(const Json& h, const std::string& path) {
  const Json* at = &h;
  for (size_t b = 0; b <= path.size();) {
    const size_t e = std::min(path.find('.', b), path.size());
    const std::string k = path.substr(b, e - b);
    if (!at->is_object() || !at->contains(k)) return "(none)";
    at = &(*at)[k];
    b = e + 1;
  }
  const std::string v = at->dump();
  return v.size() > 80 ? v.substr(0, 77) + "..." : v;
}

}  // namespace

MetaRecordsWriter::~MetaRecordsWriter() {
  if (fd_ >= 0) ::close(fd_);  // releases the lock
}

void MetaRecordsWriter::Append(const std::string& line) {
  size_t done = 0;
  while (done < line.size()) {
    const ssize_t n = ::write(fd_, line.data() + done, line.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      throw std::runtime_error("--records " + path_ + ": write failed: " + std::strerror(errno));
    }
    done += static_cast<size_t>(n);
  }
}

MetaRecordsWriter::Opened MetaRecordsWriter::Open(const std::string& path, const Json& header,
                                                  MetaEvalOptions* o) {
  const std::string ctx = "--records " + path;
  path_ = path;
  // One inode for the whole run (no rename), locked, so that a second evaluation on the same
  // file cannot interleave its trials or cut this one's line.
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd_ < 0) throw ConfigError(ctx + ": cannot open: " + std::strerror(errno));
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    throw ConfigError(ctx +
                      ": in use by another evaluation (locked); wait for it or name "
                      "another file");
  }
  std::string text;
  {
    char buf[1 << 16];
    off_t off = 0;
    for (;;) {
      const ssize_t n = ::pread(fd_, buf, sizeof(buf), off);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) throw ConfigError(ctx + ": cannot read: " + std::strerror(errno));
      if (n == 0) break;
      text.append(buf, static_cast<size_t>(n));
      off += n;
    }
  }
  Opened opened;
  // Empty, or a header cut short before its newline (killed while making it): a new file.
  if (text.empty() || text.find('\n') == std::string::npos) {
    if (!text.empty() && ::ftruncate(fd_, 0) != 0) {
      throw ConfigError(ctx + ": cannot truncate: " + std::strerror(errno));
    }
    Append(MetaRecordsHeaderLine(header) + "\n");
  } else {
    MetaRecordsFile f = ParseMetaRecords(text, path);
    const std::string diff = FirstHeaderDifference(f.header, header);
    if (!diff.empty() && f.records.empty() && !f.torn_tail) {
      // A header and no trial (a run refused or killed before its first trial ended): nothing
      // to keep, so this run's header replaces it.
      if (::ftruncate(fd_, 0) != 0) {
        throw ConfigError(ctx + ": cannot truncate: " + std::strerror(errno));
      }
      Append(MetaRecordsHeaderLine(header) + "\n");
    } else if (!diff.empty()) {
      throw ConfigError(ctx + ": its trials were run with another \"" + diff + "\" (" +
                        BriefAt(f.header, diff) + ", now " + BriefAt(header, diff) +
                        "); name a new file, or the same model, config and flags");
    }
    for (const MetaTrialRecord& r : f.records) {
      if (r.trial < o->first_trial || r.trial >= o->first_trial + o->trials) {
        throw ConfigError(ctx + ": holds trial " + std::to_string(r.trial) +
                          ", outside this run's trials " + std::to_string(o->first_trial) + " .. " +
                          std::to_string(o->first_trial + o->trials - 1) +
                          " (--first-trial / --trials)");
      }
    }
    if (f.torn_tail && ::ftruncate(fd_, static_cast<off_t>(f.complete_bytes)) != 0) {
      throw ConfigError(ctx + ": cannot cut its torn last line: " + std::strerror(errno));
    }
    opened.resumed = static_cast<int>(f.records.size());
    opened.torn_tail = f.torn_tail;
    o->done = std::move(f.records);
  }
  o->on_record = [this](const MetaTrialRecord& r) { Append(r.ToJson().dump() + "\n"); };
  return opened;
}

std::string FirstHeaderDifference(const Json& a, const Json& b) {
  std::set<std::string> keys;
  for (const auto& [k, v] : a.items()) keys.insert(k);
  for (const auto& [k, v] : b.items()) keys.insert(k);
  for (const std::string& k : keys) {
    if (k == "about") continue;  // where the files were, not what ran
    if (!a.contains(k) || !b.contains(k)) return k;
    if (a[k].is_object() && b[k].is_object()) {
      const std::string sub = FirstHeaderDifference(a[k], b[k]);
      if (!sub.empty()) return k + "." + sub;
    } else if (a[k] != b[k]) {
      return k;
    }
  }
  return "";
}

namespace {

// The records a resumed evaluation brings: each inside this call's trials and once; none when
// hand-over banks are asked for (every trial must run here then).
void CheckResumeRecords(const MetaEvalOptions& o) {
  const int end_trial = o.first_trial + o.trials;
  std::set<int> seen;
  for (const MetaTrialRecord& r : o.done) {
    if (r.trial < o.first_trial || r.trial >= end_trial) {
      throw ConfigError("eval: a record of trial " + std::to_string(r.trial) +
                        " lies outside this evaluation's trials " + std::to_string(o.first_trial) +
                        " .. " + std::to_string(end_trial - 1));
    }
    if (!seen.insert(r.trial).second) {
      throw ConfigError("eval: trial " + std::to_string(r.trial) + " recorded twice");
    }
  }
  if (!o.done.empty() && (o.sit_starts != nullptr || o.failed_sit_starts != nullptr)) {
    throw ConfigError(
        "eval: hand-over banks need every trial run in this call (not resumed from records)");
  }
}

// What decides in a trial: the meta policy or the scripted planner, alone or with a lookahead.
// One per thread.
struct DeciderFactory {
  const TaskEnvConfig& config;
  const proto::ModelWeights& meta;
  const std::vector<FrozenPolicyData>& frozen;
  const MetaEvalOptions& o;
  PolicyConfig pc;
  bool planned = false, lookahead = false;

  void Make(Decider* d) const {
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
  }
};

// The trials not in o.done, in order.
std::vector<int> TrialsToRun(const MetaEvalOptions& o) {
  std::vector<bool> have(o.trials, false);
  for (const MetaTrialRecord& r : o.done) have[r.trial - o.first_trial] = true;
  std::vector<int> todo;
  for (int i = 0; i < o.trials; ++i) {
    if (!have[i]) todo.push_back(o.first_trial + i);
  }
  return todo;
}

// Runs `todo` on `threads` threads (each its own env and decider), reporting each record as it
// finishes; results in the order of `todo`.
std::vector<TrialResult> RunTrials(const TaskEnvConfig& config,
                                   const std::vector<FrozenPolicyData>& frozen,
                                   const MetaEvalOptions& o, const DeciderFactory& deciders,
                                   const std::vector<int>& todo, int threads) {
  const int n_todo = static_cast<int>(todo.size());
  std::vector<TrialResult> results(n_todo);
  int prior_successes = 0;
  for (const MetaTrialRecord& r : o.done) prior_successes += r.success;
  std::atomic<int> next{0}, done{static_cast<int>(o.done.size())}, successes{prior_successes};
  std::mutex progress_mu;
  std::exception_ptr error;
  auto worker = [&]() {
    try {
      MetaEnv env(config);
      env.SetFrozenPolicies(frozen);
      Decider decider;
      deciders.Make(&decider);
      for (int i = next++; i < n_todo; i = next++) {
        results[i] = RunTrial(env, decider, o, todo[i], nullptr);
        successes += results[i].rec.success;
        const int d = ++done;
        if (o.progress || o.on_record) {
          std::lock_guard<std::mutex> lock(progress_mu);
          if (o.on_record) o.on_record(results[i].rec);
          if (o.progress) o.progress(d, successes.load());
        }
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(progress_mu);
      if (!error) error = std::current_exception();
      next = n_todo;  // the others stop too
    }
  };
  std::vector<std::thread> pool;
  if (n_todo > 0) {
    for (int t = 0; t < threads; ++t) pool.emplace_back(worker);
  }
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
  return results;
}

}  // namespace

Json EvaluateMeta(const TaskEnvConfig& config_in, const proto::ModelWeights& meta,
                  const std::vector<FrozenPolicyData>& frozen, const MetaEvalOptions& o,
                  MetaTrialFrames* first_success, MetaTrialFrames* first_failure) {
  if (o.trials < 1) throw ConfigError("eval: --trials must be >= 1");
  if (o.first_trial < 0) throw ConfigError("eval: --first-trial must be >= 0");
  CheckResumeRecords(o);
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
  const DeciderFactory deciders{config, meta, frozen, o, pc, planned, lookahead};
  const std::vector<int> todo = TrialsToRun(o);
  const int threads = std::clamp(o.threads, 1, std::max(1, static_cast<int>(todo.size())));
  const std::vector<TrialResult> results = RunTrials(config, frozen, o, deciders, todo, threads);

  std::vector<MetaTrialRecord> records = o.done;
  for (const TrialResult& r : results) records.push_back(r.rec);
  // Hand-over banks in trial order (every trial ran here; checked above).
  for (const TrialResult& r : results) {
    if (o.sit_starts != nullptr) {
      o.sit_starts->insert(o.sit_starts->end(), r.sit_starts.begin(), r.sit_starts.end());
    }
    if (o.failed_sit_starts != nullptr && !r.rec.success) {
      o.failed_sit_starts->insert(o.failed_sit_starts->end(), r.sit_starts.begin(),
                                  r.sit_starts.end());
    }
  }
  Json j = AggregateMeta(MetaEvalHeader(config_in, meta, frozen, o), records);
  j["threads"] = threads;

  // Filmstrip material: the first success and the first failure, replayed (trials are
  // deterministic for their seed).
  std::sort(records.begin(), records.end(),
            [](const MetaTrialRecord& a, const MetaTrialRecord& b) { return a.trial < b.trial; });
  auto replay = [&](bool want_success, MetaTrialFrames* out) {
    if (out == nullptr) return;
    for (const MetaTrialRecord& r : records) {
      if (r.success != want_success) continue;
      MetaEnv env(config);
      env.SetFrozenPolicies(frozen);
      Decider d;
      deciders.Make(&d);
      out->trial = r.trial;
      out->success = want_success;
      RunTrial(env, d, o, r.trial, &out->frames);
      return;
    }
  };
  replay(true, first_success);
  replay(false, first_failure);
  return j;
}

}  // namespace perch
