// What a training run did, read back from its run dir (<run_dir>/metrics.jsonl, config.json,
// checkpoints/): the numbers a model card needs (samples, wall time, throughput) and the
// learning curve as CSV. `perch run-summary`.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/json_util.h"

namespace perch {

struct CurveRow {
  int64_t update = 0;
  int64_t samples = 0;
  double time_s = 0.0;         // training wall time so far, summed over resumes [s]
  double samples_per_s = 0.0;  // over the last update
  double return_mean = 0.0;    // undiscounted episode return, episodes that ended in the batch
  double episode_length_mean = 0.0;  // control steps
  bool has_episodes = false;         // false: no episode ended in that batch (return/length blank)
  double policy_lag_mean = 0.0;      // updates
  double log_std_mean = 0.0;         // policy exploration (log sigma, mean over actions)
  int actors = 0;
  int64_t episodes = 0;             // episodes that ended in the batch
  int64_t episodes_terminated = 0;  // ... by early termination (a fall)
  int64_t episodes_judged = 0;      // ... judged by the task's success test (turn, sit)
  int64_t episodes_succeeded = 0;   // ... that passed it
};

struct RunSummary {
  std::string run_dir;
  std::vector<CurveRow> curve;  // ascending update; on a resume a repeated update keeps the last
  int64_t updates = 0;
  int64_t samples = 0;
  double wall_time_s = 0.0;
  int max_actors = 0;
  std::vector<std::string> checkpoints;  // paths, ascending update
  Json config;                           // <run_dir>/config.json (null when absent)
};

// ConfigError naming the file (and line) on a missing metrics.jsonl or a malformed row.
RunSummary SummarizeRun(const std::string& run_dir);
// update,samples,time_s,samples_per_s,return_mean,episode_length_mean,policy_lag_mean,
// log_std_mean,actors. Written atomically.
void WriteCurveCsv(const RunSummary& s, const std::string& path);
// {run_dir, updates, samples, wall_time_s, samples_per_s, max_actors, checkpoints, last
// {return_mean, episode_length_mean} averaged over the last 10 updates with episodes}.
Json ToJson(const RunSummary& s);
// Learning curves of one or more runs (overlaid, labelled by run dir) as a PNG, drawn by gnuplot
// (Debian's gnuplot-nox): return, episode length, fall rate (terminated / ended episodes per
// batch), success rate (passed / judged, tasks with a success test) and samples/s, each against samples (left column) and wall time (right column).
// ConfigError when gnuplot is missing or fails.
void PlotRuns(const std::vector<RunSummary>& runs, const std::string& png_path);

}  // namespace perch
