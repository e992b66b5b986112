#include "envs/humanoid_model.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>

#include "common/json_util.h"
#include "common/paths.h"

namespace perch {
namespace {

// Reads a JSON array of n finite numbers.
std::vector<double> ReadNumbers(const Json& j, const char* key, size_t n, const std::string& ctx) {
  if (!j.contains(key)) throw ConfigError(ctx + ": missing required field '" + key + "'");
  const Json& a = j.at(key);
  const std::string where = ctx + "." + key;
  if (!a.is_array() || a.size() != n) {
    throw ConfigError(where + ": expected an array of " + std::to_string(n) + " numbers, got " +
                      a.dump());
  }
  std::vector<double> out;
  for (const Json& v : a) {
    if (!v.is_number() || !std::isfinite(v.get<double>())) {
      throw ConfigError(where + ": expected finite numbers, got " + a.dump());
    }
    out.push_back(v.get<double>());
  }
  return out;
}

Eigen::Vector3d ReadVec3(const Json& j, const char* key, const std::string& ctx) {
  const auto v = ReadNumbers(j, key, 3, ctx);
  return Eigen::Vector3d(v[0], v[1], v[2]);
}

double ReadPositive(const Json& j, const char* key, const std::string& ctx, bool required,
                    double fallback) {
  double v = fallback;
  if (required) {
    GetRequired(j, key, v, ctx);
  } else {
    GetOptional(j, key, v, ctx);
  }
  if (!std::isfinite(v) || v < 0.0 || (required && v == 0.0)) {
    throw ConfigError(ctx + "." + key + ": must be " + (required ? "> 0" : ">= 0") + ", got " +
                      std::to_string(v));
  }
  return v;
}

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

// Transform of one hinge: rotation by angle about axis through anchor.
Eigen::Isometry3d HingeTransform(const Joint& j, double q) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translate(j.anchor);
  t.rotate(Eigen::AngleAxisd(q, j.axis));
  t.translate(-j.anchor);
  return t;
}

Geom ReadGeom(const Json& jg, const std::string& gctx) {
  std::string type;
  GetRequired(jg, "type", type, gctx);
  Geom g;
  if (type == "capsule") {
    CheckKnownKeys(jg, {"type", "fromto", "radius"}, gctx);
    const auto ft = ReadNumbers(jg, "fromto", 6, gctx);
    g.type = Geom::Type::kCapsule;
    g.from = Eigen::Vector3d(ft[0], ft[1], ft[2]);
    g.to = Eigen::Vector3d(ft[3], ft[4], ft[5]);
  } else if (type == "sphere") {
    CheckKnownKeys(jg, {"type", "pos", "radius"}, gctx);
    g.type = Geom::Type::kSphere;
    g.from = g.to = ReadVec3(jg, "pos", gctx);
  } else {
    throw ConfigError(gctx + ".type: expected \"capsule\" or \"sphere\", got \"" + type + "\"");
  }
  g.radius = ReadPositive(jg, "radius", gctx, true, 0.0);
  return g;
}

// Mass properties: density x volume per geom, combined about the body's centre of mass; an
// explicit "mass" rescales the density-derived mass and inertia.
void SetMassProperties(const Json& jb, const std::string& bctx, double density, Body* b) {
  double mass = 0.0;
  Eigen::Vector3d moment = Eigen::Vector3d::Zero();
  std::vector<std::tuple<double, Eigen::Vector3d, Eigen::Matrix3d>> parts;
  for (const Geom& g : b->geoms) {
    double gm;
    Eigen::Vector3d gc;
    Eigen::Matrix3d gi;
    GeomMassProperties(g, density, &gm, &gc, &gi);
    parts.emplace_back(gm, gc, gi);
    mass += gm;
    moment += gm * gc;
  }
  b->com = moment / mass;
  b->inertia.setZero();
  for (const auto& [gm, gc, gi] : parts) {
    const Eigen::Matrix3d s = Skew(gc - b->com);
    b->inertia += gi - gm * s * s;  // parallel axis theorem
  }
  if (jb.contains("mass")) {
    const double given = ReadPositive(jb, "mass", bctx, true, 0.0);
    b->inertia *= given / mass;
    mass = given;
  }
  b->mass = mass;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(b->inertia);
  b->principal_rot = eig.eigenvectors();
  if (b->principal_rot.determinant() < 0) b->principal_rot.col(2) *= -1.0;
  b->principal_inertia = eig.eigenvalues();
}

// A hinge of body `body_index`; its name unique among `earlier` (the file's joints so far).
Joint ReadJoint(const Json& jj, const std::string& jctx, int body_index, double power_to_torque,
                const std::vector<Joint>& earlier) {
  CheckKnownKeys(jj, {"name", "axis", "pos", "range", "power", "max_torque", "kp", "kd"}, jctx);
  Joint j;
  GetRequired(jj, "name", j.name, jctx);
  for (const Joint& o : earlier) {
    if (o.name == j.name) throw ConfigError(jctx + ".name: duplicate joint '" + j.name + "'");
  }
  j.body = body_index;
  const Eigen::Vector3d axis = ReadVec3(jj, "axis", jctx);
  if (axis.norm() < 1e-9) throw ConfigError(jctx + ".axis: zero axis");
  j.axis = axis.normalized();
  j.anchor = ReadVec3(jj, "pos", jctx);
  const auto range = ReadNumbers(jj, "range", 2, jctx);
  if (!(range[0] < range[1])) {
    throw ConfigError(jctx + ".range: lower must be below upper (degrees)");
  }
  j.lower = range[0] * M_PI / 180.0;
  j.upper = range[1] * M_PI / 180.0;
  j.power = ReadPositive(jj, "power", jctx, true, 0.0);
  j.max_torque = ReadPositive(jj, "max_torque", jctx, false, power_to_torque * j.power);
  j.kp = ReadPositive(jj, "kp", jctx, true, 0.0);
  j.kd = ReadPositive(jj, "kd", jctx, false, 0.0);
  return j;
}

// Body `body_index` of the file (its geoms, mass properties and hinges; the hinges appended to
// *file_joints); `m` holds the bodies before it (names, parents).
Body ReadBody(const Json& jb, const std::string& ctx, const std::string& bctx,
              const std::string& root_body, const HumanoidModel& m, int body_index, double density,
              double power_to_torque, std::vector<Joint>* file_joints) {
  CheckKnownKeys(jb, {"name", "parent", "pos", "quat", "geoms", "joints", "mass"}, bctx);
  Body b;
  GetRequired(jb, "name", b.name, bctx);
  if (m.FindBody(b.name) >= 0) throw ConfigError(bctx + ".name: duplicate body '" + b.name + "'");
  std::string parent;
  GetRequired(jb, "parent", parent, bctx);
  if (body_index == 0) {
    if (!parent.empty()) throw ConfigError(bctx + ".parent: the first body is the root: use \"\"");
    if (b.name != root_body) {
      throw ConfigError(ctx + ".root_body: '" + root_body + "' must be the first body");
    }
  } else {
    b.parent = m.FindBody(parent);
    if (b.parent < 0) {
      throw ConfigError(bctx + ".parent: unknown body '" + parent +
                        "' (parents must come before their children)");
    }
  }
  b.offset = ReadVec3(jb, "pos", bctx);
  const auto qv = ReadNumbers(jb, "quat", 4, bctx);
  const Eigen::Quaterniond quat(qv[0], qv[1], qv[2], qv[3]);  // w, x, y, z
  if (quat.norm() < 1e-9) throw ConfigError(bctx + ".quat: zero quaternion");
  b.orientation = quat.normalized();

  if (!jb.contains("geoms") || !jb["geoms"].is_array() || jb["geoms"].empty()) {
    throw ConfigError(bctx + ".geoms: expected a non-empty array");
  }
  for (size_t gi = 0; gi < jb["geoms"].size(); ++gi) {
    b.geoms.push_back(ReadGeom(jb["geoms"][gi], bctx + ".geoms[" + std::to_string(gi) + "]"));
  }
  SetMassProperties(jb, bctx, density, &b);
  if (jb.contains("joints")) {
    if (!jb["joints"].is_array()) throw ConfigError(bctx + ".joints: expected an array");
    for (size_t ji = 0; ji < jb["joints"].size(); ++ji) {
      const std::string jctx = bctx + ".joints[" + std::to_string(ji) + "]";
      b.joints.push_back(static_cast<int>(file_joints->size()));
      file_joints->push_back(
          ReadJoint(jb["joints"][ji], jctx, body_index, power_to_torque, *file_joints));
    }
  }
  if (body_index > 0 && b.joints.empty()) {
    throw ConfigError(bctx + ".joints: a non-root body needs at least one hinge");
  }
  return b;
}

}  // namespace

