// A minimal Prometheus /metrics responder on a plain TCP socket (prometheus-cpp is not a Debian 12
// package). It answers every HTTP request on the port with the current text exposition (format
// 0.0.4) and closes the connection; one request at a time, on its own thread.
#pragma once

#include <atomic>
#include <map>
#include <mutex>
#include <string>
#include <thread>

namespace perch {

class MetricsServer {
 public:
  // Binds address:port (default loopback; "0.0.0.0" for a pod that Prometheus scrapes; port 0:
  // an ephemeral port, see port()). Throws std::runtime_error naming the port or address when it
  // cannot bind.
  explicit MetricsServer(int port, const std::string& address = "127.0.0.1");
  ~MetricsServer();
  MetricsServer(const MetricsServer&) = delete;
  MetricsServer& operator=(const MetricsServer&) = delete;

  int port() const { return port_; }
  // Sets gauge/counter `name` (a Prometheus metric name, e.g. perch_updates_total).
  void Set(const std::string& name, double value, const std::string& help,
           const char* type = "gauge");
  // The text served at /metrics.
  std::string Render() const;

 private:
  void Serve();
  struct Metric {
    double value = 0;
    std::string help;
    std::string type;
  };
  mutable std::mutex mu_;
  std::map<std::string, Metric> metrics_;
  int listen_fd_ = -1;
  int wake_pipe_[2] = {-1, -1};
  int port_ = 0;
  std::thread thread_;
};

// Fetches http://127.0.0.1:port/path with a plain socket (tests and `perch bench cluster`).
// Returns the body, or throws std::runtime_error.
std::string HttpGetLocal(int port, const std::string& path, int timeout_ms = 2000);

}  // namespace perch
