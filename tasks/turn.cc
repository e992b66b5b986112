#include "tasks/turn.h"

#include <cmath>

#include "common/paths.h"
#include "tasks/config_fields.h"

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

const FieldTable<TurnTaskConfig>& TurnTaskConfigFields() {
  using C = TurnTaskConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          // First: the variant sets the defaults of the fields below.
          .With(RewardVariantField<C>)
          .Add("motion_file", &C::motion_file, "the turn clip (default: data/motions/TASK.json)")
          .With(SimilarityField<C>)
          .Add("rot_weight", &C::rot_weight, "root rotation term", NonNegative<double>())
          .Add("rot_alpha", &C::rot_alpha, "its sharpness", NonNegative<double>())
          .Add("root_vel_weight", &C::root_vel_weight, "root velocity term", NonNegative<double>())
          .Add("root_vel_alpha", &C::root_vel_alpha, "its sharpness", NonNegative<double>())
          .Add("hold_phase", &C::hold_phase, "after the clip ends: the hold terms")
          .Add("hold_pose_weight", &C::hold_pose_weight, "hold: pose term", NonNegative<double>())
          .Add("hold_energy_weight", &C::hold_energy_weight, "hold: energy term",
               NonNegative<double>())
          .Add("hold_yaw_weight", &C::hold_yaw_weight, "hold: heading term", NonNegative<double>())
          .Add("hold_yaw_alpha", &C::hold_yaw_alpha, "its sharpness", NonNegative<double>())
          .Add("hold_still_weight", &C::hold_still_weight, "hold: standing still",
               NonNegative<double>())
          .Add("hold_still_alpha", &C::hold_still_alpha, "its sharpness", NonNegative<double>())
          .With(EnergyField<C>)
          .Add("yaw_offset_max_deg", &C::yaw_offset_max_deg, "start heading offset [deg]",
               InRange<double>(0, 180, "must be in [0, 180]"))
          .Add("rsi_prob", &C::rsi_prob, "share of starts along the clip",
               InRange<double>(0, 1, "must be in [0, 1]"))
          .Add("rsi_max_fraction", &C::rsi_max_fraction, "latest start along the clip",
               InRange<double>(0, 1, "must be in [0, 1]"))
          .Add("min_root_z", &C::min_root_z, "early termination below [m]")
          .Add("max_yaw_error_deg", &C::max_yaw_error_deg, "early termination beyond [deg]",
               Satisfies<double>([](const double& v) { return v > 0 && v <= 180; },
                                 "must be in (0, 180]"))
          .Add("max_episode_steps", &C::max_episode_steps, "time limit [control steps]",
               Satisfies<int>([](const int& v) { return v >= 1; }, "must be >= 1"))
          .Add("start_joint_noise_rad", &C::start_joint_noise_rad, "start pose noise [rad]",
               InRange<double>(0, 0.5, "must be in [0, 0.5] rad"))
          .Add("success_after_end_s", &C::success_after_end_s,
               "success judged this long after the clip's end [s]", NonNegative<double>())
          .Add("success_yaw_tol_deg", &C::success_yaw_tol_deg, "heading tolerance [deg]",
               Positive<double>())
          .With(StartField<C>)
          .Add("heading_goal", &C::heading_goal, "the goal feature is the heading to reach")
          .Add("heading_lookahead_s", &C::heading_lookahead_s, "[s]",
               InRange<double>(0, 2.0, "must be in [0, 2] s"));
  return t;
}

TurnTaskConfig TurnTaskConfig::FromJson(const Json& j, const std::string& ctx,
                                        const std::string& task) {
  TurnTaskConfig defaults;
  defaults.motion_file = "data/motions/" + task + ".json";
  return TurnTaskConfigFields().Read(j, ctx, defaults);
}

Json TurnTaskConfig::ToJson() const { return TurnTaskConfigFields().Write(*this); }

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
