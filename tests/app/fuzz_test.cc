// `perch fuzz` as scripts/test.sh runs it (issue 17): 1,500 random mutations per reader
// (wire, checkpoint, BVH, config); every input is accepted or refused with the reader's own error,
// nothing crashes. PERCH_FUZZ_SECONDS runs it longer.
#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

#include "common/json_util.h"
#include "tests/common/run_perch.h"

namespace perch {
namespace {

TEST(FuzzTest, EveryReaderSurvivesMutatedInputs) {
  if (std::getenv("PERCH_BIN") == nullptr) GTEST_SKIP() << "PERCH_BIN not set (run via ctest)";
  // A fixed number of cases (not a time budget): the same inputs on a loaded or a fast machine.
  // PERCH_FUZZ_SECONDS runs it longer, by time.
  const char* env = std::getenv("PERCH_FUZZ_SECONDS");
  const std::string limit =
      env ? std::string("--seconds ") + env : std::string("--seconds 600 --cases 1500");
  const testing_util::PerchResult r =
      testing_util::RunPerch("fuzz --json " + limit + " 2>/dev/null");
  ASSERT_EQ(r.code, 0) << r.out;  // a crash or a finding: non-zero
  const Json j = Json::parse(r.out);
  EXPECT_EQ(j["findings"].get<int>(), 0) << r.out;
  for (const char* t : {"wire", "checkpoint", "bvh", "config"}) {
    SCOPED_TRACE(t);
    EXPECT_GE(j["targets"][t]["cases"].get<double>(), env ? 1000.0 : 1500.0);
    EXPECT_TRUE(j["targets"][t]["findings"].empty());
  }
}

// A mistyped target is an error, not an empty run that passes.
TEST(FuzzTest, AnUnknownTargetIsRefusedByName) {
  if (std::getenv("PERCH_BIN") == nullptr) GTEST_SKIP() << "PERCH_BIN not set (run via ctest)";
  const testing_util::PerchResult r = testing_util::RunPerch("fuzz --target nope 2>&1");
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("--target: unknown 'nope'"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace perch
