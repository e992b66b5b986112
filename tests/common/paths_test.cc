#include "common/paths.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include <gtest/gtest.h>

namespace perch {
namespace {

namespace fs = std::filesystem;

// A directory that looks like an installed share/perch: data/humanoid.json inside.
fs::path MakeRoot(const std::string& name) {
  const fs::path root = fs::path(::testing::TempDir()) / name;
  fs::create_directories(root / "data");
  std::ofstream(root / "data" / "humanoid.json") << "{}";
  return fs::absolute(root).lexically_normal();
}

class PathsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    old_ = fs::current_path();
    fs::current_path(::testing::TempDir());
    unsetenv("PERCH_DATA_DIR");
    SetDataRoot("");
  }
  void TearDown() override {
    unsetenv("PERCH_DATA_DIR");
    SetDataRoot("");
    fs::current_path(old_);
  }
  fs::path old_;
};

TEST_F(PathsTest, ATestBinaryInTheBuildTreeUsesTheSourceTree) {
  // This test runs from the build tree: the dev-build fallback applies.
  const DataRootInfo info = FindDataRoot();
  EXPECT_EQ(info.origin, "source");
  EXPECT_EQ(fs::path(info.root), fs::path(PERCH_SOURCE_DIR).lexically_normal());
  EXPECT_EQ(ResolveProjectPath("data/x.json"), (fs::path(info.root) / "data/x.json").string());
  EXPECT_EQ(ResolveProjectPath("/abs/path.json"), "/abs/path.json");
}

TEST_F(PathsTest, EnvironmentBeatsTheSourceTreeAndTheFlagBeatsBoth) {
  const fs::path env_root = MakeRoot("perch_env_root");
  setenv("PERCH_DATA_DIR", env_root.c_str(), 1);
  EXPECT_EQ(FindDataRoot().origin, "env");
  EXPECT_EQ(ResolveProjectPath("configs/x.json"), (env_root / "configs/x.json").string());
  // The image's old form, PERCH_DATA_DIR naming the data/ folder itself, means its parent.
  setenv("PERCH_DATA_DIR", (env_root / "data").c_str(), 1);
  EXPECT_EQ(fs::path(FindDataRoot().root), env_root);

  const fs::path flag_root = MakeRoot("perch_flag_root");
  SetDataRoot(flag_root.string());
  EXPECT_EQ(FindDataRoot().origin, "flag");
  EXPECT_EQ(ResolveProjectPath("data/humanoid.json"), (flag_root / "data/humanoid.json").string());
}

TEST_F(PathsTest, ADirectoryWithoutDataIsRefusedByName) {
  const fs::path empty = fs::path(::testing::TempDir()) / "perch_not_a_root";
  fs::create_directories(empty);
  try {
    SetDataRoot(empty.string());
    FAIL() << "accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("--data-dir " + empty.string()), std::string::npos);
  }
  setenv("PERCH_DATA_DIR", empty.c_str(), 1);
  try {
    ResolveProjectPath("data/humanoid.json");
    FAIL() << "accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("PERCH_DATA_DIR=" + empty.string()), std::string::npos);
  }
}

TEST_F(PathsTest, PathsThatExistFromTheWorkingDirectoryWin) {
  const fs::path root = MakeRoot("perch_cwd_root");
  fs::current_path(root);
  EXPECT_EQ(ResolveProjectPath("data/humanoid.json"), "data/humanoid.json");
}

}  // namespace
}  // namespace perch
