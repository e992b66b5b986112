// What a user needs to judge a run from its console (issue 18): rolling means over the last
// finished episodes (length, falls, the task's success test) and, when the config has a sample
// budget or a success target, percent done, an ETA and the decision to stop.
#pragma once

#include <cstdint>
#include <deque>
#include <optional>
#include <string>

namespace perch {

struct ProgressConfig {
  int64_t max_samples = 0;      // cluster.max_samples: stop once trained on this many (0: no budget)
  double target_success = 0.0;  // cluster.target_success: stop at this success rate (0: none)
  int target_window = 200;      // ... over this many of the newest judged episodes
  int episode_window = 200;     // episodes behind the console's length and fall means
  double control_dt = 0.0;      // [s] per env step; 0: lengths shown in steps
};

class RunProgress {
 public:
  // samples_at_start: a resumed run's samples (the ETA counts only this process's rate).
  RunProgress(const ProgressConfig& c, uint64_t samples_at_start, double start_s);

  void AddEpisode(int64_t length_steps, bool terminated, bool judged, bool succeeded);
  void OnUpdate(uint64_t samples_total, double now_s);

  size_t episodes_in_window() const { return lengths_.size(); }
  std::optional<double> MeanLengthSteps() const;
  std::optional<double> FallRate() const;
  // Over the newest target_window judged episodes (fewer while the run is young).
  std::optional<double> SuccessRate() const;
  size_t judged_in_window() const { return judged_.size(); }
  // Budget done in [0, 1]; empty without a budget.
  std::optional<double> FractionDone() const;
  // Seconds to the budget at this process's mean rate; empty without a budget or a rate yet.
  std::optional<double> EtaSeconds() const;

  // "max_samples" or "target_success" once the run should end by itself, "" before.
  std::string StopReason() const;

  // One console line: samples, budget %, ETA, samples/s, episode length, falls, success.
  std::string ConsoleLine(uint64_t update, double samples_per_s) const;
  // The paragraph printed when the run ends.
  std::string Summary(uint64_t update, const std::string& why, const std::string& checkpoint,
                      double train_seconds) const;

 private:
  ProgressConfig c_;
  uint64_t samples_at_start_;
  double start_s_;
  uint64_t samples_ = 0;
  double now_s_ = 0.0;
  std::deque<int64_t> lengths_;
  std::deque<bool> terminated_;
  std::deque<bool> judged_;  // success of each judged episode
};

// "1.23M", "820k", "512".
std::string HumanCount(double n);
// "42s", "12m", "3h05m".
std::string HumanDuration(double seconds);

}  // namespace perch
