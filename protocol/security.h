// Who may talk to the cluster (issue 17; docs/cluster.md "Keys"): ZeroMQ CURVE on the rollout and
// weights sockets. The learner is the CURVE server; actors are clients that must know the learner's
// public key and hold an actor key pair whose public half the learner authorizes. A ZAP handler
// in the learner's ZeroMQ context accepts only authorized client keys and counts the refusals.
//
// Key files (ZeroMQ's Z85 text, 40 characters), written by `perch keygen --out DIR`:
//   learner.pub, learner.key   the learner's pair (the .key only on the learner)
//   actor.pub, actor.key       the actors' pair (shared by all actors of a cluster)
//   authorized_keys            optional: more actor public keys, one per line (# comments)
// inproc:// endpoints (tests, one-process runs) carry no security mechanism.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>
#include <zmq.hpp>

#include "protocol/cluster_config.h"

namespace perch {

struct CurveKeys {
  std::string learner_public, learner_secret;  // Z85
  std::string actor_public, actor_secret;      // Z85
  std::vector<std::string> authorized;         // Z85 actor public keys the learner accepts
};

// cluster.keys_dir, else $PERCH_KEYS_DIR, else "".
std::string KeysDir(const ClusterConfig& c);
// True for endpoints that cross a process boundary (tcp://, ipc://): they need CURVE unless
// cluster.insecure.
bool NeedsCurve(const std::string& endpoint);
// Writes both key pairs into dir (created; secret files mode 0600). Refuses, naming the file, to
// overwrite an existing key. Throws ConfigError.
void WriteClusterKeys(const std::string& dir);

// A run on one machine (perch train, the recipe, the benches) without keys of its own gets a fresh
// pair in `dir`, shared with its children through PERCH_KEYS_DIR; returns the directory used (""
// when the config is insecure).
std::string EnsureLocalKeys(const ClusterConfig& c, const std::string& dir);
// The files a role needs; ConfigError naming the file (and cluster.keys_dir / PERCH_KEYS_DIR) when
// one is missing or not a Z85 key.
CurveKeys ReadLearnerKeys(const std::string& dir);
CurveKeys ReadActorKeys(const std::string& dir);

void MakeCurveServer(zmq::socket_t& sock, const CurveKeys& keys);
void MakeCurveClient(zmq::socket_t& sock, const CurveKeys& keys);

// The ZAP handler (RFC 27) of one ZeroMQ context: a thread answering the context's CURVE
// handshakes.
class ZapAuthenticator {
 public:
  // Throws std::runtime_error when the context already has a handler.
  ZapAuthenticator(zmq::context_t& ctx, const std::vector<std::string>& authorized_z85);
  ~ZapAuthenticator();
  uint64_t accepted() const { return accepted_.load(); }
  uint64_t refused() const { return refused_.load(); }

 private:
  void Loop();
  zmq::socket_t sock_;
  std::vector<std::string> authorized_;  // 32-byte binary keys
  std::atomic<bool> stop_{false};
  std::atomic<uint64_t> accepted_{0}, refused_{0};
  std::thread thread_;
};

}  // namespace perch
