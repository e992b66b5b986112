#include "envs/pose_frame.h"

#include <utility>

namespace perch {

PoseFrame PoseFrameOf(const HumanoidState& s, double time_s, std::string label) {
  PoseFrame f;
  f.root_pos = s.root_pos;
  f.root_quat = s.root_quat;
  f.q.assign(s.q.begin(), s.q.end());
  f.time_s = time_s;
  f.label = std::move(label);
  return f;
}

}  // namespace perch
