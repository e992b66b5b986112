// Builds the humanoid-chair env with any registered task by name (tasks/registry.h): the actor's
// drop-in for envs' MakeEnv. Config JSON: the env's (envs/env_config.h) plus the task's own
// section under its name ("walk", "turn_left", "turn_right", "sit"); env.task picks the task.
#pragma once

#include <memory>
#include <stdexcept>
#include <string>

#include "common/env.h"
#include "common/json_util.h"
#include "envs/env_config.h"
#include "envs/humanoid_env.h"
#include "tasks/registry.h"
#include "tasks/walk.h"

namespace perch {

struct TaskEnvConfig {
  EnvConfig env;
  // The "walk" section. Read whatever the task (run configs of other tasks written before the
  // registry carry one); written for walk and stand.
  WalkTaskConfig walk;
  // The section of env.task for the other registered tasks (turn_left, turn_right, sit).
  std::shared_ptr<const TaskSection> section;

  // The task's section as its typed config; std::logic_error when env.task has another type.
  template <class C>
  const C& Section() const {
    const auto* s = dynamic_cast<const TaskSectionOf<C>*>(section.get());
    if (s == nullptr) throw std::logic_error("TaskEnvConfig: no such section for " + env.task);
    return s->config;
  }
  // A copy to modify (sections are shared between copies of the config).
  template <class C>
  C& MutableSection() {
    auto copy = std::make_shared<TaskSectionOf<C>>(Section<C>());
    section = copy;
    return copy->config;
  }

  // Defaults for a task: tasks without a chair in the authors' env (walk, turns) get none.
  static TaskEnvConfig Defaults(const std::string& task);
  // Strict, like EnvConfig::FromJson: the task must be registered, its observation layout and
  // chair must suit it, a section of another task is refused.
  static TaskEnvConfig FromJson(const Json& j, const std::string& ctx);
  // A task env config file, or an experiment config / run config.json (its "env" section).
  static TaskEnvConfig Load(const std::string& path);
  Json ToJson() const;  // env fields + the task's section
  double control_dt() const { return env.physics.physics_dt * env.physics.substeps; }
};

std::unique_ptr<Task> MakeTaskFor(const TaskEnvConfig& config);
std::unique_ptr<HumanoidChairEnv> MakeTaskHumanoidEnv(const TaskEnvConfig& config);
// Same interface and behaviour as MakeEnv(config.env) for "stand"; adds the tasks of tasks/. A
// walk config with fall_restart_prob > 0 gets the training curriculum (FallRestartEnv); eval and
// tools that need the HumanoidChairEnv itself use MakeTaskHumanoidEnv, which never adds it.
std::unique_ptr<Env> MakeTaskEnv(const TaskEnvConfig& config);

}  // namespace perch