void GeomMassProperties(const Geom& g, double density, double* mass, Eigen::Vector3d* com,
                        Eigen::Matrix3d* inertia) {
  const double r = g.radius;
  const double sphere_mass = density * 4.0 / 3.0 * M_PI * r * r * r;
  *com = 0.5 * (g.from + g.to);
  if (g.type == Geom::Type::kSphere) {
    *mass = sphere_mass;
    *inertia = Eigen::Matrix3d::Identity() * (0.4 * sphere_mass * r * r);
    return;
  }
  const Eigen::Vector3d seg = g.to - g.from;
  const double h = seg.norm();
  const double cyl_mass = density * M_PI * r * r * h;
  *mass = cyl_mass + sphere_mass;
  // About the capsule centre, capsule axis = local z: the two hemispheres sit at +-(h/2 + 3r/8).
  const double izz = cyl_mass * r * r / 2.0 + sphere_mass * 0.4 * r * r;
  const double ixx = cyl_mass * (h * h / 12.0 + r * r / 4.0) +
                     sphere_mass * (0.4 * r * r + h * h / 4.0 + 3.0 * h * r / 8.0);
  const Eigen::Matrix3d local = Eigen::Vector3d(ixx, ixx, izz).asDiagonal();
  const Eigen::Matrix3d rot =
      h > 0.0 ? RotationZTo(seg / h).toRotationMatrix() : Eigen::Matrix3d::Identity();
  *inertia = rot * local * rot.transpose();
}

