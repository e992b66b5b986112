// learner/toy_train.h: PPO on a toy task in process, the library behind `perch ppo toy`.
#include "learner/toy_train.h"

#include <gtest/gtest.h>

#include <filesystem>

namespace perch {
namespace {

TEST(ToyTrain, ChoiceTargetLearnsAndTheSameSeedGivesTheSameRun) {
  ToyTrainOptions o;
  o.task = "choice_target";
  o.updates = 12;
  o.seed = 3;
  const Json a = TrainToy(o);
  ASSERT_EQ(a["curve"].size(), 12u);
  const double first = a["curve"][0]["episode_return"].get<double>();
  const double last = a["curve"][11]["episode_return"].get<double>();
  EXPECT_GT(last, first) << a["curve"].dump();
  EXPECT_GT(a["episodes"].get<int>(), 0);
  EXPECT_EQ(a["config"]["ppo"]["num_minibatches"], ToyPpoConfig("choice_target").num_minibatches);
  // Reproducible: the same options give the same curve, to the last digit.
  EXPECT_EQ(TrainToy(o).dump(), a.dump());
  o.seed = 4;
  EXPECT_NE(TrainToy(o)["curve"].dump(), a["curve"].dump());
}

TEST(ToyTrain, UnknownTaskIsRefusedBeforeAnythingIsWritten) {
  const std::string dir = ::testing::TempDir() + "/toy_train_unknown";
  std::filesystem::remove_all(dir);
  ToyTrainOptions o;
  o.task = "cartpole";
  o.out_dir = dir;
  try {
    TrainToy(o);
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("cartpole"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir));
}

}  // namespace
}  // namespace perch
