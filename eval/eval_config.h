// What `perch eval` and the commands beside it (sample-end-poses, train-local) evaluate: a task
// config resolved from --config, the model's saved config or the task's defaults, then the
// command line's overrides; a meta policy's lookahead from a file.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "hierarchy/chain_plan.h"
#include "tasks/task_env.h"
#include "tasks/task_eval.h"

namespace perch {

// Command-line overrides of a task config; empty / negative: keep the file's value.
struct ConfigOverrides {
  std::string task;         // empty: the config's task
  std::string config_path;  // empty: the model's saved config, else the task's defaults
  std::string stage, variant, action_mode, chair;
  std::string start;               // "fixed", "reference" or "end-poses"
  std::vector<std::string> banks;  // --start end-poses: the start-state banks
  std::string bank_ang_vel;        // "keep" / "zero": the bank state's torso angular velocity
  double target_turn_prob = -1.0;
  double start_noise = 0.02;  // turn / sit: start_joint_noise_rad for evaluation [rad]
};

// Whether any of a meta policy's lookahead fields (the --lookahead-* flags) is off its default.
bool SetsLookahead(const PlannerConfig& c);

// `perch eval --lookahead FILE`: a meta policy's lookahead from a JSON object of the
// --lookahead-* flags' fields (as in sit_chair.meta.planner), instead of the flags (`flags`, which
// must then be at their defaults). ConfigError naming the file and the key otherwise.
PlannerConfig LookaheadFromFile(const std::string& path, const PlannerConfig& flags);

// Task config: --config's, else the model's saved one, else the task's defaults; then the
// command-line overrides. Warns when --config's task section differs from the saved one.
TaskEnvConfig ResolveConfig(const ConfigOverrides& o, const std::string& model_path);

// A --chair naming several chairs: "all" (every preset in data/chairs/) or a directory (every
// chair file *.json in it). Each is {row name, the --chair value of that one}, sorted by name;
// empty when --chair names one chair.
std::vector<std::pair<std::string, std::string>> ChairSet(const std::string& chair);

// The registered tasks and "chain" (the scripted walk -> turn -> sit chain).
std::vector<std::string> EvalTaskNames();

}  // namespace perch
