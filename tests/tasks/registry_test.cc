// A task that is not part of Perch registers itself from this file alone (no shared list edited):
// the signpost of docs/architecture.md "A new subtask" that a new task is its own source, its
// test, its clip and config, and one registration.
#include "tasks/registry.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "tasks/task_env.h"

namespace perch {
namespace {

struct HoldStillConfig {
  int max_episode_steps = 30;
  double min_root_z = 0.5;  // [m]
  static HoldStillConfig FromJson(const Json& j, const std::string& ctx) {
    CheckKnownKeys(j, {"max_episode_steps", "min_root_z"}, ctx);
    HoldStillConfig c;
    GetOptional(j, "max_episode_steps", c.max_episode_steps, ctx);
    GetOptional(j, "min_root_z", c.min_root_z, ctx);
    if (c.max_episode_steps < 1) throw ConfigError(ctx + ".max_episode_steps: must be >= 1");
    return c;
  }
  Json ToJson() const {
    return Json{{"max_episode_steps", max_episode_steps}, {"min_root_z", min_root_z}};
  }
};

// Stand still: reward exp(-|v|^2) of the torso's speed; ends when the torso falls below min_root_z.
class HoldStillTask : public Task {
 public:
  explicit HoldStillTask(const HoldStillConfig& c) : c_(c) {}
  const char* name() const override { return "hold_still"; }
  int max_episode_steps() const override { return c_.max_episode_steps; }
  TaskStep OnStep(const HumanoidChairEnv& env, const float*) override {
    const HumanoidState& s = env.humanoid_state();
    TaskStep t;
    t.reward = static_cast<float>(std::exp(-s.root_lin_vel.squaredNorm()));
    t.terminated = s.root_pos.z() < c_.min_root_z;
    return t;
  }

 private:
  HoldStillConfig c_;
};

TaskDef HoldStillDef() {
  TaskDef d;
  d.name = "hold_still";
  d.description = "hold_still: a test task that registers itself (tests/tasks/registry_test.cc)";
  d.obs_layout = ObsLayout::kProprio;
  d.read = [](const Json* j, const std::string& ctx, TaskEnvConfig* c) {
    c->section = std::make_shared<TaskSectionOf<HoldStillConfig>>(
        HoldStillConfig::FromJson(j != nullptr ? *j : Json::object(), ctx));
  };
  d.write = [](const TaskEnvConfig& c) { return c.Section<HoldStillConfig>().ToJson(); };
  d.make = [](const TaskEnvConfig& c) -> std::unique_ptr<Task> {
    return std::make_unique<HoldStillTask>(c.Section<HoldStillConfig>());
  };
  return d;
}

const TaskRegistration kHoldStill(HoldStillDef());

TEST(TaskRegistry, ATaskRegistersItselfAndRunsThroughTheSharedPaths) {
  ASSERT_NE(FindTask("hold_still"), nullptr);
  const std::vector<std::string> names = TaskNames();
  EXPECT_NE(std::find(names.begin(), names.end(), "hold_still"), names.end());
  // The built-in tasks are still there, in their order.
  EXPECT_EQ(names.front(), "walk");
  // Its config section is read, written and checked like a built-in task's.
  const TaskEnvConfig c = TaskEnvConfig::FromJson(
      Json{{"task", "hold_still"}, {"chair", "none"}, {"hold_still", {{"max_episode_steps", 4}}}},
      "t");
  EXPECT_EQ(c.ToJson()["hold_still"]["max_episode_steps"], 4);
  EXPECT_THROW(TaskEnvConfig::FromJson(
                   Json{{"task", "hold_still"}, {"hold_still", {{"max_steps", 4}}}}, "t"),
               ConfigError);
  // The env factory builds it; its time limit truncates (not terminates) the episode.
  std::unique_ptr<Env> env = MakeTaskEnv(c);
  env->Seed(3);
  std::vector<float> obs(env->spec().obs_dim), act(env->spec().act_dim, 0.0f);
  env->Reset(obs.data());
  StepResult r;
  int steps = 0;
  do {
    r = env->Step(act.data(), obs.data());
    ++steps;
    EXPECT_GT(r.reward, 0.0f);
    EXPECT_LE(r.reward, 1.0f);
  } while (!r.terminated && !r.truncated && steps < 10);
  EXPECT_EQ(steps, 4);
  EXPECT_TRUE(r.truncated);
  EXPECT_FALSE(r.terminated);
  // A name is registered once; "stand" and "chain" are taken by the env and perch eval.
  EXPECT_THROW(RegisterTask(HoldStillDef()), ConfigError);
  TaskDef stand = HoldStillDef();
  stand.name = "stand";
  EXPECT_THROW(RegisterTask(stand), ConfigError);
}

}  // namespace
}  // namespace perch
