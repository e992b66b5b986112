#include "common/npz.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/json_util.h"

namespace perch {
namespace {

const std::string kRef = PERCH_SOURCE_DIR "/../shared/reference";

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void WriteAll(const std::string& path, const std::string& s) {
  std::ofstream out(path, std::ios::binary);
  out << s;
}

// A .npy v1.0 buffer with the given header dict and payload.
std::string Npy(const std::string& dict, const std::string& payload) {
  std::string h = dict;
  while ((10 + h.size() + 1) % 64 != 0) h += ' ';
  h += '\n';
  std::string b = "\x93NUMPY";
  b += '\x01';
  b += '\x00';
  b += static_cast<char>(h.size() & 0xFF);
  b += static_cast<char>(h.size() >> 8);
  return b + h + payload;
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(Npy, ParsesFloat32AndInt64WithShape) {
  const float f[3] = {1.5f, -2.0f, 3.25f};
  const auto a = ParseNpy(Npy("{'descr': '<f4', 'fortran_order': False, 'shape': (3,), }",
                              std::string(reinterpret_cast<const char*>(f), sizeof(f))),
                          "x");
  ASSERT_EQ(a.shape, std::vector<int64_t>{3});
  EXPECT_EQ(a.values[1], -2.0);
  EXPECT_EQ(a.At({2}), 3.25);
  const int64_t v[6] = {1, 2, 3, 4, 5, -6};
  const auto b = ParseNpy(Npy("{'descr': '<i8', 'fortran_order': False, 'shape': (2, 3), }",
                              std::string(reinterpret_cast<const char*>(v), sizeof(v))),
                          "y");
  ASSERT_EQ(b.shape, (std::vector<int64_t>{2, 3}));
  EXPECT_EQ(b.ints[5], -6);
  EXPECT_EQ(b.At({1, 0}), 4.0);
  EXPECT_THROW(b.At({2, 0}), std::out_of_range);
}

TEST(Npy, RejectsBadInputWithClearErrors) {
  EXPECT_NE(ErrorOf([] { ParseNpy("garbage!!!!!", "f.npy"); }).find("bad magic"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] {
              ParseNpy(Npy("{'descr': '|O', 'fortran_order': False, 'shape': (2,), }", "xx"),
                       "obj.npy");
            }).find("pickled"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] {
              ParseNpy(Npy("{'descr': '<f8', 'fortran_order': False, 'shape': (2,), }",
                           std::string(15, '\0')),
                       "short.npy");
            }).find("does not match shape"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] {
              ParseNpy(Npy("{'descr': '>i2', 'fortran_order': False, 'shape': (1,), }", "ab"),
                       "i2.npy");
            }).find("unsupported dtype"),
            std::string::npos);
}

class NpzReference : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!std::filesystem::exists(kRef + "/cmu_mocap_sit_plain.npz")) {
      GTEST_SKIP() << "no " << kRef;
    }
  }
};

TEST_F(NpzReference, ReadsSitAndTurnArrays) {
  const auto sit = LoadNpz(kRef + "/cmu_mocap_sit_plain.npz");
  ASSERT_TRUE(sit.count("qpos"));
  EXPECT_EQ(sit.at("qpos").shape, (std::vector<int64_t>{1, 379, 51}));
  EXPECT_EQ(sit.at("qpos").dtype, "<f8");
  EXPECT_EQ(sit.at("obs").dtype, "<f4");
  EXPECT_EQ(sit.at("offsetz_0").shape, std::vector<int64_t>{104});
  // The sit-down segment table as documented in the notes §7.2.
  const auto& sitd = sit.at("sitd");
  ASSERT_EQ(sitd.shape, (std::vector<int64_t>{2, 3}));
  EXPECT_EQ(sitd.ints[1], 11);
  EXPECT_EQ(sitd.ints[2], 103);
  // Standing torso height of the first frame is close to the humanoid's 1.29 m (notes §1.2).
  const double z0 = sit.at("qpos").At({0, 0, 44});
  EXPECT_GT(z0, 1.1);
  EXPECT_LT(z0, 1.4);
  const auto turn = LoadNpz(kRef + "/cmu_mocap_turn.npz");
  EXPECT_EQ(turn.at("qpos").shape, (std::vector<int64_t>{1, 2398, 51}));
  EXPECT_EQ(turn.at("lturn").ints[7], 1234);
}

TEST_F(NpzReference, RefusesPickledWalkArchive) {
  const std::string err = ErrorOf([] { LoadNpz(kRef + "/cmu_mocap_walk.npz"); });
  EXPECT_NE(err.find("pickled"), std::string::npos) << err;
  EXPECT_NE(err.find("cmu_mocap_walk.npz"), std::string::npos) << err;
}

TEST_F(NpzReference, RejectsCorruptAndTruncatedCopies) {
  std::string bytes = ReadAll(kRef + "/cmu_mocap_sit_plain.npz");
  const std::string tmp = ::testing::TempDir() + "/corrupt.npz";
  std::string flipped = bytes;
  flipped[2000] ^= 0x5A;  // inside the first member's data
  WriteAll(tmp, flipped);
  std::string err = ErrorOf([&] { LoadNpz(tmp); });
  EXPECT_NE(err.find("CRC"), std::string::npos) << err;
  EXPECT_NE(err.find("corrupt.npz"), std::string::npos) << err;
  WriteAll(tmp, bytes.substr(0, bytes.size() / 2));
  err = ErrorOf([&] { LoadNpz(tmp); });
  EXPECT_FALSE(err.empty());
  EXPECT_NE(err.find("corrupt.npz"), std::string::npos) << err;
  std::remove(tmp.c_str());
  EXPECT_NE(ErrorOf([] { LoadNpz("/nonexistent/x.npz"); }).find("cannot open"), std::string::npos);
}

}  // namespace
}  // namespace perch
