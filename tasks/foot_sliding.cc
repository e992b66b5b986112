#include "tasks/foot_sliding.h"

#include <algorithm>

namespace perch {

FootSlidingMeter::FootSlidingMeter(const HumanoidModel& model, const FootSlidingOptions& options)
    : options_(options) {
  for (int b : model.foot_bodies()) {
    Toe t{b, Eigen::Vector3d::Zero()};
    double best = -1e9;
    for (const Geom& g : model.body(b).geoms) {
      for (const Eigen::Vector3d& p : {g.from, g.to}) {
        if (p.x() > best) best = p.x(), t.local = p;
      }
    }
    toes_.push_back(t);
  }
}

void FootSlidingMeter::Start(const BodyPoseFn& body_pose) {
  prev_.clear();
  for (const Toe& t : toes_) prev_.push_back(body_pose(t.body) * t.local);
}

void FootSlidingMeter::Observe(const BodyPoseFn& body_pose, double dt) {
  for (size_t i = 0; i < toes_.size(); ++i) {
    const Eigen::Vector3d p = body_pose(toes_[i].body) * toes_[i].local;
    if (p.z() < options_.toe_height_m) {
      const double v = (p - prev_[i]).head<2>().norm() / dt;
      speed_sum_ += v;
      ++near_ground_;
      if (v > options_.slide_speed_mps) ++sliding_;
    }
    prev_[i] = p;
  }
}

Json FootSlidingMeter::ToJson(double seconds) const {
  return Json{{"toe_height_m", options_.toe_height_m},
              {"slide_speed_mps", options_.slide_speed_mps},
              {"mean_toe_speed_mps", mean_toe_speed_mps()},
              {"sliding_fraction", sliding_fraction()},
              {"sliding_count_per_s", seconds > 0 ? sliding_ / seconds : 0.0}};
}

FootSlidingMeter ReferenceFootSliding(const HumanoidModel& model, const ReferenceMotion& motion,
                                      double seconds, double dt,
                                      const FootSlidingOptions& options) {
  const int n = std::max(1, static_cast<int>(seconds / dt));
  std::vector<FkResult> frames;
  double lowest = 1e9;
  for (int i = 0; i <= n; ++i) {
    const MotionPose p = motion.At(i * dt);
    frames.push_back(ForwardKinematics(model, p.root_pos, p.root_rot, p.q.data()));
    lowest = std::min(lowest, LowestGeomZ(model, frames.back()));
  }
  FootSlidingMeter meter(model, options);
  for (int i = 0; i <= n; ++i) {
    auto pose = [&](int b) {
      Eigen::Isometry3d t = frames[i].body_world[b];
      t.translation().z() -= lowest;
      return t;
    };
    if (i == 0) {
      meter.Start(pose);
    } else {
      meter.Observe(pose, dt);
    }
  }
  return meter;
}

}  // namespace perch
