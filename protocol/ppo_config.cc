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

Json ToJson(const PpoConfig& c) {
  Json j{{"steps_per_update", c.steps_per_update},
         {"num_minibatches", c.num_minibatches},
         {"num_epochs", c.num_epochs},
         {"learning_rate", c.learning_rate},
         {"gamma", c.gamma},
         {"gae_lambda", c.gae_lambda},
         {"clip_range", c.clip_range},
         {"value_coef", c.value_coef},
         {"clip_value", c.clip_value},
         {"value_clip_range", c.value_clip_range},
         {"entropy_coef", c.entropy_coef},
         {"max_grad_norm", c.max_grad_norm},
         {"adam_beta1", c.adam_beta1},
         {"adam_beta2", c.adam_beta2},
         {"adam_eps", c.adam_eps},
         {"normalize_advantages", c.normalize_advantages},
         {"advantage_eps", c.advantage_eps},
         {"bootstrap_on_truncation", c.bootstrap_on_truncation},
         {"threads", c.threads},
         {"vtrace", c.vtrace},
         {"vtrace_rho_clip", c.vtrace_rho_clip},
         {"vtrace_c_clip", c.vtrace_c_clip},
         {"obs_norm", ToJson(c.obs_norm)},
         {"reward_scaling", ToJson(c.reward_scaling)}};
  // Written only when set, so that configs without one resolve as they always did.
  if (!c.lr_schedule.empty()) {
    Json sched = Json::array();
    for (const auto& [from, rate] : c.lr_schedule) sched.push_back(Json::array({from, rate}));
    j["lr_schedule"] = sched;
  }
  return j;
}

PpoConfig PpoConfigFromJson(const Json& j, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected an object, got " + j.dump());
  CheckKnownKeys(j,
                 {"steps_per_update",
                  "num_minibatches",
                  "num_epochs",
                  "learning_rate",
                  "gamma",
                  "gae_lambda",
                  "clip_range",
                  "value_coef",
                  "clip_value",
                  "value_clip_range",
                  "entropy_coef",
                  "max_grad_norm",
                  "adam_beta1",
                  "adam_beta2",
                  "adam_eps",
                  "normalize_advantages",
                  "advantage_eps",
                  "bootstrap_on_truncation",
                  "threads",
                  "vtrace",
                  "vtrace_rho_clip",
                  "vtrace_c_clip",
                  "obs_norm",
                  "reward_scaling",
                  "lr_schedule"},
                 ctx);
  PpoConfig c;
  GetOptional(j, "steps_per_update", c.steps_per_update, ctx);
  GetOptional(j, "num_minibatches", c.num_minibatches, ctx);
  GetOptional(j, "num_epochs", c.num_epochs, ctx);
  GetOptional(j, "learning_rate", c.learning_rate, ctx);
  GetOptional(j, "gamma", c.gamma, ctx);
  GetOptional(j, "gae_lambda", c.gae_lambda, ctx);
  GetOptional(j, "clip_range", c.clip_range, ctx);
  GetOptional(j, "value_coef", c.value_coef, ctx);
  GetOptional(j, "clip_value", c.clip_value, ctx);
  GetOptional(j, "value_clip_range", c.value_clip_range, ctx);
  GetOptional(j, "entropy_coef", c.entropy_coef, ctx);
  GetOptional(j, "max_grad_norm", c.max_grad_norm, ctx);
  GetOptional(j, "adam_beta1", c.adam_beta1, ctx);
  GetOptional(j, "adam_beta2", c.adam_beta2, ctx);
  GetOptional(j, "adam_eps", c.adam_eps, ctx);
  GetOptional(j, "normalize_advantages", c.normalize_advantages, ctx);
  GetOptional(j, "advantage_eps", c.advantage_eps, ctx);
  GetOptional(j, "bootstrap_on_truncation", c.bootstrap_on_truncation, ctx);
  GetOptional(j, "threads", c.threads, ctx);
  GetOptional(j, "vtrace", c.vtrace, ctx);
  GetOptional(j, "vtrace_rho_clip", c.vtrace_rho_clip, ctx);
  GetOptional(j, "vtrace_c_clip", c.vtrace_c_clip, ctx);
  if (j.contains("lr_schedule")) {
    const Json& s = j["lr_schedule"];
    const std::string sctx = ctx + ".lr_schedule";
    if (!s.is_array()) throw ConfigError(sctx + ": expected [[samples, rate], ...]");
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
  if (j.contains("obs_norm"))
    c.obs_norm = NormalizerConfigFromJson(j["obs_norm"], ctx + ".obs_norm");
  if (j.contains("reward_scaling")) {
    c.reward_scaling = RewardScalingConfigFromJson(j["reward_scaling"], ctx + ".reward_scaling");
  }
  auto require = [&](bool ok, const char* field, const char* what) {
    if (!ok) throw ConfigError(ctx + "." + field + ": " + what);
  };
  require(c.steps_per_update > 0, "steps_per_update", "must be > 0");
  require(c.num_minibatches > 0, "num_minibatches", "must be > 0");
  require(c.num_minibatches <= c.steps_per_update, "num_minibatches",
          "must be <= steps_per_update");
  require(c.num_epochs > 0, "num_epochs", "must be > 0");
  require(c.learning_rate > 0, "learning_rate", "must be > 0");
  require(c.gamma >= 0 && c.gamma <= 1, "gamma", "must be in [0, 1]");
  require(c.gae_lambda >= 0 && c.gae_lambda <= 1, "gae_lambda", "must be in [0, 1]");
  require(c.clip_range > 0, "clip_range", "must be > 0");
  require(c.value_coef >= 0, "value_coef", "must be >= 0");
  require(c.value_clip_range > 0, "value_clip_range", "must be > 0");
  require(c.entropy_coef >= 0, "entropy_coef", "must be >= 0");
  require(c.adam_beta1 >= 0 && c.adam_beta1 < 1, "adam_beta1", "must be in [0, 1)");
  require(c.adam_beta2 >= 0 && c.adam_beta2 < 1, "adam_beta2", "must be in [0, 1)");
  require(c.adam_eps > 0, "adam_eps", "must be > 0");
  require(c.advantage_eps >= 0, "advantage_eps", "must be >= 0");
  require(c.threads >= 1 && c.threads <= 256, "threads", "must be in [1, 256]");
  require(c.vtrace_rho_clip > 0 && std::isfinite(c.vtrace_rho_clip), "vtrace_rho_clip",
          "must be finite and > 0");
  require(c.vtrace_c_clip > 0 && std::isfinite(c.vtrace_c_clip), "vtrace_c_clip",
          "must be finite and > 0");
  return c;
}

}  // namespace perch
