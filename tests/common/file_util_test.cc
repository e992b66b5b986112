#include "common/file_util.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "common/json_util.h"

namespace perch {
namespace {

std::string ErrorOf(const std::string& path, const std::string& noun) {
  try {
    ReadFileBytes(path, noun);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(ReadFileBytes, ReadsEveryByteAndNamesTheFileWhenItCannot) {
  const std::string dir = ::testing::TempDir() + "perch_read_file_bytes/";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  // Binary bytes (NUL, CR LF, 0xFF) and more than one read buffer (64 KiB) come back unchanged.
  std::string bytes(200000, '\0');
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<char>((i * 131 + 7) % 256);
  bytes += "\r\n\xff";
  { std::ofstream(dir + "blob", std::ios::binary) << bytes; }
  EXPECT_EQ(ReadFileBytes(dir + "blob"), bytes);
  { std::ofstream(dir + "empty", std::ios::binary); }
  EXPECT_EQ(ReadFileBytes(dir + "empty"), "");
  // A missing file and a directory (whose read fails, not a file of no bytes) are refused,
  // naming the path, what it was read as, and why.
  const std::string missing = ErrorOf(dir + "nope", "model file");
  EXPECT_NE(missing.find(dir + "nope: cannot open model file: No such file"), std::string::npos)
      << missing;
  const std::string directory = ErrorOf(dir, "the records file");
  EXPECT_NE(directory.find(dir + ": cannot read the records file: Is a directory"),
            std::string::npos)
      << directory;
}

}  // namespace
}  // namespace perch
