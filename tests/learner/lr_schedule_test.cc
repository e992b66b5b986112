// ppo.lr_schedule: a piecewise-constant learning rate by the run's samples (issue 48).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "learner/ppo.h"

namespace perch {
namespace {

TEST(LrSchedule, StepsAtTheSamplesGiven) {
  PpoConfig c = PpoConfigFromJson(
      Json{{"learning_rate", 1e-4}, {"lr_schedule", {{1000, 3e-5}, {5000, 1e-5}}}}, "ppo");
  EXPECT_FLOAT_EQ(LearningRateAt(c, 0), 1e-4f);
  EXPECT_FLOAT_EQ(LearningRateAt(c, 999), 1e-4f);
  EXPECT_FLOAT_EQ(LearningRateAt(c, 1000), 3e-5f);
  EXPECT_FLOAT_EQ(LearningRateAt(c, 4999), 3e-5f);
  EXPECT_FLOAT_EQ(LearningRateAt(c, 123456789), 1e-5f);
  // It survives the trip through the resolved config (checkpoints hold it).
  const PpoConfig back = PpoConfigFromJson(ToJson(c), "ppo");
  EXPECT_EQ(back.lr_schedule, c.lr_schedule);
}

TEST(LrSchedule, AbsentIsConstantAndLeavesTheResolvedConfigAsItWas) {
  const PpoConfig c = PpoConfigFromJson(Json::object(), "ppo");
  EXPECT_FLOAT_EQ(LearningRateAt(c, 1 << 30), c.learning_rate);
  EXPECT_FALSE(ToJson(c).contains("lr_schedule"));
}

TEST(LrSchedule, RefusesBadEntriesNamingThem) {
  auto err = [](const Json& s) {
    try {
      PpoConfigFromJson(Json{{"lr_schedule", s}}, "cfg.ppo");
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_THAT(err(Json{{5000, 1e-5}, {1000, 3e-5}}),
              ::testing::HasSubstr("lr_schedule[1]: samples must increase"));
  EXPECT_THAT(err(Json{{1000, -1}}),
              ::testing::HasSubstr("lr_schedule[0]: rate must be in (0, 1)"));
  EXPECT_THAT(err(Json{{1000}}), ::testing::HasSubstr("lr_schedule[0]: expected [samples"));
  EXPECT_THAT(err(Json{{1.5, 1e-5}}), ::testing::HasSubstr("expected [samples (integer)"));
  EXPECT_THAT(err(Json(3)), ::testing::HasSubstr("cfg.ppo.lr_schedule: expected"));
}

}  // namespace
}  // namespace perch
