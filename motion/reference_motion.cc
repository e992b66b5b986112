#include "motion/reference_motion.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

#include "common/file_util.h"
#include "envs/humanoid_model.h"

namespace perch {
namespace {

constexpr int kJoints = 21;

double Round6(double x) { return std::round(x * 1e6) / 1e6; }

Eigen::Quaterniond YawQuat(double yaw) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
}

// Angular velocity w (world) with q1 = exp(w dt) q0.
Eigen::Vector3d AngVel(const Eigen::Quaterniond& q0, const Eigen::Quaterniond& q1, double dt) {
  Eigen::Quaterniond d = q1 * q0.conjugate();
  if (d.w() < 0) d.coeffs() = -d.coeffs();
  const Eigen::AngleAxisd aa(d);
  return aa.axis() * aa.angle() / dt;
}

// Applies the transform of `k` cycles (see the header) to a pose.
MotionPose Shift(const MotionPose& p, int k, const Eigen::Vector3d& disp, double yaw) {
  if (k == 0) return p;
  MotionPose o = p;
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
  if (k > 0) {
    for (int i = 0; i < k; ++i) offset += YawQuat(i * yaw) * disp;
  } else {
    for (int i = -1; i >= k; --i) offset -= YawQuat(i * yaw) * disp;
  }
  const Eigen::Quaterniond r = YawQuat(k * yaw);
  o.root_pos = r * p.root_pos + offset;
  o.root_rot = r * p.root_rot;
  o.root_vel = r * p.root_vel;
  o.root_angvel = r * p.root_angvel;
  return o;
}

Eigen::Vector3d ReadVec(const Json& a, size_t n, const std::string& ctx) {
  if (!a.is_array() || a.size() != n)
    throw ConfigError(ctx + ": expected " + std::to_string(n) + " numbers");
  Eigen::Vector3d v;
  for (size_t i = 0; i < 3 && i < n; ++i) {
    if (!a[i].is_number()) throw ConfigError(ctx + ": expected numbers");
    v[i] = a[i].get<double>();
  }
  return v;
}

}  // namespace

ReferenceMotion::ReferenceMotion(std::string name, double frame_time,
                                 std::vector<MotionPose> frames, bool loop)
    : name_(std::move(name)), frame_time_(frame_time), frames_(std::move(frames)), loop_(loop) {
  ComputeVelocities();
}

void ReferenceMotion::ComputeVelocities() {
  const int n = num_frames();
  if (n < 2) {
    for (auto& f : frames_) {
      f.qdot = Eigen::VectorXd::Zero(f.q.size());
      f.root_vel.setZero();
      f.root_angvel.setZero();
    }
    return;
  }
  std::vector<MotionPose> out = frames_;
  for (int i = 0; i < n; ++i) {
    // Neighbours; for a loop, frame n-1 is the phase of frame 0 in the next cycle.
    MotionPose prev, next;
    double span = 2 * frame_time_;
    if (i > 0 && i < n - 1) {
      prev = frames_[i - 1];
      next = frames_[i + 1];
    } else if (loop_ && n > 2) {
      if (i == 0) {
        prev = Shift(frames_[n - 2], -1, cycle_disp_, cycle_yaw_);
        next = frames_[1];
      } else {
        prev = frames_[n - 2];
        next = Shift(frames_[1], 1, cycle_disp_, cycle_yaw_);
      }
    } else {
      prev = frames_[i > 0 ? i - 1 : i];
      next = frames_[i < n - 1 ? i + 1 : i];
      span = frame_time_;
    }
    out[i].qdot = (next.q - prev.q) / span;
    out[i].root_vel = (next.root_pos - prev.root_pos) / span;
    out[i].root_angvel = AngVel(prev.root_rot, next.root_rot, span);
  }
  frames_ = std::move(out);
}

int ReferenceMotion::Cycle(double t) const {
  if (!loop_ || duration() <= 0) return 0;
  return static_cast<int>(std::floor(t / duration()));
}

