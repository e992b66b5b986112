#include "protocol/ppo_config.h"

#include <algorithm>
#include <cmath>

namespace perch {

PpoConfig PpoConfig::Subtask() { return PpoConfig(); }

PpoConfig PpoConfig::Meta() {
  PpoConfig c;
  c.steps_per_update = 64;
  c.num_minibatches = 8;
  c.num_epochs = 2;
  c.learning_rate = 1e-4f;
  return c;
}

float LearningRateAt(const PpoConfig& c, int64_t samples) {
  float lr = c.learning_rate;
  for (const auto& [from, rate] : c.lr_schedule) {
    if (samples >= from) lr = rate;
  }
  return lr;
}

namespace {

FieldRule<float> InUnit(const char* rule, bool closed_top) {
  return Satisfies<float>(
      [closed_top](const float& v) { return v >= 0 && (closed_top ? v <= 1 : v < 1); }, rule);
}
FieldRule<float> FinitePositive() {
  return Satisfies<float>([](const float& v) { return v > 0 && std::isfinite(v); },
                          "must be finite and > 0");
}

// [[samples, rate], ...]: samples increasing from >= 0, rates in (0, 1).
void ReadSchedule(const Json& j, PpoConfig& c, const std::string& ctx) {
  const Json& s = j["lr_schedule"];
  const std::string sctx = ctx + ".lr_schedule";
  if (!s.is_array()) throw ConfigError(sctx + ": expected [[samples, rate], ...]");
  c.lr_schedule.clear();
  int64_t prev = -1;
  for (size_t i = 0; i < s.size(); ++i) {
    const std::string ictx = sctx + "[" + std::to_string(i) + "]";
    if (!s[i].is_array() || s[i].size() != 2 || !s[i][0].is_number_integer() ||
        !s[i][1].is_number()) {
      throw ConfigError(ictx + ": expected [samples (integer), rate], got " + s[i].dump());
    }
    const int64_t from = s[i][0].get<int64_t>();
    const double rate = s[i][1].get<double>();
    if (from <= prev) throw ConfigError(ictx + ": samples must increase, from >= 0");
    if (!(rate > 0 && rate < 1)) throw ConfigError(ictx + ": rate must be in (0, 1)");
    prev = from;
    c.lr_schedule.emplace_back(from, static_cast<float>(rate));
  }
}

// Written only when set, so that configs without one resolve as they always did.
void WriteSchedule(const PpoConfig& c, Json& j) {
  if (c.lr_schedule.empty()) return;
  Json sched = Json::array();
  for (const auto& [from, rate] : c.lr_schedule) sched.push_back(Json::array({from, rate}));
  j["lr_schedule"] = sched;
}

}  // namespace

const FieldTable<PpoConfig>& PpoConfigFields() {
  using C = PpoConfig;
  static const FieldTable<PpoConfig> t =
      FieldTable<C>()
          .Add("steps_per_update", &C::steps_per_update,
               "samples per update (the learner waits for this many)", Positive<int>())
          .Add("num_minibatches", &C::num_minibatches, "minibatches per epoch", Positive<int>())
          .Add("num_epochs", &C::num_epochs, "passes over each batch", Positive<int>())
          .Add("learning_rate", &C::learning_rate, "Adam's rate (before any lr_schedule entry)",
               Positive<float>())
          .Custom("lr_schedule",
                  "[[samples, rate], ...]: piecewise constant by the run's samples (empty: "
                  "constant)",
                  ReadSchedule, WriteSchedule)
          .Add("gamma", &C::gamma, "discount", InUnit("must be in [0, 1]", true))
          .Add("gae_lambda", &C::gae_lambda, "GAE's lambda", InUnit("must be in [0, 1]", true))
          .Add("clip_range", &C::clip_range, "PPO's ratio clip", Positive<float>())
          .Add("value_coef", &C::value_coef, "value loss weight", NonNegative<float>())
          .Add("clip_value", &C::clip_value, "clip the value update as the policy's")
          .Add("value_clip_range", &C::value_clip_range, "value clip", Positive<float>())
          .Add("entropy_coef", &C::entropy_coef, "entropy bonus", NonNegative<float>())
          .Add("max_grad_norm", &C::max_grad_norm, "global L2 gradient norm; <= 0 disables")
          .Add("adam_beta1", &C::adam_beta1, "Adam", InUnit("must be in [0, 1)", false))
          .Add("adam_beta2", &C::adam_beta2, "Adam", InUnit("must be in [0, 1)", false))
          .Add("adam_eps", &C::adam_eps, "Adam", Positive<float>())
          .Add("normalize_advantages", &C::normalize_advantages, "per minibatch")
          .Add("advantage_eps", &C::advantage_eps, "added to the advantages' std",
               NonNegative<float>())
          .Add("bootstrap_on_truncation", &C::bootstrap_on_truncation,
               "bootstrap the value at a time limit (the authors: terminal)")
          .Add("threads", &C::threads, "threads of the update",
               Satisfies<int>([](const int& v) { return v >= 1 && v <= 256; },
                              "must be in [1, 256]"))
          .Add("vtrace", &C::vtrace, "V-trace correction of lagged segments")
          .Add("vtrace_rho_clip", &C::vtrace_rho_clip, "V-trace rho clip", FinitePositive())
          .Add("vtrace_c_clip", &C::vtrace_c_clip, "V-trace c clip", FinitePositive())
          .Nested("obs_norm", &C::obs_norm, NormalizerConfigFields(), "observation normalizer")
          .Nested("reward_scaling", &C::reward_scaling, RewardScalingConfigFields(),
                  "reward scaling")
          .Rule([](const C& c, const std::string& ctx) {
            return c.num_minibatches <= c.steps_per_update
                       ? std::string()
                       : ctx + ".num_minibatches: must be <= steps_per_update";
          });
  return t;
}

Json ToJson(const PpoConfig& c) { return PpoConfigFields().Write(c); }

PpoConfig PpoConfigFromJson(const Json& j, const std::string& ctx) {
  return PpoConfigFields().Read(j, ctx);
}

}  // namespace perch
