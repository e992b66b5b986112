#include "tasks/track_clip.h"

#include <cmath>
#include <iostream>
#include <vector>

#include "common/paths.h"
#include "envs/humanoid_env.h"
#include "envs/humanoid_model.h"
#include "motion/reference_motion.h"
#include "tasks/walk.h"

namespace perch {

Json TrackClip(const TrackClipOptions& a) {
  const std::string path = ResolveProjectPath(a.motions) + "/" + a.name + ".json";
  ReferenceMotion ref = ReferenceMotion::Load(path);
  EnvConfig cfg = a.env_config.empty() ? EnvConfig() : EnvConfig::Load(a.env_config);
  cfg.action_mode = ActionMode::kPd;
  const bool sit = a.name == "sit";
  if (!sit && a.env_config.empty()) cfg.chair = "none";
  HumanoidChairEnv env(cfg);
  env.Seed(0);
  std::vector<float> obs(env.spec().obs_dim), act(env.spec().act_dim);
  env.Reset(obs.data());
  // Place the clip: the sit clip so that its final pelvis is over the seat centre.
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();
  if (sit && cfg.chair != "none") {
    const auto& pe = ref.meta().at("pelvis_end_m");
    const Eigen::Vector3d seat = env.SeatTargetWorld();
    shift = Eigen::Vector3d(seat.x() - pe[0].get<double>(), seat.y() - pe[1].get<double>(), 0);
  }
  auto pose_at = [&](double t) {
    MotionPose p = ref.At(t);
    p.root_pos += shift;
    return p;
  };
  env.ResetToState(HumanoidStateFromPose(pose_at(0.0)), obs.data());
  const double dt = env.spec().control_dt;
  const double seconds =
      a.seconds > 0 ? a.seconds : (ref.loop() ? 5 * ref.duration() : ref.duration());
  const double fall_z = a.fall_z >= 0 ? a.fall_z : (sit ? a.sit_fall_z : a.walk_fall_z);
  const int steps = static_cast<int>(std::ceil(seconds / dt));
  double joint_err = 0, root_err = 0, up_s = 0;
  bool fell = false;
  int done = 0;
  for (int i = 1; i <= steps; ++i) {
    const MotionPose target = pose_at(i * dt);
    env.HoldPoseAction(target.q.data(), act.data());
    const StepResult r = env.Step(act.data(), obs.data());
    const HumanoidState& s = env.humanoid_state();
    double se = 0;
    for (int j = 0; j < HumanoidModel::kNumJoints; ++j) se += std::pow(s.q[j] - target.q[j], 2);
    joint_err += std::sqrt(se / HumanoidModel::kNumJoints);
    root_err += (s.root_pos - target.root_pos).norm();
    done = i;
    if (r.invalid || s.root_pos.z() < fall_z) {
      fell = true;
      break;
    }
    up_s = i * dt;
    if (i % 120 == 0) std::cerr << "track " << a.name << ": " << up_s << " s\n";
  }
  Json out{{"name", a.name},
           {"action_mode", "pd"},
           {"control_dt_s", dt},
           {"seconds_requested", seconds},
           {"seconds_up", up_s},
           {"fell", fell},
           {"fall_z_m", fall_z},
           {"steps", done},
           {"mean_joint_rms_err_rad", done ? joint_err / done : 0.0},
           {"mean_root_pos_err_m", done ? root_err / done : 0.0}};
  if (sit && cfg.chair != "none") out["pelvis_seat_contact_at_end"] = env.PelvisSeatContact();
  return out;
}

}  // namespace perch
