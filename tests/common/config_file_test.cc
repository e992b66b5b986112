#include "common/config_file.h"

#include <filesystem>
#include <fstream>
#include <functional>

#include <gtest/gtest.h>

namespace perch {
namespace {

namespace fs = std::filesystem;

fs::path Write(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
  return p;
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(ConfigFile, ABranchOverridesItsBaseFieldByField) {
  const fs::path dir = fs::path(::testing::TempDir()) / "perch_cfg_compose";
  Write(dir / "main.json",
        R"({"seed": 1, "env": {"task": "walk", "walk": {"stage": "forward", "max_episode_steps": 1000}},
            "ppo": {"learning_rate": 1e-4, "num_epochs": 4}})");
  Write(dir / "experiments" / "lr.json",
        R"({"base": "../main.json", "ppo": {"learning_rate": 3e-5},
            "env": {"walk": {"max_episode_steps": null}}})");
  Write(dir / "experiments" / "lr_seed.json", R"({"base": "lr.json", "seed": 7})");
  const Json j = LoadComposedConfig((dir / "experiments" / "lr_seed.json").string());
  EXPECT_FALSE(j.contains("base"));
  EXPECT_EQ(j["seed"], 7);                              // the branch's own field
  EXPECT_DOUBLE_EQ(j["ppo"]["learning_rate"], 3e-5);   // from the middle config
  EXPECT_EQ(j["ppo"]["num_epochs"], 4);                 // kept from the base: objects merge
  EXPECT_EQ(j["env"]["walk"]["stage"], "forward");
  EXPECT_FALSE(j["env"]["walk"].contains("max_episode_steps"));  // null removes
}

TEST(ConfigFile, SetOverridesOneFieldWithJsonOrAString) {
  Json j{{"ppo", {{"learning_rate", 1e-4}}}, {"env", {{"task", "walk"}}}};
  ApplySet(&j, "ppo.learning_rate=3e-5");
  ApplySet(&j, "env.task=sit");             // a bare word is a string
  ApplySet(&j, "cluster.max_samples=1000");  // missing objects are created
  ApplySet(&j, "env.walk={\"stage\": \"targets\"}");
  EXPECT_DOUBLE_EQ(j["ppo"]["learning_rate"], 3e-5);
  EXPECT_EQ(j["env"]["task"], "sit");
  EXPECT_EQ(j["cluster"]["max_samples"], 1000);
  EXPECT_EQ(j["env"]["walk"]["stage"], "targets");
  EXPECT_NE(ErrorOf([&] { ApplySet(&j, "ppo.learning_rate"); }).find("--set ppo.learning_rate: expected"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { ApplySet(&j, "env.task.x=1"); }).find("\"env.task\" is not an object"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { ApplySet(&j, "ppo..x=1"); }).find("empty field name"), std::string::npos);
}

TEST(ConfigFile, BadBasesAreNamed) {
  const fs::path dir = fs::path(::testing::TempDir()) / "perch_cfg_bad";
  Write(dir / "a.json", R"({"base": "b.json"})");
  Write(dir / "b.json", R"({"base": "a.json"})");
  EXPECT_NE(ErrorOf([&] { LoadComposedConfig((dir / "a.json").string()); }).find("cycle"),
            std::string::npos);
  Write(dir / "missing.json", R"({"base": "nowhere.json"})");
  const std::string e = ErrorOf([&] { LoadComposedConfig((dir / "missing.json").string()); });
  EXPECT_NE(e.find("missing.json.base: \"nowhere.json\": no such config"), std::string::npos) << e;
  Write(dir / "number.json", R"({"base": 3})");
  EXPECT_NE(ErrorOf([&] { LoadComposedConfig((dir / "number.json").string()); }).find(".base: expected"),
            std::string::npos);
  Write(dir / "broken.json", R"({"base": "main.json",)");
  EXPECT_NE(ErrorOf([&] { LoadComposedConfig((dir / "broken.json").string()); }).find("broken.json"),
            std::string::npos);
}

TEST(ConfigFile, EveryShippedConfigComposes) {
  // configs/ and configs/experiments/: each loads (bases found, no cycles) and keeps no "base".
  int n = 0;
  for (const auto& e : fs::recursive_directory_iterator(fs::path(PERCH_SOURCE_DIR) / "configs")) {
    if (e.path().extension() != ".json") continue;
    const Json j = LoadComposedConfig(e.path().string());
    EXPECT_FALSE(j.contains("base")) << e.path();
    ++n;
  }
  EXPECT_GT(n, 10);
}

}  // namespace
}  // namespace perch
