#include "learner/service/group.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <stdexcept>

#include "learner/service/learner.h"

namespace perch {

namespace {

constexpr size_t kHeaderBytes = 1 + sizeof(uint64_t);  // op, sequence number

std::string Header(char op, uint64_t seq) {
  std::string h(kHeaderBytes, '\0');
  h[0] = op;
  std::memcpy(h.data() + 1, &seq, sizeof(seq));
  return h;
}

bool ParseHeader(const zmq::message_t& m, char* op, uint64_t* seq) {
  if (m.size() != kHeaderBytes) return false;
  const char* p = static_cast<const char*>(m.data());
  *op = p[0];
  std::memcpy(seq, p + 1, sizeof(*seq));
  return true;
}

const char* OpName(char op) {
  switch (op) {
    case 'G':
      return "all-gather";
    case 'R':
      return "all-reduce";
    case 'H':
      return "hello";
    case 'B':
      return "bye";
    default:
      return "unknown";
  }
}

}  // namespace

ZmqGroup::ZmqGroup(zmq::context_t& ctx, const GroupOptions& options)
    : options_(options),
      sock_(ctx, options.rank == 0 ? zmq::socket_type::router : zmq::socket_type::dealer) {
  if (options_.size < 1) throw std::runtime_error("learner group: size must be >= 1");
  if (options_.rank < 0 || options_.rank >= options_.size) {
    throw std::runtime_error("learner group: rank " + std::to_string(options_.rank) +
                             " is not in 0.." + std::to_string(options_.size - 1));
  }
  // A bye must still leave when the process ends right after it.
  sock_.set(zmq::sockopt::linger, 1000);
  sock_.set(zmq::sockopt::sndtimeo, static_cast<int>(1e3 * std::min(options_.timeout_s, 3600.0)));
  if (options_.keys != nullptr) {
    if (options_.rank == 0) {
      MakeCurveServer(sock_, *options_.keys);
    } else {
      sock_.set(zmq::sockopt::curve_serverkey, options_.keys->learner_public);
      sock_.set(zmq::sockopt::curve_publickey, options_.keys->learner_public);
      sock_.set(zmq::sockopt::curve_secretkey, options_.keys->learner_secret);
    }
  }
  if (options_.rank == 0) {
    sock_.set(zmq::sockopt::router_mandatory, 1);
    sock_.bind(options_.address);
  } else {
    // Unique per process and socket: a restarted member is a new peer, not a handover of the old
    // one (a ROUTER ignores a second connection with a routing id it still holds).
    static std::atomic<uint64_t> sockets{0};
    sock_.set(zmq::sockopt::routing_id, "rank-" + std::to_string(options_.rank) + "-" +
                                            std::to_string(static_cast<long>(::getpid())) + "-" +
                                            std::to_string(++sockets));
    sock_.connect(options_.address);
  }
  try {
    Join();
  } catch (...) {
    Leave();
    throw;
  }
}

ZmqGroup::~ZmqGroup() {
  try {
    Leave();
  } catch (...) {
  }
}

bool ZmqGroup::Send(const std::string& routing_id, char op, uint64_t seq,
                    const std::string& payload, bool wait) {
  // A DEALER without a peer blocks on send: bounded by the socket's send timeout, or not at all.
  const zmq::send_flags more =
      wait ? zmq::send_flags::sndmore : zmq::send_flags::sndmore | zmq::send_flags::dontwait;
  const zmq::send_flags last = wait ? zmq::send_flags::none : zmq::send_flags::dontwait;
  if (options_.rank == 0 && !sock_.send(zmq::buffer(routing_id), more)) return false;
  // The first part is queued, so the rest of the message is too (ZeroMQ messages are atomic).
  if (!sock_.send(zmq::buffer(Header(op, seq)),
                  options_.rank == 0 ? zmq::send_flags::sndmore : more)) {
    return false;
  }
  sock_.send(zmq::buffer(payload), options_.rank == 0 ? zmq::send_flags::none : last);
  stats_.bytes_sent += kHeaderBytes + payload.size();
  return true;
}

bool ZmqGroup::Receive(std::vector<zmq::message_t>* parts, double deadline, bool part_sent) {
  const size_t want = options_.rank == 0 ? 3 : 2;  // [routing id,] header, payload
  for (;;) {
    if (options_.stop && options_.stop->load()) {
      if (!part_sent) {
        Leave();
        throw GroupStopped("learner group: this member is stopping");
      }
      // Rank 0 may already hold our part and finish this operation with it (the last one of an
      // update, say): say bye, then take its reply or its bye, so that both sides agree on
      // whether the operation happened. Bounded, in case rank 0 is gone.
      if (!left_) {
        Leave();
        deadline = std::min(deadline, MonotonicSeconds() + kStopGraceS);
      }
    }
    const double left = deadline - MonotonicSeconds();
    if (left <= 0) return false;
    zmq::pollitem_t item{sock_.handle(), 0, ZMQ_POLLIN, 0};
    try {
      zmq::poll(&item, 1,
                std::chrono::milliseconds(static_cast<int>(std::min(100.0, left * 1e3) + 1)));
    } catch (const zmq::error_t& e) {
      if (e.num() != EINTR) throw;
      continue;
    }
    if (!(item.revents & ZMQ_POLLIN)) continue;
    parts->clear();
    zmq::message_t m;
    bool more = true;
    while (more) {
      if (!sock_.recv(m, zmq::recv_flags::dontwait)) break;
      more = m.more();
      stats_.bytes_received += m.size();
      parts->push_back(std::move(m));
    }
    if (parts->size() == want) return true;
    spdlog::warn("learner group: dropped a message of {} parts (expected {})", parts->size(), want);
  }
}

void ZmqGroup::Join() {
  const double deadline = MonotonicSeconds() + options_.join_timeout_s;
  const std::string hello = std::to_string(options_.rank) + " " + std::to_string(options_.size) +
                            " " + options_.fingerprint;
  std::vector<zmq::message_t> parts;
  char op;
  uint64_t seq;
  if (options_.rank > 0) {
    if (!Send("", 'H', 0, hello)) {
      throw GroupError("learner group: could not send a hello to rank 0 at " + options_.address);
    }
    for (;;) {
      if (!Receive(&parts, deadline)) {
        throw GroupError("learner group: rank 0 at " + options_.address +
                         " did not answer within " + std::to_string(options_.join_timeout_s) +
                         " s");
      }
      if (!ParseHeader(parts[0], &op, &seq)) continue;
      if (op == 'A') return;
      if (op == 'X') {
        left_ = true;  // never joined: nobody to say bye to
        throw GroupError("learner group: rank 0 refused this member (rank " +
                         std::to_string(options_.rank) + "): " + parts[1].to_string());
      }
      if (op == 'B') {
        left_ = true;
        throw GroupStopped("learner group: rank 0 stopped during start-up");
      }
    }
  }
  id_of_.assign(options_.size, "");
  int joined = 1;
  while (joined < options_.size) {
    if (!Receive(&parts, deadline)) {
      std::string missing;
      for (int r = 1; r < options_.size; ++r) {
        if (id_of_[r].empty()) missing += (missing.empty() ? "" : ", ") + std::to_string(r);
      }
      throw GroupError("learner group: rank(s) " + missing + " did not join at " +
                       options_.address + " within " + std::to_string(options_.join_timeout_s) +
                       " s");
    }
    const std::string id = parts[0].to_string();
    if (!ParseHeader(parts[1], &op, &seq) || op != 'H') continue;
    const std::string text = parts[2].to_string();
    int r = -1, k = -1;
    char fp[4096] = {0};
    std::string why;
    if (std::sscanf(text.c_str(), "%d %d %4095[^\n]", &r, &k, fp) < 2) {
      why = "a malformed hello";
    } else if (k != options_.size) {
      why = "group size " + std::to_string(k) + " here, " + std::to_string(options_.size) +
            " at rank 0 (cluster.learners)";
    } else if (r < 1 || r >= options_.size) {
      why = "rank " + std::to_string(r) + " is not in 1.." + std::to_string(options_.size - 1);
    } else if (!id_of_[r].empty()) {
      why = "rank " + std::to_string(r) + " has already joined";
    } else if (std::string(fp) != options_.fingerprint) {
      why = "fingerprint differs: this member has '" + std::string(fp) + "', rank 0 has '" +
            options_.fingerprint + "' (the same config, update count and weights are needed)";
    }
    if (!why.empty()) {
      spdlog::warn("learner group: refused a member: {}", why);
      try {
        Send(id, 'X', 0, why);
      } catch (const zmq::error_t&) {
        // It left already.
      }
      continue;
    }
    id_of_[r] = id;
    rank_of_[id] = r;
    ++joined;
  }
  for (int r = 1; r < options_.size; ++r) Send(id_of_[r], 'A', 0, "");
}

std::vector<std::string> ZmqGroup::Collect(char op, const std::string& payload) {
  if (left_) throw GroupStopped("learner group: this member has left");
  if (options_.stop && options_.stop->load()) {
    Leave();
    throw GroupStopped("learner group: this member is stopping");
  }
  ++seq_;
  ++stats_.operations;
  const double t0 = MonotonicSeconds();
  const double deadline = t0 + options_.timeout_s;
  std::vector<zmq::message_t> parts;
  char got_op;
  uint64_t got_seq;
  auto fail = [&](const std::string& why) {
    Leave();
    throw GroupError("learner group (rank " + std::to_string(options_.rank) + ", " + OpName(op) +
                     " " + std::to_string(seq_) + "): " + why);
  };
  std::vector<std::string> out;
  if (options_.rank > 0) {
    if (!Send("", op, seq_, payload)) {
      fail("could not send to rank 0 within " + std::to_string(options_.timeout_s) + " s");
    }
    if (!Receive(&parts, deadline, /*part_sent=*/true)) {
      if (left_) throw GroupStopped("learner group: this member is stopping");
      fail("rank 0 did not answer within " + std::to_string(options_.timeout_s) + " s");
    }
    if (!ParseHeader(parts[0], &got_op, &got_seq)) fail("a malformed reply");
    if (got_op == 'B') {
      left_ = true;
      throw GroupStopped("learner group: rank 0 stopped");
    }
    if (got_op != op || got_seq != seq_) {
      fail(std::string("out of step: got ") + OpName(got_op) + " " + std::to_string(got_seq));
    }
    out.push_back(parts[1].to_string());
  } else {
    out.assign(options_.size, "");
    out[0] = payload;
    std::vector<bool> have(options_.size, false);
    int got = 1;
    while (got < options_.size) {
      if (!Receive(&parts, deadline)) {
        std::string missing;
        for (int r = 1; r < options_.size; ++r) {
          if (!have[r]) missing += (missing.empty() ? "" : ", ") + std::to_string(r);
        }
        fail("rank(s) " + missing + " did not answer within " + std::to_string(options_.timeout_s) +
             " s");
      }
      const auto it = rank_of_.find(parts[0].to_string());
      if (!ParseHeader(parts[1], &got_op, &got_seq)) continue;
      if (it == rank_of_.end()) {
        // A member that restarted, or a stranger: the running group has no place for it.
        if (got_op == 'H') {
          try {
            Send(parts[0].to_string(), 'X', 0, "the group is already running");
          } catch (const zmq::error_t&) {
          }
        }
        continue;
      }
      const int r = it->second;
      if (got_op == 'B') {
        Leave();
        throw GroupStopped("learner group: rank " + std::to_string(r) + " stopped");
      }
      if (got_op != op || got_seq != seq_ || have[r]) {
        fail("rank " + std::to_string(r) + " is out of step: sent " + OpName(got_op) + " " +
             std::to_string(got_seq));
      }
      out[r] = parts[2].to_string();
      have[r] = true;
      ++got;
    }
  }
  stats_.wait_s += MonotonicSeconds() - t0;
  return out;
}

void ZmqGroup::Reply(char op, const std::string& reply) {
  for (int r = 1; r < options_.size; ++r) {
    try {
      Send(id_of_[r], op, seq_, reply);
    } catch (const zmq::error_t& e) {
      // router_mandatory: the member's connection is gone (it died without a bye).
      Leave();
      throw GroupError("learner group: rank " + std::to_string(r) + " is gone (" + e.what() + ")");
    }
  }
}

std::vector<std::string> ZmqGroup::AllGather(const std::string& mine) {
  if (options_.size == 1) return {mine};
  std::vector<std::string> all = Collect('G', mine);
  if (options_.rank == 0) {
    Reply('G', PackStrings(all));
    return all;
  }
  std::vector<std::string> parts = UnpackStrings(all[0], "learner group: all-gather reply");
  if (static_cast<int>(parts.size()) != options_.size) {
    Leave();
    throw GroupError("learner group: all-gather reply has " + std::to_string(parts.size()) +
                     " parts for " + std::to_string(options_.size) + " members");
  }
  return parts;
}

void ZmqGroup::AllReduceSum(float* data, int n) {
  if (options_.size == 1) return;
  const size_t bytes = static_cast<size_t>(n) * sizeof(float);
  std::vector<std::string> all =
      Collect('R', std::string(reinterpret_cast<const char*>(data), bytes));
  if (options_.rank == 0) {
    for (int r = 1; r < options_.size; ++r) {
      if (all[r].size() != bytes) {
        Leave();
        throw GroupError("learner group: rank " + std::to_string(r) + " sent " +
                         std::to_string(all[r].size()) + " bytes to an all-reduce of " +
                         std::to_string(bytes));
      }
    }
    // Rank order, one member at a time: the same additions as everywhere else.
    for (int r = 1; r < options_.size; ++r) {
      const float* x = reinterpret_cast<const float*>(all[r].data());
      for (int i = 0; i < n; ++i) data[i] += x[i];
    }
    Reply('R', std::string(reinterpret_cast<const char*>(data), bytes));
    return;
  }
  if (all[0].size() != bytes) {
    Leave();
    throw GroupError("learner group: all-reduce reply of " + std::to_string(all[0].size()) +
                     " bytes, expected " + std::to_string(bytes));
  }
  std::memcpy(data, all[0].data(), bytes);
}

void ZmqGroup::Leave() {
  if (left_) return;
  left_ = true;
  try {
    if (options_.rank == 0) {
      for (int r = 1; r < static_cast<int>(id_of_.size()); ++r) {
        if (!id_of_[r].empty()) Send(id_of_[r], 'B', seq_, "", /*wait=*/false);
      }
    } else {
      Send("", 'B', seq_, "", /*wait=*/false);
    }
  } catch (const zmq::error_t&) {
    // A member already gone (router_mandatory): nothing to tell it.
  }
}

}  // namespace perch
