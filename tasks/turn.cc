#include "tasks/turn.h"

#include <cmath>

#include "common/paths.h"

namespace perch {

void TurnTaskConfig::ApplyVariant(const std::string& variant, const std::string& ctx) {
  similarity.w_pose = 0.5;
  similarity.w_vel = 0.05;
  similarity.alpha_pose = 1.0;
  rot_weight = 0.1;
  rot_alpha = 10.0;
  root_vel_alpha = 10.0;
  if (variant == "paper") {
    similarity.alpha_vel = 10.0;
    similarity.finite_difference_velocities = false;
    root_vel_weight = 0.0;
    hold_phase = false;
  } else if (variant == "authors") {  // notes 3.2-3.3
    similarity.alpha_vel = 0.01;
    similarity.finite_difference_velocities = true;
    root_vel_weight = 0.1;
    hold_phase = true;
  } else {
    throw ConfigError(ctx + ".reward_variant: expected \"paper\" or \"authors\", got \"" + variant +
                      "\"");
  }
  reward_variant = variant;
}

TurnTaskConfig TurnTaskConfig::FromJson(const Json& j, const std::string& ctx,
                                        const std::string& task) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected an object");
  CheckKnownKeys(j,
                 {"reward_variant",
                  "motion_file",
                  "similarity",
                  "rot_weight",
                  "rot_alpha",
                  "root_vel_weight",
                  "root_vel_alpha",
                  "hold_phase",
                  "hold_pose_weight",
                  "hold_energy_weight",
                  "hold_yaw_weight",
                  "hold_yaw_alpha",
                  "hold_still_weight",
                  "hold_still_alpha",
                  "energy",
                  "yaw_offset_max_deg",
                  "rsi_prob",
                  "rsi_max_fraction",
                  "min_root_z",
                  "max_yaw_error_deg",
                  "max_episode_steps",
                  "start_joint_noise_rad",
                  "success_after_end_s",
                  "success_yaw_tol_deg",
                  "start",
                  "heading_goal",
                  "heading_lookahead_s"},
                 ctx);
  TurnTaskConfig c;
  c.motion_file = "data/motions/" + task + ".json";
  std::string variant = c.reward_variant;
  GetOptional(j, "reward_variant", variant, ctx);
  c.ApplyVariant(variant, ctx);
  GetOptional(j, "motion_file", c.motion_file, ctx);
  if (j.contains("similarity")) {
    c.similarity =
        SimilarityRewardConfig::FromJson(j["similarity"], ctx + ".similarity", c.similarity);
  }
  GetOptional(j, "rot_weight", c.rot_weight, ctx);
  GetOptional(j, "rot_alpha", c.rot_alpha, ctx);
  GetOptional(j, "root_vel_weight", c.root_vel_weight, ctx);
  GetOptional(j, "root_vel_alpha", c.root_vel_alpha, ctx);
  GetOptional(j, "hold_phase", c.hold_phase, ctx);
  GetOptional(j, "hold_pose_weight", c.hold_pose_weight, ctx);
  GetOptional(j, "hold_energy_weight", c.hold_energy_weight, ctx);
  GetOptional(j, "hold_yaw_weight", c.hold_yaw_weight, ctx);
  GetOptional(j, "hold_yaw_alpha", c.hold_yaw_alpha, ctx);
  GetOptional(j, "hold_still_weight", c.hold_still_weight, ctx);
  GetOptional(j, "hold_still_alpha", c.hold_still_alpha, ctx);
  if (j.contains("energy")) c.energy = EnergyCostConfig::FromJson(j["energy"], ctx + ".energy");
  GetOptional(j, "yaw_offset_max_deg", c.yaw_offset_max_deg, ctx);
  GetOptional(j, "rsi_prob", c.rsi_prob, ctx);
  GetOptional(j, "rsi_max_fraction", c.rsi_max_fraction, ctx);
  if (!(c.rsi_prob >= 0 && c.rsi_prob <= 1))
    throw ConfigError(ctx + ".rsi_prob: must be in [0, 1]");
  if (!(c.rsi_max_fraction >= 0 && c.rsi_max_fraction <= 1)) {
    throw ConfigError(ctx + ".rsi_max_fraction: must be in [0, 1]");
  }
  GetOptional(j, "min_root_z", c.min_root_z, ctx);
  GetOptional(j, "max_yaw_error_deg", c.max_yaw_error_deg, ctx);
  GetOptional(j, "max_episode_steps", c.max_episode_steps, ctx);
  GetOptional(j, "start_joint_noise_rad", c.start_joint_noise_rad, ctx);
  if (!(c.start_joint_noise_rad >= 0 && c.start_joint_noise_rad <= 0.5)) {
    throw ConfigError(ctx + ".start_joint_noise_rad: must be in [0, 0.5] rad");
  }
  GetOptional(j, "success_after_end_s", c.success_after_end_s, ctx);
  GetOptional(j, "success_yaw_tol_deg", c.success_yaw_tol_deg, ctx);
  if (j.contains("start")) c.start = BankStartConfig::FromJson(j["start"], ctx + ".start");
  GetOptional(j, "heading_goal", c.heading_goal, ctx);
  GetOptional(j, "heading_lookahead_s", c.heading_lookahead_s, ctx);
  if (!(c.heading_lookahead_s >= 0 && c.heading_lookahead_s <= 2.0)) {
    throw ConfigError(ctx + ".heading_lookahead_s: must be in [0, 2] s");
  }
  if (c.max_episode_steps < 1) throw ConfigError(ctx + ".max_episode_steps: must be >= 1");
  if (!(c.yaw_offset_max_deg >= 0 && c.yaw_offset_max_deg <= 180)) {
    throw ConfigError(ctx + ".yaw_offset_max_deg: must be in [0, 180]");
  }
  if (!(c.max_yaw_error_deg > 0 && c.max_yaw_error_deg <= 180)) {
    throw ConfigError(ctx + ".max_yaw_error_deg: must be in (0, 180]");
  }
  if (!(c.success_after_end_s >= 0)) throw ConfigError(ctx + ".success_after_end_s: must be >= 0");
  if (!(c.success_yaw_tol_deg > 0)) throw ConfigError(ctx + ".success_yaw_tol_deg: must be > 0");
  for (double w : {c.rot_weight, c.rot_alpha, c.root_vel_weight, c.root_vel_alpha,
                   c.hold_pose_weight, c.hold_energy_weight, c.hold_yaw_weight, c.hold_yaw_alpha,
                   c.hold_still_weight, c.hold_still_alpha}) {
    if (!(w >= 0)) throw ConfigError(ctx + ": reward weights and sharpness must be >= 0");
  }
  return c;
}

