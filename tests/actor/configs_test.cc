// Every config committed under configs/ loads: experiment configs (perch train/learner/actor) give
// a learner setup and name an init_from checkpoint that is in the repository; task env configs
// (perch train-local / eval) parse as such.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include "actor/role_setup.h"
#include "common/config_file.h"
#include "common/json_util.h"
#include "common/paths.h"
#include "experiment/experiment.h"
#include "hierarchy/chain_plan.h"
#include "learner/service/learner_setup.h"
#include "tasks/task_env.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

TEST(CommittedConfigs, EveryConfigLoadsAndItsInitFromExists) {
  std::vector<fs::path> files;
  // configs/ and configs/experiments/ (branches name a `base`).
  for (const auto& e : fs::recursive_directory_iterator(fs::path(PERCH_SOURCE_DIR) / "configs")) {
    if (e.path().extension() == ".json") files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  ASSERT_GE(files.size(), 30u);
  int experiments = 0, task_configs = 0;
  int lookaheads = 0;
  for (const fs::path& f : files) {
    SCOPED_TRACE(f.string());
    const Json j = LoadComposedConfig(f.string());
    if (f.parent_path().filename() == "lookahead") {
      // perch eval --lookahead: a meta policy's lookahead, not a task or experiment config.
      ++lookaheads;
      PlannerConfig la;
      ASSERT_NO_THROW(la = PlannerConfig::FromJson(j, f.string()));
      EXPECT_TRUE(la.lookahead());
      for (const auto& [k, v] : j.items()) EXPECT_EQ(k.rfind("lookahead_", 0), 0u) << k;
    } else if (j.contains("cluster")) {
      ++experiments;
      ExperimentConfig cfg;
      ASSERT_NO_THROW(cfg = LoadExperimentConfig(f.string()));
      EXPECT_NO_THROW(MakeLearnerSetup(cfg));
      if (!cfg.cluster.init_from.empty()) {
        EXPECT_TRUE(fs::exists(ResolveProjectPath(cfg.cluster.init_from))) << cfg.cluster.init_from;
      }
    } else {
      ++task_configs;
      EXPECT_NO_THROW(TaskEnvConfig::Load(f.string()));
    }
  }
  EXPECT_GT(experiments, 0);
  EXPECT_GT(task_configs, 0);
  EXPECT_GE(lookaheads, 2);
}

std::string ExperimentError(const Json& j) {
  try {
    ExperimentConfigFromJson(j, "x.json");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(ExperimentConfig, ClusterTaskMustNameTheEnvsTaskAndIsDerivedWhenAbsent) {
  // The case: a left-turn cluster task over the walk env trains the wrong thing.
  const std::string e = ExperimentError(
      {{"env", {{"task", "walk"}, {"chair", "none"}}}, {"cluster", {{"task", "left_turn"}}}});
  EXPECT_NE(e.find("x.json.cluster.task"), std::string::npos) << e;
  EXPECT_NE(e.find("walk"), std::string::npos) << e;
  EXPECT_EQ(
      ExperimentError({{"env", {{"task", "turn_left"}}}, {"cluster", {{"task", "left_turn"}}}}),
      "");  // the older spelling of the same task
  const ExperimentConfig c = ExperimentConfigFromJson({{"env", {{"task", "sit"}}}}, "x.json");
  EXPECT_EQ(c.cluster.task, "sit");
  // The meta controller runs over sit_chair only: refused by field, not left to crash actors.
  EXPECT_NE(ExperimentError({{"env", {{"task", "sit"}}}, {"cluster", {{"task", "meta"}}}})
                .find("x.json.cluster.task"),
            std::string::npos);
  EXPECT_NE(
      ExperimentError({{"env", {{"task", "sit"}}}, {"cluster", {{"hierarchy_enabled", true}}}})
          .find("x.json.cluster.hierarchy_enabled"),
      std::string::npos);
  // The mock backend (transport tests) keeps its meta task.
  EXPECT_EQ(ExperimentError({{"env_backend", "mock"}, {"cluster", {{"task", "meta"}}}}), "");
}

// Which subtasks a meta run uses is checked when the learner's setup is made (perch train and
// --check-config do that first): a wrong model for a subtask is named, not a crash loop.
TEST(ExperimentConfig, MetaSubtasksAreCheckedAtStartUp) {
  Json j{
      {"env", {{"task", "sit_chair"}, {"sit_chair", {{"meta", {{"choices", {"walk", "sit"}}}}}}}},
      {"cluster", {{"task", "meta"}}}};
  ExperimentConfig c = ExperimentConfigFromJson(j, "x.json");
  const LearnerSetup ok = MakeLearnerSetup(c);
  EXPECT_EQ(ok.policy.num_choices, 2);
  EXPECT_EQ(ok.policy.target_choice, 0);
  EXPECT_EQ(ok.frozen.size(), 2u);
  j["env"]["sit_chair"]["meta"]["subtasks"] = {{"sit", "models/walk_stage1/policy.bin"}};
  c = ExperimentConfigFromJson(j, "x.json");
  try {
    MakeLearnerSetup(c);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("sit"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("walk_stage1"), std::string::npos) << e.what();
  }
  j["env"]["sit_chair"]["meta"]["subtasks"] = {{"sit", "models/none.bin"}};
  c = ExperimentConfigFromJson(j, "x.json");
  EXPECT_THROW(MakeLearnerSetup(c), ConfigError);
  j["env"]["sit_chair"]["meta"] = {{"choices", {"sit"}}};  // no walk: no target head
  c = ExperimentConfigFromJson(j, "x.json");
  try {
    MakeLearnerSetup(c);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("meta.choices"), std::string::npos) << e.what();
  }
}

TEST(ExperimentConfig, EachSubtaskConfigBuildsItsEnvWithThePapersObservation) {
  for (const auto& [file, dim] :
       std::vector<std::pair<std::string, int>>{{"configs/turn_left.json", 50},
                                                {"configs/turn_right.json", 50},
                                                {"configs/sit.json", 57}}) {
    SCOPED_TRACE(file);
    const ExperimentConfig c = LoadExperimentConfig(ResolveProjectPath(file));
    EXPECT_EQ(MakeExperimentEnv(c)->spec().obs_dim, dim);
  }
}

// The field tables (common/field_table.h) are what a run records: every field of the resolved
// ppo, cluster and env sections has a row (with its default) and every row is in the resolved
// config, so `perch config --fields` documents exactly what config.json holds.
TEST(CommittedConfigs, FieldTablesDescribeExactlyTheResolvedSections) {
  const std::string path = std::string(PERCH_SOURCE_DIR) + "/configs/default.json";
  const Json raw = LoadComposedConfig(path);
  Json resolved = ToJson(LoadExperimentConfig(path));
  // A run records the env section as written; the env's own resolution fills in the rest.
  resolved["env"] = TaskEnvConfig::FromJson(resolved["env"], "env").ToJson();
  const Json tables = ConfigFieldTables();
  for (const char* section : {"ppo", "cluster", "env"}) {
    SCOPED_TRACE(section);
    const Json& values = resolved[section];
    std::vector<std::string> rows;
    for (const Json& r : tables[section]) {
      const std::string name = r["name"];
      if (name == "_comment") continue;  // accepted, never written
      // A field written only when set (ppo.lr_schedule) has no default row value.
      if (r.contains("default") && r["default"].is_null()) continue;
      rows.push_back(name);
      ASSERT_TRUE(values.contains(name)) << name;
      const bool set = raw.contains(section) && raw[section].contains(name);
      if (r.contains("default")) {
        // A field the file leaves out is recorded with the table's default.
        if (!set) {
          EXPECT_EQ(r["default"], values[name]) << name;
        }
      } else {
        EXPECT_TRUE(values[name].is_object()) << name;
        EXPECT_EQ(r["fields"].size(), values[name].size()) << name;
      }
    }
    if (std::string(section) != "env") {  // env also holds the task's own sections
      EXPECT_EQ(rows.size(), values.size());
    }
  }
}

// A run records its env section resolved, as its other sections: every field at the value in
// force, so that a later change of a default cannot hide what the run ran with.
TEST(CommittedConfigs, TheResolvedConfigRecordsTheEnvWithEveryDefault) {
  const std::string path = std::string(PERCH_SOURCE_DIR) + "/configs/default.json";
  const Json raw = LoadComposedConfig(path);
  ASSERT_FALSE(raw["env"].contains("physics"));  // the file leaves the physics to the defaults
  const Json resolved = ToJson(LoadExperimentConfig(path));
  EXPECT_EQ(resolved["env"], TaskEnvConfig::FromJson(raw["env"], "env").ToJson());
  EXPECT_EQ(resolved["env"]["physics"]["chair_body"], "static");
  EXPECT_TRUE(resolved["env"]["walk"].contains("similarity"));
  // Read back, it is the same config.
  EXPECT_EQ(ToJson(ExperimentConfigFromJson(resolved, "resolved")), resolved);
}

// Each task's own section (`perch config --fields TASK`): its table's rows are exactly the keys the
// resolved section holds, with the defaults it records when the config leaves them out.
TEST(CommittedConfigs, TaskFieldTablesDescribeExactlyTheirResolvedSections) {
  const Json tables = ConfigFieldTables();
  int tasks = 0;
  for (const std::string& name : TaskNames()) {
    if (!tables.contains(name)) continue;
    SCOPED_TRACE(name);
    ++tasks;
    Json env{{"task", name}};
    if (name == "sit_chair") env["sit_chair"] = {{"start", {{"banks", Json::array()}}}};
    const Json values = TaskEnvConfig::FromJson(env, "t").ToJson()[name];
    size_t rows = 0;
    for (const Json& r : tables[name]) {
      const std::string field = r["name"];
      if (r.contains("default") && r["default"].is_null()) continue;  // written only when set
      ++rows;
      ASSERT_TRUE(values.contains(field)) << field;
      if (r.contains("fields")) {
        EXPECT_TRUE(values[field].is_object()) << field;
      } else if (field != "start") {  // the test's own start (no bank to read)
        EXPECT_EQ(r["default"], values[field]) << field;
      }
    }
    EXPECT_EQ(rows, values.size());
  }
  // walk, the two turns, sit and the hierarchy's sit_chair.
  EXPECT_EQ(tasks, 5);
}

}  // namespace
}  // namespace perch
