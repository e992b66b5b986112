// The immutable chair description: a set of axis-aligned boxes in the chair frame (origin on the
// floor under the seat centre, z up, the chair faces +x, backrest towards -x), read from
// data/chairs/*.json either as explicit boxes (the authors' chair, notes 5) or from parameters.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/json_util.h"

namespace perch {

struct ChairBox {
  std::string role;                                // "seat", "leg", "backrest", "armrest"
  Eigen::Vector3d min = Eigen::Vector3d::Zero();   // chair frame [m]
  Eigen::Vector3d max = Eigen::Vector3d::Zero();   // chair frame [m]
  Eigen::Vector3d center() const { return 0.5 * (min + max); }
  Eigen::Vector3d half_extents() const { return 0.5 * (max - min); }
};

struct Chair {
  std::string name;
  std::vector<ChairBox> boxes;
  int seat_box = -1;          // index of the box with role "seat"
  double mass = 1000.0;       // [kg]
  bool dynamic = true;        // false: a static (infinitely heavy, fixed) body
  Eigen::Vector3d com = Eigen::Vector3d::Zero();      // chair frame [m]
  Eigen::Vector3d inertia = Eigen::Vector3d::Ones();  // diagonal, about com [kg m^2]
  // "Seat surface centre": the target of the chair observation, the sit distance and metrics.
  Eigen::Vector3d seat_target = Eigen::Vector3d::Zero();  // chair frame [m]

  double seat_height() const { return boxes[seat_box].max.z(); }  // top of the seat [m]

  // Throws ConfigError "FILE: field: problem".
  static Chair Load(const std::string& path);
  static Chair FromJson(const Json& j, const std::string& ctx);
  static std::string PresetPath(const std::string& preset);  // data/chairs/<preset>.json
  static std::vector<std::string> PresetNames();              // sorted
};

}  // namespace perch
