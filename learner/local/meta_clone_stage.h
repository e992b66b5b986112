// `perch meta-clone`: one stage of the meta curriculum by cloning. The scripted planner of an
// experiment config's sit_chair.meta.planner is cloned into a meta policy (CloneMeta), packed as a
// run's checkpoint at update 0 (the clone, its config and the frozen subtasks), so that
// `perch eval --model` finds everything in it and a PPO run starts from it (cluster.init_from).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "common/json_util.h"
#include "common/proto/wire.pb.h"
#include "learner/local/meta_clone.h"

namespace perch {

struct MetaCloneStageOptions {
  std::string config;             // the sit_chair meta experiment config
  std::vector<std::string> sets;  // section.field=JSON overrides
  // A curriculum stage starts from this meta policy (round 1 is then a DAgger round driven by it);
  // with from_config_init, the config's cluster.init_from instead.
  std::string init_from;
  bool from_config_init = false;
  CloneOptions clone;
};

struct MetaCloneStage {
  proto::Checkpoint checkpoint;  // the clone as a run's checkpoint at update 0
  Json summary;                  // CloneMeta's summary + wall_s, config and stage
};

// ConfigError (naming the file or flag) on a config whose task is not sit_chair, both or neither
// start given where needed, or a start of another shape than the config's meta network; refused
// before the planner's calibration.
MetaCloneStage RunMetaCloneStage(MetaCloneStageOptions o);

}  // namespace perch
