#include "motion/reference_compare.h"

#include <cmath>
#include <filesystem>

#include "common/npz.h"

namespace perch {
namespace {

constexpr double kAuthorsFrameTime = 0.0165;  // s per row of the authors' qpos (notes 7.2)
constexpr int kJoints = 21;
constexpr int kQposCols = 51;

struct Trajectory {
  std::vector<Eigen::VectorXd> q;  // [frames][21]
  double At(double t, int j) const {
    const double x = t / kAuthorsFrameTime;
    const int n = static_cast<int>(q.size());
    const int i = std::clamp(static_cast<int>(std::floor(x)), 0, n - 1);
    const int k = std::min(i + 1, n - 1);
    const double a = std::clamp(x - i, 0.0, 1.0);
    return (1 - a) * q[i][j] + a * q[k][j];
  }
  double duration() const { return (q.size() - 1) * kAuthorsFrameTime; }
};

Trajectory FromQpos(const NpyArray& a, int clip) {
  // (T, 51) or (clips, T, 51).
  Trajectory t;
  const bool three = a.shape.size() == 3;
  const int64_t rows = three ? a.shape[1] : a.shape[0];
  if (a.shape.back() != kQposCols) throw ConfigError("authors' qpos: expected 51 columns");
  for (int64_t r = 0; r < rows; ++r) {
    Eigen::VectorXd q(kJoints);
    for (int j = 0; j < kJoints; ++j) q[j] = three ? a.At({clip, r, 2 * j}) : a.At({r, 2 * j});
    t.q.push_back(q);
  }
  return t;
}

}  // namespace

Json CompareWithReference(const ReferenceMotion& motion, const std::string& dir) {
  const std::string bvh = motion.meta().at("source").at("bvh").get<std::string>();
  std::string file, array;
  std::vector<double> scales;
  if (bvh.rfind("08_", 0) == 0) {
    const int trial = std::stoi(bvh.substr(3, 2));
    char name[32];
    std::snprintf(name, sizeof(name), "qpos_%02d", trial - 1);
    file = "cmu_mocap_walk_plain.npz";
    array = name;
    scales = {1.0};  // same take at the same (correct) rate
  } else if (bvh.rfind("69_", 0) == 0) {
    file = "cmu_mocap_turn.npz";  // 69_13, a different take of the same subject's turns
    array = "qpos";
    scales = {1.0};  // both at the true 120 Hz; a different take, so only the offset is searched
  } else if (bvh.rfind("143_", 0) == 0) {
    file = "cmu_mocap_sit_plain.npz";
    array = "qpos";
  } else {
    return Json{{"skipped", "no authors' array for " + bvh}};
  }
  if (scales.empty()) {
    // 143_18: the authors read it at 120 Hz, its header says 60 Hz; search the speed too.
    for (int s = 6; s <= 30; ++s) scales.push_back(0.05 * s);
  }
  const std::string path = dir + "/" + file;
  if (!std::filesystem::exists(path)) return Json{{"skipped", path + " not found"}};
  const auto npz = LoadNpz(path);
  if (!npz.count(array)) throw ConfigError(path + ": no array '" + array + "'");
  const Trajectory ref = FromQpos(npz.at(array), 0);
  // Our frames; a loop is compared over one cycle.
  const int n = motion.num_frames();
  const double dt = motion.frame_time();
  double best = 1e300, best_scale = 1, best_offset = 0, best_at_unit = 1e300, unit_offset = 0;
  for (double s : scales) {
    const double span = s * (n - 1) * dt;
    for (double o = 0; o + span <= ref.duration() + 1e-9; o += kAuthorsFrameTime / 2) {
      double se = 0;
      for (int i = 0; i < n; ++i) {
        const Eigen::VectorXd& q = motion.frame(i).q;
        for (int j = 0; j < kJoints; ++j) {
          const double d = q[j] - ref.At(o + s * i * dt, j);
          se += d * d;
        }
      }
      const double rms = std::sqrt(se / (n * kJoints));
      if (rms < best) best = rms, best_scale = s, best_offset = o;
      if (std::abs(s - 1.0) < 1e-9 && rms < best_at_unit) best_at_unit = rms, unit_offset = o;
    }
  }
  if (best >= 1e300) return Json{{"skipped", "authors' clip shorter than ours"}};
  Json per = Json::object();
  const auto& names = motion.meta().at("joint_names");
  for (int j = 0; j < kJoints; ++j) {
    double se = 0;
    for (int i = 0; i < n; ++i) {
      const double d = motion.frame(i).q[j] - ref.At(best_offset + best_scale * i * dt, j);
      se += d * d;
    }
    per[names[j].get<std::string>()] = std::sqrt(se / n);
  }
  return Json{{"file", file},
              {"array", array},
              {"time_scale", best_scale},  // our 1 s = their time_scale s
              {"offset_s", best_offset},
              {"rms_rad", best},
              {"rms_rad_at_time_scale_1", best_at_unit},
              {"offset_s_at_time_scale_1", unit_offset},
              {"per_joint_rms_rad", per}};
}

}  // namespace perch
