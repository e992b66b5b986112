// The task registry: every task the humanoid-chair env can run, by name, in one table (as
// EnvPool binds task ids to specs). Per task: its observation layout, whether it needs a chair,
// how its config section is read and written, its factory and its evaluation. The env factory,
// `perch train`, `perch eval` and `--check-config` find tasks here; adding a task is its own
// file plus one entry in registry.cc (or a TaskRegistration in its own file). The hierarchy's
// sit_chair task lives a floor above (hierarchy/) and is added by RegisterHierarchyTasks().
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "common/json_util.h"
#include "common/proto/model.pb.h"
#include "envs/env_config.h"
#include "envs/humanoid_env.h"

namespace perch {

struct TaskEnvConfig;
struct BankStartConfig;
struct EvalOptions;
struct EvalRecording;

// A task's typed config section, type-erased so TaskEnvConfig can hold any task's.
struct TaskSection {
  virtual ~TaskSection() = default;
  virtual Json ToJson() const = 0;
};
template <class C>
struct TaskSectionOf : TaskSection {
  explicit TaskSectionOf(C c) : config(std::move(c)) {}
  C config;
  Json ToJson() const override { return config.ToJson(); }
};

struct TaskDef {
  std::string name;  // env.task, the config section's key and the wire task name
  std::string description;
  ObsLayout obs_layout = ObsLayout::kProprioGoal;
  // When set, the layout follows from the task's section (read first) instead of obs_layout.
  std::function<ObsLayout(const TaskEnvConfig& config)> layout_for;
  bool needs_chair = false;  // false: the chair defaults to "none"
  // Reads the task's section (j null: the defaults) into config (ConfigError naming ctx).
  std::function<void(const Json* j, const std::string& ctx, TaskEnvConfig* config)> read;
  // The section as written into resolved configs (null: no section).
  std::function<Json(const TaskEnvConfig& config)> write;
  // Checks across sections, e.g. a chair the task cannot use (ConfigError naming the field).
  std::function<void(const TaskEnvConfig& config, const std::string& ctx)> check;
  std::function<std::unique_ptr<Task>(const TaskEnvConfig& config)> make;
  // `perch eval`: one JSON object with at least episodes, success_rate (+ success_ci95),
  // fall_rate and mean_imitation_reward.
  std::function<Json(const TaskEnvConfig&, const proto::ModelWeights&, const EvalOptions&,
                     EvalRecording*)>
      evaluate;
  // The section's field table as data (FieldTable::Describe: name, default, doc, rule), for
  // `perch config --fields TASK`; null for a task without one.
  std::function<Json()> fields;
};

// Adds a task (ConfigError when its name is taken or empty). A task's own file may register it
// at start-up, without editing any shared list:
//   static const TaskRegistration kHoldStill(HoldStillDef());
// (a file linked into the program directly; one inside a static library is linked only when
// something else in it is used, so the built-in tasks are listed in registry.cc).
void RegisterTask(TaskDef def);
struct TaskRegistration {
  explicit TaskRegistration(TaskDef def) { RegisterTask(std::move(def)); }
};

// nullptr when unknown.
const TaskDef* FindTask(const std::string& name);
// ConfigError "CTX: unknown task "x" (known: ...)".
const TaskDef& GetTask(const std::string& name, const std::string& ctx);
std::vector<std::string> TaskNames();
std::string TaskNamesJoined();  // "stand, walk, turn_left, ..."

// A task's `start` banks each read and fit the humanoid; with keep_pose each state carries its
// chair (ConfigError naming CTX.start.banks / CTX.start.keep_pose). For TaskDef::check.
void CheckStartBanks(const BankStartConfig& start, const TaskEnvConfig& config,
                     const std::string& ctx);

}  // namespace perch
