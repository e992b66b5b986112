#include "common/file_util.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

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

TEST(Checksums, MatchThePublishedCheckValues) {
  // The CRC-32 check value of "123456789" (zlib, ZIP, PNG) and FIPS 180-2's "abc" digest.
  EXPECT_EQ(Crc32("123456789", 9), 0xCBF43926u);
  EXPECT_EQ(Crc32("", 0), 0u);
  EXPECT_EQ(Sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  const std::string dir = ::testing::TempDir() + "perch_checksums/";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  { std::ofstream(dir + "abc", std::ios::binary) << "abc"; }
  EXPECT_EQ(FileSha256(dir + "abc"), Sha256Hex("abc"));
  EXPECT_THROW(FileSha256(dir + "missing"), ConfigError);
}

TEST(Frame, RoundTripsAndRefusesEachKindOfDamage) {
  constexpr char kMagic[8] = {'T', 'E', 'S', 'T', 'F', 'R', 'M', '1'};
  const std::string payload("payload \0 bytes", 15);
  const std::string framed = FramePayload(kMagic, 3, payload);
  ASSERT_EQ(framed.size(), kFrameHeaderBytes + payload.size());
  EXPECT_EQ(UnframePayload(framed, "f", kMagic, 3, "thing"), payload);
  auto error = [&](const std::string& bytes, uint32_t format) -> std::string {
    try {
      UnframePayload(bytes, "f.bin", kMagic, format, "thing");
    } catch (const ConfigError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(error(framed, 4).find("f.bin: thing format 3, this build reads 4"), std::string::npos);
  EXPECT_NE(error(framed.substr(0, framed.size() - 1), 3).find("truncated or corrupt"),
            std::string::npos);
  std::string flipped = framed;
  flipped.back() ^= 1;
  EXPECT_NE(error(flipped, 3).find("f.bin: thing CRC-32 mismatch"), std::string::npos);
  EXPECT_NE(error("PERCHCKP", 3).find("not a thing"), std::string::npos);
  EXPECT_TRUE(HasCheckpointMagic(std::string(kCheckpointMagic, 8) + "x"));
  EXPECT_FALSE(HasCheckpointMagic(framed));
}

TEST(WriteFileAtomic, ReplacesWholeFilesWithTheirModeAndLeavesTheOldOneOnFailure) {
  const std::string dir = ::testing::TempDir() + "perch_write_atomic/";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  WriteFileAtomic(dir + "a", "first");
  WriteFileAtomic(dir + "a", "second, longer");
  EXPECT_EQ(ReadFileBytes(dir + "a"), "second, longer");
  EXPECT_FALSE(std::filesystem::exists(dir + "a.tmp"));
  // A secret is created 0600 even when a stale temporary file with a wider mode lies there.
  { std::ofstream(dir + "key.tmp") << "stale"; }
  ::chmod((dir + "key.tmp").c_str(), 0666);
  WriteFileAtomic(dir + "key", "secret", 0600);
  struct stat st {};
  ASSERT_EQ(::stat((dir + "key").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  EXPECT_EQ(ReadFileBytes(dir + "key"), "secret");
  // A write into a missing directory fails, naming the path; nothing else is touched.
  try {
    WriteFileAtomic(dir + "no/such/file", "x");
    ADD_FAILURE() << "expected a ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(dir + "no/such/file.tmp: cannot create"),
              std::string::npos)
        << e.what();
  }
  // A finished temporary file from another writer is committed in place.
  { std::ofstream(dir + "child.tmp") << "from a child"; }
  CommitFileAtomic(dir + "child.tmp", dir + "child");
  EXPECT_EQ(ReadFileBytes(dir + "child"), "from a child");
  EXPECT_FALSE(std::filesystem::exists(dir + "child.tmp"));
  EXPECT_THROW(CommitFileAtomic(dir + "gone.tmp", dir + "a"), ConfigError);
  EXPECT_EQ(ReadFileBytes(dir + "a"), "second, longer");
}

}  // namespace
}  // namespace perch
