#include "motion/bvh_export.h"

#include <cmath>
#include <Eigen/Geometry>
#include <Eigen/QR>
#include <functional>
#include <vector>

#include "common/json_util.h"

namespace perch {
namespace {

Eigen::Matrix3d Q() {
  Eigen::Matrix3d q;
  q << 0, 1, 0, 0, 0, 1, 1, 0, 0;
  return q;
}

constexpr double kDeg = 180.0 / M_PI;

}  // namespace

Eigen::Vector3d HumanoidToBvhAxes(const Eigen::Vector3d& v) { return Q() * v; }

BvhClip HumanoidMotionToBvh(const HumanoidModel& model, const ReferenceMotion& motion,
                            double frame_time, double seconds) {
  BvhClip clip;
  clip.frame_time = frame_time;
  const int nb = model.num_bodies();
  const std::vector<BvhChannel> six = {BvhChannel::kXpos, BvhChannel::kYpos, BvhChannel::kZpos,
                                       BvhChannel::kZrot, BvhChannel::kYrot, BvhChannel::kXrot};
  std::vector<int> joint_of_body(nb, -1);
  std::vector<bool> has_child(nb, false);
  for (int b = 0; b < nb; ++b) {
    if (model.body(b).parent >= 0) has_child[model.body(b).parent] = true;
  }
  // Depth-first so that a body's children follow it (the writer nests by parent index).
  std::function<void(int)> add = [&](int b) {
    BvhJoint j;
    j.name = model.body(b).name;
    j.parent = model.body(b).parent < 0 ? -1 : joint_of_body[model.body(b).parent];
    j.offset = model.body(b).parent < 0 ? Eigen::Vector3d::Zero()
                                        : Eigen::Vector3d(Q() * model.body(b).offset);
    j.channels = six;
    j.first_channel = clip.num_channels;
    clip.num_channels += 6;
    joint_of_body[b] = static_cast<int>(clip.joints.size());
    clip.joints.push_back(j);
    for (int c = 0; c < nb; ++c) {
      if (model.body(c).parent == b) add(c);
    }
    if (!has_child[b]) {
      BvhJoint e;
      e.name = model.body(b).name + "_End";
      e.parent = joint_of_body[b];
      e.end_site = true;
      clip.joints.push_back(e);
    }
  };
  add(model.root_body());
  const double len = seconds > 0 ? seconds : motion.duration();
  const int frames = static_cast<int>(std::floor(len / frame_time + 1e-9)) + 1;
  clip.frames.resize(frames, clip.num_channels);
  const Eigen::Matrix3d q = Q();
  for (int f = 0; f < frames; ++f) {
    const MotionPose p = motion.At(f * frame_time);
    const FkResult fk = ForwardKinematics(model, p.root_pos, p.root_rot, p.q.data());
    for (int b = 0; b < nb; ++b) {
      const int pb = model.body(b).parent;
      const Eigen::Isometry3d local =
          pb < 0 ? fk.body_world[b] : fk.body_world[pb].inverse() * fk.body_world[b];
      const Eigen::Vector3d rest = pb < 0 ? Eigen::Vector3d::Zero().eval() : model.body(b).offset;
      const Eigen::Vector3d t = q * (local.translation() - rest);
      const Eigen::Vector3d zyx =
          (q * local.rotation() * q.transpose()).eulerAngles(2, 1, 0) * kDeg;
      const int c = clip.joints[joint_of_body[b]].first_channel;
      clip.frames.block<1, 3>(f, c) = t.transpose();
      clip.frames.block<1, 3>(f, c + 3) = zyx.transpose();
    }
  }
  return clip;
}

std::vector<double> HumanoidJointAnglesFromBvh(const HumanoidModel& model, const BvhClip& clip,
                                               int frame) {
  const BvhPose pose = BvhForwardKinematics(clip, frame);
  const Eigen::Matrix3d qm = Q();
  std::vector<double> q(model.num_joints(), 0.0);
  for (int b = 0; b < model.num_bodies(); ++b) {
    const Body& body = model.body(b);
    if (body.joints.empty()) continue;
    const int j = clip.Find(body.name);
    const int pj = body.parent < 0 ? -1 : clip.Find(model.body(body.parent).name);
    if (j < 0 || (body.parent >= 0 && pj < 0)) {
      throw ConfigError("BVH: no joint named \"" + body.name + "\" (not the humanoid's skeleton)");
    }
    const Eigen::Matrix3d local_bvh =
        pj < 0 ? pose.rot[j] : Eigen::Matrix3d(pose.rot[pj].transpose() * pose.rot[j]);
    // Back to humanoid axes, then remove the body's fixed orientation: M = prod_k R(u_k, q_k).
    const Eigen::Matrix3d m =
        body.orientation.toRotationMatrix().transpose() * (qm.transpose() * local_bvh * qm);
    const int n = static_cast<int>(body.joints.size());
    auto product = [&](const Eigen::VectorXd& a) {
      Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
      for (int k = 0; k < n; ++k) {
        r = r * Eigen::AngleAxisd(a[k], model.joint(body.joints[k]).axis).toRotationMatrix();
      }
      return r;
    };
    auto residual = [&](const Eigen::VectorXd& a) {
      const Eigen::AngleAxisd err(Eigen::Matrix3d(m.transpose() * product(a)));
      return Eigen::Vector3d(err.angle() * err.axis());
    };
    Eigen::VectorXd a = Eigen::VectorXd::Zero(n);
    for (int it = 0; it < 50; ++it) {
      const Eigen::Vector3d r = residual(a);
      if (r.norm() < 1e-12) break;
      Eigen::MatrixXd jac(3, n);
      for (int k = 0; k < n; ++k) {
        Eigen::VectorXd h = a;
        h[k] += 1e-7;
        jac.col(k) = (residual(h) - r) / 1e-7;
      }
      a -= jac.colPivHouseholderQr().solve(r);
    }
    for (int k = 0; k < n; ++k) q[body.joints[k]] = a[k];
  }
  return q;
}

}  // namespace perch
