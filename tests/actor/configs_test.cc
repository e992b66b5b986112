// Every config committed under configs/ loads: experiment configs (perch train/learner/actor) give
// a learner setup and name an init_from checkpoint that is in the repository; task env configs
// (perch train-local / eval) parse as such.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include "actor/experiment.h"
#include "actor/role_setup.h"
#include "common/config_file.h"
#include "common/json_util.h"
#include "common/paths.h"
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
  for (const fs::path& f : files) {
    SCOPED_TRACE(f.string());
    const Json j = LoadComposedConfig(f.string());
    if (j.contains("cluster")) {
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
  EXPECT_EQ(ExperimentError({{"env", {{"task", "turn_left"}}}, {"cluster", {{"task", "left_turn"}}}}),
            "");  // the older spelling of the same task
  const ExperimentConfig c = ExperimentConfigFromJson({{"env", {{"task", "sit"}}}}, "x.json");
  EXPECT_EQ(c.cluster.task, "sit");
  // The hierarchy has no env yet: refused by field, not left to crash actors.
  EXPECT_NE(ExperimentError({{"env", {{"task", "sit"}}}, {"cluster", {{"task", "meta"}}}})
                .find("x.json.cluster.task"),
            std::string::npos);
  EXPECT_NE(ExperimentError({{"env", {{"task", "sit"}}}, {"cluster", {{"hierarchy_enabled", true}}}})
                .find("x.json.cluster.hierarchy_enabled"),
            std::string::npos);
  // The mock backend (transport tests) keeps its meta task.
  EXPECT_EQ(ExperimentError({{"env_backend", "mock"}, {"cluster", {{"task", "meta"}}}}), "");
}

TEST(ExperimentConfig, EachSubtaskConfigBuildsItsEnvWithThePapersObservation) {
  for (const auto& [file, dim] : std::vector<std::pair<std::string, int>>{
           {"configs/turn_left.json", 50}, {"configs/turn_right.json", 50}, {"configs/sit.json", 57}}) {
    SCOPED_TRACE(file);
    const ExperimentConfig c = LoadExperimentConfig(ResolveProjectPath(file));
    EXPECT_EQ(MakeExperimentEnv(c)->spec().obs_dim, dim);
  }
}

}  // namespace
}  // namespace perch
