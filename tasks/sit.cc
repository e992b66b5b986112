#include "tasks/sit.h"

#include <cmath>

#include "common/paths.h"
#include "tasks/config_fields.h"

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

const FieldTable<SitTaskConfig>& SitTaskConfigFields() {
  using C = SitTaskConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          // First: the variant sets the defaults of the fields below.
          .With(RewardVariantField<C>)
          .Add("motion_file", &C::motion_file, "the sit clip")
          .With(SimilarityField<C>)
          .Add("approach_weight", &C::approach_weight, "Eq. 7 weight [per m/s]",
               NonNegative<double>())
          .Add("approach_horizontal", &C::approach_horizontal, "Eq. 7 in the horizontal plane")
          .Add("hold_phase", &C::hold_phase, "after the clip ends: the hold terms (authors)")
          .Add("hold_pose_weight", &C::hold_pose_weight, "hold: pose term", NonNegative<double>())
          .Add("hold_energy_weight", &C::hold_energy_weight, "hold: energy term",
               NonNegative<double>())
          .Add("hold_contact_weight", &C::hold_contact_weight, "hold: seat contact",
               NonNegative<double>())
          .Add("hold_seat_weight", &C::hold_seat_weight, "hold: pelvis at the seat target",
               NonNegative<double>())
          .Add("hold_seat_alpha", &C::hold_seat_alpha, "[1/m^2]", NonNegative<double>())
          .Add("root_pos_weight", &C::root_pos_weight, "root follows the placed clip",
               NonNegative<double>())
          .Add("root_pos_alpha", &C::root_pos_alpha, "[1/m^2]", NonNegative<double>())
          .Add("pelvis_path_weight", &C::pelvis_path_weight, "pelvis follows the placed clip (3-D)",
               NonNegative<double>())
          .Add("pelvis_path_alpha", &C::pelvis_path_alpha, "[1/m^2]", NonNegative<double>())
          .With(EnergyField<C>)
          .Add("pelvis_end_offset", &C::pelvis_end_offset,
               "the clip's end pelvis placed this far from the seat target [m]",
               Satisfies<std::array<double, 2>>(
                   [](const std::array<double, 2>& o) {
                     for (double v : o) {
                       if (!std::isfinite(v) || std::abs(v) > 1.0) return false;
                     }
                     return true;
                   },
                   "each value must be within +-1 m"))
          .Add("clip_seat_height_m", &C::clip_seat_height_m, "the clip's seat height [m]",
               Satisfies<double>([](const double& v) { return v > 0 && v < 1.0; },
                                 "must be in (0, 1) m"))
          .Add("adapt_to_seat_height", &C::adapt_to_seat_height,
               "the clip's descent follows the chair's seat")
          .Add("reference_state_init", &C::reference_state_init, "starts along the clip")
          .Add("rsi_max_fraction", &C::rsi_max_fraction, "latest start along the clip",
               InRange<double>(0, 1, "must be in [0, 1]"))
          .Add("rsi_zero_joint_speeds", &C::rsi_zero_joint_speeds, "clip starts at rest")
          .Add("min_root_z", &C::min_root_z, "early termination below [m]")
          .Add("max_episode_steps", &C::max_episode_steps, "time limit [control steps]",
               Satisfies<int>([](const int& v) { return v >= 1; }, "must be >= 1"))
          .Add("start_joint_noise_rad", &C::start_joint_noise_rad, "start pose noise [rad]",
               InRange<double>(0, 0.5, "must be in [0, 0.5] rad"))
          .Add("success_contact_s", &C::success_contact_s, "seated this long: success [s]",
               Positive<double>())
          .Add("eval_episode_s", &C::eval_episode_s, "evaluation episode length [s]",
               Positive<double>())
          .Add("max_seat_height_m", &C::max_seat_height_m, "chairs above are refused [m]",
               Positive<double>())
          .Add("observe_chair_shape", &C::observe_chair_shape,
               "observe the chair's 5 x 5 height grid (env.obs_layout proprio_chair_shape)")
          .With(StartField<C>)
          .Add("start_noise_m", &C::start_noise_m, "start position noise [m]")
          .Add("start_noise_deg", &C::start_noise_deg, "start heading noise [deg]")
          .Add("start_extra_along_m", &C::start_extra_along_m,
               "[lo, hi] extra start distance along the approach [m]",
               Satisfies<std::array<double, 2>>(
                   [](const std::array<double, 2>& v) {
                     return v[0] <= v[1] && std::abs(v[0]) <= 2.0 && std::abs(v[1]) <= 2.0;
                   },
                   "expected [lo, hi] with lo <= hi, within +-2 m"))
          .Add("start_extra_across_m", &C::start_extra_across_m, "extra start offset across [m]",
               InRange<double>(0, 2.0, "must be in [0, 2] m"))
          .Add("start_extra_yaw_deg", &C::start_extra_yaw_deg, "extra start heading [deg]",
               InRange<double>(0, 180.0, "must be in [0, 180] deg"))
          .Rule([](const C& c, const std::string& ctx) {
            if (!(c.start_noise_m[0] >= 0 && c.start_noise_m[1] >= 0 && c.start_noise_deg >= 0)) {
              return ctx + ".start_noise_m/start_noise_deg: must be >= 0";
            }
            return std::string();
          });
  return t;
}

SitTaskConfig SitTaskConfig::FromJson(const Json& j, const std::string& ctx) {
  return SitTaskConfigFields().Read(j, ctx);
}

Json SitTaskConfig::ToJson() const { return SitTaskConfigFields().Write(*this); }

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
