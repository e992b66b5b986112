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
#include "common/json_util.h"
#include "common/paths.h"
#include "tasks/task_env.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

TEST(CommittedConfigs, EveryConfigLoadsAndItsInitFromExists) {
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(fs::path(PERCH_SOURCE_DIR) / "configs")) {
    if (e.path().extension() == ".json") files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  ASSERT_GE(files.size(), 5u);
  int experiments = 0, task_configs = 0;
  for (const fs::path& f : files) {
    SCOPED_TRACE(f.string());
    const Json j = LoadJsonFile(f.string());
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

}  // namespace
}  // namespace perch
