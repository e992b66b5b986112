// The learner's Prometheus /metrics endpoint, served by prometheus-cpp's pull exposer (civetweb):
// concurrent scrapes on several threads, so a slow client cannot block the others (issue 17).
// Values are set by name; each scrape reads a snapshot (text exposition format 0.0.4).
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace prometheus {
class Exposer;
struct MetricFamily;
}  // namespace prometheus

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
  // One series of a labelled family, e.g. perch_rejected_by_reason_total{reason="parse"}.
  void SetLabelled(const std::string& name, const std::string& label,
                   const std::string& label_value, double value, const std::string& help,
                   const char* type = "gauge");
  // The text served at /metrics.
  std::string Render() const;

 private:
  class Collector;
  static constexpr int kHttpThreads = 4;
  std::vector<prometheus::MetricFamily> Families() const;
  struct Family {
    std::string help;
    std::string type;
    std::string label;                     // "" for an unlabelled metric
    std::map<std::string, double> values;  // label value ("" unlabelled) -> value
  };
  mutable std::mutex mu_;
  std::map<std::string, Family> metrics_;
  int port_ = 0;
  std::string address_;
  std::unique_ptr<prometheus::Exposer> exposer_;
  std::shared_ptr<Collector> collector_;
};

// Fetches http://127.0.0.1:port/path with a plain socket (tests and `perch bench cluster`).
// Returns the body, or throws std::runtime_error.
std::string HttpGetLocal(int port, const std::string& path, int timeout_ms = 2000);

}  // namespace perch
