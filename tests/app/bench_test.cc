// The cluster-level benchmarks as a user runs them (real processes, PERCH_BIN): `perch bench train`
// runs both arms and writes the legacy physics into the baseline's config; `perch bench cluster`
// reports the spread of its repeats; `perch bench profile` splits a control step into phases that
// add up.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "common/json_util.h"
#include "tests/common/run_perch.h"

namespace perch {
namespace {

using Result = testing_util::PerchResult;

// The benchmarks print their JSON on stdout; progress on stderr is dropped.
Result RunPerch(const std::string& args) { return testing_util::RunPerch(args + " 2>/dev/null"); }

std::string Config(const char* name) { return std::string(PERCH_SOURCE_DIR) + "/configs/" + name; }

class BenchTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (std::getenv("PERCH_BIN") == nullptr) GTEST_SKIP() << "PERCH_BIN not set (run via ctest)";
  }
};

TEST_F(BenchTest, TrainRunsBothArmsWithTheirPhysics) {
  // The mock env with some work per step, so that CPU time advances measurably (/proc ticks).
  Json mock = LoadJsonFile(Config("mock.json"));
  // Updates must be slower than the bench's 50 ms poll, or several share one CPU reading.
  mock["mock_env"]["work_iterations"] = 100000;
  const std::string config = ::testing::TempDir() + "bench_train_mock.json";
  SaveJsonFileAtomic(config, mock);
  const Result r = RunPerch("bench train --json --config " + config +
                            " --updates 5 --rounds 1 --actors 1 --envs 1");
  ASSERT_EQ(r.code, 0) << r.out;
  const Json j = Json::parse(r.out);
  for (const char* arm : {"baseline", "candidate"}) {
    SCOPED_TRACE(arm);
    EXPECT_GT(j[arm]["samples_per_s"].get<double>(), 0.0);
    EXPECT_GT(j[arm]["cpu_us_per_step"].get<double>(), 0.0);
    EXPECT_EQ(j[arm]["samples_per_s_runs"].size(), 1u);
  }
  EXPECT_NEAR(
      j["ratio_samples_per_s"].get<double>(),
      j["candidate"]["samples_per_s"].get<double>() / j["baseline"]["samples_per_s"].get<double>(),
      1e-9);
  // The baseline ran the physics before issue 19, the candidate the config's.
  const Json base = LoadJsonFile(j["baseline"]["config"].get<std::string>());
  EXPECT_EQ(base["env"]["physics"]["collision_pool_size"], 4096);
  EXPECT_EQ(base["env"]["physics"]["floor_half_extent"], 0.0);
  EXPECT_EQ(base["env"]["physics"]["chair_body"], "dynamic");
  const Json cand = LoadJsonFile(j["candidate"]["config"].get<std::string>());
  EXPECT_FALSE(cand.contains("env") && cand["env"].contains("physics"));
}

TEST_F(BenchTest, TrainRefusesAnUnknownSettingByFlag) {
  const std::string cmd = std::string(std::getenv("PERCH_BIN")) + " bench train --config " +
                          Config("mock.json") + " --baseline-physics wobbly 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string out;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  const int status = pclose(p);
  EXPECT_EQ(WEXITSTATUS(status), 2);
  EXPECT_NE(out.find("--baseline-physics"), std::string::npos) << out;
}

TEST_F(BenchTest, ClusterReportsTheSpreadOfItsRepeats) {
  const Result r = RunPerch("bench cluster --json --config " + Config("mock.json") +
                            " --repeats 2 --env-seconds 1 --cluster-seconds 5 --actors 1");
  ASSERT_EQ(r.code, 0) << r.out;
  const Json j = Json::parse(r.out);
  const Json& s = j["ratio_cluster_to_env_per_cpu_s_spread"];
  ASSERT_EQ(s["runs"].size(), 2u);
  EXPECT_LE(s["min"].get<double>(), s["median"].get<double>());
  EXPECT_LE(s["median"].get<double>(), s["max"].get<double>());
  EXPECT_GT(s["min"].get<double>(), 0.0);
  EXPECT_EQ(j["env_samples_per_s_runs"].size(), 3u);  // before, between and after
}

TEST_F(BenchTest, ProfilePhasesAddUp) {
  const Result r = RunPerch("bench profile --json --steps 300 --config " + Config("default.json"));
  ASSERT_EQ(r.code, 0) << r.out;
  const Json j = Json::parse(r.out);
  const Json& us = j["us_per_step"];
  const auto v = [&](const char* k) { return us[k].get<double>(); };
  // Bullet's zones partition its time; the phases partition the step.
  EXPECT_NEAR(v("solver") + v("dynamics") + v("collision") + v("physics_other"), v("physics"),
              1e-6 * v("physics"));
  EXPECT_NEAR(v("physics") + v("env_own") + v("policy_and_collector") + v("wire"), v("total"),
              1e-6 * v("total"));
  EXPECT_GT(v("solver"), 0.0);
  EXPECT_GT(v("narrowphase"), 0.0);
  EXPECT_GT(v("env_own"), 0.0);
  // Four physics steps per control step (240 / 60 Hz).
  EXPECT_DOUBLE_EQ(j["zones"]["internalSingleStepSimulation"]["calls_per_step"].get<double>(), 4.0);
}

}  // namespace
}  // namespace perch