Json TurnTaskConfig::ToJson() const {
  return Json{{"reward_variant", reward_variant},
              {"motion_file", motion_file},
              {"similarity", similarity.ToJson()},
              {"rot_weight", rot_weight},
              {"rot_alpha", rot_alpha},
              {"root_vel_weight", root_vel_weight},
              {"root_vel_alpha", root_vel_alpha},
              {"hold_phase", hold_phase},
              {"hold_pose_weight", hold_pose_weight},
              {"hold_energy_weight", hold_energy_weight},
              {"hold_yaw_weight", hold_yaw_weight},
              {"hold_yaw_alpha", hold_yaw_alpha},
              {"hold_still_weight", hold_still_weight},
              {"hold_still_alpha", hold_still_alpha},
              {"energy", energy.ToJson()},
              {"yaw_offset_max_deg", yaw_offset_max_deg},
              {"rsi_prob", rsi_prob},
              {"rsi_max_fraction", rsi_max_fraction},
              {"min_root_z", min_root_z},
              {"max_yaw_error_deg", max_yaw_error_deg},
              {"max_episode_steps", max_episode_steps},
              {"start_joint_noise_rad", start_joint_noise_rad},
              {"success_after_end_s", success_after_end_s},
              {"success_yaw_tol_deg", success_yaw_tol_deg},
              {"start", start.ToJson()},
              {"heading_goal", heading_goal},
              {"heading_lookahead_s", heading_lookahead_s}};
}

TurnTask::TurnTask(const std::string& name, const TurnTaskConfig& config, double control_dt)
    : ClipTask(ResolveProjectPath(config.motion_file), control_dt), name_(name), c_(config) {}

int TurnTask::SuccessStep() const {
  return ClipEndStep() + static_cast<int>(std::lround(c_.success_after_end_s / dt_));
}

