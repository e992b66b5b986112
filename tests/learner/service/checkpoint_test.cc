#include "learner/service/checkpoint.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <string>

namespace perch {
namespace {

std::string TempDir() {
  char tmpl[] = "/tmp/perch-ckpt-test-XXXXXX";
  const char* d = ::mkdtemp(tmpl);
  EXPECT_NE(d, nullptr);
  return d;
}

proto::Checkpoint Make(uint64_t update, const std::string& key = "k") {
  proto::Checkpoint c;
  c.set_wire_version(proto::WIRE_VERSION_CURRENT);
  c.mutable_counters()->set_updates(update);
  c.mutable_counters()->set_samples(update * 100);
  c.set_compat_key(key);
  c.set_resolved_config_json("{\"seed\": 3}");
  c.mutable_trainer()->set_num_updates(static_cast<int64_t>(update));
  return c;
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}
void WriteAll(const std::string& path, const std::string& s) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << s;
}

TEST(CheckpointTest, Crc32MatchesKnownVector) {
  // The standard check value of CRC-32/ISO-HDLC.
  EXPECT_EQ(Crc32("123456789", 9), 0xCBF43926u);
}

TEST(CheckpointTest, RoundTripKeepsFields) {
  CheckpointStore store(TempDir(), 3, 0);
  const std::string path = store.Save(Make(7));
  const proto::Checkpoint back = ReadCheckpointFile(path);
  EXPECT_EQ(back.counters().updates(), 7u);
  EXPECT_EQ(back.counters().samples(), 700u);
  EXPECT_EQ(back.compat_key(), "k");
  EXPECT_EQ(back.trainer().num_updates(), 7);
}

TEST(CheckpointTest, DetectsCorruptionTruncationAndGarbage) {
  CheckpointStore store(TempDir(), 3, 0);
  const std::string path = store.Save(Make(1));
  const std::string good = ReadAll(path);

  std::string flipped = good;
  flipped[flipped.size() - 3] ^= 0x40;
  WriteAll(path, flipped);
  try {
    ReadCheckpointFile(path);
    FAIL() << "corrupt file accepted";
  } catch (const CheckpointError& e) {
    EXPECT_NE(std::string(e.what()).find("CRC"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }

  // Each refusal names the file and its reason.
  auto ErrorOf = [](const std::string& p) -> std::string {
    try {
      ReadCheckpointFile(p);
    } catch (const CheckpointError& e) {
      return e.what();
    }
    return "(accepted)";
  };
  WriteAll(path, good.substr(0, good.size() / 2));
  EXPECT_EQ(ErrorOf(path).rfind(path + ": checkpoint payload is", 0), 0u) << ErrorOf(path);
  EXPECT_NE(ErrorOf(path).find("truncated"), std::string::npos) << ErrorOf(path);
  WriteAll(path, "not a checkpoint at all");
  EXPECT_EQ(ErrorOf(path).rfind(path + ": not a checkpoint", 0), 0u) << ErrorOf(path);
  WriteAll(path, "");
  EXPECT_EQ(ErrorOf(path).rfind(path + ": not a checkpoint", 0), 0u) << ErrorOf(path);
  std::string other_format = good;
  other_format[8] = 7;
  WriteAll(path, other_format);
  EXPECT_NE(ErrorOf(path).find("checkpoint format 7, this build reads 1"), std::string::npos)
      << ErrorOf(path);
  // A directory and a missing file: read errors, not "a shorter file".
  const std::string dir = TempDir();
  EXPECT_NE(ErrorOf(dir).find(": cannot read checkpoint"), std::string::npos) << ErrorOf(dir);
  EXPECT_NE(ErrorOf(dir + "/none.bin").find(": cannot open checkpoint"), std::string::npos)
      << ErrorOf(dir + "/none.bin");
  // The good bytes still read after all that.
  WriteAll(path, good);
  EXPECT_EQ(ReadCheckpointFile(path).counters().updates(), 1u);
}

TEST(CheckpointTest, RotationKeepsLastNAndMilestones) {
  CheckpointStore store(TempDir(), 2, 4);
  for (uint64_t u = 1; u <= 9; ++u) store.Save(Make(u));
  // Last 2 (8, 9) plus milestones (4, 8).
  EXPECT_EQ(store.List(), (std::vector<uint64_t>{4, 8, 9}));
}

TEST(CheckpointTest, IgnoresTemporaryAndForeignFiles) {
  const std::string dir = TempDir();
  CheckpointStore store(dir, 3, 0);
  store.Save(Make(2));
  WriteAll(dir + "/checkpoints/ckpt-0000000005.bin.tmp", "partial");
  WriteAll(dir + "/checkpoints/notes.txt", "x");
  WriteAll(dir + "/checkpoints/ckpt-00000x0005.bin", "x");
  EXPECT_EQ(store.List(), (std::vector<uint64_t>{2}));
}

TEST(CheckpointTest, LoadFallsBackToPreviousGoodOne) {
  const std::string dir = TempDir();
  CheckpointStore store(dir, 5, 0);
  store.Save(Make(1));
  store.Save(Make(2));
  const std::string newest = store.Save(Make(3));
  std::string bytes = ReadAll(newest);
  bytes[bytes.size() / 2] ^= 0x01;
  WriteAll(newest, bytes);

  std::vector<std::string> warnings, errors;
  proto::Checkpoint got;
  std::string from;
  ASSERT_TRUE(store.LoadLatestGood([](const proto::Checkpoint&) {},
                                   [&](const std::string& w) { warnings.push_back(w); }, &got,
                                   &from, &errors));
  EXPECT_EQ(got.counters().updates(), 2u);
  EXPECT_EQ(from, store.PathFor(2));
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find(newest), std::string::npos);
  // The refused file is still there (nothing saved is deleted by a resume).
  EXPECT_EQ(::access(newest.c_str(), F_OK), 0);
}

TEST(CheckpointTest, MismatchIsRefusedWithReason) {
  CheckpointStore store(TempDir(), 5, 0);
  store.Save(Make(1, "old-config"));
  store.Save(Make(2, "other-config"));
  std::vector<std::string> errors;
  proto::Checkpoint got;
  auto accept = [](const proto::Checkpoint& c) {
    if (c.compat_key() != "old-config") throw CheckpointError("mismatch: " + c.compat_key());
  };
  ASSERT_TRUE(store.LoadLatestGood(accept, nullptr, &got, nullptr, &errors));
  EXPECT_EQ(got.counters().updates(), 1u);
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("other-config"), std::string::npos);

  auto refuse_all = [](const proto::Checkpoint&) { throw CheckpointError("no"); };
  errors.clear();
  EXPECT_FALSE(store.LoadLatestGood(refuse_all, nullptr, &got, nullptr, &errors));
  EXPECT_EQ(errors.size(), 2u);
}

TEST(CheckpointTest, MisnamedFileIsRefused) {
  const std::string dir = TempDir();
  CheckpointStore store(dir, 5, 0);
  const std::string p3 = store.Save(Make(3));
  // A file claiming update 9 but holding update 3.
  WriteAll(store.PathFor(9), ReadAll(p3));
  std::vector<std::string> errors;
  proto::Checkpoint got;
  ASSERT_TRUE(
      store.LoadLatestGood([](const proto::Checkpoint&) {}, nullptr, &got, nullptr, &errors));
  EXPECT_EQ(got.counters().updates(), 3u);
  EXPECT_EQ(errors.size(), 1u);
}

TEST(CheckpointTest, FailedWriteLeavesExistingFileIntact) {
  const std::string dir = TempDir();
  const std::string path = dir + "/file.bin";
  WriteFileAtomic(path, "first");
  // The temporary file cannot be created where a directory of that name exists.
  ASSERT_EQ(::mkdir((path + ".tmp").c_str(), 0755), 0);
  EXPECT_THROW(WriteFileAtomic(path, "second"), std::runtime_error);
  EXPECT_EQ(ReadAll(path), "first");
}

}  // namespace
}  // namespace perch
