// Chairs from triangle meshes (OBJ): reading, finding the seat and facing from the geometry, and
// the convex parts a dynamic chair collides with. Used by Chair::FromJson for a chair file that
// names a "mesh"; the result is in the chair frame of envs/chair.h.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <optional>
#include <string>
#include <vector>

#include "common/json_util.h"

namespace perch {

// A triangle mesh; `vertices` in metres in whatever frame the owner says.
struct TriMesh {
  std::vector<Eigen::Vector3d> vertices;      // [m]
  std::vector<std::array<int, 3>> triangles;  // indices into vertices, counter-clockwise = outside
  bool empty() const { return triangles.empty(); }
  void Append(const TriMesh& other);
  TriMesh Transformed(const Eigen::Isometry3d& t) const;
  Eigen::AlignedBox3d Bounds() const;
};

// Limits that keep a mesh chair steppable in real time (docs/chairs.md). A file over one is
// refused with a message naming it, never decomposed or stepped slowly.
struct ChairMeshLimits {
  int max_static_triangles = 200000;    // a static chair's collision triangle mesh
  int max_decompose_triangles = 20000;  // a mesh handed to the convex decomposition
  int max_convex_parts = 48;            // a dynamic chair's convex parts
  double min_height = 0.2;              // the chair's height after its scale [m]
  double max_height = 3.0;              // [m]
  double max_extent = 6.0;              // largest horizontal size [m]
  double max_seat_error = 0.02;  // a decomposition's top over the seat target vs the seat [m]
};

// How the seat is found (the largest upward-facing surface at sitting height) and the facing (away
// from the backrest). Distances in metres, in the z-up frame with the mesh's lowest point at z = 0.
struct SeatFinderConfig {
  double upward_cos = 0.9;       // a triangle faces up when its normal's z >= this (25.8 deg)
  double min_seat_height = 0.2;  // candidate seat surfaces lie between these heights [m]
  double max_seat_height = 0.8;
  double band = 0.04;             // the seat surface is the upward area inside one band this thick
  double back_above_seat = 0.15;  // geometry this far above the seat is backrest or arms [m]
  double min_back_offset = 0.03;  // a backrest centroid closer than this to the seat says nothing
  double back_half_width = 0.15;  // |y| of the backrest's front face the spawn looks at [m]
  double back_above_seat_min = 0.05;  // ... and its height above the seat [m]
  // A found seat target lies at most this far behind the seat surface's front edge (within
  // back_half_width of it) [m]: where a person sits on a deep seat (a sofa), not its centre. The
  // authors' chair has its target 0.206 m behind its front edge; the sit's start is placed from
  // the target, so a target 0.34 m deep (the sofa's centre) starts the humanoid inside the sofa.
  double max_front_depth = 0.21;
};

// What a mesh chair's file said and what was found from its geometry (`perch chair inspect`).
struct MeshChairInfo {
  std::string mesh_path;            // as resolved
  std::string collision_mesh_path;  // empty: none
  double scale = 1.0;               // metres per file unit
  std::string up_axis = "z";
  int mesh_vertices = 0, mesh_triangles = 0;
  Eigen::Vector3d seat_file = Eigen::Vector3d::Zero();  // seat target in the file's own units/axes
  std::string seat_source;                              // "file" or "found"
  double seat_area_m2 = 0.0;  // upward area of the found seat surface (0 when given)
  double seat_moved_forward_m =
      0.0;                    // a deep seat's target moved from the centre (max_front_depth)
  double facing_deg = 0.0;    // about the up axis from the file's +x (after the up-axis turn)
  std::string facing_source;  // "file", "backrest" or "default" (nothing behind the seat)
  std::string collision;      // "triangle mesh", "file parts" or "convex decomposition"
  int collision_parts = 0;
  int collision_triangles = 0;
  Eigen::Isometry3d file_to_chair = Eigen::Isometry3d::Identity();  // after scale and up axis
  Eigen::Vector3d size = Eigen::Vector3d::Zero();  // bounding box in the chair frame [m]
};

// A loaded mesh chair in the chair frame (origin on the floor under the seat target, z up, facing
// +x). `collision_static` is what a static chair collides with; `convex_parts` a dynamic one.
struct MeshChair {
  TriMesh visual;
  TriMesh collision_static;
  std::vector<TriMesh> convex_parts;  // empty unless the chair may be dynamic
  Eigen::Vector3d seat_target = Eigen::Vector3d::Zero();
  std::optional<double> backrest_front_x;  // [m], chair frame; none: no backrest behind the seat
  MeshChairInfo info;
};

// Reads the mesh keys of chair file `ctx` (its directory resolves relative paths): mesh, scale,
// up_axis, collision_mesh, seat, facing_deg. `need_convex` decomposes when there are no file
// parts. Throws ConfigError "FILE: problem" on a missing, empty, non-finite, absurdly scaled,
// seatless or over-limit mesh.
MeshChair LoadMeshChair(const Json& j, const std::string& ctx, bool need_convex,
                        const ChairMeshLimits& limits = {}, const SeatFinderConfig& finder = {});

// Convex hulls of `mesh`'s parts by Bullet's HACD (libbullet-extras); throws ConfigError naming
// `ctx` when the mesh is over the limits. Cached per process by content.
std::vector<TriMesh> ConvexDecomposition(const TriMesh& mesh, const ChairMeshLimits& limits,
                                         const std::string& ctx);

// The convex hull of `points`, reduced by Bullet's btShapeHull to the support points of its 42
// sample directions (a box keeps its 8 corners).
TriMesh ConvexHull(const std::vector<Eigen::Vector3d>& points);

}  // namespace perch