std::string HumanoidModel::DefaultPath() { return ResolveProjectPath("data/humanoid.json"); }

HumanoidModel HumanoidModel::Load(const std::string& path) {
  const Json root = LoadJsonFile(path);
  const std::string ctx = path;
  CheckKnownKeys(root,
                 {"_comment", "name", "density", "power_to_torque", "helper_link_mass", "root_body",
                  "pelvis_body", "foot_bodies", "bodies", "observation_order", "action_order"},
                 ctx);
  HumanoidModel m;
  GetRequired(root, "name", m.name_, ctx);
  m.density_ = ReadPositive(root, "density", ctx, true, 0.0);
  const double power_to_torque = ReadPositive(root, "power_to_torque", ctx, true, 0.0);
  m.helper_link_mass_ = ReadPositive(root, "helper_link_mass", ctx, false, 0.001);
  std::string root_body, pelvis_body;
  std::vector<std::string> feet, obs_order, act_order;
  GetRequired(root, "root_body", root_body, ctx);
  GetRequired(root, "pelvis_body", pelvis_body, ctx);
  GetRequired(root, "foot_bodies", feet, ctx);
  GetRequired(root, "observation_order", obs_order, ctx);
  GetRequired(root, "action_order", act_order, ctx);
  if (!root.contains("bodies") || !root["bodies"].is_array() || root["bodies"].empty()) {
    throw ConfigError(ctx + ".bodies: expected a non-empty array of bodies");
  }

  // Bodies and joints in file order; joints are re-indexed into observation order below.
  std::vector<Joint> file_joints;
  const Json& jbodies = root["bodies"];
  for (size_t bi = 0; bi < jbodies.size(); ++bi) {
    const std::string bctx = ctx + ".bodies[" + std::to_string(bi) + "]";
    m.bodies_.push_back(ReadBody(jbodies[bi], ctx, bctx, root_body, m, static_cast<int>(bi),
                                 m.density_, power_to_torque, &file_joints));
  }

  // Observation order re-indexes the joints; it must list every joint exactly once.
  const std::string octx = ctx + ".observation_order";
  if (obs_order.size() != file_joints.size()) {
    throw ConfigError(octx + ": lists " + std::to_string(obs_order.size()) +
                      " joints, the bodies have " + std::to_string(file_joints.size()));
  }
  std::vector<int> file_to_obs(file_joints.size(), -1);
  for (size_t i = 0; i < obs_order.size(); ++i) {
    int found = -1;
    for (size_t k = 0; k < file_joints.size(); ++k) {
      if (file_joints[k].name == obs_order[i]) found = static_cast<int>(k);
    }
    if (found < 0)
      throw ConfigError(octx + "[" + std::to_string(i) + "]: unknown joint '" + obs_order[i] + "'");
    if (file_to_obs[found] >= 0)
      throw ConfigError(octx + ": joint '" + obs_order[i] + "' listed twice");
    file_to_obs[found] = static_cast<int>(i);
    m.joints_.push_back(file_joints[found]);
  }
  if (m.num_joints() != kNumJoints) {
    throw ConfigError(octx + ": the policies and observations assume " +
                      std::to_string(kNumJoints) + " joints, the file has " +
                      std::to_string(m.num_joints()));
  }
  for (Body& b : m.bodies_) {
    for (int& j : b.joints) j = file_to_obs[j];
  }

  const std::string actx = ctx + ".action_order";
  if (act_order.size() != obs_order.size()) {
    throw ConfigError(actx + ": must list all " + std::to_string(obs_order.size()) + " joints");
  }
  for (size_t a = 0; a < act_order.size(); ++a) {
    const int j = m.FindJoint(act_order[a]);
    if (j < 0)
      throw ConfigError(actx + "[" + std::to_string(a) + "]: unknown joint '" + act_order[a] + "'");
    if (m.joints_[j].action_index >= 0)
      throw ConfigError(actx + ": joint '" + act_order[a] + "' listed twice");
    m.joints_[j].action_index = static_cast<int>(a);
    m.action_to_joint_.push_back(j);
  }

  m.pelvis_body_ = m.FindBody(pelvis_body);
  if (m.pelvis_body_ < 0)
    throw ConfigError(ctx + ".pelvis_body: unknown body '" + pelvis_body + "'");
  if (feet.size() != 2) throw ConfigError(ctx + ".foot_bodies: expected [right, left]");
  for (const std::string& f : feet) {
    const int b = m.FindBody(f);
    if (b < 0) throw ConfigError(ctx + ".foot_bodies: unknown body '" + f + "'");
    m.foot_bodies_.push_back(b);
  }

  m.total_mass_ = 0.0;
  for (const Body& b : m.bodies_) m.total_mass_ += b.mass;
  const std::vector<double> zeros(m.num_joints(), 0.0);
  const FkResult fk =
      ForwardKinematics(m, Eigen::Vector3d::Zero(), Eigen::Quaterniond::Identity(), zeros.data());
  m.standing_root_height_ = -LowestGeomZ(m, fk);
  return m;
}