double ReferenceMotion::Phase(double t) const {
  const double d = duration();
  if (d <= 0) return 0.0;
  if (loop_) {
    const double ph = t / d - std::floor(t / d);
    return ph >= 1.0 ? 0.0 : ph;
  }
  return std::clamp(t / d, 0.0, 1.0);
}

MotionPose ReferenceMotion::At(double t) const {
  const int n = num_frames();
  if (n == 0) throw std::logic_error("ReferenceMotion::At on an empty motion");
  int k = 0;
  double tl = t;
  if (loop_ && duration() > 0) {
    k = Cycle(t);
    tl = t - k * duration();
  }
  tl = std::clamp(tl, 0.0, duration());
  const double x = tl / frame_time_;
  const int i = std::min(static_cast<int>(std::floor(x)), n - 1);
  const int j = std::min(i + 1, n - 1);
  const double a = std::clamp(x - i, 0.0, 1.0);
  const MotionPose& p = frames_[i];
  const MotionPose& q = frames_[j];
  MotionPose o;
  o.root_pos = (1 - a) * p.root_pos + a * q.root_pos;
  o.root_rot = p.root_rot.slerp(a, q.root_rot).normalized();
  o.q = (1 - a) * p.q + a * q.q;
  o.qdot = (1 - a) * p.qdot + a * q.qdot;
  o.root_vel = (1 - a) * p.root_vel + a * q.root_vel;
  o.root_angvel = (1 - a) * p.root_angvel + a * q.root_angvel;
  return Shift(o, k, cycle_disp_, cycle_yaw_);
}

MotionPose ReferenceMotion::MirrorPose(const MotionPose& p, const HumanoidModel& model) {
  std::vector<int> c;
  std::vector<double> s;
  MirrorJointMap(model, &c, &s);
  MotionPose o = p;
  o.root_pos = MirrorPolar(p.root_pos);
  o.root_rot = MirrorRotation(p.root_rot);
  o.root_vel = MirrorPolar(p.root_vel);
  o.root_angvel = MirrorAxial(p.root_angvel);
  for (int j = 0; j < static_cast<int>(c.size()); ++j) {
    o.q[c[j]] = s[j] * p.q[j];
    if (p.qdot.size() == p.q.size()) o.qdot[c[j]] = s[j] * p.qdot[j];
  }
  return o;
}

double ReferenceMotion::ReachBehindPelvis(const HumanoidModel& model, const MotionPose& p,
                                          const std::string& body) {
  const int b = model.FindBody(body);
  if (b < 0) throw ConfigError("no body named \"" + body + "\"");
  const FkResult fk = ForwardKinematics(model, p.root_pos, p.root_rot, p.q.data());
  double x = 1e9;
  for (const Geom& g : model.body(b).geoms) {
    for (double a = 0; a <= 1.0 + 1e-9; a += 0.05) {  // along the capsule's segment
      x = std::min(x, (fk.body_world[b] * (g.from + a * (g.to - g.from))).x() - g.radius);
    }
  }
  return fk.body_world[model.pelvis_body()].translation().x() - x;
}

