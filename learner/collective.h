// Collective operations among the learners of a group (ours, issue 20): DD-PPO-style data
// parallelism. Each learner owns its own actors and batch; PpoLearner sums every minibatch's
// gradient over the group, so all members take the same Adam steps and hold the same weights.
// The transport (ZeroMQ, learner/service/group.h) stays outside the learner library.
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

namespace perch {

// A member left (stopped or gave up): the operation did not complete on this member and its
// caller must undo whatever the operation was part of.
class GroupStopped : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The group failed: a member did not answer in time, was out of step, or refused at start-up.
class GroupError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Every member calls the same operations in the same order. Failures throw GroupError naming the
// member.
class Collective {
 public:
  virtual ~Collective() = default;
  virtual int rank() const = 0;
  virtual int size() const = 0;
  // Every member passes its bytes; every member gets all members' bytes, in rank order.
  virtual std::vector<std::string> AllGather(const std::string& mine) = 0;
  // data[n] := the sum over members, added in rank order: the same bits on every member.
  virtual void AllReduceSum(float* data, int n) = 0;
};

// [count][len][bytes]... (little-endian u32): several byte strings in one. Unpack throws
// std::runtime_error naming ctx on a truncated or malformed string.
std::string PackStrings(const std::vector<std::string>& parts);
std::vector<std::string> UnpackStrings(const std::string& packed, const std::string& ctx);

}  // namespace perch
