#include "tasks/task_env.h"

#include "common/config_file.h"
#include "tasks/fall_restart.h"

namespace perch {

TaskEnvConfig TaskEnvConfig::Defaults(const std::string& task) {
  Json j{{"task", task}};
  const TaskDef* def = FindTask(task);
  if (def != nullptr && !def->needs_chair) j["chair"] = "none";
  // Validates the name the same way a config file would.
  return FromJson(j, "task");
}

TaskEnvConfig TaskEnvConfig::FromJson(const Json& j, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected an object");
  Json env_json = j;
  TaskEnvConfig c;
  std::string task = "stand";
  GetOptional(j, "task", task, ctx);
  const TaskDef* def = task == "stand" ? nullptr : &GetTask(task, ctx + ".task");
  if (env_json.contains("walk")) {
    c.walk = WalkTaskConfig::FromJson(env_json["walk"], ctx + ".walk");
    env_json.erase("walk");
  }
  for (const std::string& other : TaskNames()) {
    if (other == task || other == "walk" || !env_json.contains(other)) continue;
    throw ConfigError(ctx + "." + other + ": a section for task \"" + other +
                      "\" but env.task is \"" + task + "\"");
  }
  if (def != nullptr) {
    if (def->name != "walk") {
      const Json* section = env_json.contains(task) ? &env_json[task] : nullptr;
      def->read(section, ctx + "." + task, &c);
      env_json.erase(task);
    }
    // The layout follows from the task; a config that says otherwise is refused by name.
    const ObsLayout layout = def->layout_for ? def->layout_for(c) : def->obs_layout;
    const std::string want = ObsLayoutName(layout);
    if (!env_json.contains("obs_layout")) {
      env_json["obs_layout"] = want;
    } else if (env_json["obs_layout"] != want) {
      throw ConfigError(ctx + ".obs_layout: task \"" + task + "\" observes \"" + want + "\" (" +
                        std::to_string(ObsLayoutDim(layout)) + "-d), got " +
                        env_json["obs_layout"].dump());
    }
  }
  c.env = EnvConfig::FromJson(env_json, ctx);
  if (def != nullptr && def->needs_chair && c.env.chair == "none") {
    throw ConfigError(ctx + ".chair: task \"" + task + "\" needs a chair (got \"none\")");
  }
  if (def != nullptr && def->check) def->check(c, ctx);
  return c;
}

TaskEnvConfig TaskEnvConfig::Load(const std::string& path) {
  const Json j = LoadComposedConfig(path);  // a `base` config counts (common/config_file.h)
  // An experiment config (configs/default.json, a run's config.json) carries the env in "env".
  if (j.is_object() && j.contains("env") && j["env"].is_object()) {
    return FromJson(j["env"], path + ": env");
  }
  return FromJson(j, path);
}

Json TaskEnvConfig::ToJson() const {
  Json j = env.ToJson();
  const TaskDef* def = FindTask(env.task);
  if (def == nullptr || def->name == "walk") {
    j["walk"] = walk.ToJson();
  } else if (def->write) {
    j[env.task] = def->write(*this);
  }
  return j;
}

std::unique_ptr<Task> MakeTaskFor(const TaskEnvConfig& config) {
  if (config.env.task == "stand") return MakeTask(config.env);
  return GetTask(config.env.task, "env.task").make(config);
}

std::unique_ptr<HumanoidChairEnv> MakeTaskHumanoidEnv(const TaskEnvConfig& config) {
  return std::make_unique<HumanoidChairEnv>(config.env, MakeTaskFor(config));
}

std::unique_ptr<Env> MakeTaskEnv(const TaskEnvConfig& config) {
  if (config.env.task == "walk" && config.walk.fall_restart_prob > 0) {
    std::unique_ptr<Task> task = MakeTaskFor(config);
    auto* t = static_cast<WalkTask*>(task.get());  // MakeTaskFor builds a WalkTask for "walk"
    return std::make_unique<FallRestartEnv>(
        std::make_unique<HumanoidChairEnv>(config.env, std::move(task)), t, config.walk);
  }
  return MakeTaskHumanoidEnv(config);
}

}  // namespace perch
