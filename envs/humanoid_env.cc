#include "envs/humanoid_env.h"

#include <algorithm>
#include <cassert>
#include <cmath>

#include "common/npz.h"
#include "envs/chair_grid.h"
#include "envs/chair_random.h"
#include "envs/spawn.h"

namespace perch {
namespace {

// Backward pelvis tilt of SeatedPose [rad]: enough for the butt capsule to reach below the thighs.
constexpr double kSeatedPelvisTilt = 0.8;

float Clip(double v, double c) {
  if (!std::isfinite(v)) return 0.0f;  // non-finite values are flagged invalid, never passed on
  return static_cast<float>(std::clamp(v, -c, c));
}

HumanoidState LoadInitPose(const EnvConfig& c, const HumanoidModel& model) {
  if (c.init.qpos_file.empty()) return StandingPose(model, c.init.standing_clearance);
  const std::string path = c.QposPath();
  const auto arrays = LoadNpz(path);
  const auto it = arrays.find(c.init.qpos_array);
  if (it == arrays.end()) {
    throw ConfigError(path + ": no array '" + c.init.qpos_array + "' (config init.qpos_array)");
  }
  const NpyArray& a = it->second;
  if (a.shape.empty() || a.shape.back() != 51) {
    throw ConfigError(path + ": array '" + c.init.qpos_array + "' is not a 51-column qpos array");
  }
  const int64_t rows = a.size() / 51;
  if (c.init.qpos_row >= rows) {
    throw ConfigError(path + ": init.qpos_row " + std::to_string(c.init.qpos_row) + " beyond " +
                      std::to_string(rows) + " rows");
  }
  return StateFromQpos(a.values.data() + 51 * c.init.qpos_row);
}

Chair RandomChair(const ChairRandomConfig& c, Rng& rng) {
  return Chair::FromJson(RandomChairJson(c, rng), "chair_random");
}

}  // namespace

Json RandomChairJson(const ChairRandomConfig& c, Rng& rng, const std::string& name) {
  auto draw = [&](const std::array<double, 2>& r) { return rng.Uniform(r[0], r[1]); };
  Json p{{"seat_height", draw(c.seat_height)},
         {"seat_width", draw(c.seat_width)},
         {"seat_depth", draw(c.seat_depth)},
         {"seat_thickness", draw(c.seat_thickness)},
         {"leg_size", draw(c.leg_size)}};
  const bool back = rng.Uniform(0.0, 1.0) < c.backrest_prob;
  const double back_h = draw(c.backrest_height);
  const bool arms = rng.Uniform(0.0, 1.0) < c.armrest_prob;
  const double arm_h = draw(c.armrest_height);
  p["backrest_height"] = back ? back_h : 0.0;
  p["armrest_height"] = arms ? arm_h : 0.0;
  return Json{{"name", name}, {"parametric", p}, {"mass", c.mass}, {"dynamic", c.dynamic}};
}

// ---- stand task ------------------------------------------------------------------------------

class StandTask : public Task {
 public:
  explicit StandTask(const StandTaskConfig& c) : c_(c) {}
  const char* name() const override { return "stand"; }
  int max_episode_steps() const override { return c_.max_episode_steps; }
  void OnReset(HumanoidChairEnv& env, Rng& rng) override {
    env.SetWalkTarget(Eigen::Vector2d(c_.walk_target[0], c_.walk_target[1]));
  }
  TaskStep OnStep(const HumanoidChairEnv& env, const float* action) override {
    TaskStep r;
    const HumanoidState& s = env.humanoid_state();
    const double up_z = (s.root_quat * Eigen::Vector3d::UnitZ()).z();
    double a2 = 0.0;
    const int n = env.model().num_joints();
    for (int i = 0; i < n; ++i) a2 += static_cast<double>(action[i]) * action[i];
    r.terminated = s.root_pos.z() < c_.min_torso_z;
    r.reward =
        static_cast<float>(c_.alive_bonus + c_.upright_weight * up_z - c_.action_cost * a2 / n);
    return r;
  }

