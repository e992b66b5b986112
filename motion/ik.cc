#include "motion/ik.h"

#include <Eigen/Cholesky>
#include <algorithm>

namespace perch {
namespace {

// Parameters: [root position (3), root rotation increment in the world frame (3), hinges (n)].
IkPose Apply(const IkPose& p, const Eigen::VectorXd& d) {
  IkPose out = p;
  out.root_pos += d.head<3>();
  const Eigen::Vector3d w = d.segment<3>(3);
  const double a = w.norm();
  if (a > 0) {
    out.root_rot = (Eigen::Quaterniond(Eigen::AngleAxisd(a, w / a)) * p.root_rot).normalized();
  }
  out.q += d.tail(p.q.size());
  return out;
}

void Clamp(const IkModel& m, IkPose* p) {
  for (int j = 0; j < m.num_joints(); ++j) p->q[j] = std::clamp(p->q[j], m.lower(j), m.upper(j));
}

double Error(const IkModel& m, const IkPose& p, const Eigen::Matrix3Xd& targets,
             const Eigen::VectorXd& w, Eigen::Matrix3Xd* pts) {
  m.KeyPoints(p, pts);
  double e = 0;
  for (int k = 0; k < m.num_points(); ++k) e += w[k] * (pts->col(k) - targets.col(k)).squaredNorm();
  return e;
}

}  // namespace

IkResult SolveIk(const IkModel& model, const Eigen::Matrix3Xd& targets,
                 const Eigen::VectorXd& weights, const IkPose& init, const IkOptions& opt) {
  const int n = 6 + model.num_joints();
  const int m = 3 * model.num_points();
  IkResult r;
  r.pose = init;
  Clamp(model, &r.pose);
  Eigen::Matrix3Xd pts(3, model.num_points()), plus = pts, minus = pts;
  double err = Error(model, r.pose, targets, weights, &pts);
  Eigen::MatrixXd jac(m, n);
  Eigen::VectorXd sw(m);
  for (int k = 0; k < model.num_points(); ++k)
    sw.segment<3>(3 * k).setConstant(std::sqrt(weights[k]));
  double lambda2 = opt.damping * opt.damping;
  for (int it = 0; it < opt.max_iters; ++it) {
    r.iterations = it + 1;
    for (int i = 0; i < n; ++i) {
      Eigen::VectorXd d = Eigen::VectorXd::Zero(n);
      d[i] = opt.fd_step;
      model.KeyPoints(Apply(r.pose, d), &plus);
      d[i] = -opt.fd_step;
      model.KeyPoints(Apply(r.pose, d), &minus);
      const Eigen::Matrix3Xd diff = plus - minus;
      jac.col(i) = Eigen::Map<const Eigen::VectorXd>(diff.data(), m) / (2 * opt.fd_step);
    }
    const Eigen::Matrix3Xd res = targets - pts;
    const Eigen::VectorXd e = Eigen::Map<const Eigen::VectorXd>(res.data(), m).cwiseProduct(sw);
    const Eigen::MatrixXd jw = sw.asDiagonal() * jac;
    Eigen::MatrixXd h = jw.transpose() * jw;
    const Eigen::VectorXd g = jw.transpose() * e;
    // Levenberg-style: accept a step only if it lowers the error, otherwise damp harder.
    bool accepted = false;
    for (int tries = 0; tries < 8 && !accepted; ++tries) {
      Eigen::MatrixXd a = h;
      a.diagonal().array() += lambda2;
      Eigen::VectorXd d = a.ldlt().solve(g);
      const double norm = d.norm();
      if (norm > opt.max_step) d *= opt.max_step / norm;
      IkPose cand = Apply(r.pose, d);
      Clamp(model, &cand);
      const double cerr = Error(model, cand, targets, weights, &plus);
      if (cerr < err) {
        const double improvement = err - cerr;
        r.pose = cand;
        pts = plus;
        err = cerr;
        accepted = true;
        lambda2 = std::max(lambda2 * 0.5, opt.damping * opt.damping);
        if (improvement < opt.min_improvement) {
          r.weighted_sq_err = err;
          return r;
        }
      } else {
        lambda2 *= 4.0;
      }
    }
    if (!accepted) break;
  }
  r.weighted_sq_err = err;
  return r;
}

}  // namespace perch
