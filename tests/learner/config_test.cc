// Config structs: defaults are the paper's (Table 2) and the authors' (notes §2, §8.1); JSON
// round trips; strict parsing names the file and field.
#include <gtest/gtest.h>

#include <string>

#include "learner/ppo.h"
#include "policy/policy.h"

namespace perch {
namespace {

TEST(ConfigTest, DefaultsFollowTable2AndTheAuthors) {
  const PpoConfig s = PpoConfig::Subtask();
  EXPECT_EQ(s.steps_per_update, 8192);
  EXPECT_EQ(s.num_minibatches, 32);
  EXPECT_EQ(s.num_epochs, 4);
  EXPECT_FLOAT_EQ(s.learning_rate, 1e-4f);
  const PpoConfig m = PpoConfig::Meta();
  EXPECT_EQ(m.steps_per_update, 64);
  EXPECT_EQ(m.num_minibatches, 8);
  EXPECT_EQ(m.num_epochs, 2);
  EXPECT_FLOAT_EQ(m.learning_rate, 1e-4f);
  EXPECT_FLOAT_EQ(s.gamma, 0.99f);
  EXPECT_FLOAT_EQ(s.gae_lambda, 0.95f);
  EXPECT_FLOAT_EQ(s.clip_range, 0.2f);
  EXPECT_FLOAT_EQ(s.value_coef, 0.5f);
  EXPECT_FLOAT_EQ(s.max_grad_norm, 0.5f);
  EXPECT_FLOAT_EQ(s.entropy_coef, 0.0f);
  EXPECT_FLOAT_EQ(s.adam_eps, 1e-5f);
  EXPECT_FLOAT_EQ(s.obs_norm.obs_clip, 10.0f);
  EXPECT_FLOAT_EQ(s.obs_norm.obs_eps, 1e-8f);
  EXPECT_DOUBLE_EQ(s.obs_norm.initial_count, 1e-4);
  const PolicyConfig p = PolicyConfig::Subtask(52);
  EXPECT_EQ(p.policy_net.hidden, (std::vector<int>{64, 64}));
  EXPECT_EQ(p.act_dim, 21);
  const PolicyConfig mp = PolicyConfig::Meta();
  EXPECT_EQ(mp.num_choices, 4);
  EXPECT_EQ(mp.act_dim, 2);
  EXPECT_EQ(mp.target_choice, 3);
}

TEST(ConfigTest, JsonRoundTrips) {
  PpoConfig c = PpoConfig::Meta();
  c.clip_value = false;
  c.reward_scaling.enabled = false;
  c.obs_norm.obs_clip = 5.0f;
  const Json j = ToJson(c);
  EXPECT_EQ(ToJson(PpoConfigFromJson(j, "cfg")), j);
  PolicyConfig p = PolicyConfig::Meta(57);
  p.value_net.hidden = {32};
  p.policy_net.activation = Activation::kRelu;
  p.std_mode = StdMode::kFixed;
  const Json pj = ToJson(p);
  EXPECT_EQ(ToJson(PolicyConfigFromJson(pj, "cfg")), pj);
  // Partial JSON keeps the defaults.
  const PpoConfig partial = PpoConfigFromJson(Json{{"num_epochs", 7}}, "cfg");
  EXPECT_EQ(partial.num_epochs, 7);
  EXPECT_EQ(partial.steps_per_update, 8192);
}

std::string ErrorOf(const Json& j, bool policy) {
  try {
    if (policy) {
      PolicyConfigFromJson(j, "run.json.policy");
    } else {
      PpoConfigFromJson(j, "run.json.ppo");
    }
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(ConfigTest, StrictParsingNamesFileAndField) {
  EXPECT_NE(ErrorOf(Json{{"gama", 0.9}}, false).find("'gama'"), std::string::npos);
  EXPECT_NE(ErrorOf(Json{{"gamma", "high"}}, false).find("run.json.ppo.gamma"), std::string::npos);
  EXPECT_NE(ErrorOf(Json{{"num_minibatches", 0}}, false).find("num_minibatches"),
            std::string::npos);
  EXPECT_NE(
      ErrorOf(Json{{"reward_scaling", {{"clipp", 1}}}}, false).find("run.json.ppo.reward_scaling"),
      std::string::npos);
  EXPECT_NE(ErrorOf(Json{{"std_mode", "learned"}}, true).find("run.json.policy.std_mode"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Json{{"policy_net", {{"activation", "gelu"}}}}, true)
                .find("run.json.policy.policy_net.activation"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Json{{"kind", "meta"}, {"target_choice", 4}}, true).find("target_choice"),
            std::string::npos);
}

}  // namespace
}  // namespace perch
