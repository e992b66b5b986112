// Evaluation of a subtask policy (perch eval --task T): RunEvalEpisodes runs a policy in the shared
// episode loop (tasks/episode_loop.h, which the hierarchy's evaluations use too) with mean or
// sampled actions, falls, the recorder and the frames of episode 0 for a filmstrip; and what each
// task measures over it (success is the task's StepResult::success, read by the metrics): turn and
// sit through EpisodeMetrics plug-ins (turn: heading at the end; sit: seated contact, seat position
// and orientation errors) and EvaluateEpisodes' common JSON; walk through its own observer
// (tasks/walk_eval.h). Definitions: docs/subtasks.md.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/json_util.h"
#include "common/proto/model.pb.h"
#include "envs/humanoid_env.h"
#include "envs/pose_frame.h"
#include "policy/policy.h"
#include "tasks/episode_loop.h"
#include "tasks/foot_sliding.h"
#include "tasks/perturbation.h"
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
  // perch eval --push/--obs-noise/--act-noise/--restore: the figures are the perturbed episodes',
  // and the same episodes also run unperturbed for the flip rate (AddFlipRate).
  Perturbation perturb;
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

// What a task's evaluation observes in the shared episode loop (RunEvalEpisodes).
class EpisodeObserver {
 public:
  virtual ~EpisodeObserver() = default;
  // After the episode's Reset (before the recorder's Begin).
  virtual void Begin(const HumanoidChairEnv& env) = 0;
  // After each step the env did not flag invalid; `steps` counts this one.
  virtual void Observe(const HumanoidChairEnv& env, const StepResult& r, int steps) = 0;
  // The episode is over (fell: early termination); returns its success (for the recorder).
  virtual bool End(const HumanoidChairEnv& env, int episode, int steps, bool fell) = 0;
};

// The loop's settings and what it counts over all episodes.
struct EpisodeLoop {
  int max_steps = 0;                // steps per episode at most
  bool stop_at_truncation = false;  // also end an episode at the task's time limit
  bool record_targets = false;      // the recording also keeps episode 0's distinct walk targets
  // The steps an episode's outcome is judged over, where perturbations fall (0: the episode's
  // length, max_steps or the task's time limit; walk: its no-fall window).
  int judged_steps = 0;
};
struct EpisodeTotals {
  int invalid = 0;    // steps the env flagged invalid
  int falls = 0;      // episodes that ended early (terminated)
  int64_t steps = 0;  // control steps over all episodes
  double sum_return = 0.0;
  Json fall_times = Json::array();     // [s] per fallen episode
  Json fall_episodes = Json::array();  // index per fallen episode
  std::vector<bool> outcomes;          // per episode: its success (the observer's End)
};

// The policy of `weights` on an env of `spec`: Gaussian, its shapes those of the env
// (ConfigError naming the task otherwise); evaluation never moves its normaliser.
PolicyRunner MakeEvalPolicy(const proto::ModelWeights& weights, const EnvSpec& spec,
                            const std::string& task);

// Runs o.episodes episodes of `policy` on `env` in the shared loop (tasks/episode_loop.h: episode
// e depends only on (o.seed, e), so any episode can be rerun alone).
EpisodeTotals RunEvalEpisodes(HumanoidChairEnv* env, PolicyRunner* policy, const EvalOptions& o,
                              const EpisodeLoop& loop, EpisodeObserver* observer,
                              EvalRecording* rec);

// With o.perturb: runs the episodes of `perturbed` again without the perturbations and adds to *j
// "perturbation", "unperturbed_success_rate" and FlipRate's keys. An episode's outcome is the
// task's success (StepResult::success) or, for a task without one, staying up for
// `no_fall_steps`.
void AddFlipRate(HumanoidChairEnv* env, PolicyRunner* policy, const EvalOptions& o,
                 const EpisodeLoop& loop, const EpisodeTotals& perturbed, int no_fall_steps,
                 Json* j);

// Runs the episodes with `metrics` and returns the common JSON (task, episodes, success_rate,
// success_ci95, fall_rate, mean_imitation_reward, mean_return, ...) plus the task's.
Json EvaluateEpisodes(const TaskEnvConfig& config, const proto::ModelWeights& weights,
                      const EvalOptions& options, EpisodeMetrics* metrics, EvalRecording* rec);

// The plug-ins of the clip tasks (registered in tasks/registry.cc).
std::unique_ptr<EpisodeMetrics> MakeTurnMetrics();
std::unique_ptr<EpisodeMetrics> MakeSitMetrics();

}  // namespace perch
