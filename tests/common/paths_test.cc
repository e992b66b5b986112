#include "common/paths.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

namespace perch {
namespace {

TEST(Paths, ResolvesSourceTreeAndDataDir) {
  namespace fs = std::filesystem;
  // From an unrelated working directory, data/ resolves into the source tree.
  const fs::path old = fs::current_path();
  fs::current_path(::testing::TempDir());
  unsetenv("PERCH_DATA_DIR");
  EXPECT_EQ(ResolveProjectPath("data/x.json"), std::string(PERCH_SOURCE_DIR) + "/data/x.json");
  // An installed data dir wins when the file is there.
  const fs::path dd = fs::path(::testing::TempDir()) / "perch_data_dir";
  fs::create_directories(dd);
  std::ofstream(dd / "x.json") << "{}";
  setenv("PERCH_DATA_DIR", dd.c_str(), 1);
  EXPECT_EQ(ResolveProjectPath("data/x.json"), (dd / "x.json").string());
  EXPECT_EQ(ResolveProjectPath("data/missing.json"),
            std::string(PERCH_SOURCE_DIR) + "/data/missing.json");
  unsetenv("PERCH_DATA_DIR");
  EXPECT_EQ(ResolveProjectPath("/abs/path.json"), "/abs/path.json");
  fs::current_path(old);
}

}  // namespace
}  // namespace perch
