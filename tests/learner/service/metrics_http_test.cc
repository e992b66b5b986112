#include "learner/service/metrics_http.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <ifaddrs.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <string>
#include <vector>

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
  // Labelled series of one family.
  server.SetLabelled("perch_rejected_by_reason_total", "reason", "parse", 3, "rejected", "counter");
  server.SetLabelled("perch_rejected_by_reason_total", "reason", "out_of_range", 5, "rejected",
                     "counter");
  const std::string labelled = HttpGetLocal(server.port(), "/metrics");
  EXPECT_NE(labelled.find("perch_rejected_by_reason_total{reason=\"parse\"} 3\n"),
            std::string::npos)
      << labelled;
  EXPECT_NE(labelled.find("perch_rejected_by_reason_total{reason=\"out_of_range\"} 5\n"),
            std::string::npos);
}

// A non-loopback IPv4 address of this machine, or "" when it has none.
std::string NonLoopbackAddress() {
  ifaddrs* list = nullptr;
  if (::getifaddrs(&list) != 0) return "";
  std::string found;
  for (ifaddrs* a = list; a != nullptr && found.empty(); a = a->ifa_next) {
    if (a->ifa_addr == nullptr || a->ifa_addr->sa_family != AF_INET) continue;
    char buf[INET_ADDRSTRLEN] = {0};
    ::inet_ntop(AF_INET, &reinterpret_cast<sockaddr_in*>(a->ifa_addr)->sin_addr, buf, sizeof(buf));
    if (std::string(buf).rfind("127.", 0) != 0) found = buf;
  }
  ::freeifaddrs(list);
  return found;
}

bool Connects(const std::string& address, int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  ::inet_pton(AF_INET, address.c_str(), &addr.sin_addr);
  const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0;
  ::close(fd);
  return ok;
}

TEST(MetricsHttpTest, ListensOnLoopbackUnlessToldOtherwise) {
  MetricsServer local(0);
  EXPECT_TRUE(Connects("127.0.0.1", local.port()));
  EXPECT_THROW(MetricsServer bad(0, "not-an-address"), std::runtime_error);
  const std::string other = NonLoopbackAddress();
  if (other.empty()) GTEST_SKIP() << "no non-loopback interface to try from";
  EXPECT_FALSE(Connects(other, local.port())) << other;
  MetricsServer everywhere(0, "0.0.0.0");
  EXPECT_TRUE(Connects(other, everywhere.port())) << other;
}

// Slow or stuck clients (a byte every few seconds, or none) hold a worker each, not the endpoint:
// other scrapes are still answered at once (issue 17: one client blocked it for everyone).
TEST(MetricsHttpTest, SlowClientsDoNotBlockOtherScrapes) {
  MetricsServer server(0);
  server.Set("perch_updates_total", 7, "PPO updates", "counter");
  std::vector<int> slow;
  for (int i = 0; i < 2; ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(static_cast<uint16_t>(server.port()));
    ::inet_pton(AF_INET, "127.0.0.1", &addr.sin_addr);
    ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
    ASSERT_EQ(::send(fd, "GET /met", 8, MSG_NOSIGNAL), 8);  // and nothing more
    slow.push_back(fd);
  }
  for (int k = 0; k < 3; ++k) {
    EXPECT_NE(HttpGetLocal(server.port(), "/metrics", 1000).find("perch_updates_total 7"),
              std::string::npos);
  }
  for (int fd : slow) ::close(fd);
}

TEST(MetricsHttpTest, SecondServerOnSamePortFails) {
  MetricsServer a(0);
  EXPECT_THROW(MetricsServer b(a.port()), std::runtime_error);
}

}  // namespace
}  // namespace perch
