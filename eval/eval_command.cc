#include "eval/eval_command.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <functional>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>

#include "common/paths.h"
#include "envs/chair.h"
#include "hierarchy/meta_env.h"
#include "hierarchy/meta_eval.h"
#include "hierarchy/meta_expert.h"
#include "tasks/model_source.h"
#include "tasks/recording.h"
#include "tasks/registry.h"
#include "viz/filmstrip.h"
#include "viz/transition_matrix.h"

namespace perch {
namespace {

// Writes --record's recording of (task, model files, config) once the evaluation is done.
using RecordingWriter =
    std::function<void(const std::string& task, const std::string& model, const Json& config)>;

// The meta policy's lookahead from the --lookahead-* flags or --lookahead FILE. Refused before
// any work (the planner's calibration, the trials).
PlannerConfig ResolveLookahead(const EvalCommand& o) {
  PlannerConfig la = o.lookahead;  // a meta policy's lookahead: only its lookahead_* fields count
  if (!o.lookahead_file.empty()) {
    la = LookaheadFromFile(o.lookahead_file, la);
  }
  if (o.planner && SetsLookahead(la)) {
    throw ConfigError(
        "--lookahead / --lookahead-delays-s / --lookahead-sides / --lookahead-straight-s / "
        "--lookahead-detour-deg / --lookahead-rank: for a meta policy; the planner's "
        "lookahead is its config's sit_chair.meta.planner.lookahead_*");
  }
  if (la.lookahead_rank != "sooner" && !la.lookahead()) {
    throw ConfigError(
        "--lookahead-rank: only with a lookahead (--lookahead-delays-s, --lookahead-sides "
        "or --lookahead-straight-s)");
  }
  // The planner config's own checks (at most 8 times, ranges, a detour needs its times).
  PlannerConfig::FromJson(la.ToJson(), "--lookahead-*");
  return la;
}

// The records file: made with its header, or resumed (the same header: the same trials);
// appended to as trials finish (hierarchy/meta_eval.h). Returns the trials resumed.
int OpenRecords(const EvalCommand& o, const TaskEnvConfig& mc,
                const proto::ModelWeights& meta_weights,
                const std::vector<FrozenPolicyData>& frozen, const std::string& model_file,
                MetaRecordsWriter* records, MetaEvalOptions* mo) {
  Json header = MetaEvalHeader(mc, meta_weights, frozen, *mo);
  header["about"] = {{"model", o.planner ? Json("planner") : Json(model_file)},
                     {"start_bank", o.start_bank}};
  const MetaRecordsWriter::Opened r = records->Open(o.records, header, mo);
  if (r.torn_tail) {
    std::cerr << "eval: " << o.records << ": its last line was cut short (a killed "
              << "run); that trial runs again\n";
  }
  const int resumed = r.resumed;
  if (resumed > 0) {
    std::cerr << "eval: " << o.records << ": " << resumed << " of " << mo->trials
              << " trials already run; resuming\n";
    // The header holds what ran, not the code: say when the file's trials came from
    // another build (the JSON's "builds" counts them).
    int other = 0;
    for (const MetaTrialRecord& t : mo->done) other += t.build != PerchVersion();
    if (other > 0) {
      std::cerr << "eval: " << o.records << ": " << other << " of its trials were run "
                << "by another build than this " << PerchVersion()
                << " (\"builds\" in the JSON); a change to the simulation between "
                << "them would mix two sets of trials\n";
    }
  }
  return resumed;
}

// Progress on stderr every 5% of the trials, and at least once a minute: a 10,000-trial run with
// the lookahead takes ~1.5 s a trial, so 5% is ~12 min apart. The rate counts this run's own
// trials (not those resumed from the records).
std::function<void(int, int)> ProgressPrinter(int trials, int resumed) {
  const auto t0 = std::chrono::steady_clock::now();
  const int every = std::max(1, trials / 20);
  auto last_print_s = std::make_shared<double>(0.0);
  return [=](int done, int successes) {
    const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (done % every != 0 && done != trials && sec - *last_print_s < 60) return;
    *last_print_s = sec;
    std::cerr << "eval: " << done << "/" << trials << " trials, success "
              << static_cast<double>(successes) / done << " so far, " << static_cast<int>(sec)
              << " s";
    const int ran = done - resumed;
    if (ran > 0 && done < trials) {
      std::cerr << ", " << std::setprecision(3) << sec / ran << " s a trial, about "
                << static_cast<int>((trials - done) * sec / ran / 60 + 0.5) << " min to go"
                << std::setprecision(6);
    }
    std::cerr << "\n";
  };
}

// <name>.png: the first success; <name>_failure.png: the first failure.
void SaveMetaFilmstrips(const EvalCommand& o, const TaskEnvConfig& mc, const MetaTrialFrames& ok,
                        const MetaTrialFrames& bad, Json* result) {
  const Chair chair = Chair::Load(mc.env.ChairPath());
  const HumanoidModel model = HumanoidModel::Load(mc.env.HumanoidPath());
  FilmstripOptions fo;
  fo.panel_px = o.panel_px;
  fo.follow = !o.fixed_window;
  // <name>.png: the first success; <name>_failure.png: the first failure.
  const std::string base = o.filmstrip.substr(0, o.filmstrip.rfind(".png"));
  for (const MetaTrialFrames* t : {&ok, &bad}) {
    if (t->frames.empty()) continue;
    const std::string path = t->success ? base + ".png" : base + "_failure.png";
    RenderFilmstrip(model, &chair, mc.env.chair_placement.Transform(),
                    PickFrames(t->frames, o.frames), fo)
        .SavePng(path);
    (*result)[t->success ? "filmstrip_success" : "filmstrip_failure"] = {{"path", path},
                                                                         {"trial", t->trial}};
  }
}

// The meta controller on the main task: the authors' zones as defined (whatever spawn the run
// trained with), walk start states from the evaluation bank (docs/meta.md). The planner is
// measured on each chair (where the sit's clip starts depends on it).
Json EvaluateMetaOnChair(EvalCommand& o, const TaskEnvConfig& on_chair) {
  const PlannerConfig la = ResolveLookahead(o);
  TaskEnvConfig mc = on_chair;
  mc.env.spawn = SpawnConfig();
  mc.env.spawn.zone = o.chain.zone;
  mc.MutableSection<SitChairTaskConfig>().start.banks = {o.start_bank};
  const std::string model_file = o.planner ? "" : ModelFile(o.model);
  std::vector<FrozenPolicyData> frozen;
  if (!o.planner) frozen = FrozenPoliciesIn(o.model);
  if (frozen.empty()) frozen = LoadFrozenPolicies(mc);
  MetaEvalOptions mo;
  if (o.planner) {
    mo.planner = std::make_shared<const MetaPlan>(
        BuildMetaPlan(mc, frozen, mc.Section<SitChairTaskConfig>().meta.planner));
  }
  mo.trials = o.trials > 0 ? o.trials : o.eval.episodes;
  mo.seed = o.eval.seed;
  mo.stochastic = o.eval.stochastic;
  mo.threads = o.threads;
  mo.first_trial = o.first_trial;
  mo.policy_lookahead = la;
  mo.perturb = o.eval.perturb;
  if (o.record_routes && (o.records.empty() || la.lookahead_straight_s.empty())) {
    throw ConfigError(
        "--record-routes: needs --records and a lookahead with straight-on starts "
        "(--lookahead-straight-s or lookahead_straight_s in --lookahead)");
  }
  mo.record_routes = o.record_routes;
  const proto::ModelWeights meta_weights =
      o.planner ? proto::ModelWeights() : LoadModelFile(model_file);
  std::vector<proto::BankState> sit_starts, failed_sit_starts;
  // Refuse before the work, as the bank writer would after it.
  for (const std::string* f : {&o.save_sit_starts, &o.save_failed_sit_starts}) {
    if (!f->empty() && std::filesystem::exists(*f) && !o.force) {
      throw ConfigError("--save-" + std::string(f == &o.save_sit_starts ? "" : "failed-") +
                        "sit-starts " + *f + ": exists (--force replaces it)");
    }
  }
  mo.starts_subtask = SubtaskIdOf(o.hand_overs_to);
  if (mo.starts_subtask < 0) {
    throw ConfigError("--hand-overs-to \"" + o.hand_overs_to +
                      "\": not a subtask (sit, turn_left, turn_right, walk)");
  }
  if (!o.save_sit_starts.empty()) mo.sit_starts = &sit_starts;
  if (!o.save_failed_sit_starts.empty()) mo.failed_sit_starts = &failed_sit_starts;
  MetaRecordsWriter records;
  const int resumed =
      o.records.empty() ? 0 : OpenRecords(o, mc, meta_weights, frozen, model_file, &records, &mo);
  const auto t0 = std::chrono::steady_clock::now();
  mo.progress = ProgressPrinter(mo.trials, resumed);
  MetaTrialFrames ok, bad;
  const bool film = !o.filmstrip.empty();
  Json result =
      EvaluateMeta(mc, meta_weights, frozen, mo, film ? &ok : nullptr, film ? &bad : nullptr);
  if (!o.records.empty()) {
    result["records"] = o.records;
    result["resumed_trials"] = resumed;
  }
  result["model"] = o.planner ? Json("planner") : Json(model_file);
  result["start_bank"] = o.start_bank;
  auto write_bank = [&](const std::string& file, std::vector<proto::BankState>& states,
                        const std::string& key) {
    if (file.empty()) return;
    if (states.empty()) {
      std::cerr << "eval: no hand-over to " << o.hand_overs_to << " for " << file
                << "; not written\n";
      result[key] = {{"file", file}, {"states", 0}};
      return;
    }
    const int n = static_cast<int>(states.size());
    WriteHandOverBank(file, "sit_chair", mc, o.planner ? "planner" : model_file, o.eval.seed,
                      o.eval.stochastic, mo.trials, states, o.force);
    result[key] = {{"file", file}, {"states", n}, {"hand_overs_to", o.hand_overs_to}};
  };
  write_bank(o.save_sit_starts, sit_starts, "sit_starts");
  write_bank(o.save_failed_sit_starts, failed_sit_starts, "failed_sit_starts");
  result["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (film) SaveMetaFilmstrips(o, mc, ok, bad, &result);
  if (!o.matrix_png.empty()) {
    SaveTransitionMatrixPng(result, o.matrix_png);
    result["transition_matrix_png"] = o.matrix_png;
  }
  return result;
}

void RunChain(EvalCommand& o, const RecordingWriter& write_recording) {
  // The scripted chain: four subtask policies on the sit_chair env, no meta policy.
  Json env{{"task", "sit_chair"},
           {"chair", o.cfg.chair.empty() ? "authors" : o.cfg.chair},
           {"spawn", {{"zone", o.chain.zone}}}};
  if (!o.cfg.config_path.empty()) {
    env = TaskEnvConfig::Load(o.cfg.config_path).ToJson();
    env["spawn"]["zone"] = o.chain.zone;
  }
  const TaskEnvConfig config = TaskEnvConfig::FromJson(env, "--task chain");
  std::array<proto::ModelWeights, kNumSubtasks> models;
  std::array<std::string, kNumSubtasks> files;
  std::array<Json, kNumSubtasks> saved;
  for (int id = 0; id < kNumSubtasks; ++id) {
    files[id] = ModelFile(ResolveProjectPath(o.chain.models[id]));
    models[id] = LoadModelFile(files[id]);
    saved[id] = SavedConfig(ResolveProjectPath(o.chain.models[id]));
  }
  o.chain.options.episodes = o.eval.episodes;
  o.chain.options.seed = o.eval.seed;
  o.chain.options.stochastic = o.eval.stochastic;
  std::vector<proto::BankState> sit_starts;
  if (!o.chain.save_sit_starts.empty()) {
    // Refuse before the work, as the bank writer would after it.
    if (std::filesystem::exists(o.chain.save_sit_starts) && !o.force) {
      throw ConfigError("--chain-save-sit-starts " + o.chain.save_sit_starts +
                        ": exists (--force replaces it)");
    }
    o.chain.options.sit_starts = &sit_starts;
  }
  std::vector<PoseFrame> frames;
  Json result = EvaluateChain(config, models, files, saved, o.chain.options,
                              o.filmstrip.empty() ? nullptr : &frames);
  if (!o.chain.save_sit_starts.empty()) {
    if (sit_starts.empty()) throw ConfigError("--chain-save-sit-starts: no episode reached sit");
    const int n = static_cast<int>(sit_starts.size());
    WriteHandOverBank(o.chain.save_sit_starts, "chain", config,
                      files[kWalk] + "," + files[kLeftTurn] + "," + files[kRightTurn], o.eval.seed,
                      o.eval.stochastic, o.eval.episodes, sit_starts, o.force);
    result["sit_starts"] = {{"file", o.chain.save_sit_starts}, {"states", n}};
  }
  std::string all_models;
  for (const std::string& f : files) all_models += (all_models.empty() ? "" : ",") + f;
  write_recording("chain", all_models, config.ToJson());
  if (!o.filmstrip.empty()) {
    const Chair chair = Chair::Load(config.env.ChairPath());
    const HumanoidModel model = HumanoidModel::Load(config.env.HumanoidPath());
    FilmstripOptions fo;
    fo.panel_px = o.panel_px;
    fo.follow = !o.fixed_window;
    RenderFilmstrip(model, &chair, config.env.chair_placement.Transform(),
                    PickFrames(frames, o.frames), fo)
        .SavePng(o.filmstrip);
    result["filmstrip"] = o.filmstrip;
  }
  if (o.json) {
    std::cout << result.dump() << "\n";
  } else {
    std::cout << "chain zone " << o.chain.zone << ": success_rate " << result["success_rate"] << " "
              << result["success_ci95"].dump() << ", min_dist " << result["min_dist_mean_m"]
              << " +- " << result["min_dist_std_m"] << " m\n";
  }
}

// Over the chairs of a --chair all / DIR run, each weighing the same: the mean success and the
// worst chair's (a checkpoint selected on "min_success_rate" is the one that fails no chair).
void AddChairAggregates(const Json& table, Json* result) {
  double sum = 0.0, worst = 1.0;
  std::string worst_chair;
  for (const auto& [name, r] : table.items()) {
    const double v = r.value("success_rate", 0.0);
    sum += v;
    if (worst_chair.empty() || v < worst) {
      worst = v;
      worst_chair = name;
    }
  }
  (*result)["chairs"] = static_cast<int>(table.size());
  (*result)["success_rate"] = table.empty() ? 0.0 : sum / static_cast<double>(table.size());
  (*result)["min_success_rate"] = worst;
  (*result)["min_success_chair"] = worst_chair;
}

void RunSitChair(EvalCommand& o, const TaskEnvConfig& config) {
  const auto chairs = ChairSet(o.cfg.chair);
  if (!chairs.empty() && (!o.filmstrip.empty() || !o.matrix_png.empty() || !o.records.empty())) {
    throw ConfigError("--filmstrip / --matrix-png / --records: not with --chair " + o.cfg.chair +
                      " (name one chair)");
  }
  if (!chairs.empty()) {
    // Every preset (--chair all) or every chair file of a folder, one row each.
    Json table = Json::object();
    for (const auto& [name, chair] : chairs) {
      ConfigOverrides co = o.cfg;
      co.chair = chair;
      std::cerr << "eval: chair " << name << "\n";
      Json r = EvaluateMetaOnChair(o, ResolveConfig(co, o.model));
      r.erase("sequences");
      table[name] = r;
    }
    Json all{{"task", "sit_chair"},
             {"model", o.planner ? Json("planner") : Json(ModelFile(o.model))},
             {"zone", o.chain.zone},
             {"per_chair", table}};
    AddChairAggregates(table, &all);
    if (o.json) {
      std::cout << all.dump() << "\n";
    } else {
      for (const auto& [name, r] : table.items()) {
        std::cout << "sit_chair zone " << o.chain.zone << " chair " << name << ": success_rate "
                  << r["success_rate"] << " " << r["success_ci95"].dump() << "\n";
      }
    }
    return;
  }
  const Json result = EvaluateMetaOnChair(o, config);
  if (o.json) {
    std::cout << result.dump() << "\n";
  } else {
    std::cout << "sit_chair zone " << o.chain.zone << ": success_rate " << result["success_rate"]
              << " " << result["success_ci95"].dump() << ", min_dist " << result["min_dist_mean_m"]
              << " +- " << result["min_dist_std_m"] << " m, falls " << result["fall_rate"] << "\n";
  }
}

// A subtask over seeded episodes (the task registry's evaluation), on one chair or on every
// preset (--chair all), with its filmstrip.
void RunTaskEval(EvalCommand& o, const TaskEnvConfig& config,
                 const RecordingWriter& write_recording) {
  const std::string model_file = ModelFile(o.model);
  const proto::ModelWeights weights = LoadModelFile(model_file);
  EvalRecording rec;
  std::cerr << "eval: " << model_file << " (version " << weights.version() << "), task "
            << config.env.task << ", " << o.eval.episodes << " episodes, seed " << o.eval.seed
            << "\n";
  const TaskDef& def = GetTask(config.env.task, "--task");
  if (!def.evaluate) throw ConfigError("--task " + def.name + ": has no evaluation");
  const auto chairs = ChairSet(o.cfg.chair);
  if (!chairs.empty()) {
    // Every preset (--chair all) or every chair file of a folder, one row each.
    Json table = Json::object();
    for (const auto& [name, chair] : chairs) {
      ConfigOverrides co = o.cfg;
      co.chair = chair;
      const TaskEnvConfig cc = ResolveConfig(co, o.model);
      std::cerr << "eval: chair " << name << "\n";
      Json r = def.evaluate(cc, weights, o.eval, nullptr);
      r.erase("fall_times_s");
      r.erase("fall_episodes");
      Json chair_json = LoadJsonFile(cc.env.ChairPath());
      if (chair_json.contains("source")) r["chair_source"] = chair_json["source"];
      table[name] = r;
    }
    Json result{{"model", model_file},
                {"task", config.env.task},
                {"per_chair", table},
                {"episodes_per_chair", o.eval.episodes},
                {"seed", o.eval.seed}};
    AddChairAggregates(table, &result);
    if (o.json) {
      std::cout << result.dump() << "\n";
    } else {
      for (const auto& [name, r] : table.items()) {
        std::cout << name << ": success_rate " << r["success_rate"] << " "
                  << r["success_ci95"].dump() << "\n";
      }
    }
    return;
  }
  Json result = def.evaluate(config, weights, o.eval, o.filmstrip.empty() ? nullptr : &rec);
  write_recording(config.env.task, model_file, config.ToJson());
  if (!o.record.empty()) result["recording"] = o.record;
  result["model"] = model_file;
  result["config"] = config.ToJson();
  if (!o.filmstrip.empty()) {
    std::unique_ptr<Chair> chair;
    const std::string chair_path = config.env.ChairPath();
    if (!chair_path.empty()) chair = std::make_unique<Chair>(Chair::Load(chair_path));
    const HumanoidModel model = HumanoidModel::Load(config.env.HumanoidPath());
    FilmstripOptions fo;
    fo.panel_px = o.panel_px;
    fo.follow = !o.fixed_window;
    fo.targets = rec.targets;
    const Canvas c = RenderFilmstrip(model, chair.get(), config.env.chair_placement.Transform(),
                                     PickFrames(rec.frames, o.frames), fo);
    c.SavePng(o.filmstrip);
    result["filmstrip"] = o.filmstrip;
    std::cerr << "eval: filmstrip of episode 0 (" << rec.frames.size() << " frames) -> "
              << o.filmstrip << "\n";
  }
  if (o.json) {
    std::cout << result.dump() << "\n";
  } else {
    std::cout << "task " << result["task"] << ", episodes " << result["episodes"]
              << ", success_rate " << result["success_rate"] << " (95% "
              << result["success_ci95"].dump() << "), fall_rate " << result["fall_rate"]
              << ", mean_imitation_reward " << result["mean_imitation_reward"] << "\n";
  }
}

}  // namespace

void RunEvalCommand(EvalCommand& o) {
  // --record: checked before the (long) evaluation, written after it.
  std::unique_ptr<EpisodeRecorder> recorder;
  if (!o.record.empty()) {
    if (!ChairSet(o.cfg.chair).empty()) {
      throw ConfigError("--record: not with --chair " + o.cfg.chair + " (name one chair)");
    }
    if (!o.force && std::filesystem::exists(o.record)) {
      throw ConfigError("--record " + o.record + ": exists; not overwritten (--force)");
    }
    recorder = std::make_unique<EpisodeRecorder>(o.record_episodes);
    o.eval.recorder = recorder.get();
    o.chain.options.recorder = recorder.get();
  }
  const RecordingWriter write_recording = [&](const std::string& task, const std::string& model,
                                              const Json& config) {
    if (!recorder) return;
    proto::Recording& r = recorder->recording();
    r.set_task(task);
    r.set_model(model);
    r.set_config_json(config.dump());
    r.set_seed(o.eval.seed);
    r.set_stochastic(o.eval.stochastic);
    r.set_perch_version(PerchVersion());
    WriteRecording(o.record, r, o.force);
    std::cerr << "eval: recording of " << r.episodes_size() << " episodes -> " << o.record << "\n";
  };
  const auto no_perturbation = [&](const std::string& task) {
    if (o.eval.perturb.any()) {
      throw ConfigError("--push, --obs-noise, --act-noise, --restore: not yet for --task " + task +
                        " (the subtasks' and sit_chair's evaluations take them)");
    }
  };
  if (o.cfg.task == "chain") {
    no_perturbation("chain");
    RunChain(o, write_recording);
    return;
  }
  if (o.planner && (!o.model.empty() || o.cfg.config_path.empty())) {
    throw ConfigError("--planner: needs --config (the sit_chair experiment) and no --model");
  }
  if (o.model.empty() && !o.planner) {
    throw ConfigError("--model: required (but for --task chain and --planner)");
  }
  const TaskEnvConfig config = ResolveConfig(o.cfg, o.model);
  if (o.planner && config.env.task != "sit_chair") {
    throw ConfigError("--planner: only for the sit_chair task, the config's is \"" +
                      config.env.task + "\"");
  }
  if (config.env.task == "sit_chair") {
    RunSitChair(o, config);
    return;
  }
  RunTaskEval(o, config, write_recording);
}

Json MergeEvalRecords(EvalMergeOptions o) {
  Json header;
  std::vector<MetaTrialRecord> all;
  std::map<int, std::string> owner;  // trial -> the file that holds it
  for (const std::string& file : o.files) {
    MetaRecordsFile f = ReadMetaRecords(file);
    if (f.torn_tail) {
      std::cerr << "eval-merge: " << file << ": its last line was cut short; left out\n";
    }
    if (header.is_null()) {
      header = f.header;
    } else if (const std::string d = FirstHeaderDifference(header, f.header); !d.empty()) {
      throw ConfigError(file + ": its trials were run with another \"" + d + "\" than " +
                        o.files.front() +
                        "'s; shards of one evaluation share model, "
                        "config, seed and flags");
    }
    for (MetaTrialRecord& r : f.records) {
      auto [it, fresh] = owner.emplace(r.trial, file);
      if (!fresh) {
        throw ConfigError(file + ": trial " + std::to_string(r.trial) + " is also in " +
                          it->second + " (overlapping shards)");
      }
      all.push_back(std::move(r));
    }
  }
  if (all.empty()) throw ConfigError("eval-merge: the records hold no trials");
  const int lo = owner.begin()->first;
  if (o.so_far) {
    int n = 0;
    while (owner.count(lo + n)) ++n;
    o.trials = n;
  }
  if (o.trials > 0) {
    all.erase(std::remove_if(all.begin(), all.end(),
                             [&](const MetaTrialRecord& r) { return r.trial >= lo + o.trials; }),
              all.end());
    owner.erase(owner.lower_bound(lo + o.trials), owner.end());
    if (static_cast<int>(all.size()) < o.trials) {
      throw ConfigError("eval-merge --trials " + std::to_string(o.trials) + ": the records " +
                        "hold " + std::to_string(all.size()) + " of trials " + std::to_string(lo) +
                        " .. " + std::to_string(lo + o.trials - 1));
    }
  }
  // Contiguous trials only: a gap is a shard not run (or not finished).
  const int hi = owner.rbegin()->first;
  if (hi - lo + 1 != static_cast<int>(all.size())) {
    int missing = lo;
    while (owner.count(missing)) ++missing;
    throw ConfigError("eval-merge: trials " + std::to_string(lo) + " .. " + std::to_string(hi) +
                      " lack " + std::to_string(hi - lo + 1 - static_cast<int>(all.size())) +
                      ", the first " + std::to_string(missing) +
                      " (resume that shard: perch eval --records its file)");
  }
  Json result = AggregateMeta(header, std::move(all));
  const Json about = header.value("about", Json::object());
  for (const char* k : {"model", "start_bank"}) {
    if (about.contains(k)) result[k] = about[k];
  }
  result["records"] = o.files;
  if (!o.matrix_png.empty()) {
    SaveTransitionMatrixPng(result, o.matrix_png);
    result["transition_matrix_png"] = o.matrix_png;
  }
  return result;
}

}  // namespace perch
