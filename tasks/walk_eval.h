// Evaluation of a walk policy (perch eval --task walk): seeded episodes with mean (or sampled)
// actions, the paper's and DAFNet's metrics (docs/walk.md), and the frames for a filmstrip.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/json_util.h"
#include "common/proto/model.pb.h"
#include "envs/pose_frame.h"
#include "policy/policy.h"
#include "tasks/foot_sliding.h"
#include "tasks/model_source.h"
#include "tasks/recording.h"
#include "tasks/task_env.h"
#include "tasks/task_eval.h"

namespace perch {

// Runs the episodes in the shared loop (tasks/task_eval.h). Episodes last at least o.no_fall_s
// (the time limit is raised when shorter); recording: episode 0's poses and distinct targets.
Json EvaluateWalk(const TaskEnvConfig& config, const proto::ModelWeights& weights,
                  const EvalOptions& o, EvalRecording* recording);

}  // namespace perch
