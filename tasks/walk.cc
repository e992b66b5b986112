#include "tasks/walk.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/paths.h"
#include "tasks/clip_task.h"
#include "tasks/config_fields.h"

namespace perch {

// ---- config ----------------------------------------------------------------------------------

void WalkTaskConfig::ApplyVariant(const std::string& variant, const std::string& ctx) {
  // Terms both variants share (Eq. 2-3 weights, alpha_pose, the Eq. 5 slope).
  similarity.w_pose = 0.5;
  similarity.w_vel = 0.05;
  similarity.alpha_pose = 1.0;
  target_k = 10.0;
  if (variant == "paper") {
    similarity.alpha_vel = 10.0;
    similarity.finite_difference_velocities = false;
    root_vel_weight = 0.5;
    root_vel_alpha = 10.0;
    target_weight = 0.1;
  } else if (variant == "authors") {  // notes 3.2-3.3, walk clip 08_01
    similarity.alpha_vel = 0.01;
    similarity.finite_difference_velocities = true;
    root_vel_weight = 0.1;
    root_vel_alpha = 1.0;
    target_weight = 0.5;
  } else {
    throw ConfigError(ctx + ".reward_variant: expected \"paper\" or \"authors\", got \"" + variant +
                      "\"");
  }
  reward_variant = variant;
}

const FieldTable<WalkTaskConfig>& WalkTaskConfigFields() {
  using C = WalkTaskConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          // First: the variant sets the defaults of the fields below.
          .With(RewardVariantField<C>)
          .Add("motion_file", &C::motion_file, "the walk clip")
          .Custom(
              "stage", "\"forward\" (stage 1) or \"target\" (stage 2)",
              [](const Json& j, C& c, const std::string& ctx) {
                std::string stage;
                GetOptional(j, "stage", stage, ctx);
                if (stage == "forward") {
                  c.stage = WalkStage::kForward;
                } else if (stage == "target") {
                  c.stage = WalkStage::kTarget;
                } else {
                  throw ConfigError(ctx + ".stage: expected \"forward\" or \"target\", got \"" +
                                    stage + "\"");
                }
              },
              [](const C& c, Json& j) {
                j["stage"] = c.stage == WalkStage::kForward ? "forward" : "target";
              })
          .With(SimilarityField<C>)
          .Add("root_vel_weight", &C::root_vel_weight, "stage 1: root velocity term")
          .Add("root_vel_alpha", &C::root_vel_alpha, "its sharpness")
          .Add("target_weight", &C::target_weight, "stage 2: target progress (Eq. 5)")
          .Add("target_k", &C::target_k, "Eq. 5 sigmoid slope [s/m]")
          .Add("min_root_z", &C::min_root_z, "early termination below [m]")
          .Add("max_episode_steps", &C::max_episode_steps, "time limit [control steps]",
               Satisfies<int>([](const int& v) { return v >= 1; }, "must be >= 1"))
          .Add("reference_state_init", &C::reference_state_init, "starts along the clip")
          .Add("target_redraw_s", &C::target_redraw_s, "a new target after this [s]",
               Positive<double>())
          .Add("target_reach_m", &C::target_reach_m, "or when this close [m]")
          .Add("target_min_dist_m", &C::target_min_dist_m, "targets drawn this far at least [m]")
          .Add("target_max_dist_m", &C::target_max_dist_m, "and at most [m]")
          .Add("target_max_angle_deg", &C::target_max_angle_deg, "within this of the heading [deg]")
          .Add("target_turn_prob", &C::target_turn_prob, "share of targets drawn wide",
               InRange<double>(0, 1, "must be in [0, 1]"))
          .Add("target_turn_max_angle_deg", &C::target_turn_max_angle_deg, "their angle [deg]",
               Satisfies<double>([](const double& v) { return v >= 0 && v <= 180; },
                                 "must be in [0, 180]"))
          .Add("fall_restart_prob", &C::fall_restart_prob,
               "share of episodes started shortly before a remembered fall",
               InRange<double>(0, 1, "must be in [0, 1]"))
          .Add("fall_restart_lead_s", &C::fall_restart_lead_s, "that long before it [s]",
               Satisfies<double>([](const double& v) { return v > 0 && v <= 10; },
                                 "must be in (0, 10] s"))
          .Add("fall_restart_pool", &C::fall_restart_pool, "falls kept per env",
               Satisfies<int>([](const int& v) { return v >= 1; }, "must be >= 1"))
          .With(StartField<C>)
          .Add("forward_target", &C::forward_target, "stage 1's goal features [m]")
          .Rule([](const C& c, const std::string& ctx) {
            if (c.start.keep_pose) return ctx + ".start.keep_pose: the walk has no chair frame";
            if (!(c.target_min_dist_m > 0) || c.target_max_dist_m < c.target_min_dist_m) {
              return ctx + ".target_min_dist_m/target_max_dist_m: need 0 < min <= max";
            }
            return std::string();
          });
  return t;
}

WalkTaskConfig WalkTaskConfig::FromJson(const Json& j, const std::string& ctx) {
  return WalkTaskConfigFields().Read(j, ctx);
}

Json WalkTaskConfig::ToJson() const { return WalkTaskConfigFields().Write(*this); }

std::string WalkTaskConfig::MotionPath() const { return ResolveProjectPath(motion_file); }

// ---- task ------------------------------------------------------------------------------------

WalkTask::WalkTask(const WalkTaskConfig& config, double control_dt)
    : c_(config), dt_(control_dt), motion_(ReferenceMotion::Load(config.MotionPath())) {
  if (motion_.num_frames() < 2 || motion_.frame(0).q.size() != HumanoidModel::kNumJoints) {
    throw ConfigError(c_.MotionPath() + ": a walk reference needs >= 2 frames of " +
                      std::to_string(HumanoidModel::kNumJoints) + " joint angles");
  }
  redraw_steps_ = std::max(1, static_cast<int>(std::lround(c_.target_redraw_s / dt_)));
}

MotionPose WalkTask::ReferenceAt(int step) const {
  MotionPose p = motion_.At(m_.t0 + step * dt_);
  p.root_pos += m_.offset;
  return p;
}

HumanoidState HumanoidStateFromPose(const MotionPose& p) {
  HumanoidState s;
  s.root_pos = p.root_pos;
  s.root_quat = p.root_rot;
  s.root_lin_vel = p.root_vel;
  s.root_ang_vel = p.root_angvel;
  for (int j = 0; j < HumanoidModel::kNumJoints; ++j) {
    s.q[j] = p.q[j];
    s.qd[j] = p.qdot[j];
  }
  return s;
}

HumanoidState WalkTask::ReferenceState(int step) const {
  return HumanoidStateFromPose(ReferenceAt(step));
}

bool WalkTask::InitialState(const HumanoidChairEnv& env, Rng& rng, HumanoidState* s) {
  // No bank: no draw, so runs without one draw as before.
  from_bank_ = DrawBankStart(c_.start, env, rng, std::nullopt, Eigen::Vector2d::Zero(), &bank_, s);
  if (from_bank_) {
    // The reference goes on from the clip's pose nearest to the state's, under its root.
    m_.t0 = NearestPhase(s->q);
    const MotionPose p = motion_.At(m_.t0);
    m_.offset =
        Eigen::Vector3d(s->root_pos.x() - p.root_pos.x(), s->root_pos.y() - p.root_pos.y(), 0.0);
    return true;
  }
  m_.t0 = c_.reference_state_init ? rng.Uniform(0.0, motion_.duration()) : 0.0;
  const MotionPose start = motion_.At(m_.t0);
  // Root over the origin; the clip already faces +x (docs/motion.md), so no rotation.
  m_.offset = Eigen::Vector3d(-start.root_pos.x(), -start.root_pos.y(), 0.0);
  *s = ReferenceState(0);
  return true;
}

double WalkTask::NearestPhase(const std::array<double, HumanoidModel::kNumJoints>& q) const {
  double best_t = 0.0, best = std::numeric_limits<double>::infinity();
  const int n = std::max(1, static_cast<int>(std::floor(motion_.duration() / dt_)));
  for (int i = 0; i < n; ++i) {
    const MotionPose p = motion_.At(i * dt_);
    double d = 0.0;
    for (int j = 0; j < HumanoidModel::kNumJoints; ++j) d += (q[j] - p.q[j]) * (q[j] - p.q[j]);
    if (d < best) {
      best = d;
      best_t = i * dt_;
    }
  }
  return best_t;
}

double WalkTask::TargetDistance(const HumanoidChairEnv& env) {
  return (env.walk_target() - env.BodyXyz().head<2>()).norm();
}

void WalkTask::DrawTarget(HumanoidChairEnv& env, Rng& rng) {
  // Authors: heading = the torso's x axis projected on the ground (length cos(pitch), kept).
  const HumanoidState& s = env.humanoid_state();
  const Eigen::Vector2d heading = (s.root_quat * Eigen::Vector3d::UnitX()).head<2>();
  // The curriculum's coin is only tossed when it is on, so runs without it draw as before.
  const bool turn = c_.target_turn_prob > 0 && rng.Uniform(0.0, 1.0) < c_.target_turn_prob;
  const double max_theta =
      (turn ? c_.target_turn_max_angle_deg : c_.target_max_angle_deg) * M_PI / 180.0;
  const double theta = rng.Uniform(-max_theta, max_theta);
  const double dist = rng.Uniform(c_.target_min_dist_m, c_.target_max_dist_m);
  const Eigen::Vector2d dir = Eigen::Rotation2Dd(theta) * heading;
  env.SetWalkTarget(s.root_pos.head<2>() + dist * dir);
  m_.target_drawn_dist_m = dist;
  m_.countdown = redraw_steps_;
}

void WalkTask::OnReset(HumanoidChairEnv& env, Rng& rng) {
  const HumanoidState& s = env.humanoid_state();
  m_.prev_q = s.q;
  m_.prev_root = s.root_pos;
  m_.targets_reached = 0;
  m_.redrawn = m_.reached = false;
  m_.terms = WalkTerms();
  if (c_.stage == WalkStage::kTarget) {
    DrawTarget(env, rng);
  } else {
    env.SetWalkTarget(Eigen::Vector2d(c_.forward_target[0], c_.forward_target[1]));
  }
  m_.prev_distance = TargetDistance(env);
}

void WalkTask::BeforeObservation(HumanoidChairEnv& env, Rng& rng) {
  m_.redrawn = m_.reached = false;
  if (c_.stage != WalkStage::kTarget) return;
  --m_.countdown;
  m_.reached = TargetDistance(env) < c_.target_reach_m;
  if (m_.reached) ++m_.targets_reached;
  if (m_.reached || m_.countdown <= 0) {
    DrawTarget(env, rng);
    m_.redrawn = true;
  }
}

TaskStep WalkTask::OnStep(const HumanoidChairEnv& env, const float* /*action*/) {
  constexpr int n = HumanoidModel::kNumJoints;
  const int k = env.episode_step();
  const HumanoidState& s = env.humanoid_state();
  const MotionPose ref = ReferenceAt(k);  // the reference index advances first (notes 3.2)
  const SimilarityRewardConfig& sc = c_.similarity;
  const bool fd = sc.finite_difference_velocities;
  MotionPose ref_prev;
  if (fd) ref_prev = ReferenceAt(k - 1);

  const SimilarityTerms sim =
      SimilarityTermsAt(sc, s.q.data(), m_.prev_q.data(), s.qd.data(), ref.q.data(),
                        ref_prev.q.data(), ref.qdot.data(), n, dt_);
  WalkTerms t;
  t.pose = sim.pose;
  t.joint_vel = sim.joint_vel;
  t.similarity = sim.total;

  if (c_.stage == WalkStage::kForward) {
    const Eigen::Vector3d v =
        fd ? Eigen::Vector3d((s.root_pos - m_.prev_root) / dt_) : s.root_lin_vel;
    const Eigen::Vector3d v_ref =
        fd ? Eigen::Vector3d((ref.root_pos - ref_prev.root_pos) / dt_) : ref.root_vel;
    t.goal = RootVelocityReward(v.data(), v_ref.data(), c_.root_vel_weight, c_.root_vel_alpha);
  } else {
    const double d = TargetDistance(env);
    // After a re-draw the progress is reset: that step earns the sigmoid at V = 0 (notes 4.4).
    t.goal = TargetProgressReward(m_.redrawn ? d : m_.prev_distance, d, dt_, c_.target_weight,
                                  c_.target_k);
    m_.prev_distance = d;
  }
  t.target_redrawn = m_.redrawn;
  t.target_reached = m_.reached;
  t.total = t.similarity + t.goal;
  m_.terms = t;
  m_.prev_q = s.q;
  m_.prev_root = s.root_pos;

  TaskStep r;
  r.reward = static_cast<float>(t.total);
  r.terminated = s.root_pos.z() < c_.min_root_z;
  return r;
}

Json WalkTask::SaveMemory() const {
  return Json{{"t0", m_.t0},
              {"offset", {m_.offset.x(), m_.offset.y(), m_.offset.z()}},
              {"countdown", m_.countdown},
              {"prev_distance", m_.prev_distance},
              {"redrawn", m_.redrawn},
              {"reached", m_.reached},
              {"targets_reached", m_.targets_reached},
              {"target_drawn_dist_m", m_.target_drawn_dist_m},
              {"prev_q", m_.prev_q},
              {"prev_root", {m_.prev_root.x(), m_.prev_root.y(), m_.prev_root.z()}}};
}

void WalkTask::LoadMemory(const Json& j) {
  const std::string ctx = "walk task memory";
  Memory m;
  std::array<double, 3> offset{}, prev_root{};
  GetRequired(j, "t0", m.t0, ctx);
  GetRequired(j, "offset", offset, ctx);
  GetRequired(j, "countdown", m.countdown, ctx);
  GetRequired(j, "prev_distance", m.prev_distance, ctx);
  GetRequired(j, "redrawn", m.redrawn, ctx);
  GetRequired(j, "reached", m.reached, ctx);
  GetRequired(j, "targets_reached", m.targets_reached, ctx);
  GetRequired(j, "target_drawn_dist_m", m.target_drawn_dist_m, ctx);
  GetRequired(j, "prev_q", m.prev_q, ctx);
  GetRequired(j, "prev_root", prev_root, ctx);
  m.offset = Eigen::Vector3d(offset[0], offset[1], offset[2]);
  m.prev_root = Eigen::Vector3d(prev_root[0], prev_root[1], prev_root[2]);
  m_ = m;
}

}  // namespace perch