ReferenceMotion ReferenceMotion::Straightened(const HumanoidModel& model, double deg, double t0,
                                              double t1, const std::string& keep) const {
  if (keep != "torso" && keep != "pelvis") {
    throw ConfigError("straighten: keep must be torso or pelvis (got \"" + keep + "\")");
  }
  const int ay = model.FindJoint("abdomen_y");
  const int rh = model.FindJoint("right_hip_y");
  const int lh = model.FindJoint("left_hip_y");
  if (ay < 0 || rh < 0 || lh < 0) {
    throw ConfigError("straighten: the humanoid needs abdomen_y, right_hip_y and left_hip_y");
  }
  if (!(t1 > t0)) throw ConfigError("straighten: the ramp must end after it starts (t1 > t0)");
  const int pelvis = model.pelvis_body();
  ReferenceMotion m = *this;
  for (int i = 0; i < num_frames(); ++i) {
    const double t = i * frame_time_;
    const double a = deg * M_PI / 180.0 * std::clamp((t - t0) / (t1 - t0), 0.0, 1.0);
    MotionPose& f = m.frames_[i];
    const Eigen::Isometry3d before =
        ForwardKinematics(model, f.root_pos, f.root_rot, f.q.data()).body_world[pelvis];
    // abdomen_y + DEG with the torso held opens the torso-pelvis angle and the hips close it
    // again (the torso-thigh angle is unchanged); with the pelvis held, abdomen_y - DEG closes
    // the torso-thigh angle by DEG: the torso pitches forward, i.e. sits up.
    if (keep == "torso") {
      f.q[ay] += a;
      f.q[rh] -= a;
      f.q[lh] -= a;
    } else {
      f.q[ay] -= a;
    }
    const Eigen::Isometry3d after =
        ForwardKinematics(model, f.root_pos, f.root_rot, f.q.data()).body_world[pelvis];
    if (keep == "torso") {
      f.root_pos += before.translation() - after.translation();
    } else {
      // The rigid motion that puts the pelvis back where it was, applied to the whole body.
      const Eigen::Isometry3d g = before * after.inverse();
      f.root_rot = Eigen::Quaterniond(g.linear() * f.root_rot.toRotationMatrix()).normalized();
      f.root_pos = g * f.root_pos;
    }
  }
  m.ComputeVelocities();
  if (m.meta_.is_object()) {
    m.meta_["straightened"] = {{"abdomen_y_deg", deg}, {"ramp_s", {t0, t1}}, {"keep", keep}};
  }
  return m;
}

ReferenceMotion ReferenceMotion::Mirrored(const HumanoidModel& model) const {
  ReferenceMotion m = *this;
  for (auto& f : m.frames_) f = MirrorPose(f, model);
  m.cycle_disp_.y() = -cycle_disp_.y();
  m.cycle_yaw_ = -cycle_yaw_;
  if (m.meta_.is_object()) {
    m.meta_["mirrored"] = !(meta_.contains("mirrored") && meta_["mirrored"].get<bool>());
  }
  return m;
}

Json ReferenceMotion::ToJson() const {
  Json j;
  j["format"] = kFormat;
  j["name"] = name_;
  j["meta"] = meta_;
  j["frame_time_s"] = frame_time_;
  j["num_frames"] = num_frames();
  j["loop"] = loop_;
  j["cycle_displacement_m"] = {Round6(cycle_disp_.x()), Round6(cycle_disp_.y()),
                               Round6(cycle_disp_.z())};
  j["cycle_yaw_rad"] = Round6(cycle_yaw_);
  Json pos = Json::array(), rot = Json::array(), q = Json::array();
  for (const auto& f : frames_) {
    pos.push_back({Round6(f.root_pos.x()), Round6(f.root_pos.y()), Round6(f.root_pos.z())});
    rot.push_back({Round6(f.root_rot.w()), Round6(f.root_rot.x()), Round6(f.root_rot.y()),
                   Round6(f.root_rot.z())});
    Json row = Json::array();
    for (int k = 0; k < f.q.size(); ++k) row.push_back(Round6(f.q[k]));
    q.push_back(row);
  }
  j["root_pos_m"] = pos;
  j["root_quat_wxyz"] = rot;
  j["q_rad"] = q;
  return j;
}

