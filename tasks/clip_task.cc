#include "tasks/clip_task.h"

#include <algorithm>
#include <cmath>

#include "envs/spawn.h"

namespace perch {

const FieldTable<EnergyCostConfig>& EnergyCostConfigFields() {
  using C = EnergyCostConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("speed_weight", &C::speed_weight, "x mean |a qdot_n| (3.5 x Roboschool's 2.0)")
          .Add("action_weight", &C::action_weight, "x mean a^2 (3.5 x Roboschool's 0.1)")
          .Rule([](const C& c, const std::string& ctx) {
            return c.speed_weight >= 0 && c.action_weight >= 0 ? std::string()
                                                               : ctx + ": weights must be >= 0";
          });
  return t;
}

EnergyCostConfig EnergyCostConfig::FromJson(const Json& j, const std::string& ctx) {
  return EnergyCostConfigFields().Read(j, ctx);
}

Json EnergyCostConfig::ToJson() const { return EnergyCostConfigFields().Write(*this); }

double EnergyCost(const EnergyCostConfig& c, const HumanoidChairEnv& env, const float* action) {
  const HumanoidModel& model = env.model();
  const HumanoidState& s = env.humanoid_state();
  const int n = model.num_joints();
  const double speed_scale = env.config().obs.joint_speed_scale;
  double power = 0.0, a2 = 0.0;
  for (int i = 0; i < n; ++i) {
    const double a = std::isfinite(action[i]) ? action[i] : 0.0;
    const int j = model.action_to_joint()[i];
    power += std::abs(a * speed_scale * s.qd[j]);
    a2 += a * a;
  }
  return -c.speed_weight * power / n - c.action_weight * a2 / n;
}

const FieldTable<BankStartConfig>& BankStartConfigFields() {
  using C = BankStartConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("banks", &C::banks, "bank files (their union); empty: never")
          .Add("prob", &C::prob, "share of episodes started from a bank state",
               Satisfies<double>([](const double& v) { return v >= 0 && v <= 1; },
                                 "must be in [0, 1]"))
          .Add("zero_root_ang_vel", &C::zero_root_ang_vel,
               "zero the torso's angular velocity (as the authors' restore did)")
          .Add("keep_pose", &C::keep_pose, "keep the state where it was relative to its chair");
  return t;
}

BankStartConfig BankStartConfig::FromJson(const Json& j, const std::string& ctx) {
  return BankStartConfigFields().Read(j, ctx);
}

Json BankStartConfig::ToJson() const { return BankStartConfigFields().Write(*this); }

MotionPose ClipPlacement::Apply(const MotionPose& p) const {
  const Eigen::AngleAxisd rz(yaw, Eigen::Vector3d::UnitZ());
  MotionPose out = p;
  out.root_pos = rz * p.root_pos + offset;
  out.root_rot = Eigen::Quaterniond(rz) * p.root_rot;
  out.root_vel = rz * p.root_vel;
  out.root_angvel = rz * p.root_angvel;
  if (descent_dz != 0.0 && z_top > z_bottom) {
    const double w = std::clamp((z_top - p.root_pos.z()) / (z_top - z_bottom), 0.0, 1.0);
    out.root_pos.z() += descent_dz * w;
    // d/dt of the shift (inside the descent only).
    if (w > 0.0 && w < 1.0) out.root_vel.z() -= descent_dz * p.root_vel.z() / (z_top - z_bottom);
  }
  return out;
}

ClipTask::ClipTask(const std::string& motion_path, double control_dt)
    : motion_(ReferenceMotion::Load(motion_path)), dt_(control_dt) {
  if (motion_.num_frames() < 2 || motion_.frame(0).q.size() != HumanoidModel::kNumJoints) {
    throw ConfigError(motion_path + ": a reference clip needs >= 2 frames of " +
                      std::to_string(HumanoidModel::kNumJoints) + " joint angles");
  }
  if (motion_.loop()) {
    throw ConfigError(motion_path + ": a looping clip; turn and sit follow a clip once");
  }
}

MotionPose ClipTask::ReferenceAt(int step) const {
  const double t = m_.t0 + step * dt_;
  MotionPose p = motion_.At(t);   // clamps to the last frame
  if (t >= motion_.duration()) {  // the held last frame stands still
    p.qdot.setZero();
    p.root_vel.setZero();
    p.root_angvel.setZero();
  }
  return m_.placement.Apply(p);
}

int ClipTask::ClipEndStep() const {
  return std::max(0, static_cast<int>(std::ceil((motion_.duration() - m_.t0) / dt_ - 1e-9)));
}

HumanoidState ClipTask::StartState(const ClipPlacement& placement, double t0,
                                   bool zero_joint_speeds) {
  const MotionPose p = placement.Apply(motion_.At(t0));
  HumanoidState s;
  s.root_pos = p.root_pos;
  s.root_quat = p.root_rot;
  s.root_lin_vel = p.root_vel;
  s.root_ang_vel = p.root_angvel;
  for (int j = 0; j < HumanoidModel::kNumJoints; ++j) {
    s.q[j] = p.q[j];
    s.qd[j] = zero_joint_speeds ? 0.0 : p.qdot[j];
  }
  return s;
}

ClipTask::Similarity ClipTask::ComputeSimilarity(const SimilarityRewardConfig& c,
                                                 const HumanoidChairEnv& env, int k) const {
  const HumanoidState& s = env.humanoid_state();
  const MotionPose ref = ReferenceAt(k);
  MotionPose ref_prev;
  if (c.finite_difference_velocities) ref_prev = ReferenceAt(k - 1);
  return SimilarityTermsAt(c, s.q.data(), m_.prev_q.data(), s.qd.data(), ref.q.data(),
                           ref_prev.q.data(), ref.qdot.data(), HumanoidModel::kNumJoints, dt_);
}

void ClipTask::RootVelocities(bool fd, const HumanoidChairEnv& env, int k, Eigen::Vector3d* v,
                              Eigen::Vector3d* v_ref) const {
  const HumanoidState& s = env.humanoid_state();
  const MotionPose ref = ReferenceAt(k);
  if (fd) {
    *v = (s.root_pos - m_.prev_root) / dt_;
    *v_ref = (ref.root_pos - ReferenceAt(k - 1).root_pos) / dt_;
  } else {
    *v = s.root_lin_vel;
    *v_ref = ref.root_vel;
  }
}

void ClipTask::PerturbJoints(double rad, const HumanoidChairEnv& env, Rng& rng, HumanoidState* s) {
  if (!(rad > 0)) return;  // no draws when off, so other runs keep their streams
  const HumanoidModel& m = env.model();
  for (int j = 0; j < m.num_joints(); ++j) {
    s->q[j] = std::clamp(s->q[j] + rng.Uniform(-rad, rad), m.joint(j).lower, m.joint(j).upper);
  }
}

bool DrawBankStart(const BankStartConfig& c, const HumanoidChairEnv& env, Rng& rng,
                   std::optional<double> yaw, const Eigen::Vector2d& xy,
                   std::shared_ptr<const StartBank>* cache, HumanoidState* s) {
  if (c.banks.empty()) return false;
  // The coin first, so the draws do not depend on whether the bank is loaded.
  if (!(rng.Uniform(0.0, 1.0) < c.prob)) return false;
  if (!*cache) *cache = LoadStartBanks(c.banks, env.model());
  const proto::BankState& b = (*cache)->states[rng.UniformInt((*cache)->states.size())];
  HumanoidState h = HumanoidStateOf(b);
  if (c.keep_pose) {
    if (!b.has_chair()) {
      throw ConfigError("start.keep_pose: bank states without a chair (sample them in the chain)");
    }
    // From the bank's chair frame to this env's chair placement (yaw and ground position).
    const ChairPlacement& to = env.config().chair_placement;
    const Eigen::Quaterniond cq(b.chair_quat().w(), b.chair_quat().x(), b.chair_quat().y(),
                                b.chair_quat().z());
    const double turn = to.yaw - RpyFromQuat(cq).z();
    h.root_pos.x() -= b.chair_pos().x();
    h.root_pos.y() -= b.chair_pos().y();
    h = TransformHorizontally(h, turn, to.x, to.y);
    if (c.zero_root_ang_vel) h.root_ang_vel.setZero();
    *s = h;
    return true;
  }
  const double turn = yaw.has_value() ? *yaw - RpyFromQuat(h.root_quat).z() : 0.0;
  const Eigen::AngleAxisd rz(turn, Eigen::Vector3d::UnitZ());
  h.root_quat = (Eigen::Quaterniond(rz) * h.root_quat).normalized();
  h.root_lin_vel = rz * h.root_lin_vel;
  h.root_ang_vel =
      c.zero_root_ang_vel ? Eigen::Vector3d::Zero() : Eigen::Vector3d(rz * h.root_ang_vel);
  h.root_pos.x() = xy.x();
  h.root_pos.y() = xy.y();
  *s = h;
  return true;
}

bool ClipTask::BankStart(const BankStartConfig& c, const HumanoidChairEnv& env, Rng& rng,
                         double yaw, const Eigen::Vector2d& xy, HumanoidState* s) {
  from_bank_ = DrawBankStart(c, env, rng, yaw, xy, &bank_, s);
  return from_bank_;
}

Json ClipTask::SaveMemory() const {
  const ClipPlacement& p = m_.placement;
  return Json{{"yaw", p.yaw},
              {"offset", {p.offset.x(), p.offset.y(), p.offset.z()}},
              {"descent_dz", p.descent_dz},
              {"z_top", p.z_top},
              {"z_bottom", p.z_bottom},
              {"t0", m_.t0},
              {"prev_q", m_.prev_q},
              {"prev_root", {m_.prev_root.x(), m_.prev_root.y(), m_.prev_root.z()}},
              {"prev_distance", m_.prev_distance}};
}

void ClipTask::LoadMemory(const Json& j) {
  const std::string ctx = std::string(name()) + " task memory";
  Memory m;
  std::array<double, 3> offset{}, prev_root{};
  GetRequired(j, "yaw", m.placement.yaw, ctx);
  GetRequired(j, "offset", offset, ctx);
  GetRequired(j, "descent_dz", m.placement.descent_dz, ctx);
  GetRequired(j, "z_top", m.placement.z_top, ctx);
  GetRequired(j, "z_bottom", m.placement.z_bottom, ctx);
  GetRequired(j, "t0", m.t0, ctx);
  GetRequired(j, "prev_q", m.prev_q, ctx);
  GetRequired(j, "prev_root", prev_root, ctx);
  GetRequired(j, "prev_distance", m.prev_distance, ctx);
  m.placement.offset = Eigen::Vector3d(offset[0], offset[1], offset[2]);
  m.prev_root = Eigen::Vector3d(prev_root[0], prev_root[1], prev_root[2]);
  m_ = m;
}

void ClipTask::RememberPose(const HumanoidChairEnv& env) {
  m_.prev_q = env.humanoid_state().q;
  m_.prev_root = env.humanoid_state().root_pos;
}

}  // namespace perch
