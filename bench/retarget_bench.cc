#include "bench/retarget_bench.h"

#include <Eigen/Geometry>
#include <chrono>
#include <vector>

#include "common/paths.h"
#include "envs/humanoid_model.h"
#include "motion/bvh.h"
#include "motion/retarget.h"

namespace perch {

Json RunRetargetBench(const RetargetBenchOptions& o) {
  using Clock = std::chrono::steady_clock;
  const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
  const BvhClip bvh = ReadBvhFile(ResolveProjectPath(o.bvh));
  RetargetConfig cfg;
  ClipSpec spec = cfg.clips[0];
  spec.loop = false;
  spec.last_frame = o.last_frame;
  // Baseline: forward kinematics of the humanoid, the IK's inner operation.
  const int fk_calls = 20000;
  std::vector<double> q(model.num_joints(), 0.1);
  double sink = 0;
  const auto f0 = Clock::now();
  for (int i = 0; i < fk_calls; ++i) {
    q[i % q.size()] += 1e-9;
    sink +=
        ForwardKinematics(model, Eigen::Vector3d(0, 0, 1), Eigen::Quaterniond::Identity(), q.data())
            .body_world[5]
            .translation()
            .z();
  }
  const double fk_s = std::chrono::duration<double>(Clock::now() - f0).count() / fk_calls;
  const auto r0 = Clock::now();
  const RetargetOutput out = RetargetClip(bvh, o.bvh, spec, model, cfg);
  const double rt_s = std::chrono::duration<double>(Clock::now() - r0).count();
  const int frames = out.motion.num_frames();
  Json j{{"frames", frames},
         {"retarget_s", rt_s},
         {"frames_per_s", frames / rt_s},
         {"fk_call_us", fk_s * 1e6},
         {"frame_cost_in_fk_calls", rt_s / frames / fk_s},
         {"checksum", sink}};
  return j;
}

}  // namespace perch
