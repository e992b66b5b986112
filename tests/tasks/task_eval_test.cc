#include "tasks/task_eval.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "learner/ppo.h"
#include "tasks/registry.h"
#include "tests/support/untrained.h"

namespace perch {
namespace {

TEST(TaskEval, WilsonInterval) {
  auto a = WilsonInterval95(0, 10);
  EXPECT_EQ(a[0], 0.0);
  EXPECT_NEAR(a[1], 0.2775, 1e-3);
  auto b = WilsonInterval95(10, 10);
  EXPECT_NEAR(b[0], 0.7225, 1e-3);
  EXPECT_NEAR(b[1], 1.0, 1e-12);
  auto c = WilsonInterval95(50, 100);
  EXPECT_NEAR(c[0], 0.4038, 1e-3);
  EXPECT_NEAR(c[1], 0.5962, 1e-3);
}

TEST(TaskEval, EveryRegisteredTaskEvaluatesReproduciblyWithTheCommonKeys) {
  for (const std::string& name : TaskNames()) {
    SCOPED_TRACE(name);
    if (!GetTask(name, "test").evaluate) continue;  // sit_chair: evaluated as a hierarchy
    const TaskEnvConfig c = TaskEnvConfig::Defaults(name);
    const int obs_dim = ObsLayoutDim(c.env.obs_layout);
    const proto::ModelWeights w = Untrained(obs_dim, 3);
    EvalOptions o;
    o.episodes = 2;
    o.seed = 7;
    o.no_fall_s = 1.0;
    EvalRecording rec;
    const TaskDef& def = GetTask(name, "test");
    const Json a = def.evaluate(c, w, o, &rec);
    const Json b = def.evaluate(c, w, o, nullptr);
    EXPECT_EQ(a.dump(), b.dump());  // same seed, same episodes; recording changes nothing
    for (const char* k :
         {"episodes", "success_rate", "success_ci95", "fall_rate", "mean_imitation_reward"}) {
      EXPECT_TRUE(a.contains(k)) << k;
    }
    const double p = a["success_rate"].get<double>();
    EXPECT_LE(a["success_ci95"][0].get<double>(), p);
    EXPECT_GE(a["success_ci95"][1].get<double>(), p);
    EXPECT_GE(rec.frames.size(), 2u);
    o.seed = 8;
    EXPECT_NE(def.evaluate(c, w, o, nullptr).dump(), a.dump());
  }
}

TEST(TaskEval, UntrainedPoliciesNeitherTurnNorSit) {
  // A random policy falls over: neither task's success test may pass it.
  for (const char* name : {"turn_left", "sit"}) {
    SCOPED_TRACE(name);
    const TaskEnvConfig c = TaskEnvConfig::Defaults(name);
    EvalOptions o;
    o.episodes = 3;
    const Json j =
        GetTask(name, "t").evaluate(c, Untrained(ObsLayoutDim(c.env.obs_layout), 1), o, nullptr);
    EXPECT_EQ(j["success_rate"].get<double>(), 0.0);
    EXPECT_GT(j["fall_rate"].get<double>(), 0.0);
    if (std::string(name) == "sit") {
      // Every episode failed; each fall among them is counted as a failure that fell.
      EXPECT_EQ(j["failures"]["fell"].get<int>(),
                static_cast<int>(std::lround(j["fall_rate"].get<double>() * o.episodes)));
      EXPECT_GE(j["failures"]["longest_contact_s_mean"].get<double>(), 0.0);
    }
    if (std::string(name) == "turn_left") {
      // Every early termination is attributed to exactly one rule.
      const Json& by = j["terminations_by_rule"];
      EXPECT_EQ(by["root_height"].get<int>() + by["yaw"].get<int>(),
                static_cast<int>(std::lround(j["fall_rate"].get<double>() * o.episodes)));
    }
  }
}

}  // namespace
}  // namespace perch
