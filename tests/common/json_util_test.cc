#include "common/json_util.h"

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

namespace perch {
namespace {

std::string TempPath(const char* name) { return std::string(::testing::TempDir()) + name; }

TEST(JsonUtil, MalformedFileNamesFile) {
  const std::string p = TempPath("bad.json");
  std::ofstream(p) << "{\"a\": 1,,}";
  try {
    LoadJsonFile(p);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
  }
}

TEST(JsonUtil, WrongTypeNamesField) {
  Json j = Json::parse(R"({"height": "tall"})");
  double h = 1.0;
  try {
    GetOptional(j, "height", h, "chair.json");
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("chair.json.height"), std::string::npos) << e.what();
  }
  EXPECT_EQ(h, 1.0);
}

TEST(JsonUtil, IntegersAreNeitherRoundedNorWrapped) {
  // Issue 17's config cases: seed -1 became 18446744073709551615, 2^70 became 0, 1.5 became 1.
  const Json j = Json::parse(
      R"({"neg": -1, "huge": 1180591620717411303424, "frac": 1.5, "whole_float": 1024.0,
          "text": "8", "big": 3000000000, "ok": 8192, "x": 2.5})");
  uint64_t seed = 7;
  int steps = 7;
  int64_t wide = 0;
  auto error = [&](auto& out, const char* key) {
    try {
      GetOptional(j, key, out, "cfg");
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error(seed, "neg").find("cfg.neg: expected a non-negative integer"), std::string::npos);
  EXPECT_NE(error(seed, "huge").find("cfg.huge: expected an integer"), std::string::npos);
  EXPECT_NE(error(steps, "frac").find("cfg.frac: expected an integer, got 1.5"), std::string::npos);
  EXPECT_NE(error(steps, "whole_float").find("expected an integer"), std::string::npos);
  EXPECT_NE(error(steps, "text").find("expected an integer"), std::string::npos);
  EXPECT_NE(error(steps, "big").find("in range"), std::string::npos);  // > INT_MAX
  EXPECT_EQ(seed, 7u);
  EXPECT_EQ(steps, 7);
  GetOptional(j, "big", wide, "cfg");
  EXPECT_EQ(wide, 3000000000);
  GetOptional(j, "ok", steps, "cfg");
  EXPECT_EQ(steps, 8192);
  double x = 0;  // floating fields take integers and fractions alike
  GetOptional(j, "ok", x, "cfg");
  EXPECT_EQ(x, 8192.0);
  GetOptional(j, "x", x, "cfg");
  EXPECT_EQ(x, 2.5);
}

TEST(JsonUtil, DuplicateKeysAreRefusedByName) {
  const std::string p = TempPath("dup.json");
  std::ofstream(p) << R"({"ppo": {"learning_rate": 1e-4, "num_epochs": 4, "learning_rate": 1}})";
  try {
    LoadJsonFile(p);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(p + ": duplicate key \"learning_rate\""), std::string::npos)
        << e.what();
  }
  // The same key in different objects is fine.
  std::ofstream(p) << R"({"a": {"k": 1}, "b": {"k": 2}, "k": [ {"k": 3}, {"k": 4} ]})";
  EXPECT_EQ(LoadJsonFile(p)["b"]["k"], 2);
}

TEST(JsonUtil, UnknownAndMissingKeys) {
  Json j = Json::parse(R"({"a": 1, "typo": 2})");
  EXPECT_THROW(CheckKnownKeys(j, {"a", "b"}, "cfg"), ConfigError);
  EXPECT_NO_THROW(CheckKnownKeys(j, {"a", "typo"}, "cfg"));
  int b = 0;
  EXPECT_THROW(GetRequired(j, "b", b, "cfg"), ConfigError);
}

TEST(JsonUtil, AtomicSaveKeepsOldFileOnFailure) {
  const std::string p = TempPath("keep.json");
  SaveJsonFileAtomic(p, Json{{"v", 1}});
  EXPECT_EQ(LoadJsonFile(p)["v"], 1);
  // A directory that does not exist: the save fails and nothing is written.
  EXPECT_THROW(SaveJsonFileAtomic("/nonexistent_dir_perch/x.json", Json{{"v", 2}}), ConfigError);
  SaveJsonFileAtomic(p, Json{{"v", 3}});
  EXPECT_EQ(LoadJsonFile(p)["v"], 3);
}

}  // namespace
}  // namespace perch
