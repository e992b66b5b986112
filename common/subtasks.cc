#include "common/subtasks.h"

namespace perch {

const std::vector<SubtaskInfo>& Subtasks() {
  static const std::vector<SubtaskInfo> rows = {
      {kLeftTurn, "turn_left", proto::TASK_LEFT_TURN},
      {kRightTurn, "turn_right", proto::TASK_RIGHT_TURN},
      {kSit, "sit", proto::TASK_SIT},
      {kWalk, "walk", proto::TASK_WALK},
  };
  return rows;
}

const char* SubtaskName(int id) { return id >= 0 && id < kNumSubtasks ? Subtasks()[id].name : "?"; }

int SubtaskIdOf(const std::string& name) {
  for (const SubtaskInfo& s : Subtasks()) {
    if (name == s.name) return s.id;
  }
  return -1;
}

int SubtaskIdOfWire(proto::Task task) {
  for (const SubtaskInfo& s : Subtasks()) {
    if (task == s.wire) return s.id;
  }
  return -1;
}

std::vector<std::string> SubtaskNames() {
  std::vector<std::string> names;
  for (const SubtaskInfo& s : Subtasks()) names.push_back(s.name);
  return names;
}

std::string SubtaskNamesJoined(const char* sep) {
  std::string out;
  for (const SubtaskInfo& s : Subtasks()) out += (out.empty() ? "" : sep) + std::string(s.name);
  return out;
}

}  // namespace perch
