#include "common/subtasks.h"

#include <gtest/gtest.h>

#include <set>

namespace perch {
namespace {

// Saved meta policies' switch classes and the transition matrices are in id order: the ids are
// the authors' alphabetical keys (notes 4.7) and must never move.
TEST(Subtasks, StableIdsNamesAndWireTasksEachOnce) {
  ASSERT_EQ(Subtasks().size(), static_cast<size_t>(kNumSubtasks));
  EXPECT_STREQ(SubtaskName(kLeftTurn), "turn_left");
  EXPECT_STREQ(SubtaskName(kRightTurn), "turn_right");
  EXPECT_STREQ(SubtaskName(kSit), "sit");
  EXPECT_STREQ(SubtaskName(kWalk), "walk");
  std::set<std::string> names;
  std::set<int> wires;
  for (int id = 0; id < kNumSubtasks; ++id) {
    EXPECT_EQ(Subtasks()[id].id, id);
    EXPECT_EQ(SubtaskIdOf(SubtaskName(id)), id);
    EXPECT_EQ(SubtaskIdOfWire(Subtasks()[id].wire), id);
    names.insert(SubtaskName(id));
    wires.insert(Subtasks()[id].wire);
  }
  EXPECT_EQ(names.size(), Subtasks().size());
  EXPECT_EQ(wires.size(), Subtasks().size());
  EXPECT_EQ(SubtaskIdOf("left_turn"), -1);
  EXPECT_EQ(SubtaskIdOfWire(proto::TASK_META), -1);
  EXPECT_STREQ(SubtaskName(kNumSubtasks), "?");
  EXPECT_EQ(SubtaskNamesJoined(), "turn_left, turn_right, sit, walk");
}

}  // namespace
}  // namespace perch