 private:
  StandTaskConfig c_;
};

std::unique_ptr<Task> MakeTask(const EnvConfig& config) {
  if (config.task == "stand") return std::make_unique<StandTask>(config.stand);
  throw ConfigError("task: \"" + config.task +
                    "\" is not built by envs/; tasks/ builds it (MakeTaskEnv, tasks/task_env.h)");
}

// ---- poses -----------------------------------------------------------------------------------

HumanoidState StandingPose(const HumanoidModel& model, double clearance) {
  HumanoidState s;
  for (int j = 0; j < model.num_joints(); ++j) {
    s.q[j] = std::clamp(0.0, model.joint(j).lower, model.joint(j).upper);
  }
  const FkResult fk =
      ForwardKinematics(model, Eigen::Vector3d::Zero(), Eigen::Quaterniond::Identity(), s.q.data());
  s.root_pos = Eigen::Vector3d(0, 0, clearance - LowestGeomZ(model, fk));
  return s;
}

HumanoidState SeatedPose(const HumanoidModel& model, const Chair& chair,
                         const ChairPlacement& placement, double clearance) {
  HumanoidState s;
  for (int j = 0; j < model.num_joints(); ++j) {
    s.q[j] = std::clamp(0.0, model.joint(j).lower, model.joint(j).upper);
  }
  // The pelvis tilts back (abdomen flexed) so that the butt, not only the thighs, rests on the
  // seat; the hips flex less by the same angle, keeping the thighs level and the shins vertical.
  const double tilt = kSeatedPelvisTilt;
  s.q[model.FindJoint("abdomen_y")] = -tilt;
  for (const char* name : {"right_hip_y", "left_hip_y"})
    s.q[model.FindJoint(name)] = -M_PI / 2 + tilt;
  for (const char* name : {"right_knee", "left_knee"}) s.q[model.FindJoint(name)] = -M_PI / 2;
  // Lowest point of the pelvis and thighs `clearance` above the seat top; pelvis over the target.
  const FkResult fk =
      ForwardKinematics(model, Eigen::Vector3d::Zero(), Eigen::Quaterniond::Identity(), s.q.data());
  const int pelvis = model.pelvis_body();
  double low = 1e9;
  for (int b : {pelvis, model.FindBody("right_thigh"), model.FindBody("left_thigh")}) {
    for (const Geom& g : model.body(b).geoms) {
      low = std::min(
          low, std::min((fk.body_world[b] * g.from).z(), (fk.body_world[b] * g.to).z()) - g.radius);
    }
  }
  const Eigen::Vector3d pelvis_pos = fk.body_world[pelvis].translation();
  double x = chair.seat_target.x() - pelvis_pos.x();
  // Keep the trunk in front of a backrest: rearmost point of torso, lwaist and pelvis.
  if (const std::optional<double> back = chair.backrest_front_x()) {
    double rear = 1e9;
    for (int b : {0, model.FindBody("lwaist"), pelvis}) {
      for (const Geom& g : model.body(b).geoms) {
        rear = std::min(
            rear,
            std::min((fk.body_world[b] * g.from).x(), (fk.body_world[b] * g.to).x()) - g.radius);
      }
    }
    x = std::max(x, *back + clearance - rear);
  }
  s.root_pos = Eigen::Vector3d(x, chair.seat_target.y() - pelvis_pos.y(),
                               chair.seat_height() + clearance - low);
  return TransformHorizontally(s, placement.yaw, placement.x, placement.y);
}

// ---- env -------------------------------------------------------------------------------------

HumanoidChairEnv::HumanoidChairEnv(const EnvConfig& config) : HumanoidChairEnv(config, nullptr) {}

HumanoidChairEnv::HumanoidChairEnv(const EnvConfig& config, std::unique_ptr<Task> task)
    : config_(config), model_(HumanoidModel::Load(config.HumanoidPath())) {
  const std::string chair_path = config_.ChairPath();
  if (!chair_path.empty()) chair_ = std::make_unique<Chair>(Chair::Load(chair_path));
  UpdateChairGrid();
  world_ = std::make_unique<World>(model_, chair_.get(), config_.chair_placement, config_.physics);
  task_ = task ? std::move(task) : MakeTask(config_);
  init_pose_ = LoadInitPose(config_, model_);
  body_pos_.resize(model_.num_bodies());
  pd_ = std::make_unique<PdController>(model_, config_.physics.physics_dt, config_.pd_implicit);
  BuildSpec();
}

HumanoidChairEnv::~HumanoidChairEnv() = default;

MirrorMap BuildMirrorMap(const HumanoidModel& model, ObsLayout layout, ActionMode mode) {
  std::vector<int> c;
  std::vector<double> sign;
  MirrorJointMap(model, &c, &sign);
  MirrorMap m;
  const int obs_dim = ObsLayoutDim(layout);
  m.obs_src.resize(obs_dim);
  m.obs_scale.assign(obs_dim, 1.0f);
  m.obs_offset.assign(obs_dim, 0.0f);
  for (int i = 0; i < obs_dim; ++i) m.obs_src[i] = i;
  // more(6): height, roll, pitch, heading-frame velocity: roll and the sideways speed flip.
  m.obs_scale[kObsMore + 1] = -1.0f;
  m.obs_scale[kObsMore + 4] = -1.0f;
  // joints(42): q' of joint c(j) = sign_j q_j; in normalised units q_n = (q - mid) / half-range,
  // so q_n' = sign hr_j / hr_c q_n + (sign mid_j - mid_c) / hr_c (exactly +-q_n for mirrored
  // limits).
  for (int j = 0; j < model.num_joints(); ++j) {
    const Joint& a = model.joint(j);
    const Joint& b = model.joint(c[j]);
    const double hr_a = 0.5 * (a.upper - a.lower), hr_b = 0.5 * (b.upper - b.lower);
    const int dst = kObsJoints + 2 * c[j], src = kObsJoints + 2 * j;
    m.obs_src[dst] = src;
    m.obs_scale[dst] = static_cast<float>(sign[j] * hr_a / hr_b);
    m.obs_offset[dst] = static_cast<float>((sign[j] * a.mid() - b.mid()) / hr_b);
    m.obs_src[dst + 1] = src + 1;
    m.obs_scale[dst + 1] = static_cast<float>(sign[j]);
  }
  // feet(2): right and left swap.
  m.obs_src[kObsFeet] = kObsFeet + 1;
  m.obs_src[kObsFeet + 1] = kObsFeet;
  if (layout == ObsLayout::kProprioGoal) {
    m.obs_scale[kObsExtra] = -1.0f;  // sin of the target's azimuth; cos unchanged
  } else if (layout == ObsLayout::kProprioChair || layout == ObsLayout::kProprioChairShape) {
    m.obs_scale[kObsExtra + 1] = -1.0f;  // seat target's y in the torso frame
    // Relative quaternion (x, y, z, w): a reflection maps (w, x, y, z) to (w, -x, y, -z).
    m.obs_scale[kObsExtra + 3] = -1.0f;
    m.obs_scale[kObsExtra + 5] = -1.0f;
  }
  if (layout == ObsLayout::kProprioChairShape) {
    // shape(25): the chair's left and right swap (grid columns reversed).
    for (int k = 0; k < kChairGridDim; ++k)
      m.obs_src[kObsShape + MirroredGridIndex(k)] = kObsShape + k;
  }
  // Actions in action order: torque max_torque clip(a), or a PD target mid + a half-range.
  const int nj = model.num_joints();
  m.act_src.resize(nj);
  m.act_scale.assign(nj, 1.0f);
  m.act_offset.assign(nj, 0.0f);
  for (int j = 0; j < nj; ++j) {
    const Joint& a = model.joint(j);
    const Joint& b = model.joint(c[j]);
    const int dst = b.action_index, src = a.action_index;
    m.act_src[dst] = src;
    if (mode == ActionMode::kPd) {
      const double hr_a = 0.5 * (a.upper - a.lower), hr_b = 0.5 * (b.upper - b.lower);
      m.act_scale[dst] = static_cast<float>(sign[j] * hr_a / hr_b);
      m.act_offset[dst] = static_cast<float>((sign[j] * a.mid() - b.mid()) / hr_b);
    } else {
      m.act_scale[dst] = static_cast<float>(sign[j] * a.max_torque / b.max_torque);
    }
  }
  return m;
}

HumanoidState MirrorHumanoidState(const HumanoidState& s, const HumanoidModel& model) {
  std::vector<int> c;
  std::vector<double> sign;
  MirrorJointMap(model, &c, &sign);
  HumanoidState o = s;
  o.root_pos = MirrorPolar(s.root_pos);
  o.root_quat = MirrorRotation(s.root_quat);
  o.root_lin_vel = MirrorPolar(s.root_lin_vel);
  o.root_ang_vel = MirrorAxial(s.root_ang_vel);
  for (int j = 0; j < model.num_joints(); ++j) {
    o.q[c[j]] = sign[j] * s.q[j];
    o.qd[c[j]] = sign[j] * s.qd[j];
  }
  return o;
}

void HumanoidChairEnv::BuildSpec() {
  spec_.name = std::string("humanoid_chair_") + task_->name();
  const ObsLayout layout = config_.obs_layout;
  spec_.obs_dim = ObsLayoutDim(layout);
  spec_.act_dim = model_.num_joints();
  spec_.obs_low.assign(spec_.obs_dim, static_cast<float>(-config_.obs.clip));
  spec_.obs_high.assign(spec_.obs_dim, static_cast<float>(config_.obs.clip));
  spec_.act_low.assign(spec_.act_dim, -1.0f);
  spec_.act_high.assign(spec_.act_dim, 1.0f);
  spec_.obs_slices = {{"more", kObsMore, kObsJoints - kObsMore},
                      {"joints", kObsJoints, kObsFeet - kObsJoints},
                      {"feet", kObsFeet, kObsExtra - kObsFeet}};
  if (layout == ObsLayout::kProprioChair || layout == ObsLayout::kProprioChairShape) {
    spec_.obs_slices.push_back({"chair", kObsExtra, 7});
  }
  if (layout == ObsLayout::kProprioChairShape) {
    spec_.obs_slices.push_back({"shape", kObsShape, kChairGridDim});
  }
  if (layout == ObsLayout::kProprioGoal) spec_.obs_slices.push_back({"goal", kObsExtra, 2});
  spec_.control_dt = config_.physics.physics_dt * config_.physics.substeps;
  spec_.max_episode_steps = task_->max_episode_steps();
  spec_.has_success = task_->has_success();
  spec_.mirror = BuildMirrorMap(model_, layout, config_.action_mode);
}

void HumanoidChairEnv::UpdateChairGrid() {
  chair_grid_.fill(0.0f);
  if (chair_) chair_grid_ = ChairHeightGrid(*chair_, config_.obs.chair_grid_spacing);
}

void HumanoidChairEnv::Reset(float* obs) {
  // The coin is only tossed when random chairs are on, so other runs draw as before.
  if (chair_ && config_.chair_random.prob > 0) {
    if (!base_chair_) {
      base_chair_ = std::make_unique<Chair>(*chair_);
      base_chair_grid_ = ChairHeightGrid(*base_chair_, config_.obs.chair_grid_spacing);
    }
    if (rng_.Uniform(0.0, 1.0) < config_.chair_random.prob) {
      // The second coin and the file's draw only when files are given, so runs without them
      // draw as before.
      const auto& files = config_.chair_random.files;
      if (!files.empty() && rng_.Uniform(0.0, 1.0) < config_.chair_random.files_prob) {
        if (file_chairs_.empty()) {
          for (const std::string& f : files) {
            file_chairs_.push_back(Chair::Load(EnvConfig::ChairFilePath(f)));
            file_chair_grids_.push_back(
                ChairHeightGrid(file_chairs_.back(), config_.obs.chair_grid_spacing));
          }
        }
        const int k = std::min(static_cast<int>(rng_.Uniform(0.0, 1.0) * file_chairs_.size()),
                               static_cast<int>(file_chairs_.size()) - 1);
        chair_ = std::make_unique<Chair>(file_chairs_[k]);
        chair_grid_ = file_chair_grids_[k];
      } else {
        chair_ = std::make_unique<Chair>(RandomChair(config_.chair_random, rng_));
        UpdateChairGrid();  // boxes: cheap
      }
    } else {
      chair_ = std::make_unique<Chair>(*base_chair_);
      chair_grid_ = base_chair_grid_;
    }
    world_->SetChair(chair_.get());
  }
  // Per-episode physics scales (env.randomize), drawn only when a range is set.
  const DomainRandomConfig& dr = config_.randomize;
  if (dr.friction_scale[0] != 1.0 || dr.friction_scale[1] != 1.0 || dr.mass_scale[0] != 1.0 ||
      dr.mass_scale[1] != 1.0) {
    const double f = rng_.Uniform(dr.friction_scale[0], dr.friction_scale[1]);
    const double m = rng_.Uniform(dr.mass_scale[0], dr.mass_scale[1]);
    world_->SetDynamicsScales(f, m);
  }
  HumanoidState chosen;
  if (task_->InitialState(*this, rng_, &chosen)) {
    ResetToState(chosen, obs);
    return;
  }
  const SpawnPose spawn = SampleSpawn(config_.spawn, rng_);
  ResetToState(PlaceAtSpawn(init_pose_, spawn, config_.chair_placement), obs);
}

void HumanoidChairEnv::ResetFromQpos(const double* qpos51, float* obs) {
  ResetToState(StateFromQpos(qpos51), obs);
}

void HumanoidChairEnv::ResetToState(const HumanoidState& s, float* obs) {
  world_->SetState(s);
  step_ = 0;
  push_steps_left_ = 0;
  pushes_ = 0;
  foot_flags_ = {false, false};  // authors: zeros right after reset
  tau_.fill(0.0);
  AfterPhysics();
  task_->OnReset(*this, rng_);
  WriteObs(obs);
}

EnvState HumanoidChairEnv::GetState() const {
  EnvState s;
  s.world = world_->GetState();
  s.foot_flags = foot_flags_;
  s.shown_flags = shown_flags_;
  s.step = step_;
  s.walk_target = walk_target_;
  return s;
}

void HumanoidChairEnv::SetState(const EnvState& s) {
  world_->SetState(s.world);  // ends a push: pushes are a training perturbation, not state
  push_steps_left_ = 0;
  foot_flags_ = s.foot_flags;
  if (s.shown_flags) shown_flags_ = *s.shown_flags;
  step_ = s.step;
  walk_target_ = s.walk_target;
  AfterPhysics();
}

void HumanoidChairEnv::HoldPoseAction(const double* q, float* action) const {
  for (int a = 0; a < model_.num_joints(); ++a) {
    const int j = model_.action_to_joint()[a];
    action[a] = static_cast<float>(std::clamp(model_.joint(j).Normalize(q[j]), -1.0, 1.0));
  }
}

void HumanoidChairEnv::ComputePdTorques(const float* a) {
  double q[HumanoidModel::kNumJoints], qd[HumanoidModel::kNumJoints];
  world_->ReadJoints(q, qd);
  pd_->Torques(a, q, qd, tau_.data());
}

void HumanoidChairEnv::UpdatePush() {
  const PushConfig& p = config_.push;
  if (push_steps_left_ > 0 && --push_steps_left_ == 0)
    world_->SetRootForce(Eigen::Vector3d::Zero());
  // The RNG is drawn from only when pushes are on, so runs without them draw as before.
  if (p.rate_hz <= 0.0 || push_steps_left_ > 0) return;
  const double dt = config_.physics.physics_dt * config_.physics.substeps;
  const double t = step_ * dt;
  if (t < p.delay_s || (p.until_s > 0.0 && t >= p.until_s)) return;
  if (rng_.Uniform() >= p.rate_hz * dt) return;
  const double force = rng_.Uniform(p.force_min_n, p.force_max_n);
  const double angle = rng_.Uniform(-M_PI, M_PI);
  world_->SetRootForce(Eigen::Vector3d(force * std::cos(angle), force * std::sin(angle), 0.0));
  push_steps_left_ = std::max(1, static_cast<int>(std::lround(p.duration_s / dt)));
  ++pushes_;
}

void HumanoidChairEnv::StartPush(const Eigen::Vector3d& force_n, int steps) {
  world_->SetRootForce(force_n);
  // UpdatePush counts the step about to run down first, so the force lasts `steps` steps.
  push_steps_left_ = std::max(1, steps) + 1;
  ++pushes_;
}

StepResult HumanoidChairEnv::Step(const float* action, float* obs) {
  UpdatePush();
  const int n = model_.num_joints();
  const double act_noise = config_.randomize.act_noise_std;
  for (int i = 0; i < n; ++i) {
    float a = action[i];
    if (act_noise > 0.0) a += static_cast<float>(rng_.Normal(0.0, act_noise));
    action_clipped_[i] = std::isfinite(a) ? std::clamp(a, -1.0f, 1.0f) : 0.0f;
  }
  if (config_.action_mode == ActionMode::kTorque) {
    for (int i = 0; i < n; ++i) {
      const int j = model_.action_to_joint()[i];
      tau_[j] = model_.joint(j).max_torque * action_clipped_[i];
    }
    world_->SetJointTorques(tau_.data());
    for (int s = 0; s < config_.physics.substeps; ++s) world_->StepPhysics();
  } else {
    for (int s = 0; s < config_.physics.substeps; ++s) {
      ComputePdTorques(action_clipped_.data());
      world_->SetJointTorques(tau_.data());
      world_->StepPhysics();
    }
  }
  ++step_;
  AfterPhysics();
  StepResult r;
  if (StateInvalid()) {
    r.invalid = true;
    r.terminated = true;
    r.reward = 0.0f;
    WriteObs(obs);
    return r;
  }
  task_->BeforeObservation(*this, rng_);
  WriteObs(obs);  // builds with the previous step's foot flags when lagged
  const TaskStep t = task_->OnStep(*this, action);
  r.reward = t.reward;
  r.terminated = t.terminated;
  r.success = t.success;
  r.truncated = !r.terminated && step_ >= task_->max_episode_steps();
  return r;
}

void HumanoidChairEnv::AfterPhysics() {
  const WorldState ws = world_->GetState();
  state_ = ws.humanoid;
  rpy_ = RpyFromQuat(state_.root_quat);
  for (int b = 0; b < model_.num_bodies(); ++b) body_pos_[b] = world_->BodyPose(b).translation();
  contacts_ = world_->ReadContacts();
}

bool HumanoidChairEnv::StateInvalid() const {
  const SafetyConfig& c = config_.safety;
  const HumanoidState& s = state_;
  if (!s.root_pos.allFinite() || !s.root_lin_vel.allFinite() || !s.root_ang_vel.allFinite() ||
      !s.root_quat.coeffs().allFinite()) {
    return true;
  }
  if (s.root_pos.cwiseAbs().maxCoeff() > c.max_abs_position) return true;
  if (s.root_lin_vel.norm() > c.max_root_speed || s.root_ang_vel.norm() > c.max_root_ang_speed) {
    return true;
  }
  for (int j = 0; j < model_.num_joints(); ++j) {
    if (!std::isfinite(s.q[j]) || !std::isfinite(s.qd[j]) ||
        std::abs(s.qd[j]) > c.max_joint_speed) {
      return true;
    }
  }
  return false;
}

double HumanoidChairEnv::SeatContactMaxPelvisZ() const {
  constexpr double kAuthorsSeatHeight = 0.4029;  // the top of the authors' seat (notes 5) [m]
  if (!config_.seat_contact_relative || !chair_) return config_.seat_contact_max_pelvis_z;
  return config_.seat_contact_max_pelvis_z - kAuthorsSeatHeight + chair_->seat_height();
}

bool HumanoidChairEnv::PelvisSeatContact() const {
  return contacts_.pelvis_chair && PelvisPosition().z() < SeatContactMaxPelvisZ();
}

double HumanoidChairEnv::PelvisSeatDistance() const {
  return (PelvisPosition() - world_->SeatTargetWorld()).norm();
}

Eigen::Vector3d HumanoidChairEnv::BodyXyz() const {
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  for (int b = 1; b < model_.num_bodies(); ++b) sum += body_pos_[b].head<2>();
  sum /= (model_.num_bodies() - 1);
  return Eigen::Vector3d(sum.x(), sum.y(), state_.root_pos.z());
}

void HumanoidChairEnv::WriteObs(float* obs) {
  // feet(2): [right, left] floor contact, one step late when lagged (notes 1.5).
  const std::array<bool, 2> now = {contacts_.foot_floor[0], contacts_.foot_floor[1]};
  shown_flags_ = config_.obs.foot_contact_lag ? foot_flags_ : now;
  foot_flags_ = now;
  WriteObservation(config_.obs_layout, obs);
  if (config_.randomize.obs_noise_std > 0.0) {
    for (int i = 0; i < spec_.obs_dim; ++i) {
      obs[i] += static_cast<float>(rng_.Normal(0.0, config_.randomize.obs_noise_std));
    }
  }
}

void HumanoidChairEnv::WriteObservation(ObsLayout layout, float* obs) const {
  const ObsConfig& oc = config_.obs;
  const double clip = oc.clip;
  const HumanoidState& s = state_;
  const double yaw = rpy_.z();
  // more(6): height, roll, pitch, velocity in the heading frame.
  const Eigen::Vector3d v = Eigen::AngleAxisd(-yaw, Eigen::Vector3d::UnitZ()) * s.root_lin_vel;
  int k = 0;
  obs[k++] = Clip(s.root_pos.z() - oc.initial_z, clip);
  obs[k++] = Clip(rpy_.x(), clip);
  obs[k++] = Clip(rpy_.y(), clip);
  for (int i = 0; i < 3; ++i) obs[k++] = Clip(oc.velocity_scale * v[i], clip);
  // joints(42): (q_n, 0.1 qdot) in observation order.
  for (int j = 0; j < model_.num_joints(); ++j) {
    obs[k++] = Clip(model_.joint(j).Normalize(s.q[j]), clip);
    obs[k++] = Clip(oc.joint_speed_scale * s.qd[j], clip);
  }
  assert(k == kObsFeet);
  obs[k++] = shown_flags_[0] ? 1.0f : 0.0f;
  obs[k++] = shown_flags_[1] ? 1.0f : 0.0f;
  if (layout == ObsLayout::kProprioGoal) {
    // goal(2): sin, cos of the walk target's azimuth relative to the heading.
    const Eigen::Vector3d b = BodyXyz();
    const double psi = std::atan2(walk_target_.y() - b.y(), walk_target_.x() - b.x()) - yaw;
    obs[k++] = Clip(std::sin(psi), clip);
    obs[k++] = Clip(std::cos(psi), clip);
  } else if (layout == ObsLayout::kProprioChair || layout == ObsLayout::kProprioChairShape) {
    // chair(7): pelvis -> seat target in the torso frame; conjugate torso quaternion relative to
    // the chair frame (= world for the authors' unrotated chair), x y z w with w >= 0.
    const Eigen::Vector3d p =
        s.root_quat.conjugate() * (world_->SeatTargetWorld() - PelvisPosition());
    for (int i = 0; i < 3; ++i) obs[k++] = Clip(p[i], clip);
    const Eigen::Quaterniond chair_rot(
        Eigen::AngleAxisd(config_.chair_placement.yaw, Eigen::Vector3d::UnitZ()));
    Eigen::Quaterniond rel = (chair_rot.conjugate() * s.root_quat).conjugate();
    if (rel.w() < 0) rel.coeffs() *= -1.0;
    obs[k++] = Clip(rel.x(), clip);
    obs[k++] = Clip(rel.y(), clip);
    obs[k++] = Clip(rel.z(), clip);
    obs[k++] = Clip(rel.w(), clip);
  }
  if (layout == ObsLayout::kProprioChairShape) {
    // shape(25): the chair's height grid (chair frame, fixed per chair).
    for (int i = 0; i < kChairGridDim; ++i) obs[k++] = Clip(chair_grid_[i], clip);
  }
}

std::unique_ptr<Env> MakeEnv(const EnvConfig& config) {
  return std::make_unique<HumanoidChairEnv>(config);
}

}  // namespace perch
