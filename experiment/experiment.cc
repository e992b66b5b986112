#include "experiment/experiment.h"

#include <algorithm>
#include <array>

#include "common/config_file.h"
#include "common/field_text.h"
#include "hierarchy/meta_env.h"
#include "tasks/task_env.h"

namespace perch {

ExperimentConfig ExperimentConfigFromJson(const Json& j, const std::string& ctx) {
  CheckKnownKeys(j, {"seed", "env_backend", "env", "mock_env", "policy", "ppo", "cluster"}, ctx);
  ExperimentConfig c;
  c.source = ctx;
  GetOptional(j, "seed", c.seed, ctx);
  GetOptional(j, "env_backend", c.env_backend, ctx);
  if (c.env_backend != "bullet" && c.env_backend != "mock") {
    throw ConfigError(ctx + ".env_backend: expected \"bullet\" or \"mock\", got \"" +
                      c.env_backend + "\"");
  }
  if (j.contains("env")) {
    if (!j["env"].is_object()) throw ConfigError(ctx + ".env: expected an object");
    c.env = j["env"];
  }
  if (j.contains("mock_env")) c.mock_env = MockEnvConfigFromJson(j["mock_env"], ctx + ".mock_env");
  if (j.contains("policy")) {
    if (!j["policy"].is_object()) throw ConfigError(ctx + ".policy: expected an object");
    c.policy = j["policy"];
  }
  c.ppo = j.contains("ppo") ? PpoConfigFromJson(j["ppo"], ctx + ".ppo") : PpoConfig::Subtask();
  if (j.contains("cluster")) c.cluster = ClusterConfigFromJson(j["cluster"], ctx + ".cluster");
  if (c.env_backend == "bullet") {
    // env.task and cluster.task name the same thing; a config where they differ would train one
    // task under the other's name.
    std::string env_task = "stand";
    GetOptional(c.env, "task", env_task, ctx + ".env");
    if (c.cluster.hierarchy_enabled) {
      throw ConfigError(ctx +
                        ".cluster.hierarchy_enabled: true: the hierarchy is trained with "
                        "cluster.task \"meta\" on env.task \"sit_chair\" (the meta env)");
    }
    if (c.cluster.task == "meta") {
      // The meta controller trains over the sit_chair env (hierarchy/meta_env.h).
      if (env_task != "sit_chair") {
        throw ConfigError(ctx + ".cluster.task: \"meta\" needs env.task \"sit_chair\", got \"" +
                          env_task + "\"");
      }
      if (c.cluster.hierarchy_meta_period != 30) {
        throw ConfigError(ctx +
                          ".cluster.hierarchy_meta_period: the meta period is "
                          "env.sit_chair.meta.period now (leave this at 30)");
      }
    } else if (!j.contains("cluster") || !j["cluster"].contains("task")) {
      c.cluster.task = env_task;  // derived when not given
      TaskFromName(env_task, ctx + ".env.task");
    } else if (c.cluster.task != env_task) {
      throw ConfigError(ctx + ".cluster.task: \"" + c.cluster.task + "\" but env.task is \"" +
                        env_task + "\" (they must name the same task)");
    }
  }
  return c;
}

ExperimentConfig LoadExperimentConfig(const std::string& path,
                                      const std::vector<std::string>& sets) {
  // Messages name the file; a field that came from --set is named the same way.
  const std::string& ctx = path;
  ExperimentConfig c = ExperimentConfigFromJson(LoadComposedConfig(path, sets), ctx);
  // Building one env validates the env section; resolving the policy checks the dims.
  std::unique_ptr<Env> env = MakeExperimentEnv(c);
  ResolvePolicyConfig(c, env->spec());
  if (c.cluster.target_success > 0 && !env->spec().has_success) {
    throw ConfigError(ctx + ".cluster.target_success: task \"" + c.cluster.task +
                      "\" has no success test (use cluster.max_samples)");
  }
  return c;
}

Json ToJson(const ExperimentConfig& c) {
  // The env section resolved (every field at the value in force), as the other sections are: a
  // run's config.json says what ran even after a default changes (the env's physics defaults did
  // once, issue 19, and an unresolved record hid it).
  const Json env = c.env_backend == "bullet"
                       ? TaskEnvConfig::FromJson(c.env, c.source + ".env").ToJson()
                       : c.env;
  Json j{{"seed", c.seed},
         {"env_backend", c.env_backend},
         {"env", env},
         {"mock_env", ToJson(c.mock_env)},
         {"policy", c.policy},
         {"ppo", ToJson(c.ppo)},
         {"cluster", ToJson(c.cluster)}};
  return j;
}

std::unique_ptr<Env> MakeExperimentEnv(const ExperimentConfig& c) {
  if (c.env_backend == "mock") return std::make_unique<MockEnv>(c.mock_env);
  // Any task by name (stand, walk, ...): tasks/ builds the humanoid-chair env with it.
  const TaskEnvConfig tc = TaskEnvConfig::FromJson(c.env, c.source + ".env");
  if (c.cluster.task == "meta") return std::make_unique<MetaEnv>(tc);
  return MakeTaskEnv(tc);
}

PolicyConfig ResolvePolicyConfig(const ExperimentConfig& c, const EnvSpec& spec) {
  const std::string ctx = c.source + ".policy";
  Json p = c.policy;
  const bool meta = c.cluster.task == "meta";
  for (const char* dim : {"obs_dim", "act_dim"}) {
    const int want = std::string(dim) == "obs_dim" ? spec.obs_dim : spec.act_dim;
    if (p.contains(dim) && !meta && p[dim] != want) {
      throw ConfigError(ctx + "." + dim + ": " + p[dim].dump() + " but the env has " +
                        std::to_string(want));
    }
  }
  p["obs_dim"] = spec.obs_dim;
  if (!meta) p["act_dim"] = spec.act_dim;
  if (!p.contains("kind")) p["kind"] = meta ? "meta" : "gaussian";
  if (meta && c.env_backend == "bullet") {
    // The switch's classes are the env's choice of subtasks; the target drives walk.
    const MetaConfig m =
        TaskEnvConfig::FromJson(c.env, c.source + ".env").Section<SitChairTaskConfig>().meta;
    for (const char* k : {"num_choices", "target_choice", "act_dim"}) {
      if (p.contains(k)) {
        throw ConfigError(ctx + "." + k + ": set by env.sit_chair.meta.choices for the meta task");
      }
    }
    p["num_choices"] = static_cast<int>(m.choices.size());
    p["target_choice"] = m.target_choice();
    p["act_dim"] = 2;
  }
  return PolicyConfigFromJson(p, ctx);
}

std::vector<FrozenPolicyData> ExperimentFrozenPolicies(const ExperimentConfig& c) {
  if (c.cluster.task != "meta" || c.env_backend != "bullet") return {};
  return LoadFrozenPolicies(TaskEnvConfig::FromJson(c.env, c.source + ".env"));
}

Json ConfigFieldTables() {
  Json t{{"env", EnvConfigFields().Describe()},
         {"ppo", PpoConfigFields().Describe()},
         {"cluster", ClusterConfigFields().Describe()},
         // The defaults of a subtask's policy; a meta's starts from PolicyConfig::Meta().
         {"policy", PolicyConfigFields().Describe()},
         {"mock_env", MockEnvConfigFields().Describe()}};
  // Each task's own section (env.<task> in a config).
  for (const std::string& name : TaskNames()) {
    const TaskDef& d = GetTask(name, "--fields");
    if (d.fields) t[name] = d.fields();
  }
  return t;
}

std::string ConfigFieldsText(const std::string& section, bool json) {
  const Json all = ConfigFieldTables();
  Json pick = Json::object();
  if (section == "all") {
    pick = all;
  } else if (all.contains(section)) {
    pick[section] = all[section];
  } else {
    std::string known = "env, ppo, cluster, policy, mock_env";
    for (const std::string& name : TaskNames()) {
      if (all.contains(name)) known += ", " + name;
    }
    throw ConfigError("--fields: unknown section \"" + section + "\" (" + known + ", all)");
  }
  if (json) return pick.dump(2) + "\n";
  std::vector<std::pair<std::string, Json>> tables;
  for (auto it = pick.begin(); it != pick.end(); ++it) {
    // A task's section sits under env in a config.
    const bool task = FindTask(it.key()) != nullptr;
    tables.push_back({task ? "env." + it.key() : it.key(), it.value()});
  }
  return DescribedFieldsText(tables);
}

std::string CompatKey(const ExperimentConfig& c, const PolicyConfig& policy) {
  Json pj = ToJson(policy);
  return Json{{"task", c.cluster.task}, {"env_backend", c.env_backend}, {"policy", pj}}.dump();
}

}  // namespace perch
