#include "tasks/registry.h"

#include <deque>

#include "common/paths.h"
#include "envs/chair.h"
#include "tasks/sit.h"
#include "tasks/state_bank.h"
#include "tasks/task_env.h"
#include "tasks/task_eval.h"
#include "tasks/turn.h"
#include "tasks/walk_eval.h"

namespace perch {

// Every start bank of a task config reads and fits the humanoid (ConfigError naming the field).
void CheckStartBanks(const BankStartConfig& start, const TaskEnvConfig& c, const std::string& ctx) {
  if (start.banks.empty()) return;
  const HumanoidModel model = HumanoidModel::Load(c.env.HumanoidPath());
  for (const std::string& b : start.banks) {
    proto::StateBank bank;
    try {
      bank = ReadStateBank(ResolveProjectPath(b), &model);
    } catch (const ConfigError& e) {
      throw ConfigError(ctx + ".start.banks: " + e.what());
    }
    // keep_pose places each state relative to its own chair: a bank without one is refused
    // here, at start-up, rather than at the first episode that draws it.
    if (start.keep_pose) {
      for (const proto::BankState& st : bank.states()) {
        if (!st.has_chair()) {
          throw ConfigError(ctx + ".start.keep_pose: " + b +
                            " holds states without a chair (sample them in the chain: perch "
                            "eval --task chain --chain-save-sit-starts)");
        }
      }
    }
  }
}

namespace {

TaskDef WalkDef() {
  TaskDef d;
  d.name = "walk";
  d.description = "walk: imitation of the walk cycle, forward (stage 1) or to targets (stage 2)";
  d.obs_layout = ObsLayout::kProprioGoal;
  d.read = [](const Json* j, const std::string& ctx, TaskEnvConfig* c) {
    if (j != nullptr) c->walk = WalkTaskConfig::FromJson(*j, ctx);
  };
  d.write = [](const TaskEnvConfig& c) { return c.walk.ToJson(); };
  d.fields = [] { return WalkTaskConfigFields().Describe(); };
  d.check = [](const TaskEnvConfig& c, const std::string& ctx) {
    CheckStartBanks(c.walk.start, c, ctx + ".walk");
  };
  d.make = [](const TaskEnvConfig& c) -> std::unique_ptr<Task> {
    return std::make_unique<WalkTask>(c.walk, c.control_dt());
  };
  d.evaluate = [](const TaskEnvConfig& c, const proto::ModelWeights& w, const EvalOptions& o,
                  EvalRecording* rec) {
    Json j = EvaluateWalk(c, w, o, rec);
    // The common keys: walk's success is staying up for the no-fall window.
    const int ok = static_cast<int>(std::lround(j["no_fall_rate"].get<double>() * o.episodes));
    const auto ci = WilsonInterval95(ok, o.episodes);
    j["success_rate"] = j["no_fall_rate"];
    j["success_ci95"] = {ci[0], ci[1]};
    return j;
  };
  return d;
}

TaskDef TurnDef(const std::string& name) {
  TaskDef d;
  d.name = name;
  d.description = name + ": in-place turn by imitation of the turn clip, random yaw per episode";
  d.obs_layout = ObsLayout::kProprio;
  d.layout_for = [](const TaskEnvConfig& c) {
    return c.Section<TurnTaskConfig>().heading_goal ? ObsLayout::kProprioGoal : ObsLayout::kProprio;
  };
  d.read = [name](const Json* j, const std::string& ctx, TaskEnvConfig* c) {
    c->section = std::make_shared<TaskSectionOf<TurnTaskConfig>>(
        TurnTaskConfig::FromJson(j != nullptr ? *j : Json::object(), ctx, name));
  };
  d.write = [](const TaskEnvConfig& c) { return c.Section<TurnTaskConfig>().ToJson(); };
  d.fields = [name] {
    return TurnTaskConfigFields().Describe(TurnTaskConfig::FromJson(Json::object(), name, name));
  };
  d.check = [name](const TaskEnvConfig& c, const std::string& ctx) {
    CheckStartBanks(c.Section<TurnTaskConfig>().start, c, ctx + "." + name);
  };
  d.make = [name](const TaskEnvConfig& c) -> std::unique_ptr<Task> {
    return std::make_unique<TurnTask>(name, c.Section<TurnTaskConfig>(), c.control_dt());
  };
  d.evaluate = [](const TaskEnvConfig& c, const proto::ModelWeights& w, const EvalOptions& o,
                  EvalRecording* rec) {
    auto m = MakeTurnMetrics();
    Json j = EvaluateEpisodes(c, w, o, m.get(), rec);
    j["reward_variant"] = c.Section<TurnTaskConfig>().reward_variant;
    return j;
  };
  return d;
}

TaskDef SitDef() {
  TaskDef d;
  d.name = "sit";
  d.description = "sit: from standing with the back to the chair to seated, imitating the sit clip";
  d.obs_layout = ObsLayout::kProprioChair;
  d.layout_for = [](const TaskEnvConfig& c) {
    return c.Section<SitTaskConfig>().observe_chair_shape ? ObsLayout::kProprioChairShape
                                                          : ObsLayout::kProprioChair;
  };
  d.needs_chair = true;
  d.read = [](const Json* j, const std::string& ctx, TaskEnvConfig* c) {
    c->section = std::make_shared<TaskSectionOf<SitTaskConfig>>(
        SitTaskConfig::FromJson(j != nullptr ? *j : Json::object(), ctx));
  };
  d.write = [](const TaskEnvConfig& c) { return c.Section<SitTaskConfig>().ToJson(); };
  d.fields = [] { return SitTaskConfigFields().Describe(); };
  d.check = [](const TaskEnvConfig& c, const std::string& ctx) {
    CheckStartBanks(c.Section<SitTaskConfig>().start, c, ctx + ".sit");
    const Chair chair = Chair::Load(c.env.ChairPath());
    const double limit = c.Section<SitTaskConfig>().max_seat_height_m;
    if (chair.seat_height() > limit) {
      throw ConfigError(ctx + ".chair: \"" + c.env.chair + "\" has its seat at " +
                        std::to_string(chair.seat_height()) + " m, above the humanoid's reach (" +
                        ctx + ".sit.max_seat_height_m " + std::to_string(limit) + " m)");
    }
  };
  d.make = [](const TaskEnvConfig& c) -> std::unique_ptr<Task> {
    return std::make_unique<SitTask>(c.Section<SitTaskConfig>(), c.control_dt());
  };
  d.evaluate = [](const TaskEnvConfig& c, const proto::ModelWeights& w, const EvalOptions& o,
                  EvalRecording* rec) {
    auto m = MakeSitMetrics();
    Json j = EvaluateEpisodes(c, w, o, m.get(), rec);
    j["reward_variant"] = c.Section<SitTaskConfig>().reward_variant;
    j["reference_state_init"] = c.Section<SitTaskConfig>().reference_state_init;
    return j;
  };
  return d;
}

// A deque: registering a task never moves the others (FindTask hands out pointers).
std::deque<TaskDef>& Registry() {
  static std::deque<TaskDef> tasks = {WalkDef(), TurnDef("turn_left"), TurnDef("turn_right"),
                                      SitDef()};
  return tasks;
}

}  // namespace

void RegisterTask(TaskDef def) {
  if (def.name.empty() || def.name == "stand" || def.name == "chain") {
    throw ConfigError("RegisterTask: a task needs a name other than stand and chain");
  }
  if (FindTask(def.name) != nullptr) {
    throw ConfigError("RegisterTask: task \"" + def.name + "\" is registered already");
  }
  if (!def.make) throw ConfigError("RegisterTask: task \"" + def.name + "\" has no factory");
  Registry().push_back(std::move(def));
}

const TaskDef* FindTask(const std::string& name) {
  for (const TaskDef& d : Registry()) {
    if (d.name == name) return &d;
  }
  return nullptr;
}

std::vector<std::string> TaskNames() {
  std::vector<std::string> names;
  for (const TaskDef& d : Registry()) names.push_back(d.name);
  return names;
}

std::string TaskNamesJoined() {
  std::string s = "stand";
  for (const std::string& n : TaskNames()) s += ", " + n;
  return s;
}

const TaskDef& GetTask(const std::string& name, const std::string& ctx) {
  const TaskDef* d = FindTask(name);
  if (d == nullptr) {
    throw ConfigError(ctx + ": unknown task \"" + name + "\" (known: " + TaskNamesJoined() + ")");
  }
  return *d;
}

}  // namespace perch
