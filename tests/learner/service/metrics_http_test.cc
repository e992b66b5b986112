#include "learner/service/metrics_http.h"

#include <gtest/gtest.h>

#include <string>

namespace perch {
namespace {

TEST(MetricsHttpTest, ServesTextExposition) {
  MetricsServer server(0);
  ASSERT_GT(server.port(), 0);
  server.Set("perch_updates_total", 12, "PPO updates", "counter");
  server.Set("perch_return_mean", -1.5, "mean return");
  const std::string body = HttpGetLocal(server.port(), "/metrics");
  EXPECT_NE(body.find("# TYPE perch_updates_total counter\nperch_updates_total 12\n"),
            std::string::npos)
      << body;
  EXPECT_NE(body.find("perch_return_mean -1.5\n"), std::string::npos) << body;
  // Values change between scrapes.
  server.Set("perch_updates_total", 13, "PPO updates", "counter");
  EXPECT_NE(HttpGetLocal(server.port(), "/metrics").find("perch_updates_total 13\n"),
            std::string::npos);
  EXPECT_THROW(HttpGetLocal(server.port(), "/other"), std::runtime_error);  // 404
}

TEST(MetricsHttpTest, SecondServerOnSamePortFails) {
  MetricsServer a(0);
  EXPECT_THROW(MetricsServer b(a.port()), std::runtime_error);
}

}  // namespace
}  // namespace perch
