// Evaluation of a subtask policy (perch eval --task T): one episode runner (seeding, mean or
// sampled actions, falls, the frames of episode 0 for a filmstrip) and per-task metric plug-ins
// (turn: heading at the end; sit: seated contact, seat position and orientation errors). Walk
// keeps its own runner (tasks/walk_eval.h). Definitions: docs/subtasks.md.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/json_util.h"
#include "common/proto/model.pb.h"
#include "envs/humanoid_env.h"
#include "envs/pose_frame.h"
#include "tasks/foot_sliding.h"
#include "tasks/recording.h"
#include "tasks/task_env.h"

namespace perch {

struct EvalOptions {
  int episodes = 10;
  uint64_t seed = 0;
  bool stochastic = false;  // default: the Gaussian's mean
  double no_fall_s = 10.0;  // walk: an episode counts as no-fall if it stays up this long [s]
  FootSlidingOptions foot_sliding;
  EpisodeRecorder* recorder = nullptr;  // perch eval --record (not owned)
};

// Episode 0, for the filmstrip.
struct EvalRecording {
  std::vector<PoseFrame> frames;
  std::vector<Eigen::Vector2d> targets;  // distinct walk targets [m]
};

// Mean and population standard deviation of per-episode values (0 for none).
double MeanOf(const std::vector<double>& v);
double StdOf(const std::vector<double>& v);

// Wilson score interval of a binomial proportion at 95%: [lo, hi].
std::array<double, 2> WilsonInterval95(int successes, int n);

// What a task measures over one episode; one instance per evaluation.
class EpisodeMetrics {
 public:
  virtual ~EpisodeMetrics() = default;
  // Extra steps the episodes need beyond the task's time limit (e.g. sit: 3 s seated).
  virtual int MinEpisodeSteps(const HumanoidChairEnv& env) const { return 0; }
  virtual void Start(const HumanoidChairEnv& env) = 0;
  virtual void Observe(const HumanoidChairEnv& env, const StepResult& r) = 0;
  // Episode over (fell = early termination). Returns success.
  virtual bool Finish(const HumanoidChairEnv& env, bool fell) = 0;
  virtual double ImitationReward(const HumanoidChairEnv& env) const = 0;  // this step's r^S
  virtual void AddSummary(Json* j) const = 0;
};

// Runs the episodes with `metrics` and returns the common JSON (task, episodes, success_rate,
// success_ci95, fall_rate, mean_imitation_reward, mean_return, ...) plus the task's.
Json EvaluateEpisodes(const TaskEnvConfig& config, const proto::ModelWeights& weights,
                      const EvalOptions& options, EpisodeMetrics* metrics, EvalRecording* rec);

// The plug-ins of the clip tasks (registered in tasks/registry.cc).
std::unique_ptr<EpisodeMetrics> MakeTurnMetrics();
std::unique_ptr<EpisodeMetrics> MakeSitMetrics();

}  // namespace perch
