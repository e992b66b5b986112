#include "motion/retarget.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "common/field_table.h"

namespace perch {

const char* const kCmuAcknowledgement =
    "The data used in this project was obtained from mocap.cs.cmu.edu. The database was created "
    "with funding from NSF EIA-0196217.";

const char* const kKeyPointNames[kNumKeyPoints] = {
    "pelvis",      "right_hip",   "right_knee",      "right_ankle", "right_toe",
    "left_hip",    "left_knee",   "left_ankle",      "left_toe",    "right_shoulder",
    "right_elbow", "right_wrist", "left_shoulder",   "left_elbow",  "left_wrist",
    "head",        "right_heel",  "right_toe_outer", "left_heel",   "left_toe_outer"};

namespace {

enum Key {
  kPelvis = 0,
  kRHip,
  kRKnee,
  kRAnkle,
  kRToe,
  kLHip,
  kLKnee,
  kLAnkle,
  kLToe,
  kRShoulder,
  kRElbow,
  kRWrist,
  kLShoulder,
  kLElbow,
  kLWrist,
  kHead,
  kRHeel,
  kRToeOut,
  kLHeel,
  kLToeOut
};

// Source (cgspeed CMU) joints whose positions/rotations define the targets.
struct SourceJoints {
  int hips, spine1, head;
  int up_leg[2], leg[2], foot[2], arm[2], fore_arm[2], hand[2];  // [right, left]
};

int Need(const BvhClip& c, const std::string& name) {
  const int i = c.Find(name);
  if (i < 0)
    throw ConfigError("BVH skeleton lacks joint '" + name + "' (cgspeed CMU layout expected)");
  return i;
}

SourceJoints FindSourceJoints(const BvhClip& c) {
  SourceJoints s;
  s.hips = Need(c, "Hips");
  s.spine1 = Need(c, "Spine1");
  s.head = Need(c, "Head");
  const char* side[2] = {"Right", "Left"};
  for (int k = 0; k < 2; ++k) {
    const std::string p = side[k];
    s.up_leg[k] = Need(c, p + "UpLeg");
    s.leg[k] = Need(c, p + "Leg");
    s.foot[k] = Need(c, p + "Foot");
    s.arm[k] = Need(c, p + "Arm");
    s.fore_arm[k] = Need(c, p + "ForeArm");
    s.hand[k] = Need(c, p + "Hand");
  }
  return s;
}

// BVH (Y up, facing +Z, left = +X) to humanoid world (Z up, facing +X, left = +Y).
Eigen::Matrix3d Perm() {
  Eigen::Matrix3d p;
  p << 0, 0, 1, 1, 0, 0, 0, 1, 0;
  return p;
}

double Yaw(const Eigen::Matrix3d& r) {
  const Eigen::Vector3d f = r.col(0);
  return std::atan2(f.y(), f.x());
}

Eigen::VectorXd TPoseFrame(const BvhClip& c, const std::map<std::string, Eigen::Vector3d>& zyx) {
  Eigen::VectorXd v = Eigen::VectorXd::Zero(c.num_channels);
  for (const auto& [name, deg] : zyx) {
    const int j = c.Find(name);
    if (j < 0) continue;
    const BvhJoint& jt = c.joints[j];
    for (size_t k = 0; k < jt.channels.size(); ++k) {
      const int col = jt.first_channel + static_cast<int>(k);
      if (jt.channels[k] == BvhChannel::kZrot) v[col] = deg[0];
      if (jt.channels[k] == BvhChannel::kYrot) v[col] = deg[1];
      if (jt.channels[k] == BvhChannel::kXrot) v[col] = deg[2];
    }
  }
  return v;
}

// cgspeed T-pose (mocap README): all rotations 0 except these (Z, Y, X degrees).
const std::map<std::string, Eigen::Vector3d>& TPoseAngles() {
  static const std::map<std::string, Eigen::Vector3d> m = {
      {"LeftUpLeg", {-21, 0, 0}}, {"RightUpLeg", {21, 0, 0}}, {"Neck", {0, 0, -16}},
      {"Neck1", {0, 0, 21}},      {"Head", {0, 0, 11}},       {"LeftArm", {-8, 0, 0}},
      {"RightArm", {8, 0, 0}}};
  return m;
}

Eigen::Vector3d CatmullRom(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                           const Eigen::Vector3d& p2, const Eigen::Vector3d& p3, double u) {
  const double u2 = u * u, u3 = u2 * u;
  return 0.5 * ((2 * p1) + (-p0 + p2) * u + (2 * p0 - 5 * p1 + 4 * p2 - p3) * u2 +
                (-p0 + 3 * p1 - 3 * p2 + p3) * u3);
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

Eigen::VectorXd KeyWeights(const RetargetConfig& cfg) {
  Eigen::VectorXd w = Eigen::VectorXd::Ones(kNumKeyPoints);
  for (int k : {kRAnkle, kRToe, kLAnkle, kLToe, kRHeel, kRToeOut, kLHeel, kLToeOut}) {
    w[k] = cfg.foot_weight;
  }
  return w;
}

// Rigid transform of the horizontal plane: p -> Rz(yaw) p + t.
struct Planar {
  double yaw = 0.0;
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d Apply(const Eigen::Vector3d& p) const {
    return Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * p + t;
  }
  Eigen::Quaterniond Rot() const {
    return Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
  }
};

Eigen::Matrix3Xd ApplyPlanar(const Planar& pl, const Eigen::Matrix3Xd& m) {
  Eigen::Matrix3Xd o = m;
  for (int k = 0; k < m.cols(); ++k) o.col(k) = pl.Apply(m.col(k));
  return o;
}

}  // namespace

// ---------------------------------------------------------------- config

const FieldTable<ClipSpec>& ClipSpecFields() {
  using C = ClipSpec;
  static const FieldTable<C> t =
      FieldTable<C>()
          .CustomAlways(
              "name", "output clip data/motions/NAME.json (required)",
              [](const Json& j, C& c, const std::string& ctx) {
                GetRequired(j, "name", c.name, ctx);
              },
              [](const C& c, Json& j) { j["name"] = c.name; })
          .CustomAlways(
              "bvh", "source BVH file name (required)",
              [](const Json& j, C& c, const std::string& ctx) {
                GetRequired(j, "bvh", c.bvh, ctx);
              },
              [](const C& c, Json& j) { j["bvh"] = c.bvh; })
          .Add("description", &C::description, "what the clip is and where it comes from")
          .Add("first_frame", &C::first_frame, "first source frame (inclusive)", NonNegative<int>())
          .Add("last_frame", &C::last_frame, "last source frame (inclusive; -1: the last)")
          .Add("source_frame_time_s", &C::source_frame_time_s,
               "source frame time [s] (0: the header's)", NonNegative<double>())
          .Add("mirror", &C::mirror, "left/right mirror of the source")
          .Add("loop", &C::loop, "cut one cycle and make it loop");
  return t;
}

Json ClipSpec::ToJson() const { return ClipSpecFields().Write(*this); }

ClipSpec ClipSpec::FromJson(const Json& j, const std::string& ctx) {
  return ClipSpecFields().Read(j, ctx);
}

RetargetConfig::RetargetConfig() {
  ik.max_iters = 60;
  ClipSpec walk;
  walk.name = "walk";
  walk.bvh = "08_01.bvh";
  walk.description = "walk cycle (two steps), looping; CMU 08_01 'walk' (the paper's walk take)";
  walk.first_frame = 1;
  walk.loop = true;
  ClipSpec left;
  left.name = "turn_left";
  left.bvh = "69_17_excerpt.bvh";
  left.description = "turn in place to the left, about 180 deg; CMU 69_17 (substitute for 69_13)";
  left.first_frame = 0;
  ClipSpec right = left;
  right.name = "turn_right";
  right.description = "turn in place to the right: left/right mirror of the 69_17 left turn";
  right.mirror = true;
  ClipSpec sit;
  sit.name = "sit";
  sit.bvh = "143_18_excerpt.bvh";
  sit.description =
      "sit down on a chair from standing with the back to it, to seated; CMU 143_18 (header "
      "rate 60 Hz)";
  sit.first_frame = 50;
  sit.last_frame = 220;
  clips = {walk, left, right, sit};
}

const FieldTable<IkOptions>& IkOptionsFields() {
  using C = IkOptions;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("damping", &C::damping, "lambda of (J^T W J + lambda^2 I) [m]")
          .Add("max_iters", &C::max_iters, "iterations per solve")
          .Add("min_improvement", &C::min_improvement, "stop below this error drop [m^2]")
          .Add("fd_step", &C::fd_step, "finite-difference step [m or rad]")
          .Add("max_step", &C::max_step, "cap on |delta| per iteration [m or rad]");
  return t;
}

const FieldTable<RetargetConfig>& RetargetConfigFields() {
  using C = RetargetConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("frame_time_s", &C::frame_time_s, "output frame time [s]", Positive<double>())
          .Add("bvh_unit_m", &C::bvh_unit_m, "BVH units to metres", Positive<double>())
          .Add("foot_weight", &C::foot_weight, "IK weight of ankle and toe points")
          .Add("contact_height_m", &C::contact_height_m, "foot on the ground below [m]")
          .Add("loop_min_period_s", &C::loop_min_period_s, "gait-cycle search window from [s]")
          .Add("loop_max_period_s", &C::loop_max_period_s, "... to [s]")
          .Add("first_frame_iters", &C::first_frame_iters, "IK iterations of the first frame")
          .Nested("ik", &C::ik, IkOptionsFields(), "the IK solver")
          .Custom(
              "clips", "the clips (given: replace the defaults)",
              [](const Json& j, C& c, const std::string& ctx) {
                if (!j["clips"].is_array()) throw ConfigError(ctx + ".clips: expected an array");
                c.clips.clear();
                for (size_t i = 0; i < j["clips"].size(); ++i) {
                  c.clips.push_back(
                      ClipSpec::FromJson(j["clips"][i], ctx + ".clips[" + std::to_string(i) + "]"));
                }
              },
              [](const C& c, Json& j) {
                Json a = Json::array();
                for (const ClipSpec& s : c.clips) a.push_back(s.ToJson());
                j["clips"] = a;
              });
  return t;
}

Json RetargetConfig::ToJson() const { return RetargetConfigFields().Write(*this); }

RetargetConfig RetargetConfig::FromJson(const Json& j, const std::string& ctx) {
  return RetargetConfigFields().Read(j, ctx);
}

// ---------------------------------------------------------------- humanoid key points

HumanoidKeyPoints::HumanoidKeyPoints(const HumanoidModel& model) : model_(model) {
  defs_.resize(kNumKeyPoints);
  auto body = [&](const std::string& n) {
    const int b = model.FindBody(n);
    if (b < 0) throw ConfigError("humanoid model lacks body '" + n + "'");
    return b;
  };
  auto joint = [&](const std::string& n) {
    const int j = model.FindJoint(n);
    if (j < 0) throw ConfigError("humanoid model lacks joint '" + n + "'");
    return j;
  };
  // First sphere geom of a body (hand, head) or the mean front end of its capsules (toes).
  auto sphere = [&](int b) {
    for (const Geom& g : model.body(b).geoms) {
      if (g.type == Geom::Type::kSphere) return g.from;
    }
    throw ConfigError("humanoid body '" + model.body(b).name + "' has no sphere geom");
  };
  auto toe = [&](int b) {
    Eigen::Vector3d s = Eigen::Vector3d::Zero();
    int n = 0;
    for (const Geom& g : model.body(b).geoms) {
      s += g.from.x() > g.to.x() ? g.from : g.to;
      ++n;
    }
    return Eigen::Vector3d(s / std::max(n, 1));
  };
  auto heel = [&](int b) {
    Eigen::Vector3d s = Eigen::Vector3d::Zero();
    int n = 0;
    for (const Geom& g : model.body(b).geoms) {
      s += g.from.x() < g.to.x() ? g.from : g.to;
      ++n;
    }
    return Eigen::Vector3d(s / std::max(n, 1));
  };
  // Front end of the foot capsule farthest from the body's midline.
  auto toe_out = [&](int b, double side) {
    Eigen::Vector3d best = Eigen::Vector3d::Zero();
    double y = -1e9;
    for (const Geom& g : model.body(b).geoms) {
      const Eigen::Vector3d f = g.from.x() > g.to.x() ? g.from : g.to;
      if (side * f.y() > y) y = side * f.y(), best = f;
    }
    return best;
  };
  defs_[kPelvis].body = model.pelvis_body();
  const char* side[2] = {"right_", "left_"};
  for (int k = 0; k < 2; ++k) {
    const std::string s = side[k];
    const int o = k == 0 ? 0 : 4;
    defs_[kRHip + o].joint = joint(s + "hip_x");
    defs_[kRKnee + o].joint = joint(s + "knee");
    defs_[kRAnkle + o].joint = joint(s + "ankle_y");
    defs_[kRToe + o].body = body(s + "foot");
    defs_[kRToe + o].local = toe(defs_[kRToe + o].body);
    const int f = k == 0 ? 0 : 2;
    defs_[kRHeel + f].body = defs_[kRToe + o].body;
    defs_[kRHeel + f].local = heel(defs_[kRToe + o].body);
    defs_[kRToeOut + f].body = defs_[kRToe + o].body;
    defs_[kRToeOut + f].local = toe_out(defs_[kRToe + o].body, k == 0 ? -1.0 : 1.0);
    const int a = k == 0 ? 0 : 3;
    defs_[kRShoulder + a].joint = joint(s + "shoulder1");
    defs_[kRElbow + a].joint = joint(s + "elbow");
    defs_[kRWrist + a].body = body(s + "lower_arm");
    defs_[kRWrist + a].local = sphere(defs_[kRWrist + a].body);
  }
  defs_[kHead].body = model.root_body();
  defs_[kHead].local = sphere(model.root_body());
}

void HumanoidKeyPoints::FromFk(const FkResult& fk, Eigen::Matrix3Xd* out) const {
  out->resize(3, kNumKeyPoints);
  for (int k = 0; k < kNumKeyPoints; ++k) {
    const Def& d = defs_[k];
    out->col(k) = d.joint >= 0 ? fk.joint_anchor_world[d.joint] : fk.body_world[d.body] * d.local;
  }
}

void HumanoidKeyPoints::KeyPoints(const IkPose& pose, Eigen::Matrix3Xd* out) const {
  FromFk(ForwardKinematics(model_, pose.root_pos, pose.root_rot, pose.q.data()), out);
}

// ---------------------------------------------------------------- source targets

SourceTargets ComputeSourceTargets(const BvhClip& bvh, const ClipSpec& spec,
                                   const HumanoidModel& model, const RetargetConfig& cfg) {
  const SourceJoints sj = FindSourceJoints(bvh);
  const int last = spec.last_frame < 0 ? bvh.num_frames() - 1 : spec.last_frame;
  if (spec.first_frame >= bvh.num_frames() || last >= bvh.num_frames() ||
      last <= spec.first_frame) {
    throw ConfigError("clip '" + spec.name + "': frame range " + std::to_string(spec.first_frame) +
                      ".." + std::to_string(last) + " outside the BVH's " +
                      std::to_string(bvh.num_frames()) + " frames");
  }
  SourceTargets out;
  out.source_frame_time = spec.source_frame_time_s > 0 ? spec.source_frame_time_s : bvh.frame_time;
  const Eigen::Matrix3d perm = Perm();
  const double unit = cfg.bvh_unit_m;
  auto wpos = [&](const BvhPose& p, int j) -> Eigen::Vector3d { return perm * p.pos[j] * unit; };
  auto wrot = [&](const BvhPose& p, int j) -> Eigen::Matrix3d {
    return perm * p.rot[j] * perm.transpose();
  };

  // Humanoid standing rest pose (all angles 0, feet flat on z = 0, facing +x).
  HumanoidKeyPoints hk(model);
  const std::vector<double> zeros(model.num_joints(), 0.0);
  const FkResult fk0 = ForwardKinematics(model, Eigen::Vector3d(0, 0, model.standing_root_height()),
                                         Eigen::Quaterniond::Identity(), zeros.data());
  Eigen::Matrix3Xd k0;
  hk.FromFk(fk0, &k0);
  // Trunk pivot: the mean of the abdomen hinge anchors (where the humanoid bends).
  Eigen::Vector3d pivot0 = Eigen::Vector3d::Zero();
  int npiv = 0;
  for (int j = 0; j < model.num_joints(); ++j) {
    if (model.joint(j).name.rfind("abdomen", 0) == 0) {
      pivot0 += fk0.joint_anchor_world[j];
      ++npiv;
    }
  }
  if (npiv == 0) throw ConfigError("humanoid model has no abdomen joints");
  pivot0 /= npiv;
  const double thigh[2] = {(k0.col(kRKnee) - k0.col(kRHip)).norm(),
                           (k0.col(kLKnee) - k0.col(kLHip)).norm()};
  const double shin[2] = {(k0.col(kRAnkle) - k0.col(kRKnee)).norm(),
                          (k0.col(kLAnkle) - k0.col(kLKnee)).norm()};
  const double upper[2] = {(k0.col(kRElbow) - k0.col(kRShoulder)).norm(),
                           (k0.col(kLElbow) - k0.col(kLShoulder)).norm()};
  const double fore[2] = {(k0.col(kRWrist) - k0.col(kRElbow)).norm(),
                          (k0.col(kLWrist) - k0.col(kLElbow)).norm()};

  // Source T-pose: calibration of the rotation-following offsets.
  const BvhPose tp = BvhForwardKinematics(bvh, TPoseFrame(bvh, TPoseAngles()));
  double src_leg = 0;
  for (int k = 0; k < 2; ++k) {
    src_leg +=
        0.5 * unit * (bvh.joints[sj.leg[k]].offset.norm() + bvh.joints[sj.foot[k]].offset.norm());
  }
  out.scale = (0.5 * (thigh[0] + thigh[1] + shin[0] + shin[1])) / src_leg;
  const Eigen::Matrix3d hips_t = wrot(tp, sj.hips).transpose();
  const Eigen::Matrix3d chest_t = wrot(tp, sj.spine1).transpose();
  Eigen::Vector3d v_hip[2], v_toe[2], v_sh[2], v_heel[2], v_toe_out[2];
  const int heel_key[2] = {kRHeel, kLHeel}, toe_out_key[2] = {kRToeOut, kLToeOut};
  const int hip_key[2] = {kRHip, kLHip}, ankle_key[2] = {kRAnkle, kLAnkle},
            toe_key[2] = {kRToe, kLToe};
  const int sh_key[2] = {kRShoulder, kLShoulder};
  for (int k = 0; k < 2; ++k) {
    v_hip[k] = hips_t * (k0.col(hip_key[k]) - k0.col(kPelvis));
    const Eigen::Matrix3d foot_t = wrot(tp, sj.foot[k]).transpose();
    v_toe[k] = foot_t * (k0.col(toe_key[k]) - k0.col(ankle_key[k]));
    v_heel[k] = foot_t * (k0.col(heel_key[k]) - k0.col(ankle_key[k]));
    v_toe_out[k] = foot_t * (k0.col(toe_out_key[k]) - k0.col(ankle_key[k]));
    v_sh[k] = chest_t * (k0.col(sh_key[k]) - pivot0);
  }
  const Eigen::Vector3d v_pivot = hips_t * (pivot0 - k0.col(kPelvis));
  const Eigen::Vector3d v_head = chest_t * (k0.col(kHead) - pivot0);

  for (int f = spec.first_frame; f <= last; ++f) {
    const BvhPose p = BvhForwardKinematics(bvh, f);
    Eigen::Matrix3Xd t(3, kNumKeyPoints);
    const Eigen::Matrix3d rh = wrot(p, sj.hips), rc = wrot(p, sj.spine1);
    t.col(kPelvis) = out.scale * wpos(p, sj.hips);
    const Eigen::Vector3d pivot = t.col(kPelvis) + rh * v_pivot;
    t.col(kHead) = pivot + rc * v_head;
    const int knee_key[2] = {kRKnee, kLKnee}, el_key[2] = {kRElbow, kLElbow},
              wr_key[2] = {kRWrist, kLWrist};
    for (int k = 0; k < 2; ++k) {
      t.col(hip_key[k]) = t.col(kPelvis) + rh * v_hip[k];
      t.col(knee_key[k]) =
          t.col(hip_key[k]) + thigh[k] * (wpos(p, sj.leg[k]) - wpos(p, sj.up_leg[k])).normalized();
      t.col(ankle_key[k]) =
          t.col(knee_key[k]) + shin[k] * (wpos(p, sj.foot[k]) - wpos(p, sj.leg[k])).normalized();
      const Eigen::Matrix3d rf = wrot(p, sj.foot[k]);
      t.col(toe_key[k]) = t.col(ankle_key[k]) + rf * v_toe[k];
      t.col(heel_key[k]) = t.col(ankle_key[k]) + rf * v_heel[k];
      t.col(toe_out_key[k]) = t.col(ankle_key[k]) + rf * v_toe_out[k];
      t.col(sh_key[k]) = pivot + rc * v_sh[k];
      t.col(el_key[k]) =
          t.col(sh_key[k]) + upper[k] * (wpos(p, sj.fore_arm[k]) - wpos(p, sj.arm[k])).normalized();
      t.col(wr_key[k]) =
          t.col(el_key[k]) + fore[k] * (wpos(p, sj.hand[k]) - wpos(p, sj.fore_arm[k])).normalized();
    }
    out.frames.push_back(t);
  }
  // Ground: the median over frames of the lowest foot clearance (relative to the humanoid's flat
  // standing foot) is put at zero; the stance foot touches the ground in almost every frame.
  std::vector<double> clearance;
  for (const auto& t : out.frames) {
    double c = 1e9;
    for (int k = 0; k < 2; ++k) {
      for (int key : {ankle_key[k], toe_key[k], heel_key[k], toe_out_key[k]})
        c = std::min(c, t(2, key) - k0(2, key));
    }
    clearance.push_back(c);
  }
  out.ground_offset_m = -Median(clearance);
  for (auto& t : out.frames) t.row(2).array() += out.ground_offset_m;
  return out;
}

std::vector<Eigen::Matrix3Xd> ResampleTargets(const SourceTargets& src, double frame_time) {
  const int n = static_cast<int>(src.frames.size());
  const double duration = (n - 1) * src.source_frame_time;
  std::vector<Eigen::Matrix3Xd> out;
  for (int i = 0;; ++i) {
    const double t = i * frame_time;
    if (t > duration + 1e-5) break;  // tolerance: headers round the frame time (0.0333332 s)
    const double s = t / src.source_frame_time;
    const int a = std::min(static_cast<int>(std::floor(s)), n - 1);
    const double u = std::clamp(s - a, 0.0, 1.0);
    auto at = [&](int k) -> const Eigen::Matrix3Xd& { return src.frames[std::clamp(k, 0, n - 1)]; };
    Eigen::Matrix3Xd m(3, src.frames[0].cols());
    for (int k = 0; k < m.cols(); ++k) {
      m.col(k) = CatmullRom(at(a - 1).col(k), at(a).col(k), at(a + 1).col(k), at(a + 2).col(k), u);
    }
    out.push_back(m);
  }
  return out;
}

// ---------------------------------------------------------------- mirror

BvhClip MirrorBvh(const BvhClip& clip, const std::string& source) {
  BvhClip m = clip;
  const int n = static_cast<int>(clip.joints.size());
  auto counterpart = [&](const std::string& name) -> std::string {
    const std::pair<const char*, const char*> pre[] = {
        {"Left", "Right"}, {"Right", "Left"}, {"L", "R"}, {"R", "L"}};
    for (const auto& [a, b] : pre) {
      const std::string sa = a;
      if (name.rfind(sa, 0) == 0) {
        const std::string other = b + name.substr(sa.size());
        if (clip.Find(other) >= 0) return other;
      }
    }
    return name;  // midline joint
  };
  for (int i = 0; i < n; ++i) {
    const int c = clip.Find(counterpart(clip.joints[i].name));
    const BvhJoint& src = clip.joints[c];
    if (src.channels != clip.joints[i].channels) {
      throw ConfigError(source + ": joints '" + clip.joints[i].name + "' and '" + src.name +
                        "' have different channels; cannot mirror");
    }
    m.joints[i].offset = Eigen::Vector3d(-src.offset.x(), src.offset.y(), src.offset.z());
    for (size_t k = 0; k < src.channels.size(); ++k) {
      const BvhChannel ch = src.channels[k];
      // Reflection x -> -x: positions negate x; rotations about Y and Z change sign.
      const double sign =
          (ch == BvhChannel::kXpos || ch == BvhChannel::kYrot || ch == BvhChannel::kZrot) ? -1.0
                                                                                          : 1.0;
      m.frames.col(m.joints[i].first_channel + k) = sign * clip.frames.col(src.first_channel + k);
    }
  }
  return m;
}

// ---------------------------------------------------------------- retargeting

namespace {

std::vector<MotionPose> SolveFrames(const HumanoidKeyPoints& hk,
                                    const std::vector<Eigen::Matrix3Xd>& targets,
                                    const RetargetConfig& cfg, const std::string& name,
                                    const std::function<void(int, int)>& progress) {
  const HumanoidModel& model = hk.model();
  const Eigen::VectorXd w = KeyWeights(cfg);
  // Cold start: upright, facing the source pelvis heading (from the hip line), above the pelvis.
  const Eigen::Matrix3Xd& t0 = targets[0];
  const Eigen::Vector3d lateral = t0.col(kLHip) - t0.col(kRHip);
  const double yaw = std::atan2(lateral.y(), lateral.x()) - M_PI / 2;
  IkPose pose;
  pose.root_rot = Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
  const std::vector<double> zeros(model.num_joints(), 0.0);
  const FkResult fk0 = ForwardKinematics(model, Eigen::Vector3d::Zero(),
                                         Eigen::Quaterniond::Identity(), zeros.data());
  pose.root_pos =
      t0.col(kPelvis) - pose.root_rot * fk0.body_world[model.pelvis_body()].translation();
  pose.q = Eigen::VectorXd::Zero(model.num_joints());
  std::vector<MotionPose> out;
  for (size_t i = 0; i < targets.size(); ++i) {
    IkOptions opt = cfg.ik;
    if (i == 0) opt.max_iters = cfg.first_frame_iters;
    pose = SolveIk(hk, targets[i], w, pose, opt).pose;
    MotionPose mp;
    mp.root_pos = pose.root_pos;
    mp.root_rot = pose.root_rot;
    mp.q = pose.q;
    out.push_back(mp);
    if (progress && (i % 20 == 0 || i + 1 == targets.size()))
      progress(static_cast<int>(i + 1), static_cast<int>(targets.size()));
  }
  return out;
}

// Best gait cycle [a, b] (b is the same phase as a): minimises the joint-angle and joint-velocity
// mismatch between its ends.
std::pair<int, int> FindCycle(const std::vector<MotionPose>& p, const RetargetConfig& cfg) {
  const int n = static_cast<int>(p.size());
  const int lo = static_cast<int>(std::round(cfg.loop_min_period_s / cfg.frame_time_s));
  const int hi = static_cast<int>(std::round(cfg.loop_max_period_s / cfg.frame_time_s));
  double best = 1e300;
  std::pair<int, int> ab{-1, -1};
  for (int a = 1; a + lo < n - 1; ++a) {
    for (int b = a + lo; b <= std::min(a + hi, n - 2); ++b) {
      const Eigen::VectorXd dq = p[a].q - p[b].q;
      const Eigen::VectorXd dv = (p[a + 1].q - p[a - 1].q) - (p[b + 1].q - p[b - 1].q);
      const double dz = p[a].root_pos.z() - p[b].root_pos.z();
      const double cost = dq.squaredNorm() + dv.squaredNorm() + 10.0 * dz * dz;
      if (cost < best) {
        best = cost;
        ab = {a, b};
      }
    }
  }
  if (ab.first < 0)
    throw ConfigError("walk clip too short for a gait cycle of the configured period");
  return ab;
}

}  // namespace

RetargetOutput RetargetClip(const BvhClip& bvh_in, const std::string& bvh_path,
                            const ClipSpec& spec, const HumanoidModel& model,
                            const RetargetConfig& cfg,
                            const std::function<void(int, int)>& progress) {
  const BvhClip bvh = spec.mirror ? MirrorBvh(bvh_in, bvh_path) : bvh_in;
  const SourceTargets src = ComputeSourceTargets(bvh, spec, model, cfg);
  std::vector<Eigen::Matrix3Xd> targets = ResampleTargets(src, cfg.frame_time_s);
  HumanoidKeyPoints hk(model);
  std::vector<MotionPose> poses = SolveFrames(hk, targets, cfg, spec.name, progress);

  int first = 0, count = static_cast<int>(poses.size());
  Eigen::Vector3d disp = Eigen::Vector3d::Zero();
  if (spec.loop) {
    const auto [a, b] = FindCycle(poses, cfg);
    first = a;
    count = b - a + 1;
    // Spread the end mismatch of angles, height and orientation linearly over the cycle so that
    // the last frame equals the first (up to the displacement).
    const MotionPose pa = poses[a], pb = poses[b];
    const Eigen::Quaterniond drot = pb.root_rot * pa.root_rot.conjugate();
    for (int i = 0; i < count; ++i) {
      const double u = static_cast<double>(i) / (count - 1);
      MotionPose& p = poses[a + i];
      p.q -= u * (pb.q - pa.q);
      p.root_pos.z() -= u * (pb.root_pos.z() - pa.root_pos.z());
      p.root_rot =
          (Eigen::Quaterniond::Identity().slerp(u, drot).conjugate() * p.root_rot).normalized();
    }
    disp = pb.root_pos - pa.root_pos;
    disp.z() = 0;
  }
  // Canonical placement: the first frame's root at x, y = 0; heading +x (for a loop: the cycle's
  // displacement along +x; otherwise the first frame's facing).
  Planar pl;
  if (spec.loop) {
    pl.yaw = -std::atan2(disp.y(), disp.x());
  } else {
    pl.yaw = -Yaw(poses[first].root_rot.toRotationMatrix());
  }
  const Eigen::Vector3d r0 = poses[first].root_pos;
  pl.t =
      -(Eigen::AngleAxisd(pl.yaw, Eigen::Vector3d::UnitZ()) * Eigen::Vector3d(r0.x(), r0.y(), 0));
  std::vector<MotionPose> frames;
  RetargetOutput out;
  for (int i = 0; i < count; ++i) {
    MotionPose p = poses[first + i];
    // Feet (and everything else) never below the ground: lift the root where needed.
    const double low =
        LowestGeomZ(model, ForwardKinematics(model, p.root_pos, p.root_rot, p.q.data()));
    if (low < 0) p.root_pos.z() -= low;
    p.root_pos = pl.Apply(p.root_pos);
    p.root_rot = pl.Rot() * p.root_rot;
    frames.push_back(p);
    out.targets.push_back(ApplyPlanar(pl, targets[first + i]));
  }
  const Eigen::Vector3d cycle = pl.Rot() * disp;
  out.motion = ReferenceMotion(spec.name, cfg.frame_time_s, frames, false);
  out.motion.set_loop(spec.loop, cycle, 0.0);
  out.motion.ComputeVelocities();
  const int last = spec.last_frame < 0 ? bvh.num_frames() - 1 : spec.last_frame;
  std::string base = bvh_path;
  const size_t slash = base.find_last_of('/');
  if (slash != std::string::npos) base = base.substr(slash + 1);
  Json& m = out.motion.meta();
  m["description"] = spec.description;
  m["acknowledgement"] = kCmuAcknowledgement;
  m["source"] = {{"bvh", base},
                 {"first_frame", spec.first_frame},
                 {"last_frame", last},
                 {"header_frame_time_s", bvh.frame_time},
                 {"source_frame_time_s", src.source_frame_time},
                 {"mirrored", spec.mirror}};
  m["retarget"] = {{"spec", spec.ToJson()},
                   {"scale", src.scale},
                   {"ground_offset_m", src.ground_offset_m},
                   {"first_output_frame", first},
                   {"alignment_yaw_rad", pl.yaw},
                   {"alignment_translation_m", {pl.t.x(), pl.t.y(), pl.t.z()}}};
  m["mirrored"] = spec.mirror;
  m["units"] =
      "root_pos_m: torso origin, world, m (z up, ground z = 0); root_quat_wxyz: torso "
      "to world; q_rad: 21 joint angles in observation order (notes 1.3), rad; "
      "frame_time_s: s per frame; velocities are central differences, computed on load";
  m["joint_names"] = Json::array();
  for (const Joint& j : model.joints()) m["joint_names"].push_back(j.name);
  // Where the pelvis ends (for the sit clip: on the seat; the chair goes there).
  const MotionPose& end = out.motion.frame(out.motion.num_frames() - 1);
  const Eigen::Vector3d pelvis_end =
      ForwardKinematics(model, end.root_pos, end.root_rot, end.q.data())
          .body_world[model.pelvis_body()]
          .translation();
  m["pelvis_end_m"] = {pelvis_end.x(), pelvis_end.y(), pelvis_end.z()};
  if (spec.loop) {
    m["cycle_source_frames"] = {
        spec.first_frame + first * cfg.frame_time_s / src.source_frame_time,
        spec.first_frame + (first + count - 1) * cfg.frame_time_s / src.source_frame_time};
  }
  return out;
}

std::vector<Eigen::Matrix3Xd> TargetsForMotion(const ReferenceMotion& motion, const BvhClip& bvh_in,
                                               const HumanoidModel& model,
                                               const RetargetConfig& cfg) {
  const Json& r = motion.meta().at("retarget");
  const ClipSpec spec = ClipSpec::FromJson(r.at("spec"), motion.name() + ".meta.retarget.spec");
  const BvhClip bvh = spec.mirror ? MirrorBvh(bvh_in, spec.bvh) : bvh_in;
  RetargetConfig c = cfg;
  c.frame_time_s = motion.frame_time();
  const std::vector<Eigen::Matrix3Xd> all =
      ResampleTargets(ComputeSourceTargets(bvh, spec, model, c), c.frame_time_s);
  Planar pl;
  pl.yaw = r.at("alignment_yaw_rad").get<double>();
  const auto t = r.at("alignment_translation_m");
  pl.t = Eigen::Vector3d(t[0].get<double>(), t[1].get<double>(), t[2].get<double>());
  const int first = r.at("first_output_frame").get<int>();
  if (first + motion.num_frames() > static_cast<int>(all.size())) {
    throw ConfigError(motion.name() + ": recorded frame range exceeds the source clip");
  }
  std::vector<Eigen::Matrix3Xd> out;
  for (int i = 0; i < motion.num_frames(); ++i) out.push_back(ApplyPlanar(pl, all[first + i]));
  return out;
}

Json EvaluateMotion(const ReferenceMotion& motion, const std::vector<Eigen::Matrix3Xd>& targets,
                    const HumanoidModel& model, const RetargetConfig& cfg) {
  HumanoidKeyPoints hk(model);
  const int n = motion.num_frames();
  const std::vector<double> zeros(model.num_joints(), 0.0);
  Eigen::Matrix3Xd k0;
  hk.FromFk(ForwardKinematics(model, Eigen::Vector3d(0, 0, model.standing_root_height()),
                              Eigen::Quaterniond::Identity(), zeros.data()),
            &k0);
  double sum = 0, maxe = 0;
  std::vector<double> per_key(kNumKeyPoints, 0.0);
  std::vector<Eigen::Matrix3Xd> result(n);
  double penetration = 0, src_penetration = 0;
  for (int i = 0; i < n; ++i) {
    const MotionPose& p = motion.frame(i);
    const FkResult fk = ForwardKinematics(model, p.root_pos, p.root_rot, p.q.data());
    hk.FromFk(fk, &result[i]);
    penetration = std::max(penetration, -LowestGeomZ(model, fk));
    for (int k = 0; k < kNumKeyPoints; ++k) {
      const double e = (result[i].col(k) - targets[i].col(k)).norm();
      sum += e;
      per_key[k] += e / n;
      maxe = std::max(maxe, e);
    }
    for (int k : {kRToe, kLToe, kRAnkle, kLAnkle, kRHeel, kLHeel, kRToeOut, kLToeOut}) {
      src_penetration = std::max(src_penetration, k0(2, k) - targets[i](2, k));
    }
  }
  // Foot sliding: horizontal speed of the toe point while it is within contact height of its
  // flat-standing height.
  // With lower_only, only the lower foot counts (the stance foot when walking: the swing toe
  // passes within a few cm of the ground too).
  auto sliding = [&](const std::vector<Eigen::Matrix3Xd>& pts, bool lower_only) {
    double s = 0;
    int cnt = 0;
    for (int i = 1; i + 1 < n; ++i) {
      const double cr = pts[i](2, kRToe) - k0(2, kRToe), cl = pts[i](2, kLToe) - k0(2, kLToe);
      for (int k : {kRToe, kLToe}) {
        if (pts[i](2, k) - k0(2, k) >= cfg.contact_height_m) continue;
        if (lower_only && (k == kRToe ? cr > cl : cl >= cr)) continue;
        const Eigen::Vector3d v =
            (pts[i + 1].col(k) - pts[i - 1].col(k)) / (2 * motion.frame_time());
        s += std::hypot(v.x(), v.y());
        ++cnt;
      }
    }
    return cnt ? s / cnt : 0.0;
  };
  Json per = Json::object();
  for (int k = 0; k < kNumKeyPoints; ++k) per[kKeyPointNames[k]] = per_key[k];
  return Json{{"name", motion.name()},
              {"frames", n},
              {"frame_time_s", motion.frame_time()},
              {"duration_s", motion.duration()},
              {"mean_err_m", sum / (n * kNumKeyPoints)},
              {"max_err_m", maxe},
              {"per_key_point_mean_err_m", per},
              {"foot_sliding_source_m_s", sliding(targets, false)},
              {"foot_sliding_result_m_s", sliding(result, false)},
              {"stance_foot_sliding_source_m_s", sliding(targets, true)},
              {"stance_foot_sliding_result_m_s", sliding(result, true)},
              {"ground_penetration_source_m", std::max(0.0, src_penetration)},
              {"ground_penetration_result_m", std::max(0.0, penetration)}};
}

}  // namespace perch
