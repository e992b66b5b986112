#include "protocol/security.h"

#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <zmq.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/file_util.h"
#include "common/json_util.h"

namespace perch {

namespace {

constexpr size_t kZ85KeyChars = 40;
constexpr const char* kWhere =
    "(cluster.keys_dir or PERCH_KEYS_DIR; `perch keygen --out DIR` writes them)";

bool IsZ85Key(const std::string& k) {
  if (k.size() != kZ85KeyChars) return false;
  uint8_t bin[32];
  return zmq_z85_decode(bin, k.c_str()) != nullptr;
}

std::string ReadKeyFile(const std::string& dir, const std::string& name) {
  if (dir.empty()) {
    throw ConfigError("cluster.insecure is false and no key directory is set " +
                      std::string(kWhere) +
                      "; set cluster.insecure: true only on a trusted network");
  }
  const std::string path = dir + "/" + name;
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot read the key file " + kWhere);
  std::string key;
  std::getline(in, key);
  while (!key.empty() && (key.back() == '\r' || key.back() == ' ')) key.pop_back();
  if (!IsZ85Key(key)) {
    throw ConfigError(path + ": not a CURVE key (expected 40 Z85 characters)");
  }
  return key;
}

void WriteKeyFile(const std::string& path, const std::string& key, bool secret) {
  if (std::filesystem::exists(path)) {
    throw ConfigError(path + ": exists; keys are never overwritten (remove it to replace it)");
  }
  // The secret key is never readable by others, not even between create and chmod.
  WriteFileAtomic(path, key + "\n", secret ? 0600 : 0644);
}

}  // namespace

std::string EnsureLocalKeys(const ClusterConfig& c, const std::string& dir) {
  if (c.insecure) return "";
  const std::string have = KeysDir(c);
  if (!have.empty()) return have;
  if (!std::filesystem::exists(dir + "/learner.key")) WriteClusterKeys(dir);
  const std::string abs = std::filesystem::absolute(dir).string();
  ::setenv("PERCH_KEYS_DIR", abs.c_str(), 1);
  return abs;
}

std::string KeysDir(const ClusterConfig& c) {
  if (!c.keys_dir.empty()) return c.keys_dir;
  const char* env = std::getenv("PERCH_KEYS_DIR");
  return env ? env : "";
}

bool NeedsCurve(const std::string& endpoint) {
  return endpoint.rfind("tcp://", 0) == 0 || endpoint.rfind("ipc://", 0) == 0;
}

void WriteClusterKeys(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw ConfigError(dir + ": cannot create it: " + ec.message());
  for (const char* name : {"learner.pub", "learner.key", "actor.pub", "actor.key"}) {
    if (std::filesystem::exists(dir + "/" + name)) {
      throw ConfigError(dir + "/" + name +
                        ": exists; keys are never overwritten (remove it to replace it)");
    }
  }
  for (const char* who : {"learner", "actor"}) {
    char pub[kZ85KeyChars + 1], sec[kZ85KeyChars + 1];
    if (zmq_curve_keypair(pub, sec) != 0) {
      throw ConfigError("perch keygen: this libzmq has no CURVE support (libsodium)");
    }
    WriteKeyFile(dir + "/" + who + ".key", sec, true);
    WriteKeyFile(dir + "/" + who + ".pub", pub, false);
  }
}

CurveKeys ReadLearnerKeys(const std::string& dir) {
  CurveKeys k;
  k.learner_public = ReadKeyFile(dir, "learner.pub");
  k.learner_secret = ReadKeyFile(dir, "learner.key");
  k.authorized.push_back(ReadKeyFile(dir, "actor.pub"));
  const std::string extra = dir + "/authorized_keys";
  std::ifstream in(extra);
  int line_no = 0;
  for (std::string line; std::getline(in, line);) {
    ++line_no;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    if (!IsZ85Key(line)) {
      throw ConfigError(extra + ":" + std::to_string(line_no) +
                        ": not a CURVE public key (expected 40 Z85 characters)");
    }
    k.authorized.push_back(line);
  }
  return k;
}

CurveKeys ReadActorKeys(const std::string& dir) {
  CurveKeys k;
  k.learner_public = ReadKeyFile(dir, "learner.pub");
  k.actor_public = ReadKeyFile(dir, "actor.pub");
  k.actor_secret = ReadKeyFile(dir, "actor.key");
  return k;
}

void MakeCurveServer(zmq::socket_t& sock, const CurveKeys& keys) {
  sock.set(zmq::sockopt::curve_server, 1);
  sock.set(zmq::sockopt::curve_secretkey, keys.learner_secret);
  // ZAP: every handshake is checked against the authorized actor keys.
  sock.set(zmq::sockopt::zap_domain, "perch");
}

void MakeCurveClient(zmq::socket_t& sock, const CurveKeys& keys) {
  sock.set(zmq::sockopt::curve_serverkey, keys.learner_public);
  sock.set(zmq::sockopt::curve_publickey, keys.actor_public);
  sock.set(zmq::sockopt::curve_secretkey, keys.actor_secret);
}

ZapAuthenticator::ZapAuthenticator(zmq::context_t& ctx,
                                   const std::vector<std::string>& authorized_z85)
    : sock_(ctx, zmq::socket_type::rep) {
  for (const std::string& z : authorized_z85) {
    std::string bin(32, '\0');
    if (z.size() != kZ85KeyChars ||
        zmq_z85_decode(reinterpret_cast<uint8_t*>(bin.data()), z.c_str()) == nullptr) {
      throw ConfigError("an authorized key is not a Z85 CURVE key");
    }
    authorized_.push_back(bin);
  }
  sock_.set(zmq::sockopt::linger, 0);
  try {
    sock_.bind("inproc://zeromq.zap.01");
  } catch (const zmq::error_t& e) {
    throw std::runtime_error(std::string("ZAP handler: cannot bind inproc://zeromq.zap.01 (") +
                             e.what() + "): one authenticator per ZeroMQ context");
  }
  thread_ = std::thread([this] { Loop(); });
}

ZapAuthenticator::~ZapAuthenticator() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

void ZapAuthenticator::Loop() {
  double last_log = -1e9;
  while (!stop_.load()) {
    zmq::pollitem_t item{sock_.handle(), 0, ZMQ_POLLIN, 0};
    try {
      zmq::poll(&item, 1, std::chrono::milliseconds(100));
    } catch (const zmq::error_t& e) {
      if (e.num() == EINTR) continue;
      if (e.num() == ETERM) return;
      throw;
    }
    if (!(item.revents & ZMQ_POLLIN)) continue;
    std::vector<zmq::message_t> frames;
    try {
      zmq::message_t m;
      bool more = true;
      while (more && sock_.recv(m, zmq::recv_flags::dontwait)) {
        more = m.more();
        frames.push_back(std::move(m));
      }
    } catch (const zmq::error_t& e) {
      if (e.num() == ETERM) return;
      continue;
    }
    // version, request id, domain, address, identity, mechanism, credentials... A REP socket
    // must answer every request, a malformed one too (refused).
    auto frame = [&](size_t i) {
      return i < frames.size() ? frames[i].to_string() : std::string();
    };
    const std::string version = frames.empty() ? "1.0" : frame(0);
    const std::string request_id = frame(1);
    const std::string address = frame(3);
    const std::string mechanism = frame(5);
    bool ok = false;
    if (mechanism == "CURVE" && frames.size() >= 7 && frames[6].size() == 32) {
      const std::string key = frames[6].to_string();
      for (const std::string& a : authorized_) ok |= a == key;
    }
    (ok ? accepted_ : refused_)++;
    if (!ok) {
      const double now =
          std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
              .count();
      if (now - last_log > 5.0) {  // a flood of strangers costs one line per 5 s
        spdlog::warn("learner: refused a {} client from {} (not an authorized key); {} so far",
                     mechanism, address, refused_.load());
        last_log = now;
      }
    }
    const std::string code = ok ? "200" : "400";
    const std::string text = ok ? "OK" : "unauthorized key";
    try {
      sock_.send(zmq::buffer(version), zmq::send_flags::sndmore);
      sock_.send(zmq::buffer(request_id), zmq::send_flags::sndmore);
      sock_.send(zmq::buffer(code), zmq::send_flags::sndmore);
      sock_.send(zmq::buffer(text), zmq::send_flags::sndmore);
      sock_.send(zmq::buffer(std::string(ok ? "actor" : "")), zmq::send_flags::sndmore);
      sock_.send(zmq::buffer(std::string()), zmq::send_flags::none);
    } catch (const zmq::error_t& e) {
      if (e.num() == ETERM) return;
    }
  }
}

}  // namespace perch
