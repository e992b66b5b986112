// The hierarchy's subtasks, in one table: each one's stable id (the meta policy's switch class,
// the order of MetaConfig::subtasks and of the transition matrices; saved meta policies depend on
// it, so ids never change), its name (env.task, the config section, the clip) and its wire task
// (protocol's Task enum, for frozen policies shipped with weights). A new subtask is one more row
// here (docs/architecture.md "A new subtask").
#pragma once

#include <string>
#include <vector>

#include "common/proto/wire.pb.h"

namespace perch {

// The authors' subtask indices of the meta switch (alphabetical keys, notes 4.7).
enum SubtaskId { kLeftTurn = 0, kRightTurn = 1, kSit = 2, kWalk = 3, kNumSubtasks = 4 };

struct SubtaskInfo {
  SubtaskId id;
  const char* name;  // "turn_left", "turn_right", "sit", "walk"
  proto::Task wire;
};

// kNumSubtasks rows, row i of id i.
const std::vector<SubtaskInfo>& Subtasks();
const char* SubtaskName(int id);                         // "?" when out of range
int SubtaskIdOf(const std::string& name);                // -1 when unknown
int SubtaskIdOfWire(proto::Task task);                   // -1 when not a subtask
std::vector<std::string> SubtaskNames();                 // in id order
std::string SubtaskNamesJoined(const char* sep = ", ");  // "turn_left, turn_right, sit, walk"

}  // namespace perch
