// `perch bench retarget`: IK retargeting speed, as a ratio to one humanoid forward-kinematics
// call (its inner operation) timed in the same run.
#pragma once

#include <string>

#include "common/json_util.h"

namespace perch {

struct RetargetBenchOptions {
  std::string bvh = "../shared/mocap/08_01.bvh";  // the walk clip
  int last_frame = 30;                            // retarget source frames 1..N
};

// JSON: frames, retarget_s, frames_per_s, fk_call_us, frame_cost_in_fk_calls.
Json RunRetargetBench(const RetargetBenchOptions& o);

}  // namespace perch
