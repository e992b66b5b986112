#include "eval/eval_config.h"

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <set>

#include "common/paths.h"
#include "envs/chair.h"
#include "envs/humanoid_model.h"
#include "tasks/model_source.h"
#include "tasks/registry.h"
#include "tasks/state_bank.h"

namespace perch {

// Whether any of a meta policy's lookahead fields (the --lookahead-* flags) is off its default.
bool SetsLookahead(const PlannerConfig& c) {
  return c.lookahead() || c.lookahead_rank != PlannerConfig().lookahead_rank ||
         !c.lookahead_detour_deg.empty();
}

// `perch eval --lookahead FILE`: a meta policy's lookahead from a JSON object of the
// --lookahead-* flags' fields (as in sit_chair.meta.planner), instead of the flags (`flags`, which
// must then be at their defaults). ConfigError naming the file and the key otherwise.
PlannerConfig LookaheadFromFile(const std::string& path, const PlannerConfig& flags) {
  if (SetsLookahead(flags)) {
    throw ConfigError("--lookahead " + path +
                      ": not with --lookahead-delays-s / --lookahead-sides / "
                      "--lookahead-straight-s / --lookahead-detour-deg / --lookahead-rank (the "
                      "file holds them)");
  }
  const Json j = LoadJsonFile(path);
  if (!j.is_object()) throw ConfigError(path + ": not a JSON object");
  const std::vector<std::string>& keys = LookaheadFieldNames();
  std::string known;
  for (const std::string& k : keys) known += (known.empty() ? "" : ", ") + k;
  for (const auto& [k, v] : j.items()) {
    if (std::find(keys.begin(), keys.end(), k) == keys.end()) {
      throw ConfigError(path + ": \"" + k + "\" is not a lookahead field (" + known + ")");
    }
  }
  // The planner config's own checks (types, ranges, at most 8 times, a detour needs its times);
  // with only lookahead keys, every other field keeps its default, as with the flags.
  PlannerConfig file = PlannerConfig::FromJson(j, path);
  if (!file.lookahead()) {
    throw ConfigError(path +
                      ": no lookahead (lookahead_delays_s, lookahead_sides or "
                      "lookahead_straight_s)");
  }
  return file;
}

// Task config: --config's, else the model's saved one, else the task's defaults; then the
// command-line overrides. Warns when --config's task section differs from the saved one.
TaskEnvConfig ResolveConfig(const ConfigOverrides& o, const std::string& model_path) {
  const Json saved = model_path.empty() ? Json() : SavedConfig(model_path);
  auto env_of = [](const Json& j) { return j.is_object() && j.contains("env") ? j["env"] : j; };
  Json j;
  std::string ctx;
  if (!o.config_path.empty()) {
    j = TaskEnvConfig::Load(o.config_path).ToJson();
    ctx = o.config_path;
    if (saved.is_object()) {
      const Json s = TaskEnvConfig::FromJson(env_of(saved), model_path + " (saved)").ToJson();
      const std::string t = s.value("task", "");
      if (s.value("task", "") != j.value("task", "") || (s.contains(t) && s[t] != j[t])) {
        std::cerr << "eval: warning: --config " << o.config_path << " differs from the config "
                  << "saved with " << model_path << " in the task section (\"" << t
                  << "\"); using --config\n";
      }
    }
  } else if (saved.is_object()) {
    j = TaskEnvConfig::FromJson(env_of(saved), model_path + " (saved config)").ToJson();
    ctx = model_path + " (saved config)";
  } else {
    if (o.task.empty()) {
      throw ConfigError("--task: required when neither --config nor the model carries a config");
    }
    j = TaskEnvConfig::Defaults(o.task).ToJson();
    ctx = "--task " + o.task;
  }
  const std::string task = j["task"].get<std::string>();
  if (!o.task.empty() && task != o.task) {
    throw ConfigError(ctx + ": task is \"" + task + "\", --task says \"" + o.task + "\"");
  }
  Json& sec = j[task == "stand" ? "walk" : task];
  if (task == "walk") {
    if (!o.stage.empty()) sec["stage"] = o.stage;
    if (o.start == "reference") sec["reference_state_init"] = true;
    if (o.start == "fixed") sec["reference_state_init"] = false;
    if (o.target_turn_prob >= 0) sec["target_turn_prob"] = o.target_turn_prob;
  } else if (!o.stage.empty() || o.target_turn_prob > 0) {
    throw ConfigError("--stage / --target-turn-prob: only for --task walk");
  }
  if (task == "sit") {
    // Evaluation starts from the clip's first frame (Table 4), unless asked otherwise.
    sec["reference_state_init"] = o.start == "reference";
  }
  if (task == "turn_left" || task == "turn_right" || task == "sit") {
    sec["start_joint_noise_rad"] = o.start_noise;
  }
  if ((task == "turn_left" || task == "turn_right") && o.start != "reference") {
    sec["rsi_prob"] = 0.0;  // evaluation starts turns at frame 0 (Table 4)
  }
  if (o.start == "end-poses") {
    if (o.banks.empty()) throw ConfigError("--start end-poses: needs --bank FILE");
    if (task != "turn_left" && task != "turn_right" && task != "sit" && task != "walk") {
      throw ConfigError("--start end-poses: only for walk, turn_left, turn_right and sit");
    }
    // Keeps the config's other start settings (zero_root_ang_vel).
    if (!sec.contains("start") || !sec["start"].is_object()) sec["start"] = Json::object();
    sec["start"]["banks"] = o.banks;
    sec["start"]["prob"] = 1.0;
    if (!o.bank_ang_vel.empty()) sec["start"]["zero_root_ang_vel"] = o.bank_ang_vel == "zero";
  } else if (!o.banks.empty() || !o.bank_ang_vel.empty()) {
    throw ConfigError("--bank / --bank-ang-vel: only with --start end-poses");
  } else if (task != "stand" && sec.contains("start")) {
    // A fine-tuned policy is evaluated from its clip's first frame unless asked otherwise, as
    // the subtask itself is: without the banks' placement noise (sit applies it to every
    // episode of a run that lists banks), so the retention figure compares like with like.
    sec["start"]["prob"] = 0.0;
    sec["start"]["banks"] = Json::array();
  }
  if (!o.variant.empty()) {
    // The preset replaces the reward fields, so drop them before re-reading.
    for (const char* k : {"similarity", "root_vel_weight", "root_vel_alpha", "target_weight",
                          "target_k", "rot_weight", "rot_alpha", "hold_phase", "approach_weight"}) {
      sec.erase(k);
    }
    sec["reward_variant"] = o.variant;
  }
  if (!o.action_mode.empty()) j["action_mode"] = o.action_mode;
  if (!o.chair.empty() && ChairSet(o.chair).empty()) j["chair"] = o.chair;
  // Evaluation measures the chair asked for, not a training distribution of chairs.
  if (j.contains("chair_random")) j["chair_random"]["prob"] = 0.0;
  if (task == "stand") j.erase("walk");
  return TaskEnvConfig::FromJson(j, ctx);
}

std::vector<std::pair<std::string, std::string>> ChairSet(const std::string& chair) {
  std::vector<std::pair<std::string, std::string>> set;
  if (chair == "all") {
    for (const std::string& preset : Chair::PresetNames()) set.push_back({preset, preset});
    return set;
  }
  std::error_code ec;
  if (chair.empty()) return set;
  // A folder as given, else under the data root (a recipe's "data/chairs/meshes" from any cwd);
  // a bare name is a preset, never a folder.
  std::string dir = chair;
  if (chair.find('/') == std::string::npos) return set;
  if (!std::filesystem::is_directory(dir, ec)) dir = ResolveProjectPath(chair);
  if (!std::filesystem::is_directory(dir, ec)) return set;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (e.path().extension() == ".json") {
      set.push_back({e.path().stem().string(), std::filesystem::absolute(e.path()).string()});
    }
  }
  std::sort(set.begin(), set.end());
  if (set.empty())
    throw ConfigError("--chair " + chair + ": a directory with no chair files (*.json)");
  return set;
}

std::vector<std::string> EvalTaskNames() {
  std::vector<std::string> names = TaskNames();
  names.push_back("chain");  // the scripted walk -> turn -> sit chain (hierarchy/hierarchy.h)
  return names;
}

}  // namespace perch
