#include "tasks/task_env.h"

#include "tasks/fall_restart.h"

namespace perch {

TaskEnvConfig TaskEnvConfig::Defaults(const std::string& task) {
  TaskEnvConfig c;
  c.env.task = task;
  if (task == "walk") c.env.chair = "none";
  // Validates the name the same way a config file would.
  return FromJson(c.ToJson(), "task");
}

TaskEnvConfig TaskEnvConfig::FromJson(const Json& j, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected an object");
  Json env_json = j;
  TaskEnvConfig c;
  if (env_json.contains("walk")) {
    c.walk = WalkTaskConfig::FromJson(env_json["walk"], ctx + ".walk");
    env_json.erase("walk");
  }
  c.env = EnvConfig::FromJson(env_json, ctx);
  return c;
}

TaskEnvConfig TaskEnvConfig::Load(const std::string& path) {
  const Json j = LoadJsonFile(path);
  // An experiment config (configs/default.json, a run's config.json) carries the env in "env".
  if (j.is_object() && j.contains("env") && j["env"].is_object()) {
    return FromJson(j["env"], path + ": env");
  }
  return FromJson(j, path);
}

Json TaskEnvConfig::ToJson() const {
  Json j = env.ToJson();
  j["walk"] = walk.ToJson();
  return j;
}

std::unique_ptr<Task> MakeTaskFor(const TaskEnvConfig& config) {
  if (config.env.task == "walk") {
    const PhysicsConfig& p = config.env.physics;
    return std::make_unique<WalkTask>(config.walk, p.physics_dt * p.substeps);
  }
  return MakeTask(config.env);  // stand (and unknown names: ConfigError)
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