ReferenceMotion ReferenceMotion::FromJson(const Json& j, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected a JSON object");
  CheckKnownKeys(j,
                 {"format", "name", "meta", "frame_time_s", "num_frames", "loop",
                  "cycle_displacement_m", "cycle_yaw_rad", "root_pos_m", "root_quat_wxyz", "q_rad"},
                 ctx);
  std::string format;
  GetRequired(j, "format", format, ctx);
  if (format != kFormat)
    throw ConfigError(ctx + ".format: expected '" + kFormat + "', got '" + format + "'");
  ReferenceMotion m;
  GetRequired(j, "name", m.name_, ctx);
  GetOptional(j, "meta", m.meta_, ctx);
  GetRequired(j, "frame_time_s", m.frame_time_, ctx);
  if (!(m.frame_time_ > 0)) throw ConfigError(ctx + ".frame_time_s: must be > 0");
  int n = 0;
  GetRequired(j, "num_frames", n, ctx);
  GetOptional(j, "loop", m.loop_, ctx);
  if (j.contains("cycle_displacement_m")) {
    m.cycle_disp_ = ReadVec(j["cycle_displacement_m"], 3, ctx + ".cycle_displacement_m");
  }
  GetOptional(j, "cycle_yaw_rad", m.cycle_yaw_, ctx);
  for (const char* key : {"root_pos_m", "root_quat_wxyz", "q_rad"}) {
    if (!j.contains(key) || !j[key].is_array() || static_cast<int>(j[key].size()) != n) {
      throw ConfigError(ctx + "." + key +
                        ": expected an array of num_frames = " + std::to_string(n) + " rows");
    }
  }
  m.frames_.resize(n);
  for (int i = 0; i < n; ++i) {
    const std::string row = "[" + std::to_string(i) + "]";
    MotionPose& f = m.frames_[i];
    f.root_pos = ReadVec(j["root_pos_m"][i], 3, ctx + ".root_pos_m" + row);
    const Json& r = j["root_quat_wxyz"][i];
    if (!r.is_array() || r.size() != 4 || !r[0].is_number() || !r[1].is_number() ||
        !r[2].is_number() || !r[3].is_number()) {
      throw ConfigError(ctx + ".root_quat_wxyz" + row + ": expected 4 numbers");
    }
    f.root_rot = Eigen::Quaterniond(r[0].get<double>(), r[1].get<double>(), r[2].get<double>(),
                                    r[3].get<double>());
    if (std::abs(f.root_rot.norm() - 1.0) > 1e-3) {
      throw ConfigError(ctx + ".root_quat_wxyz" + row + ": not a unit quaternion");
    }
    f.root_rot.normalize();
    const Json& q = j["q_rad"][i];
    if (!q.is_array() || q.size() != kJoints) {
      throw ConfigError(ctx + ".q_rad" + row + ": expected " + std::to_string(kJoints) +
                        " numbers");
    }
    f.q.resize(kJoints);
    for (int k = 0; k < kJoints; ++k) {
      if (!q[k].is_number()) throw ConfigError(ctx + ".q_rad" + row + ": expected numbers");
      f.q[k] = q[k].get<double>();
    }
  }
  m.ComputeVelocities();
  return m;
}

ReferenceMotion ReferenceMotion::Load(const std::string& path) {
  return FromJson(LoadJsonFile(path), path);
}

void ReferenceMotion::Save(const std::string& path) const {
  // One frame per line keeps the committed files small and diffable.
  const Json j = ToJson();
  std::string text = "{\n";
  bool first = true;
  for (const auto& [key, value] : j.items()) {
    text += first ? "" : ",\n";
    first = false;
    text += "  " + Json(key).dump() + ": ";
    if (value.is_array() && !value.empty() && value[0].is_array()) {
      text += "[\n";
      for (size_t i = 0; i < value.size(); ++i) {
        text += "    " + value[i].dump() + (i + 1 < value.size() ? ",\n" : "\n");
      }
      text += "  ]";
    } else {
      // Objects (meta) indented, two spaces deeper than the top level.
      std::string v = value.is_object() ? value.dump(2) : value.dump();
      for (size_t pos = v.find('\n'); pos != std::string::npos; pos = v.find('\n', pos + 3)) {
        v.replace(pos, 1, "\n  ");
      }
      text += v;
    }
  }
  text += "\n}\n";
  WriteFileAtomic(path, text);
}

}  // namespace perch
