#include "learner/service/progress.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <fmt/format.h>

namespace perch {
namespace {

template <typename T>
void PushBounded(std::deque<T>* q, T v, size_t cap) {
  q->push_back(v);
  while (q->size() > cap) q->pop_front();
}

std::string Percent(double x) { return fmt::format("{:.0f}%", 100.0 * x); }

}  // namespace

std::string HumanCount(double n) {
  if (n >= 1e9) return fmt::format("{:.2f}G", n / 1e9);
  if (n >= 1e6) return fmt::format("{:.2f}M", n / 1e6);
  if (n >= 1e4) return fmt::format("{:.0f}k", n / 1e3);
  return fmt::format("{:.0f}", n);
}

std::string HumanDuration(double s) {
  if (!(s >= 0) || !std::isfinite(s)) return "?";
  if (s < 60) return fmt::format("{:.0f}s", s);
  if (s < 3600) return fmt::format("{:.0f}m", s / 60);
  const int64_t m = static_cast<int64_t>(std::lround(s / 60));
  return fmt::format("{}h{:02d}m", m / 60, static_cast<int>(m % 60));
}

RunProgress::RunProgress(const ProgressConfig& c, uint64_t samples_at_start, double start_s)
    : c_(c), samples_at_start_(samples_at_start), start_s_(start_s), samples_(samples_at_start),
      now_s_(start_s) {}

void RunProgress::AddEpisode(int64_t length_steps, bool terminated, bool judged, bool succeeded) {
  const size_t cap = static_cast<size_t>(std::max(1, c_.episode_window));
  PushBounded(&lengths_, length_steps, cap);
  PushBounded(&terminated_, terminated, cap);
  if (judged) PushBounded(&judged_, succeeded, static_cast<size_t>(std::max(1, c_.target_window)));
}

void RunProgress::OnUpdate(uint64_t samples_total, double now_s) {
  samples_ = samples_total;
  now_s_ = now_s;
}

std::optional<double> RunProgress::MeanLengthSteps() const {
  if (lengths_.empty()) return std::nullopt;
  double s = 0;
  for (int64_t l : lengths_) s += static_cast<double>(l);
  return s / lengths_.size();
}

std::optional<double> RunProgress::FallRate() const {
  if (terminated_.empty()) return std::nullopt;
  return static_cast<double>(std::count(terminated_.begin(), terminated_.end(), true)) /
         terminated_.size();
}

std::optional<double> RunProgress::SuccessRate() const {
  if (judged_.empty()) return std::nullopt;
  return static_cast<double>(std::count(judged_.begin(), judged_.end(), true)) / judged_.size();
}

std::optional<double> RunProgress::FractionDone() const {
  if (c_.max_samples <= 0) return std::nullopt;
  return std::min(1.0, static_cast<double>(samples_) / static_cast<double>(c_.max_samples));
}

std::optional<double> RunProgress::EtaSeconds() const {
  if (c_.max_samples <= 0) return std::nullopt;
  const double done = static_cast<double>(samples_) - static_cast<double>(samples_at_start_);
  const double elapsed = now_s_ - start_s_;
  if (done <= 0 || elapsed <= 0) return std::nullopt;
  const double left = std::max(0.0, static_cast<double>(c_.max_samples) - static_cast<double>(samples_));
  return left / (done / elapsed);
}

std::string RunProgress::StopReason() const {
  if (c_.max_samples > 0 && samples_ >= static_cast<uint64_t>(c_.max_samples)) return "max_samples";
  // The target needs a full window: a lucky first few episodes must not end a run.
  if (c_.target_success > 0 && judged_.size() >= static_cast<size_t>(std::max(1, c_.target_window)) &&
      *SuccessRate() >= c_.target_success) {
    return "target_success";
  }
  return "";
}

std::string RunProgress::ConsoleLine(uint64_t update, double samples_per_s) const {
  std::string s = fmt::format("update {} | {} samples", update, HumanCount(static_cast<double>(samples_)));
  if (auto f = FractionDone()) {
    s += fmt::format(" ({} of {}", Percent(*f), HumanCount(static_cast<double>(c_.max_samples)));
    if (auto eta = EtaSeconds()) s += ", ETA " + HumanDuration(*eta);
    s += ")";
  }
  s += fmt::format(" | {:.0f} samples/s", samples_per_s);
  if (auto l = MeanLengthSteps()) {
    s += c_.control_dt > 0 ? fmt::format(" | episode {:.1f} s", *l * c_.control_dt)
                           : fmt::format(" | episode {:.0f} steps", *l);
    s += fmt::format(" | falls {}", Percent(*FallRate()));
  } else {
    s += " | no episode finished yet";
  }
  if (auto r = SuccessRate()) {
    s += fmt::format(" | success {} of last {}", Percent(*r), judged_.size());
    if (c_.target_success > 0) s += fmt::format(" (target {})", Percent(c_.target_success));
  }
  return s;
}

std::string RunProgress::Summary(uint64_t update, const std::string& why, const std::string& checkpoint,
                                 double train_seconds) const {
  std::string s = fmt::format("Run ended ({}) at update {} after {} samples", why, update,
                              HumanCount(static_cast<double>(samples_)));
  const double elapsed = now_s_ - start_s_;
  const double done = static_cast<double>(samples_) - static_cast<double>(samples_at_start_);
  if (elapsed > 0 && done > 0) {
    s += fmt::format(" ({} in this process at {:.0f} samples/s)", HumanDuration(elapsed), done / elapsed);
  }
  s += fmt::format("; {} of training in all.", HumanDuration(train_seconds));
  if (auto l = MeanLengthSteps()) {
    s += fmt::format(" Last {} episodes: mean length {}, falls {}.", lengths_.size(),
                     c_.control_dt > 0 ? fmt::format("{:.1f} s", *l * c_.control_dt)
                                       : fmt::format("{:.0f} steps", *l),
                     Percent(*FallRate()));
  }
  if (auto r = SuccessRate()) {
    s += fmt::format(" Training success {} over the last {} judged episodes (sampled actions; "
                     "perch eval measures the mean policy).", Percent(*r), judged_.size());
  }
  if (!checkpoint.empty()) {
    s += fmt::format(" Final checkpoint: {}. Next: perch eval --model {} --episodes 200 --json, "
                     "or continue with the same command and --resume.", checkpoint, checkpoint);
  }
  return s;
}

}  // namespace perch
