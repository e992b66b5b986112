#include "learner/local/meta_clone_stage.h"

#include <chrono>
#include <iostream>
#include <memory>

#include "common/paths.h"
#include "experiment/experiment.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/meta_expert.h"
#include "protocol/wire.h"
#include "tasks/model_source.h"
#include "tasks/task_env.h"

namespace perch {

MetaCloneStage RunMetaCloneStage(MetaCloneStageOptions o) {
  const ExperimentConfig c = LoadExperimentConfig(o.config, o.sets);
  const TaskEnvConfig config = TaskEnvConfig::FromJson(c.env, o.config + ": env");
  if (config.env.task != "sit_chair") {
    throw ConfigError(o.config + ": env.task is \"" + config.env.task +
                      "\"; meta-clone needs sit_chair");
  }
  if (o.from_config_init) {
    if (!o.init_from.empty()) throw ConfigError("meta-clone: --stage or --init-from, not both");
    if (c.cluster.init_from.empty()) {
      throw ConfigError(o.config + ": --stage needs cluster.init_from (the previous stage)");
    }
    o.init_from = ResolveProjectPath(c.cluster.init_from);
  }
  if (!o.init_from.empty()) o.clone.init = LoadModelFile(o.init_from);
  const std::vector<FrozenPolicyData> frozen = ExperimentFrozenPolicies(c);
  const PolicyConfig pc = ResolvePolicyConfig(c, MakeExperimentEnv(c)->spec());
  if (o.clone.init) {
    // Refuse a start of another shape now, not after the planner's calibration.
    try {
      CheckCloneInit(pc, c.ppo.obs_norm, *o.clone.init);
    } catch (const ConfigError& e) {
      throw ConfigError(o.init_from + ": does not fit the config's meta network: " + e.what());
    }
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::cerr << "meta-clone: measuring the turns for the planner\n";
  auto plan = std::make_shared<const MetaPlan>(
      BuildMetaPlan(config, frozen, config.Section<SitChairTaskConfig>().meta.planner));
  if (!o.clone.progress) {
    o.clone.progress = [](const std::string& line) { std::cerr << line << "\n"; };
  }
  const CloneResult r = CloneMeta(config, frozen, pc, c.ppo.obs_norm, plan, o.clone);
  MetaCloneStage out;
  proto::Checkpoint& ck = out.checkpoint;
  ck.set_wire_version(proto::WIRE_VERSION_CURRENT);
  proto::TaskPolicy* tp = ck.mutable_weights()->add_policies();
  tp->set_task(proto::TASK_META);
  *tp->mutable_model() = r.weights;
  for (const FrozenPolicyData& f : frozen) {
    *ck.mutable_weights()->add_policies() = FrozenPolicyToProto(f);
  }
  *ck.mutable_trainer()->mutable_model() = r.weights;
  ck.set_resolved_config_json(ToJson(c).dump());
  ck.set_compat_key(CompatKey(c, pc));
  ck.set_seed(c.seed);
  out.summary = r.summary;
  // The stage's cost (issue 15 asks for meta steps, samples and wall time per stage).
  out.summary["wall_s"] =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  out.summary["config"] = ToJson(c);
  // Which curriculum stage this is: the zone it was cloned on and the stage it started from.
  out.summary["stage"] = Json{{"zone", config.env.spawn.zone},
                              {"init_from", o.init_from.empty() ? Json() : Json(o.init_from)}};
  return out;
}

}  // namespace perch
