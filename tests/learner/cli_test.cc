// The perch subcommands of the learner, as a user runs them: `perch bench ppo --json` prints one
// JSON object; `perch ppo toy` writes its resolved config and refuses a bad one (exit 2).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "common/json_util.h"
#include "tests/common/run_perch.h"

namespace perch {
namespace {

using Result = testing_util::PerchResult;
using testing_util::RunPerch;

class CliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (std::getenv("PERCH_BIN") == nullptr) GTEST_SKIP() << "PERCH_BIN not set (run via ctest)";
    dir_ = std::filesystem::temp_directory_path() /
           ("perch-ppo-cli-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override {
    if (!dir_.empty()) std::filesystem::remove_all(dir_);
  }
  std::filesystem::path dir_;
};

TEST_F(CliTest, BenchPrintsOneJsonObject) {
  const Result r = RunPerch("bench ppo --json --batch 1024 --repeats 2 --obs-dim 52 2>/dev/null");
  ASSERT_EQ(r.code, 0) << r.out;
  const Json j = Json::parse(r.out);
  EXPECT_GT(j.at("samples_per_s").get<double>(), 0.0);
  EXPECT_EQ(j.at("obs_dim").get<int>(), 52);
  EXPECT_EQ(j.at("act_dim").get<int>(), 21);
  EXPECT_EQ(j.at("batch").get<int>(), 1024);
}

TEST_F(CliTest, ToyWritesResolvedConfigAndRefusesBadConfig) {
  const std::string cfg = (dir_ / "cfg.json").string();
  std::ofstream(cfg) << R"({"ppo": {"steps_per_update": 256, "num_minibatches": 4}})";
  const std::string out = (dir_ / "run").string();
  const Result ok = RunPerch("ppo toy --task choice_target --updates 2 --json --config " + cfg +
                             " --out " + out + " 2>/dev/null");
  ASSERT_EQ(ok.code, 0) << ok.out;
  const Json j = Json::parse(ok.out);
  EXPECT_EQ(j.at("curve").size(), 2u);
  const Json saved = LoadJsonFile(out + "/config.json");
  EXPECT_EQ(saved.at("ppo").at("steps_per_update").get<int>(), 256);
  EXPECT_EQ(saved.at("ppo").at("num_epochs").get<int>(), 4);  // the task's default, resolved
  EXPECT_TRUE(std::filesystem::exists(out + "/learner_state.pb"));

  std::ofstream(cfg) << R"({"ppo": {"gama": 0.9}})";
  const Result bad = RunPerch("ppo toy --task choice_target --config " + cfg + " 2>&1");
  EXPECT_EQ(bad.code, 2);
  EXPECT_NE(bad.out.find("perch: error:"), std::string::npos) << bad.out;
  EXPECT_NE(bad.out.find("gama"), std::string::npos) << bad.out;
  EXPECT_NE(bad.out.find("cfg.json"), std::string::npos) << bad.out;
}

}  // namespace
}  // namespace perch
