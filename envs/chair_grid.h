// A compact description of the chair's shape near the seat (issue 51), for a sit that must sit on
// chairs it has not seen: the height of the chair's top surface on a kChairGridSide^2 grid centred
// on the seat target, in the chair frame, relative to the seat target's height. It shows the
// seat's height and extent, a backrest behind, arms at the sides, and nothing (the floor) where
// the chair is not. A property of the immutable chair description, computed once per chair.
#pragma once

#include <array>

#include "envs/chair.h"
#include "envs/env_config.h"

namespace perch {

// Grid point (i, j): chair-frame x = seat_target.x + (i - 2) spacing (i along the facing),
// y = seat_target.y + (j - 2) spacing (j to the chair's left); element i * kChairGridSide + j.
// Value: the highest chair surface over that point minus seat_target.z [m]; the floor
// (-seat_target.z) where the chair has no surface there.
using ChairGrid = std::array<float, kChairGridDim>;
ChairGrid ChairHeightGrid(const Chair& chair, double spacing_m);

// The grid element of the left/right mirror image of element k (j -> side - 1 - j).
inline int MirroredGridIndex(int k) {
  const int i = k / kChairGridSide, j = k % kChairGridSide;
  return i * kChairGridSide + (kChairGridSide - 1 - j);
}

}  // namespace perch
