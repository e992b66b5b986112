// Builds the humanoid-chair env with any task by name: the actor's drop-in for envs' MakeEnv.
// Config JSON: the env's (envs/env_config.h) plus an optional "walk" section (WalkTaskConfig);
// env.task picks the task ("stand" | "walk").
#pragma once

#include <memory>
#include <string>

#include "common/env.h"
#include "common/json_util.h"
#include "envs/env_config.h"
#include "envs/humanoid_env.h"
#include "tasks/walk.h"

namespace perch {

struct TaskEnvConfig {
  EnvConfig env;
  WalkTaskConfig walk;

  // Defaults for a task: "walk" has no chair (the authors' walk env has none; the chair frame's
  // origin would stand where the walk starts).
  static TaskEnvConfig Defaults(const std::string& task);
  // Strict, like EnvConfig::FromJson; a "walk" section is read with the walk preset rules.
  static TaskEnvConfig FromJson(const Json& j, const std::string& ctx);
  // A task env config file, or an experiment config / run config.json (its "env" section).
  static TaskEnvConfig Load(const std::string& path);
  Json ToJson() const;  // env fields + "walk"
};

std::unique_ptr<Task> MakeTaskFor(const TaskEnvConfig& config);
std::unique_ptr<HumanoidChairEnv> MakeTaskHumanoidEnv(const TaskEnvConfig& config);
// Same interface and behaviour as MakeEnv(config.env) for "stand"; adds the tasks of tasks/. A
// walk config with fall_restart_prob > 0 gets the training curriculum (FallRestartEnv); eval and
// tools that need the HumanoidChairEnv itself use MakeTaskHumanoidEnv, which never adds it.
std::unique_ptr<Env> MakeTaskEnv(const TaskEnvConfig& config);

}  // namespace perch
