// The sit_chair config the planner tests share: Zone 1, the delivered subtasks, the meta seeing
// its active subtask, mean subtask actions and the planned hand-over calibrated on `runs` turn
// runs (tests/tasks/chain_plan_test.cc, tests/learner/local/meta_clone_test.cc).
#pragma once

#include "common/json_util.h"
#include "tasks/task_env.h"

namespace perch {
namespace testing_util {

inline TaskEnvConfig PlannedMeta(int runs) {
  Json env{{"task", "sit_chair"},
           {"spawn", {{"zone", 1}}},
           {"sit_chair",
            {{"support_reward", 5.0},
             {"meta",
              {{"observe_active", true},
               {"subtask_stochastic", false},
               {"planner", {{"calibration_runs", runs}}}}}}}};
  return TaskEnvConfig::FromJson(env, "t");
}

}  // namespace testing_util
}  // namespace perch
