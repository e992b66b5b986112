// gtest's main for the test programs at or above the hierarchy's floor: the program's tasks are
// registered as perch's own main registers them (app/main.cc), so a config naming sit_chair reads
// in a test as it does in the program.
#include <gtest/gtest.h>

#include "hierarchy/hierarchy.h"

int main(int argc, char** argv) {
  perch::RegisterHierarchyTasks();
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