bool TurnTask::InitialState(const HumanoidChairEnv& env, Rng& rng, HumanoidState* s) {
  // Notes 4.3: frame 0 over the origin (the clip's canonical placement), the whole clip rotated
  // by a random yaw; start at frame 0 with its velocities.
  const double max = c_.yaw_offset_max_deg * M_PI / 180.0;
  m_.placement.yaw = max > 0 ? rng.Uniform(-max, max) : 0.0;
  const Eigen::Vector3d p0 = motion_.frame(0).root_pos;
  m_.placement.offset = Eigen::Vector3d(-p0.x(), -p0.y(), 0.0);
  m_.placement.offset =
      Eigen::AngleAxisd(m_.placement.yaw, Eigen::Vector3d::UnitZ()) * m_.placement.offset;
  m_.t0 = 0.0;
  *s = StartState(m_.placement, 0.0, false);
  // A bank start replaces frame 0; otherwise maybe a reference state initialisation (the coin
  // is only tossed when RSI is on, so other runs keep their random streams).
  if (!BankStart(c_.start, env, rng, RpyFromQuat(s->root_quat).z(), s->root_pos.head<2>(), s) &&
      c_.rsi_prob > 0 && rng.Uniform(0.0, 1.0) < c_.rsi_prob) {
    m_.t0 = rng.Uniform(0.0, c_.rsi_max_fraction * motion_.duration());
    *s = StartState(m_.placement, m_.t0, false);
  }
  PerturbJoints(c_.start_joint_noise_rad, env, rng, s);
  return true;
}

void TurnTask::OnReset(HumanoidChairEnv& env, Rng& rng) {
  RememberPose(env);
  terms_ = TurnTerms();
  if (c_.heading_goal) {
    BeforeObservation(env, rng);
  } else {
    // The goal feature is not in the turn state; the target is kept neutral for other layouts.
    env.SetWalkTarget(env.humanoid_state().root_pos.head<2>());
  }
}

double TurnTask::HeadingGoalYaw(int k) const {
  const int ahead = static_cast<int>(std::lround(c_.heading_lookahead_s / dt_));
  return RpyFromQuat(ReferenceAt(k + ahead).root_rot).z();
}

void TurnTask::BeforeObservation(HumanoidChairEnv& env, Rng& /*rng*/) {
  if (!c_.heading_goal) return;
  // A target 1 m away along the reference's heading: the walk layout's goal feature then reads
  // [sin, cos] of the heading relative to the humanoid.
  const double yaw = HeadingGoalYaw(env.episode_step());
  env.SetWalkTarget(env.BodyXyz().head<2>() + Eigen::Vector2d(std::cos(yaw), std::sin(yaw)));
}

TaskStep TurnTask::OnStep(const HumanoidChairEnv& env, const float* action) {
  const int k = env.episode_step();
  const MotionPose ref = ReferenceAt(k);  // the reference index advances first (notes 3.2)
  const Eigen::Vector3d rpy = env.RootRpy();
  const Eigen::Vector3d rpy_ref = RpyFromQuat(ref.root_rot);
  TurnTerms t;
  const Similarity sim = ComputeSimilarity(c_.similarity, env, k);
  t.pose = sim.pose;
  t.joint_vel = sim.joint_vel;
  t.rotation = RootRotationReward(rpy.data(), rpy_ref.data(), c_.rot_weight, c_.rot_alpha);
  t.yaw_error_rad = AngleDiff(rpy.z(), rpy_ref.z());
  if (ClipEnded(k) && c_.hold_yaw_weight > 0) {
    t.yaw = c_.hold_yaw_weight * std::exp(-c_.hold_yaw_alpha * t.yaw_error_rad * t.yaw_error_rad);
  }
  if (ClipEnded(k) && c_.hold_still_weight > 0) {
    const double v2 = env.humanoid_state().root_lin_vel.head<2>().squaredNorm();
    t.still = c_.hold_still_weight * std::exp(-c_.hold_still_alpha * v2);
  }
  if (c_.hold_phase && ClipEnded(k)) {
    t.similarity = c_.hold_pose_weight * t.pose;
    t.energy = c_.hold_energy_weight * EnergyCost(c_.energy, env, action);
  } else {
    t.similarity = sim.total;
    if (c_.root_vel_weight > 0) {
      Eigen::Vector3d v, v_ref;
      RootVelocities(c_.similarity.finite_difference_velocities, env, k, &v, &v_ref);
      t.root_vel =
          RootVelocityReward(v.data(), v_ref.data(), c_.root_vel_weight, c_.root_vel_alpha);
    }
  }
  t.total = t.similarity + t.rotation + t.root_vel + t.energy + t.yaw + t.still;
  terms_ = t;
  RememberPose(env);
  TaskStep r;
  r.reward = static_cast<float>(t.total);
  r.terminated = env.humanoid_state().root_pos.z() < c_.min_root_z ||
                 std::abs(t.yaw_error_rad) > c_.max_yaw_error_deg * M_PI / 180.0;
  // Success (docs/subtasks.md): judged once, at SuccessStep, as perch eval does.
  r.success = k == SuccessStep() && !r.terminated &&
              std::abs(t.yaw_error_rad) <= c_.success_yaw_tol_deg * M_PI / 180.0;
  return r;
}

}  // namespace perch
