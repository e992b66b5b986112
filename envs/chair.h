// The immutable chair description in the chair frame (origin on the floor under the seat centre,
// z up, the chair faces +x, backrest towards -x), read from data/chairs/*.json or any chair file:
// axis-aligned boxes, explicit (the authors' chair, notes 5) or from parameters, or a triangle
// mesh from an OBJ file (envs/chair_mesh.h; docs/chairs.md).
#pragma once

#include <Eigen/Core>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/json_util.h"
#include "envs/chair_mesh.h"

namespace perch {

struct ChairBox {
  std::string role;                               // "seat", "leg", "backrest", "armrest"
  Eigen::Vector3d min = Eigen::Vector3d::Zero();  // chair frame [m]
  Eigen::Vector3d max = Eigen::Vector3d::Zero();  // chair frame [m]
  Eigen::Vector3d center() const { return 0.5 * (min + max); }
  Eigen::Vector3d half_extents() const { return 0.5 * (max - min); }
};

struct Chair {
  std::string name;
  std::string source;           // provenance and licence of a mesh (the file's "source"), cited
  std::vector<ChairBox> boxes;  // empty for a mesh chair
  int seat_box = -1;            // index of the box with role "seat"; -1 for a mesh chair
  std::shared_ptr<const MeshChair> mesh;          // null: a box chair
  double mass = 1000.0;                           // [kg]
  bool dynamic = true;                            // false: a static (infinitely heavy, fixed) body
  Eigen::Vector3d com = Eigen::Vector3d::Zero();  // chair frame [m]
  Eigen::Vector3d inertia = Eigen::Vector3d::Ones();  // diagonal, about com [kg m^2]
  // "Seat surface centre": the target of the chair observation, the sit distance and metrics.
  Eigen::Vector3d seat_target = Eigen::Vector3d::Zero();  // chair frame [m]

  // Top of the seat [m]: the seat box's top, or a mesh's seat target height.
  double seat_height() const { return mesh ? mesh->seat_target.z() : boxes[seat_box].max.z(); }
  // The front face of the backrest [m, chair frame x]; none without a backrest.
  std::optional<double> backrest_front_x() const;

  // Throws ConfigError "FILE: field: problem".
  static Chair Load(const std::string& path);
  static Chair FromJson(const Json& j, const std::string& ctx);
  static std::string PresetPath(const std::string& preset);  // data/chairs/<preset>.json
  // A path ending in .json (or holding a '/') as given, else PresetPath.
  static std::string ResolvePath(const std::string& preset_or_path);
  static std::vector<std::string> PresetNames();  // sorted
};

}  // namespace perch
