#include "tasks/sit.h"

#include <cmath>

#include "common/paths.h"

namespace perch {

void SitTaskConfig::ApplyVariant(const std::string& variant, const std::string& ctx) {
  similarity.w_pose = 0.5;
  similarity.w_vel = 0.05;
  similarity.alpha_pose = 1.0;
  approach_weight = 0.5;
  if (variant == "paper") {
    similarity.alpha_vel = 10.0;
    similarity.finite_difference_velocities = false;
    hold_phase = false;
  } else if (variant == "authors") {  // notes 3.2-3.3
    similarity.alpha_vel = 0.01;
    similarity.finite_difference_velocities = true;
    hold_phase = true;
  } else {
    throw ConfigError(ctx + ".reward_variant: expected \"paper\" or \"authors\", got \"" + variant +
                      "\"");
  }
  reward_variant = variant;
}

SitTaskConfig SitTaskConfig::FromJson(const Json& j, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected an object");
  CheckKnownKeys(j,
                 {"reward_variant",
                  "motion_file",
                  "similarity",
                  "approach_weight",
                  "approach_horizontal",
                  "hold_phase",
                  "hold_pose_weight",
                  "hold_energy_weight",
                  "hold_contact_weight",
                  "hold_seat_weight",
                  "hold_seat_alpha",
                  "root_pos_weight",
                  "root_pos_alpha",
                  "pelvis_path_weight",
                  "pelvis_path_alpha",
                  "energy",
                  "pelvis_end_offset",
                  "clip_seat_height_m",
                  "adapt_to_seat_height",
                  "reference_state_init",
                  "rsi_max_fraction",
                  "rsi_zero_joint_speeds",
                  "min_root_z",
                  "max_episode_steps",
                  "start_joint_noise_rad",
                  "success_contact_s",
                  "eval_episode_s",
                  "max_seat_height_m",
                  "start",
                  "start_noise_m",
                  "start_noise_deg",
                  "start_extra_along_m",
                  "start_extra_across_m",
                  "start_extra_yaw_deg"},
                 ctx);
  SitTaskConfig c;
  std::string variant = c.reward_variant;
  GetOptional(j, "reward_variant", variant, ctx);
  c.ApplyVariant(variant, ctx);
  GetOptional(j, "motion_file", c.motion_file, ctx);
  if (j.contains("similarity")) {
    c.similarity =
        SimilarityRewardConfig::FromJson(j["similarity"], ctx + ".similarity", c.similarity);
  }
  GetOptional(j, "approach_weight", c.approach_weight, ctx);
  GetOptional(j, "approach_horizontal", c.approach_horizontal, ctx);
  GetOptional(j, "hold_phase", c.hold_phase, ctx);
  GetOptional(j, "hold_pose_weight", c.hold_pose_weight, ctx);
  GetOptional(j, "hold_energy_weight", c.hold_energy_weight, ctx);
  GetOptional(j, "hold_contact_weight", c.hold_contact_weight, ctx);
  GetOptional(j, "hold_seat_weight", c.hold_seat_weight, ctx);
  GetOptional(j, "hold_seat_alpha", c.hold_seat_alpha, ctx);
  GetOptional(j, "root_pos_weight", c.root_pos_weight, ctx);
  GetOptional(j, "pelvis_path_weight", c.pelvis_path_weight, ctx);
  GetOptional(j, "pelvis_path_alpha", c.pelvis_path_alpha, ctx);
  GetOptional(j, "root_pos_alpha", c.root_pos_alpha, ctx);
  if (j.contains("energy")) c.energy = EnergyCostConfig::FromJson(j["energy"], ctx + ".energy");
  GetOptional(j, "pelvis_end_offset", c.pelvis_end_offset, ctx);
  GetOptional(j, "clip_seat_height_m", c.clip_seat_height_m, ctx);
  GetOptional(j, "adapt_to_seat_height", c.adapt_to_seat_height, ctx);
  if (!(c.clip_seat_height_m > 0 && c.clip_seat_height_m < 1.0)) {
    throw ConfigError(ctx + ".clip_seat_height_m: must be in (0, 1) m");
  }
  GetOptional(j, "reference_state_init", c.reference_state_init, ctx);
  GetOptional(j, "rsi_max_fraction", c.rsi_max_fraction, ctx);
  GetOptional(j, "rsi_zero_joint_speeds", c.rsi_zero_joint_speeds, ctx);
  GetOptional(j, "min_root_z", c.min_root_z, ctx);
  GetOptional(j, "max_episode_steps", c.max_episode_steps, ctx);
  GetOptional(j, "start_joint_noise_rad", c.start_joint_noise_rad, ctx);
  if (!(c.start_joint_noise_rad >= 0 && c.start_joint_noise_rad <= 0.5)) {
    throw ConfigError(ctx + ".start_joint_noise_rad: must be in [0, 0.5] rad");
  }
  GetOptional(j, "success_contact_s", c.success_contact_s, ctx);
  GetOptional(j, "eval_episode_s", c.eval_episode_s, ctx);
  GetOptional(j, "max_seat_height_m", c.max_seat_height_m, ctx);
  if (j.contains("start")) c.start = BankStartConfig::FromJson(j["start"], ctx + ".start");
  GetOptional(j, "start_noise_m", c.start_noise_m, ctx);
  GetOptional(j, "start_noise_deg", c.start_noise_deg, ctx);
  if (!(c.start_noise_m[0] >= 0 && c.start_noise_m[1] >= 0 && c.start_noise_deg >= 0)) {
    throw ConfigError(ctx + ".start_noise_m/start_noise_deg: must be >= 0");
  }
  GetOptional(j, "start_extra_along_m", c.start_extra_along_m, ctx);
  GetOptional(j, "start_extra_across_m", c.start_extra_across_m, ctx);
  GetOptional(j, "start_extra_yaw_deg", c.start_extra_yaw_deg, ctx);
  if (!(c.start_extra_along_m[0] <= c.start_extra_along_m[1] &&
        std::abs(c.start_extra_along_m[0]) <= 2.0 && std::abs(c.start_extra_along_m[1]) <= 2.0)) {
    throw ConfigError(ctx + ".start_extra_along_m: expected [lo, hi] with lo <= hi, within +-2 m");
  }
  if (!(c.start_extra_across_m >= 0 && c.start_extra_across_m <= 2.0)) {
    throw ConfigError(ctx + ".start_extra_across_m: must be in [0, 2] m");
  }
  if (!(c.start_extra_yaw_deg >= 0 && c.start_extra_yaw_deg <= 180.0)) {
    throw ConfigError(ctx + ".start_extra_yaw_deg: must be in [0, 180] deg");
  }
  if (c.max_episode_steps < 1) throw ConfigError(ctx + ".max_episode_steps: must be >= 1");
  if (!(c.rsi_max_fraction >= 0 && c.rsi_max_fraction <= 1)) {
    throw ConfigError(ctx + ".rsi_max_fraction: must be in [0, 1]");
  }
  if (!(c.success_contact_s > 0)) throw ConfigError(ctx + ".success_contact_s: must be > 0");
  if (!(c.eval_episode_s > 0)) throw ConfigError(ctx + ".eval_episode_s: must be > 0");
  if (!(c.max_seat_height_m > 0)) throw ConfigError(ctx + ".max_seat_height_m: must be > 0");
  for (double w : {c.approach_weight, c.hold_pose_weight, c.hold_energy_weight,
                   c.hold_contact_weight, c.hold_seat_weight, c.hold_seat_alpha, c.root_pos_weight,
                   c.root_pos_alpha, c.pelvis_path_weight, c.pelvis_path_alpha}) {
    if (!(w >= 0)) throw ConfigError(ctx + ": reward weights must be >= 0");
  }
  for (double v : c.pelvis_end_offset) {
    if (!std::isfinite(v) || std::abs(v) > 1.0) {
      throw ConfigError(ctx + ".pelvis_end_offset: each value must be within +-1 m");
    }
  }
  return c;
}

Json SitTaskConfig::ToJson() const {
  return Json{{"reward_variant", reward_variant},
              {"motion_file", motion_file},
              {"similarity", similarity.ToJson()},
              {"approach_weight", approach_weight},
              {"approach_horizontal", approach_horizontal},
              {"hold_phase", hold_phase},
              {"hold_pose_weight", hold_pose_weight},
              {"hold_energy_weight", hold_energy_weight},
              {"hold_contact_weight", hold_contact_weight},
              {"hold_seat_weight", hold_seat_weight},
              {"hold_seat_alpha", hold_seat_alpha},
              {"root_pos_weight", root_pos_weight},
              {"root_pos_alpha", root_pos_alpha},
              {"pelvis_path_weight", pelvis_path_weight},
              {"pelvis_path_alpha", pelvis_path_alpha},
              {"energy", energy.ToJson()},
              {"pelvis_end_offset", pelvis_end_offset},
              {"clip_seat_height_m", clip_seat_height_m},
              {"adapt_to_seat_height", adapt_to_seat_height},
              {"reference_state_init", reference_state_init},
              {"rsi_max_fraction", rsi_max_fraction},
              {"rsi_zero_joint_speeds", rsi_zero_joint_speeds},
              {"min_root_z", min_root_z},
              {"max_episode_steps", max_episode_steps},
              {"start_joint_noise_rad", start_joint_noise_rad},
              {"success_contact_s", success_contact_s},
              {"eval_episode_s", eval_episode_s},
              {"max_seat_height_m", max_seat_height_m},
              {"start", start.ToJson()},
              {"start_noise_m", start_noise_m},
              {"start_noise_deg", start_noise_deg},
              {"start_extra_along_m", start_extra_along_m},
              {"start_extra_across_m", start_extra_across_m},
              {"start_extra_yaw_deg", start_extra_yaw_deg}};
}

SitTask::SitTask(const SitTaskConfig& config, double control_dt)
    : ClipTask(ResolveProjectPath(config.motion_file), control_dt), c_(config) {}

double SitTask::ChairYaw(const HumanoidChairEnv& env) { return env.config().chair_placement.yaw; }

ClipPlacement SitTask::PlacementFor(const HumanoidChairEnv& env) const {
  ClipPlacement p;
  p.yaw = ChairYaw(env);
  const Eigen::AngleAxisd rz(p.yaw, Eigen::Vector3d::UnitZ());
  const Eigen::Vector3d seat = env.SeatTargetWorld();
  const Eigen::Vector3d want =
      seat + rz * Eigen::Vector3d(c_.pelvis_end_offset[0], c_.pelvis_end_offset[1], 0.0);
  const Eigen::Vector3d have = rz * pelvis_end_clip_;
  p.offset = Eigen::Vector3d(want.x() - have.x(), want.y() - have.y(), 0.0);
  if (c_.adapt_to_seat_height && env.chair() != nullptr) {
    p.descent_dz = env.chair()->seat_height() - c_.clip_seat_height_m;
    p.z_top = root_top_z_;
    p.z_bottom = root_bottom_z_;
  }
  return p;
}

bool SitTask::InitialState(const HumanoidChairEnv& env, Rng& rng, HumanoidState* s) {
  if (!pelvis_end_known_) {
    // The chair check needs the env's chair, so it happens at the first reset.
    if (env.config().chair == "none") {
      throw ConfigError("env.chair: the sit task needs a chair (got \"none\")");
    }
    const MotionPose& last = motion_.frame(motion_.num_frames() - 1);
    const FkResult fk = ForwardKinematics(env.model(), last.root_pos, last.root_rot, last.q.data());
    pelvis_end_clip_ = fk.body_world[env.model().pelvis_body()].translation();
    root_top_z_ = motion_.frame(0).root_pos.z();
    root_bottom_z_ = last.root_pos.z();
    pelvis_end_known_ = true;
  }
  m_.placement = PlacementFor(env);
  if (!c_.start.banks.empty()) {
    // The coin and the noise are drawn for every episode, bank or not (the authors' placement
    // noise applies to both halves).
    const double along = rng.Normal(0.0, c_.start_noise_m[0]);
    const double across = rng.Normal(0.0, c_.start_noise_m[1]);
    const double turn = rng.Normal(0.0, c_.start_noise_deg * M_PI / 180.0);
    const Eigen::AngleAxisd rz(ChairYaw(env), Eigen::Vector3d::UnitZ());
    const Eigen::Vector3d seat = env.SeatTargetWorld();
    // Rotate the placed clip about the seat by `turn`, then shift it.
    const Eigen::AngleAxisd rt(turn, Eigen::Vector3d::UnitZ());
    m_.placement.yaw += turn;
    const Eigen::Vector3d off = m_.placement.offset - Eigen::Vector3d(seat.x(), seat.y(), 0.0);
    m_.placement.offset = rt * off + Eigen::Vector3d(seat.x(), seat.y(), 0.0) +
                          rz * Eigen::Vector3d(along, across, 0.0);
    const HumanoidState f0 = StartState(m_.placement, 0.0, false);
    // Drawn for every episode (bank or not) when configured; not drawn at all otherwise, so
    // runs without it keep their random streams.
    double extra_along = 0.0, extra_across = 0.0, extra_yaw = 0.0;
    if (c_.start_extra_along_m[1] != 0.0 || c_.start_extra_along_m[0] != 0.0 ||
        c_.start_extra_across_m > 0.0 || c_.start_extra_yaw_deg > 0.0) {
      extra_along = rng.Uniform(c_.start_extra_along_m[0], c_.start_extra_along_m[1]);
      extra_across = rng.Uniform(-c_.start_extra_across_m, c_.start_extra_across_m);
      extra_yaw = rng.Uniform(-c_.start_extra_yaw_deg, c_.start_extra_yaw_deg) * M_PI / 180.0;
    }
    const Eigen::Vector2d xy =
        f0.root_pos.head<2>() + (rz * Eigen::Vector3d(extra_along, extra_across, 0.0)).head<2>();
    if (BankStart(c_.start, env, rng, RpyFromQuat(f0.root_quat).z() + extra_yaw, xy, s)) {
      m_.t0 = 0.0;
      PerturbJoints(c_.start_joint_noise_rad, env, rng, s);
      return true;
    }
  }
  const bool rsi = c_.reference_state_init;
  m_.t0 = rsi ? rng.Uniform(0.0, c_.rsi_max_fraction * motion_.duration()) : 0.0;
  *s = StartState(m_.placement, m_.t0, rsi && c_.rsi_zero_joint_speeds);
  PerturbJoints(c_.start_joint_noise_rad, env, rng, s);
  return true;
}

double SitTask::ApproachDistance(const HumanoidChairEnv& env) const {
  if (!c_.approach_horizontal) return env.PelvisSeatDistance();
  return (env.PelvisPosition() - env.SeatTargetWorld()).head<2>().norm();
}

void SitTask::OnReset(HumanoidChairEnv& env, Rng& rng) {
  RememberPose(env);
  m_.prev_distance = ApproachDistance(env);
  terms_ = SitTerms();
  terms_.seat_distance_m = env.PelvisSeatDistance();
  contact_run_ = 0;
  succeeded_ = false;
  env.SetWalkTarget(env.SeatTargetWorld().head<2>());
}

TaskStep SitTask::OnStep(const HumanoidChairEnv& env, const float* action) {
  const int k = env.episode_step();
  SitTerms t;
  const Similarity sim = ComputeSimilarity(c_.similarity, env, k);
  t.pose = sim.pose;
  t.joint_vel = sim.joint_vel;
  t.seat_distance_m = env.PelvisSeatDistance();
  const double approach_distance = ApproachDistance(env);
  if (c_.hold_phase && ClipEnded(k)) {
    t.similarity = c_.hold_pose_weight * t.pose;
    t.energy = c_.hold_energy_weight * EnergyCost(c_.energy, env, action);
  } else {
    t.similarity = sim.total;
    t.approach = ApproachReward(m_.prev_distance, approach_distance, dt_, c_.approach_weight);
  }
  if (c_.hold_contact_weight > 0 && ClipEnded(k) && env.PelvisSeatContact()) {
    t.contact = c_.hold_contact_weight;
  }
  if (c_.hold_seat_weight > 0 && ClipEnded(k)) {
    const double d2 = (env.PelvisPosition() - env.SeatTargetWorld()).head<2>().squaredNorm();
    t.seat = c_.hold_seat_weight * std::exp(-c_.hold_seat_alpha * d2);
  }
  if (c_.root_pos_weight > 0) {
    const double d2 =
        (env.humanoid_state().root_pos - ReferenceAt(k).root_pos).head<2>().squaredNorm();
    t.root_pos = c_.root_pos_weight * std::exp(-c_.root_pos_alpha * d2);
  }
  if (c_.pelvis_path_weight > 0) {
    const MotionPose ref = ReferenceAt(k);
    const FkResult fk = ForwardKinematics(env.model(), ref.root_pos, ref.root_rot, ref.q.data());
    const Eigen::Vector3d d =
        env.PelvisPosition() - fk.body_world[env.model().pelvis_body()].translation();
    t.pelvis_path = c_.pelvis_path_weight * std::exp(-c_.pelvis_path_alpha * d.squaredNorm());
  }
  t.total = t.similarity + t.approach + t.energy + t.contact + t.seat + t.root_pos + t.pelvis_path;
  terms_ = t;
  m_.prev_distance = approach_distance;
  RememberPose(env);
  TaskStep r;
  r.reward = static_cast<float>(t.total);
  r.terminated = env.humanoid_state().root_pos.z() < c_.min_root_z;
  contact_run_ = env.PelvisSeatContact() ? contact_run_ + 1 : 0;
  const int need = static_cast<int>(std::ceil(c_.success_contact_s / dt_ - 1e-9));
  if (!succeeded_ && contact_run_ >= need) {
    succeeded_ = true;
    r.success = true;
  }
  return r;
}

}  // namespace perch
