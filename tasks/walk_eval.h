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

namespace perch {

struct WalkEvalOptions {
  int episodes = 10;
  uint64_t seed = 0;
  bool stochastic = false;  // default: the Gaussian's mean
  double no_fall_s = 10.0;  // an episode counts as no-fall if it stays up this long [s]
  FootSlidingOptions foot_sliding;
  EpisodeRecorder* recorder = nullptr;  // perch eval --record (not owned)
};

// Episode 0, for the filmstrip.
struct WalkEvalRecording {
  std::vector<PoseFrame> frames;
  std::vector<Eigen::Vector2d> targets;  // distinct walk targets (target stage) [m]
};

// Runs the episodes. Episodes last at least no_fall_s (the time limit is raised when shorter).
Json EvaluateWalk(const TaskEnvConfig& config, const proto::ModelWeights& weights,
                  const WalkEvalOptions& options, WalkEvalRecording* recording);

}  // namespace perch
