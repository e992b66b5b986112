#include "viz/transition_matrix.h"

#include <gtest/gtest.h>

#include <string>

#include "viz/canvas.h"

namespace perch {
namespace {

TEST(TransitionMatrix, DrawsOnePanelPerSideShadedByTheRowShare) {
  // One start side with every run from the start going to walk, and walk -> sit 3 of 4 times.
  const Json result = {{"transitions",
                        {{"left", {{"start", {{"walk", 6}}}, {"walk", {{"sit", 3}, {"end", 1}}}}},
                         {"right", Json::object()}}}};
  const std::string png = ::testing::TempDir() + "/perch_matrix.png";
  SaveTransitionMatrixPng(result, png);
  const Canvas c = Canvas::LoadPng(png);
  ASSERT_GT(c.width(), 500);
  // Layout of viz/transition_matrix.cc: cells of 90 px after a 110 px label column, rows below a
  // 60 px header, panels 30 px apart. start -> walk (all of its row) is the darkest shade; an empty
  // cell of the right panel is white.
  const int gap = 30, label_w = 110, head_h = 60, cell = 90;
  const Rgb full = c.at(gap + label_w + 3 * cell + 45, head_h + 0 * cell + 70);
  EXPECT_EQ(full.r, 55);
  EXPECT_EQ(full.b, 255);
  const int right_x0 = gap + (label_w + 5 * cell) + gap;
  const Rgb empty = c.at(right_x0 + label_w + 45, head_h + 70);
  EXPECT_EQ(empty.r, 255);
  // walk -> sit: 3 of 4, shade 255 - 200 * 0.75 = 105.
  const Rgb three_quarters = c.at(gap + label_w + 2 * cell + 45, head_h + 4 * cell + 70);
  EXPECT_EQ(three_quarters.r, 105);
}

}  // namespace
}  // namespace perch