int HumanoidModel::FindBody(const std::string& name) const {
  for (size_t i = 0; i < bodies_.size(); ++i) {
    if (bodies_[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

int HumanoidModel::FindJoint(const std::string& name) const {
  for (size_t i = 0; i < joints_.size(); ++i) {
    if (joints_[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

FkResult ForwardKinematics(const HumanoidModel& model, const Eigen::Vector3d& root_pos,
                           const Eigen::Quaterniond& root_quat, const double* q) {
  FkResult r;
  r.body_world.resize(model.num_bodies());
  r.joint_anchor_world.resize(model.num_joints());
  for (int bi = 0; bi < model.num_bodies(); ++bi) {
    const Body& b = model.body(bi);
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    if (b.parent < 0) {
      t.translate(root_pos);
      t.rotate(root_quat.normalized());
    } else {
      t = r.body_world[b.parent];
      t.translate(b.offset);
      t.rotate(b.orientation);
    }
    for (int j : b.joints) {
      const Joint& jt = model.joint(j);
      r.joint_anchor_world[j] = t * jt.anchor;  // the anchor is fixed by its own hinge
      t = t * HingeTransform(jt, q[j]);
    }
    r.body_world[bi] = t;
  }
  return r;
}

double LowestGeomZ(const HumanoidModel& model, const FkResult& fk) {
  double z = std::numeric_limits<double>::infinity();
  for (int bi = 0; bi < model.num_bodies(); ++bi) {
    for (const Geom& g : model.body(bi).geoms) {
      const double z0 = (fk.body_world[bi] * g.from).z();
      const double z1 = (fk.body_world[bi] * g.to).z();
      z = std::min(z, std::min(z0, z1) - g.radius);
    }
  }
  return z;
}

Eigen::Quaterniond RotationZTo(const Eigen::Vector3d& d) {
  // Axis-angle instead of Quaternion::FromTwoVectors, whose SVD branch trips -Wmaybe-uninitialized.
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d axis = z.cross(d);
  const double s = axis.norm();
  const double c = z.dot(d);
  if (s < 1e-12) {
    return c > 0 ? Eigen::Quaterniond::Identity()
                 : Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()));
  }
  return Eigen::Quaterniond(Eigen::AngleAxisd(std::atan2(s, c), axis / s));
}

Eigen::Quaterniond QuatFromRpy(double roll, double pitch, double yaw) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                            Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                            Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()));
}

Eigen::Vector3d RpyFromQuat(const Eigen::Quaterniond& q) {
  const Eigen::Matrix3d r = q.normalized().toRotationMatrix();
  // R = Rz(y) Ry(p) Rx(r): r20 = -sin p, r21 = cos p sin r, r22 = cos p cos r, r10/r00 = tan y.
  const double pitch = std::asin(std::clamp(-r(2, 0), -1.0, 1.0));
  const double roll = std::atan2(r(2, 1), r(2, 2));
  const double yaw = std::atan2(r(1, 0), r(0, 0));
  return Eigen::Vector3d(roll, pitch, yaw);
}

void MirrorJointMap(const HumanoidModel& model, std::vector<int>* counterpart,
                    std::vector<double>* sign) {
  const int n = model.num_joints();
  counterpart->assign(n, -1);
  sign->assign(n, 1.0);
  for (int j = 0; j < n; ++j) {
    std::string name = model.joint(j).name;
    if (name.rfind("right_", 0) == 0) {
      name = "left_" + name.substr(6);
    } else if (name.rfind("left_", 0) == 0) {
      name = "right_" + name.substr(5);
    }
    const int c = model.FindJoint(name);
    if (c < 0) throw ConfigError("mirror: joint '" + model.joint(j).name + "' has no counterpart");
    const Eigen::Vector3d u = model.joint(j).axis;
    const Eigen::Vector3d mu(u.x(), -u.y(), u.z());
    const double dot = model.joint(c).axis.normalized().dot(mu.normalized());
    if (std::abs(std::abs(dot) - 1.0) > 1e-6) {
      throw ConfigError("mirror: axes of '" + model.joint(j).name + "' and '" + name +
                        "' are not mirror images");
    }
    (*counterpart)[j] = c;
    (*sign)[j] = dot > 0 ? -1.0 : 1.0;
  }
}

}  // namespace perch
