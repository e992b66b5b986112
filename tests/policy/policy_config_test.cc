// policy/policy.h: the policy section, read and written from its field table.
#include <gtest/gtest.h>

#include <string>

#include "policy/policy.h"

namespace perch {
namespace {

TEST(PolicyConfig, TheTableReadsWritesAndDescribesTheSameFields) {
  const Json written = ToJson(PolicyConfig());
  const Json rows = PolicyConfigFields().Describe();
  ASSERT_EQ(rows.size(), written.size());
  for (const Json& r : rows) EXPECT_TRUE(written.contains(r["name"].get<std::string>())) << r;
  // Round trip, and a meta section starts from the meta's defaults (four classes, a 2-d target).
  const PolicyConfig m = PolicyConfigFromJson(Json{{"kind", "meta"}, {"obs_dim", 62}}, "policy");
  EXPECT_EQ(m.kind, PolicyKind::kMeta);
  EXPECT_EQ(m.act_dim, 2);
  EXPECT_EQ(m.num_choices, 4);
  EXPECT_EQ(ToJson(PolicyConfigFromJson(ToJson(m), "policy")), ToJson(m));
  const PolicyConfig g = PolicyConfigFromJson(
      Json{{"policy_net", {{"hidden", {128, 128}}}}, {"std_mode", "fixed"}}, "policy");
  EXPECT_EQ(g.policy_net.hidden, (std::vector<int>{128, 128}));
  EXPECT_EQ(g.value_net.hidden, (std::vector<int>{64, 64}));
  EXPECT_EQ(g.std_mode, StdMode::kFixed);
}

TEST(PolicyConfig, BadValuesAreRefusedNamingTheField) {
  auto error = [](const Json& j) {
    try {
      PolicyConfigFromJson(j, "p");
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(error({{"obs_dim", 0}}), "p.obs_dim: must be > 0");
  EXPECT_EQ(error({{"value_net", {{"hidden", {64, -1}}}}}),
            "p.value_net.hidden: widths must be positive, got -1");
  EXPECT_EQ(error({{"kind", "meta"}, {"target_choice", 4}}),
            "p.target_choice: must be in [0, num_choices)");
  EXPECT_NE(error({{"std_mode", "both"}}).find("p.std_mode"), std::string::npos);
  EXPECT_NE(error({{"width", 3}}).find("unknown field 'width'"), std::string::npos);
}

}  // namespace
}  // namespace perch
