#include "protocol/cluster_config.h"

#include <gtest/gtest.h>

#include <string>

namespace perch {
namespace {

std::string ErrorOf(const Json& j) {
  try {
    ClusterConfigFromJson(j, "f.json:cluster");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(ClusterConfigTest, DefaultsRoundTrip) {
  const ClusterConfig d;
  const ClusterConfig back = ClusterConfigFromJson(ToJson(d), "x");
  EXPECT_EQ(ToJson(back), ToJson(d));
  EXPECT_EQ(d.checkpoint_every, 100);      // the authors' checkpoint period (notes §8.1)
  EXPECT_EQ(d.hierarchy_meta_period, 30);  // notes §4.7
}

TEST(ClusterConfigTest, ErrorsNameFileAndField) {
  EXPECT_NE(ErrorOf({{"segmant_steps", 3}}).find("f.json:cluster: unknown field 'segmant_steps'"),
            std::string::npos);
  EXPECT_NE(ErrorOf({{"segment_steps", "many"}}).find("f.json:cluster.segment_steps"),
            std::string::npos);
  EXPECT_NE(ErrorOf({{"segment_steps", 0}}).find("segment_steps"), std::string::npos);
  EXPECT_NE(ErrorOf({{"task", "dance"}}).find("unknown task 'dance'"), std::string::npos);
  EXPECT_NE(ErrorOf({{"segment_steps", 100}, {"max_segment_steps", 50}}).find("exceeds"),
            std::string::npos);
  EXPECT_EQ(ErrorOf({{"segment_steps", 64}, {"task", "sit"}}), "");
}

TEST(ClusterConfigTest, CreditFieldsAreCheckedByName) {
  const ClusterConfig d = ClusterConfigFromJson(Json::object(), "cluster");
  EXPECT_EQ(d.credit_slack, 1.0);  // flow control on by default
  EXPECT_EQ(ClusterConfigFromJson(Json{{"credit_slack", 0}}, "cluster").credit_slack, 0.0);
  for (const Json& bad : {Json{{"credit_slack", -0.5}}, Json{{"credit_slack", 1e9}},
                          Json{{"credit_regrant_s", 0}}, Json{{"credit_slack", "lots"}}}) {
    try {
      ClusterConfigFromJson(bad, "cluster");
      FAIL() << bad.dump();
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("cluster.credit_"), std::string::npos) << e.what();
    }
  }
}

TEST(ClusterConfigTest, SimulatedLagMustFitTheLearnersWindow) {
  EXPECT_EQ(ClusterConfigFromJson(Json::object(), "cluster").simulated_lag, 0);
  EXPECT_EQ(ClusterConfigFromJson(Json{{"simulated_lag", 2}}, "cluster").simulated_lag, 2);
  for (const Json& bad : {Json{{"simulated_lag", -1}}, Json{{"simulated_lag", 3}},
                          Json{{"simulated_lag", 5}, {"max_policy_lag", 4}}}) {
    try {
      ClusterConfigFromJson(bad, "cluster");
      FAIL() << bad.dump();
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("cluster.simulated_lag"), std::string::npos) << e.what();
    }
  }
}

TEST(ClusterConfigTest, TaskNamesRoundTrip) {
  for (const char* n : {"walk", "turn_left", "turn_right", "sit", "meta", "stand"}) {
    EXPECT_EQ(TaskName(TaskFromName(n, "t")), n);
  }
  // The older spellings still read, and become the env's task names.
  EXPECT_EQ(TaskName(TaskFromName("left_turn", "t")), "turn_left");
  EXPECT_EQ(TaskName(TaskFromName("right_turn", "t")), "turn_right");
}

TEST(ClusterConfigTest, Endpoints) {
  for (const char* ok : {"tcp://*:5555", "tcp://127.0.0.1:1", "tcp://perch-learner:5556",
                         "inproc://weights", "ipc:///tmp/x"}) {
    EXPECT_NO_THROW(CheckEndpoint(ok, "--x")) << ok;
  }
  for (const char* bad : {"", "tcp://", "tcp://host", "tcp://:5555", "tcp://h:0", "tcp://h:70000",
                          "tcp://h:55x", "udp://h:1", "inproc://"}) {
    EXPECT_THROW(CheckEndpoint(bad, "--x"), ConfigError) << bad;
  }
  EXPECT_THROW(CheckPort(0, "--p"), ConfigError);
  EXPECT_NO_THROW(CheckPort(65535, "--p"));
}

}  // namespace
}  // namespace perch
