#include "learner/service/metrics_http.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <prometheus/collectable.h>
#include <prometheus/exposer.h>
#include <prometheus/metric_family.h>
#include <prometheus/text_serializer.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace perch {

// What the exposer collects at each scrape: a snapshot of the values Set() last gave.
class MetricsServer::Collector : public prometheus::Collectable {
 public:
  explicit Collector(const MetricsServer* owner) : owner_(owner) {}
  std::vector<prometheus::MetricFamily> Collect() const override { return owner_->Families(); }

 private:
  const MetricsServer* owner_;
};

MetricsServer::MetricsServer(int port, const std::string& address) {
  in_addr parsed{};
  if (::inet_pton(AF_INET, address.c_str(), &parsed) != 1) {
    throw std::runtime_error("--metrics-bind " + address + ": not an IPv4 address");
  }
  if (port < 0 || port > 65535) {
    throw std::runtime_error("--metrics-port " + std::to_string(port) + ": not a port");
  }
  try {
    // civetweb worker threads: one slow or stuck client holds one of them, not the endpoint.
    exposer_ =
        std::make_unique<prometheus::Exposer>(address + ":" + std::to_string(port), kHttpThreads);
  } catch (const std::exception& e) {
    throw std::runtime_error("--metrics-port " + std::to_string(port) + ": cannot listen on " +
                             address + " (" + e.what() + ")");
  }
  const std::vector<int> ports = exposer_->GetListeningPorts();
  if (ports.empty()) {
    throw std::runtime_error("--metrics-port " + std::to_string(port) + ": cannot listen on " +
                             address);
  }
  port_ = ports.front();
  address_ = address;
  collector_ = std::make_shared<Collector>(this);
  exposer_->RegisterCollectable(collector_, "/metrics");
}

MetricsServer::~MetricsServer() {
  // Stop serving before the values go away.
  if (!exposer_) return;
  exposer_->RemoveCollectable(collector_, "/metrics");
  // civetweb's listener looks at its stop flag only between 2-second polls; a connection made
  // while it stops wakes it, so that a learner exits at once rather than up to 2 s later.
  std::atomic<bool> done{false};
  std::thread waker([this, &done] {
    for (int i = 0; i < 40 && !done.load(); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
      if (fd < 0) return;
      sockaddr_in addr{};
      addr.sin_family = AF_INET;
      addr.sin_port = htons(static_cast<uint16_t>(port_));
      ::inet_pton(AF_INET, address_ == "0.0.0.0" ? "127.0.0.1" : address_.c_str(), &addr.sin_addr);
      ::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr));
      ::close(fd);
    }
  });
  exposer_.reset();
  done = true;
  waker.join();
}

void MetricsServer::Set(const std::string& name, double value, const std::string& help,
                        const char* type) {
  SetLabelled(name, "", "", value, help, type);
}

void MetricsServer::SetLabelled(const std::string& name, const std::string& label,
                                const std::string& label_value, double value,
                                const std::string& help, const char* type) {
  std::lock_guard<std::mutex> lock(mu_);
  Family& f = metrics_[name];
  f.help = help;
  f.type = type;
  f.label = label;
  f.values[label_value] = value;
}

std::vector<prometheus::MetricFamily> MetricsServer::Families() const {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<prometheus::MetricFamily> out;
  out.reserve(metrics_.size());
  for (const auto& [name, m] : metrics_) {
    prometheus::MetricFamily f;
    f.name = name;
    f.help = m.help;
    f.type = m.type == "counter" ? prometheus::MetricType::Counter : prometheus::MetricType::Gauge;
    for (const auto& [label_value, value] : m.values) {
      prometheus::ClientMetric c;
      if (!m.label.empty()) c.label.push_back({m.label, label_value});
      if (f.type == prometheus::MetricType::Counter) {
        c.counter.value = value;
      } else {
        c.gauge.value = value;
      }
      f.metric.push_back(c);
    }
    out.push_back(std::move(f));
  }
  return out;
}

std::string MetricsServer::Render() const {
  return prometheus::TextSerializer().Serialize(Families());
}

std::string HttpGetLocal(int port, const std::string& path, int timeout_ms) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) throw std::runtime_error("http: socket() failed");
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(static_cast<uint16_t>(port));
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    ::close(fd);
    throw std::runtime_error("http: cannot connect to 127.0.0.1:" + std::to_string(port));
  }
  const std::string req =
      "GET " + path + " HTTP/1.0\r\nHost: localhost\r\nConnection: close\r\n\r\n";
  if (::send(fd, req.data(), req.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(req.size())) {
    ::close(fd);
    throw std::runtime_error("http: send failed");
  }
  std::string resp;
  char buf[4096];
  pollfd pfd{fd, POLLIN, 0};
  // Until the server closes, or the Content-Length it announced has arrived.
  size_t want = std::string::npos;
  while (::poll(&pfd, 1, timeout_ms) > 0) {
    const ssize_t n = ::read(fd, buf, sizeof(buf));
    if (n <= 0) break;
    resp.append(buf, static_cast<size_t>(n));
    const size_t head = resp.find("\r\n\r\n");
    if (want == std::string::npos && head != std::string::npos) {
      std::string lower = resp.substr(0, head);
      for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      const size_t cl = lower.find("content-length:");
      if (cl != std::string::npos) want = head + 4 + std::stoul(lower.substr(cl + 15));
    }
    if (want != std::string::npos && resp.size() >= want) break;
  }
  ::close(fd);
  const size_t head = resp.find("\r\n\r\n");
  const bool ok = resp.rfind("HTTP/1.0 200", 0) == 0 || resp.rfind("HTTP/1.1 200", 0) == 0;
  if (!ok || head == std::string::npos) {
    throw std::runtime_error("http: bad response from port " + std::to_string(port));
  }
  return resp.substr(head + 4);
}

}  // namespace perch
