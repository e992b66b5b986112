// The files an experiment config names travel with it to actors that have no files of their own
// (issue 48: a recipe's banks on a cluster).
#include "protocol/config_files.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/file_util.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

TEST(ConfigFiles, ShipsAbsoluteFilesOutsideTheClusterSectionAndPointsTheConfigAtCopies) {
  const std::string dir = ::testing::TempDir() + "perch_config_files/";
  fs::remove_all(dir);
  fs::create_directories(dir + "recipe");
  const std::string bank = dir + "recipe/bank.bin";
  const std::string init = dir + "recipe/policy.bin";
  {
    std::ofstream(bank, std::ios::binary) << std::string(
        "\x01\x02"
        "bank",
        6);
  }
  { std::ofstream(init, std::ios::binary) << "weights"; }
  const Json config{{"env",
                     {{"task", "turn_left"},
                      {"turn_left", {{"start", {{"banks", {bank, "data/banks/x.bin"}}}}}},
                      {"motion", "data/motions/walk.json"},
                      {"missing", dir + "nope.bin"}}},
                    {"cluster", {{"init_from", init}}}};
  const auto files = CollectConfigFiles(config, 1 << 20);
  ASSERT_EQ(files.size(), 1u);  // not the learner's init_from, not data-root or missing paths
  EXPECT_EQ(files[0].path(), bank);
  EXPECT_EQ(files[0].content(), std::string("\x01\x02"
                                            "bank",
                                            6));

  const Json local = LocalizeConfigFiles(config, files, dir + "cache");
  const std::string copy = local["env"]["turn_left"]["start"]["banks"][0];
  EXPECT_NE(copy, bank);
  EXPECT_EQ(copy.rfind(dir + "cache/", 0), 0u) << copy;
  EXPECT_EQ(ReadFileBytes(copy), std::string("\x01\x02"
                                             "bank",
                                             6));
  EXPECT_EQ(local["env"]["turn_left"]["start"]["banks"][1], "data/banks/x.bin");
  EXPECT_EQ(local["cluster"]["init_from"], init);
}

TEST(ConfigFiles, RefusesFilesTooBigToTravel) {
  const std::string dir = ::testing::TempDir() + "perch_config_files_big/";
  fs::remove_all(dir);
  fs::create_directories(dir);
  { std::ofstream(dir + "big.bin") << std::string(5000, 'x'); }
  try {
    CollectConfigFiles(Json{{"env", {{"bank", dir + "big.bin"}}}}, 4096);
    FAIL() << "a 5000-byte file passed a 4096-byte limit";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("big.bin"));
    EXPECT_THAT(e.what(), ::testing::HasSubstr("4096"));
  }
}

}  // namespace
}  // namespace perch
