// A group of learners over ZeroMQ (ours, issue 20; docs/scaling.md "Several learners"): rank 0
// binds a ROUTER at the group address, the others connect a DEALER to it. Every collective is a
// star: the members send their part to rank 0, which combines them in rank order and sends the
// same bytes back to all, so sums have the same bits everywhere. The group is for a handful of
// learners (each feeding tens of actor cores); a ring would halve rank 0's traffic at larger sizes.
//
// Start-up: every member says hello with the group size and a fingerprint (config, update count,
// weights); rank 0 refuses a member whose values differ from its own, naming the difference, and
// waits for the right one. A member that stops (Ctrl-C, a budget reached) says bye: the others'
// current and later operations throw GroupStopped, so the whole group stops at the same update.
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <string>
#include <vector>
#include <zmq.hpp>

#include "learner/collective.h"
#include "protocol/security.h"

namespace perch {

struct GroupOptions {
  int rank = 0;
  int size = 1;
  std::string address;          // rank 0 binds it, the others connect to it
  double timeout_s = 120.0;     // an operation whose members have not all answered by then fails
  double join_timeout_s = 600;  // start-up: everybody must have joined by then
  std::string fingerprint;      // must be the same on every member
  const std::atomic<bool>* stop = nullptr;  // set: the waiting operation leaves the group
  // CURVE (issue 17): rank 0 is the server with the learner's key pair, the others clients with
  // the same pair; the context's ZAP handler must authorize learner_public. Null: no security.
  const CurveKeys* keys = nullptr;
};

// What went over the group's socket, for metrics and `perch bench scale`.
struct GroupStats {
  uint64_t operations = 0;
  uint64_t bytes_sent = 0;
  uint64_t bytes_received = 0;
  double wait_s = 0.0;  // time inside operations (transfer + waiting for the slowest member)
};

class ZmqGroup : public Collective {
 public:
  // Binds or connects, then blocks until every member has joined (throws std::runtime_error on a
  // refused fingerprint, a timeout or the stop flag).
  ZmqGroup(zmq::context_t& ctx, const GroupOptions& options);
  ~ZmqGroup() override;

  int rank() const override { return options_.rank; }
  int size() const override { return options_.size; }
  std::vector<std::string> AllGather(const std::string& mine) override;
  void AllReduceSum(float* data, int n) override;

  // Tells the others this member stops (idempotent). Later operations throw GroupStopped.
  void Leave();
  bool left() const { return left_; }
  const GroupStats& stats() const { return stats_; }

 private:
  // One operation: send `payload` (members) or collect everybody's (rank 0); returns the reply
  // (members) or every member's payload in rank order (rank 0, its own first).
  std::vector<std::string> Collect(char op, const std::string& payload);
  void Reply(char op, const std::string& reply);
  void Join();
  // Receives one message within the deadline; false on timeout. On stop: throws GroupStopped,
  // or, once this member's part of the operation is sent (part_sent), says bye and still waits
  // (at most kStopGraceS) for rank 0's reply or bye.
  bool Receive(std::vector<zmq::message_t>* parts, double deadline, bool part_sent = false);
  static constexpr double kStopGraceS = 10.0;
  // False when the message could not be queued (wait: within the send timeout; else at once).
  bool Send(const std::string& routing_id, char op, uint64_t seq, const std::string& payload,
            bool wait = true);

  GroupOptions options_;
  zmq::socket_t sock_;
  std::map<std::string, int> rank_of_;  // rank 0: routing id -> rank
  std::vector<std::string> id_of_;      // rank 0: rank -> routing id
  uint64_t seq_ = 0;
  bool left_ = false;
  GroupStats stats_;
};

}  // namespace perch
