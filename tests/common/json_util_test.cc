#include "common/json_util.h"

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
