#include "envs/chair_mesh.h"

#include <BulletCollision/CollisionShapes/btConvexHullShape.h>
#include <BulletCollision/CollisionShapes/btShapeHull.h>
#include <hacdHACD.h>
#include <tiny_obj_loader.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>

#include "common/paths.h"

namespace perch {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::string Num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// tinyobjloader reads "nan" or "1e999" as 0 without a word, so the vertex lines are checked first.
void CheckFiniteVertices(const std::string& path, const std::string& ctx) {
  std::ifstream in(path);
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.size() < 2 || line[0] != 'v' || (line[1] != ' ' && line[1] != '\t')) continue;
    std::istringstream fields(line.substr(2));
    std::string tok;
    for (int k = 0; k < 3; ++k) {
      if (!(fields >> tok)) {
        throw ConfigError(ctx + ": " + path + ":" + std::to_string(lineno) +
                          ": a vertex needs 3 coordinates");
      }
      char* end = nullptr;
      const double v = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0' || !std::isfinite(v)) {
        throw ConfigError(ctx + ": " + path + ":" + std::to_string(lineno) +
                          ": vertex coordinate '" + tok + "' is not a finite number");
      }
    }
  }
}

// The OBJ's objects ("o"/"g"), each a triangle mesh in file units; vertices shared by all.
struct ObjFile {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::vector<std::array<int, 3>>> parts;  // triangles of each object
  std::vector<std::string> part_names;
};

ObjFile ReadObj(const std::string& path, const std::string& ctx) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw ConfigError(ctx + ": mesh file '" + path + "' not found");
  }
  CheckFiniteVertices(path, ctx);
  tinyobj::ObjReaderConfig rc;
  rc.triangulate = true;
  rc.vertex_color = false;
  tinyobj::ObjReader reader;
  if (!reader.ParseFromFile(path, rc)) {
    throw ConfigError(ctx + ": " + path + ": not a readable OBJ: " + reader.Error());
  }
  ObjFile f;
  const auto& v = reader.GetAttrib().vertices;
  f.vertices.reserve(v.size() / 3);
  for (size_t i = 0; i + 2 < v.size(); i += 3) f.vertices.emplace_back(v[i], v[i + 1], v[i + 2]);
  const int nv = static_cast<int>(f.vertices.size());
  for (const tinyobj::shape_t& s : reader.GetShapes()) {
    std::vector<std::array<int, 3>> tris;
    const auto& idx = s.mesh.indices;
    for (size_t k = 0; k + 2 < idx.size(); k += 3) {
      std::array<int, 3> t{idx[k].vertex_index, idx[k + 1].vertex_index, idx[k + 2].vertex_index};
      for (int i : t) {
        if (i < 0 || i >= nv) {
          throw ConfigError(ctx + ": " + path + ": a face names vertex " + std::to_string(i + 1) +
                            " of " + std::to_string(nv));
        }
      }
      tris.push_back(t);
    }
    if (tris.empty()) continue;
    f.parts.push_back(std::move(tris));
    f.part_names.push_back(s.name);
  }
  if (f.parts.empty()) throw ConfigError(ctx + ": " + path + ": the mesh has no faces");
  return f;
}

TriMesh Whole(const ObjFile& f) {
  TriMesh m;
  m.vertices = f.vertices;
  for (const auto& p : f.parts) m.triangles.insert(m.triangles.end(), p.begin(), p.end());
  return m;
}

// File units and axes -> metres, z up.
Eigen::Matrix3d FileToMetric(double scale, const std::string& up_axis) {
  Eigen::Matrix3d up = Eigen::Matrix3d::Identity();
  if (up_axis == "y") up << 1, 0, 0, 0, 0, -1, 0, 1, 0;  // +90 deg about x: file +y -> +z
  return scale * up;
}

Eigen::Vector3d TriNormalArea(const TriMesh& m, const std::array<int, 3>& t, double* area) {
  const Eigen::Vector3d n =
      (m.vertices[t[1]] - m.vertices[t[0]]).cross(m.vertices[t[2]] - m.vertices[t[0]]);
  *area = 0.5 * n.norm();
  return *area > 0.0 ? Eigen::Vector3d(n / (2.0 * *area)) : Eigen::Vector3d::Zero();
}

Eigen::Vector3d Centroid(const TriMesh& m, const std::array<int, 3>& t) {
  return (m.vertices[t[0]] + m.vertices[t[1]] + m.vertices[t[2]]) / 3.0;
}

struct FoundSeat {
  double height = 0.0;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  double area = 0.0;
  double z_lo = 0.0, z_hi = 0.0;  // the band's upward triangles have centroids in [z_lo, z_hi]
};

// The band of `finder.band` at sitting height with the most upward-facing area (z-up, floor 0).
std::optional<FoundSeat> FindSeat(const TriMesh& m, const SeatFinderConfig& finder) {
  struct Up {
    double z, area;
    Eigen::Vector2d xy;
  };
  std::vector<Up> up;
  for (const auto& t : m.triangles) {
    double a = 0.0;
    const Eigen::Vector3d n = TriNormalArea(m, t, &a);
    const Eigen::Vector3d c = Centroid(m, t);
    if (a <= 0.0 || n.z() < finder.upward_cos) continue;
    if (c.z() < finder.min_seat_height || c.z() > finder.max_seat_height) continue;
    up.push_back({c.z(), a, c.head<2>()});
  }
  if (up.empty()) return std::nullopt;
  std::sort(up.begin(), up.end(), [](const Up& a, const Up& b) { return a.z < b.z; });
  // Sliding window [z_i, z_i + band]: the one with the most area (ties: the lowest).
  size_t best_lo = 0, best_hi = 0, hi = 0;
  double best = -1.0, sum = 0.0;
  for (size_t lo = 0; lo < up.size(); ++lo) {
    while (hi < up.size() && up[hi].z <= up[lo].z + finder.band) sum += up[hi++].area;
    if (sum > best * (1.0 + 1e-9)) {
      best = sum;
      best_lo = lo;
      best_hi = hi;
    }
    sum -= up[lo].area;
  }
  FoundSeat s;
  s.z_lo = up[best_lo].z;
  s.z_hi = up[best_hi - 1].z;
  for (size_t i = best_lo; i < best_hi; ++i) {
    s.area += up[i].area;
    s.height += up[i].area * up[i].z;
    s.centre += up[i].area * up[i].xy;
  }
  s.height /= s.area;
  s.centre /= s.area;
  return s;
}

using Polygon = std::vector<Eigen::Vector3d>;

// The part of convex polygon `in` where n . p >= d (exact, so how a face is split into triangles
// changes nothing found from it).
Polygon Clip(const Polygon& in, const Eigen::Vector3d& n, double d) {
  Polygon out;
  for (size_t k = 0; k < in.size(); ++k) {
    const Eigen::Vector3d& a = in[k];
    const Eigen::Vector3d& b = in[(k + 1) % in.size()];
    const double da = n.dot(a) - d, db = n.dot(b) - d;
    if (da >= 0.0) out.push_back(a);
    if ((da >= 0.0) != (db >= 0.0)) out.push_back(a + (b - a) * (da / (da - db)));
  }
  return out;
}

Polygon Tri(const TriMesh& m, const std::array<int, 3>& t) {
  return {m.vertices[t[0]], m.vertices[t[1]], m.vertices[t[2]]};
}

// Area and area moment (xy) of the part of triangle `t` above z = zt.
double AreaAbove(const TriMesh& m, const std::array<int, 3>& t, double zt,
                 Eigen::Vector2d* moment) {
  const Polygon poly = Clip(Tri(m, t), Eigen::Vector3d::UnitZ(), zt);
  double area = 0.0;
  for (size_t k = 1; k + 1 < poly.size(); ++k) {
    const double a = 0.5 * (poly[k] - poly[0]).cross(poly[k + 1] - poly[0]).norm();
    area += a;
    *moment += a * ((poly[0] + poly[k] + poly[k + 1]) / 3.0).head<2>();
  }
  return area;
}

// Facing [rad] from the file's +x: away from the area centroid of everything well above the seat.
std::optional<double> FindFacing(const TriMesh& m, const Eigen::Vector2d& seat_xy, double seat_h,
                                 const SeatFinderConfig& finder) {
  double area = 0.0;
  Eigen::Vector2d moment = Eigen::Vector2d::Zero();
  for (const auto& t : m.triangles)
    area += AreaAbove(m, t, seat_h + finder.back_above_seat, &moment);
  if (area <= 0.0) return std::nullopt;
  const Eigen::Vector2d away = seat_xy - moment / area;
  if (away.norm() < finder.min_back_offset) return std::nullopt;
  return std::atan2(away.y(), away.x());
}

// The highest point of `parts` on the vertical line through the chair frame's origin; none when
// the line misses them all.
std::optional<double> TopAtOrigin(const std::vector<TriMesh>& parts) {
  std::optional<double> top;
  for (const TriMesh& m : parts) {
    for (const auto& t : m.triangles) {
      const Eigen::Vector3d& a = m.vertices[t[0]];
      const Eigen::Vector3d& b = m.vertices[t[1]];
      const Eigen::Vector3d& c = m.vertices[t[2]];
      // Barycentric coordinates of (0, 0) in the triangle's xy projection.
      const double det = (b.x() - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (b.y() - a.y());
      if (std::abs(det) < 1e-12) continue;
      const double u = ((0 - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (0 - a.y())) / det;
      const double v = ((b.x() - a.x()) * (0 - a.y()) - (0 - a.x()) * (b.y() - a.y())) / det;
      if (u < 0 || v < 0 || u + v > 1) continue;
      const double z = a.z() + u * (b.z() - a.z()) + v * (c.z() - a.z());
      if (!top || z > *top) top = z;
    }
  }
  return top;
}

// A decomposition that fills the space over the seat (a hull joining the seat to the backrest)
// would hold the pelvis above the seat: refused.
void CheckSeatKept(const std::vector<TriMesh>& parts, double seat_h, const ChairMeshLimits& limits,
                   const std::string& ctx) {
  const std::optional<double> top = TopAtOrigin(parts);
  if (!top || std::abs(*top - seat_h) > limits.max_seat_error) {
    throw ConfigError(ctx +
                      ": the convex decomposition (HACD) does not keep the seat: its top over "
                      "the seat target is " +
                      (top ? Num(*top) + " m" : std::string("missing")) + ", the seat is at " +
                      Num(seat_h) +
                      " m; give a \"collision_mesh\" of convex "
                      "parts or make it \"static\"");
  }
}

uint64_t Fnv1a(const void* data, size_t n, uint64_t h) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ULL;
  return h;
}

std::string ReadString(const Json& j, const char* key, const std::string& fallback,
                       const std::string& ctx) {
  std::string v = fallback;
  GetOptional(j, key, v, ctx);
  return v;
}

// "shared:chairs/X.obj" is ../shared/chairs/X.obj beside the data root (the project does not copy
// the shared meshes); other relative paths are relative to the chair file.
std::string ResolveBeside(const std::string& ctx, const std::string& rel) {
  if (rel.rfind("shared:", 0) == 0) {
    const std::string shared = SharedDir();
    if (shared.empty()) {
      throw ConfigError(ctx + ": '" + rel +
                        "' names ../shared beside the data root, which is absent");
    }
    return (std::filesystem::path(shared) / rel.substr(7)).lexically_normal().string();
  }
  const std::filesystem::path p(rel);
  if (p.is_absolute()) return rel;
  return (std::filesystem::path(ctx).parent_path() / p).lexically_normal().string();
}

}  // namespace

void TriMesh::Append(const TriMesh& other) {
  const int base = static_cast<int>(vertices.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  for (const auto& t : other.triangles)
    triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
}

TriMesh TriMesh::Transformed(const Eigen::Isometry3d& t) const {
  TriMesh m = *this;
  for (Eigen::Vector3d& v : m.vertices) v = t * v;
  return m;
}

Eigen::AlignedBox3d TriMesh::Bounds() const {
  Eigen::AlignedBox3d b;
  for (const Eigen::Vector3d& v : vertices) b.extend(v);
  return b;
}

TriMesh ConvexHull(const std::vector<Eigen::Vector3d>& points) {
  btConvexHullShape shape;
  for (const Eigen::Vector3d& p : points) {
    shape.addPoint(btVector3(btScalar(p.x()), btScalar(p.y()), btScalar(p.z())), false);
  }
  shape.recalcLocalAabb();
  shape.setMargin(0);
  btShapeHull hull(&shape);
  hull.buildHull(0);
  TriMesh m;
  for (int i = 0; i < hull.numVertices(); ++i) {
    const btVector3& v = hull.getVertexPointer()[i];
    m.vertices.emplace_back(v.x(), v.y(), v.z());
  }
  if (m.vertices.size() < 4) {
    // btShapeHull gives nothing for a flat or degenerate set: keep the points (a flat hull).
    m.vertices = points;
    return m;
  }
  const unsigned int* idx = hull.getIndexPointer();
  for (int i = 0; i + 2 < hull.numIndices(); i += 3) {
    m.triangles.push_back(
        {static_cast<int>(idx[i]), static_cast<int>(idx[i + 1]), static_cast<int>(idx[i + 2])});
  }
  return m;
}

std::vector<TriMesh> ConvexDecomposition(const TriMesh& mesh, const ChairMeshLimits& limits,
                                         const std::string& ctx) {
  const int nt = static_cast<int>(mesh.triangles.size());
  if (nt > limits.max_decompose_triangles) {
    throw ConfigError(ctx + ": the mesh has " + std::to_string(nt) +
                      " triangles, too large to decompose into convex parts for a dynamic chair "
                      "(limit " +
                      std::to_string(limits.max_decompose_triangles) +
                      "); give a \"collision_mesh\" of convex parts or make it \"static\"");
  }
  uint64_t key = 1469598103934665603ULL;
  for (const Eigen::Vector3d& v : mesh.vertices) key = Fnv1a(v.data(), 3 * sizeof(double), key);
  for (const auto& t : mesh.triangles) key = Fnv1a(t.data(), 3 * sizeof(int), key);
  static std::mutex mu;
  static std::map<uint64_t, std::vector<TriMesh>> cache;
  {
    std::lock_guard<std::mutex> lock(mu);
    auto it = cache.find(key);
    if (it != cache.end()) return it->second;
  }
  std::vector<HACD::Vec3<HACD::Real>> points;
  points.reserve(mesh.vertices.size());
  for (const Eigen::Vector3d& v : mesh.vertices) points.emplace_back(v.x(), v.y(), v.z());
  std::vector<HACD::Vec3<long>> tris;
  tris.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) tris.emplace_back(t[0], t[1], t[2]);
  HACD::HACD hacd;
  hacd.SetPoints(points.data());
  hacd.SetNPoints(points.size());
  hacd.SetTriangles(tris.data());
  hacd.SetNTriangles(tris.size());
  hacd.SetCompacityWeight(0.1);
  hacd.SetVolumeWeight(0.0);
  hacd.SetNClusters(1);
  hacd.SetNVerticesPerCH(64);
  // HACD scales the mesh to 1000 units: a part's surface may lie 2% of the chair's size inside
  // its hull (the shared meshes: 9 to 30 parts, about a second each).
  hacd.SetScaleFactor(1000.0);
  hacd.SetConcavity(20.0);
  hacd.SetAddExtraDistPoints(false);
  hacd.SetAddFacesPoints(false);
  hacd.SetAddNeighboursDistPoints(false);
  if (!hacd.Compute()) throw ConfigError(ctx + ": the convex decomposition (HACD) failed");
  const size_t n = hacd.GetNClusters();
  if (static_cast<int>(n) > limits.max_convex_parts) {
    throw ConfigError(
        ctx + ": too concave for real-time stepping as a dynamic chair: " + std::to_string(n) +
        " convex parts (limit " + std::to_string(limits.max_convex_parts) +
        "); give a \"collision_mesh\" of fewer parts or make it \"static\"");
  }
  std::vector<TriMesh> parts;
  for (size_t c = 0; c < n; ++c) {
    std::vector<HACD::Vec3<HACD::Real>> cp(hacd.GetNPointsCH(c));
    std::vector<HACD::Vec3<long>> ct(hacd.GetNTrianglesCH(c));
    if (cp.size() < 4) continue;
    hacd.GetCH(c, cp.data(), ct.data());
    std::vector<Eigen::Vector3d> pts;
    for (const auto& p : cp) pts.emplace_back(p.X(), p.Y(), p.Z());
    parts.push_back(ConvexHull(pts));
  }
  if (parts.empty()) throw ConfigError(ctx + ": the convex decomposition (HACD) found no parts");
  std::lock_guard<std::mutex> lock(mu);
  cache.emplace(key, parts);
  return parts;
}

MeshChair LoadMeshChair(const Json& j, const std::string& ctx, bool need_convex,
                        const ChairMeshLimits& limits, const SeatFinderConfig& finder) {
  MeshChair out;
  MeshChairInfo& info = out.info;
  std::string mesh_rel;
  GetRequired(j, "mesh", mesh_rel, ctx);
  info.mesh_path = ResolveBeside(ctx, mesh_rel);
  GetOptional(j, "scale", info.scale, ctx);
  if (!std::isfinite(info.scale) || info.scale <= 0.0) {
    throw ConfigError(ctx + ".scale: must be > 0 metres per file unit");
  }
  info.up_axis = ReadString(j, "up_axis", "z", ctx);
  if (info.up_axis != "y" && info.up_axis != "z") {
    throw ConfigError(ctx + ".up_axis: '" + info.up_axis + "', expected \"y\" or \"z\"");
  }
  const ObjFile file = ReadObj(info.mesh_path, ctx);
  const Eigen::Matrix3d to_metric = FileToMetric(info.scale, info.up_axis);
  TriMesh metric = Whole(file);
  for (Eigen::Vector3d& v : metric.vertices) v = to_metric * v;
  info.mesh_vertices = static_cast<int>(metric.vertices.size());
  info.mesh_triangles = static_cast<int>(metric.triangles.size());
  const Eigen::AlignedBox3d box = metric.Bounds();
  const Eigen::Vector3d size = box.sizes();
  if (size.z() < limits.min_height || size.z() > limits.max_height ||
      size.head<2>().maxCoeff() > limits.max_extent) {
    throw ConfigError(ctx + ": " + info.mesh_path + " is " + Num(size.x()) + " x " + Num(size.y()) +
                      " x " + Num(size.z()) + " m at scale " + Num(info.scale) + " (up " +
                      info.up_axis + "): an absurd size for a chair (height " +
                      Num(limits.min_height) + ".." + Num(limits.max_height) + " m, extent <= " +
                      Num(limits.max_extent) + " m); check \"scale\" and \"up_axis\"");
  }
  const double floor_z = box.min().z();
  for (Eigen::Vector3d& v : metric.vertices) v.z() -= floor_z;

  // Seat: given (file units and axes) or the largest upward surface at sitting height.
  Eigen::Vector3d seat;                                 // metric, floor at 0
  Eigen::Vector2d seat_band = Eigen::Vector2d::Zero();  // the found seat's [z_lo, z_hi] [m]
  if (j.contains("seat")) {
    std::vector<double> s;
    GetRequired(j, "seat", s, ctx);
    if (s.size() != 3 || !std::isfinite(s[0]) || !std::isfinite(s[1]) || !std::isfinite(s[2])) {
      throw ConfigError(ctx + ".seat: expected 3 finite numbers (file units and axes)");
    }
    seat = to_metric * Eigen::Vector3d(s[0], s[1], s[2]);
    seat.z() -= floor_z;
    info.seat_source = "file";
  } else {
    const std::optional<FoundSeat> found = FindSeat(metric, finder);
    if (!found) {
      throw ConfigError(ctx + ": " + info.mesh_path + ": no upward-facing surface between " +
                        Num(finder.min_seat_height) + " and " + Num(finder.max_seat_height) +
                        " m to sit on; give \"seat\" [x, y, z] or check \"up_axis\"");
    }
    seat = Eigen::Vector3d(found->centre.x(), found->centre.y(), found->height);
    info.seat_area_m2 = found->area;
    seat_band = Eigen::Vector2d(found->z_lo, found->z_hi);
    info.seat_source = "found";
  }
  // Facing: given, away from the backrest, or the file's +x.
  double facing = 0.0;
  if (j.contains("facing_deg")) {
    GetRequired(j, "facing_deg", info.facing_deg, ctx);
    if (!std::isfinite(info.facing_deg)) throw ConfigError(ctx + ".facing_deg: not finite");
    facing = info.facing_deg * kPi / 180.0;
    info.facing_source = "file";
  } else if (auto f = FindFacing(metric, seat.head<2>(), seat.z(), finder)) {
    facing = *f;
    info.facing_deg = facing * 180.0 / kPi;
    info.facing_source = "backrest";
  } else {
    info.facing_source = "default";
  }
  // A deep seat's target: at most max_front_depth behind the front edge of the seat surface
  // (its foremost point within back_half_width of the target, in the facing direction).
  if (info.seat_source == "found") {
    const Eigen::Vector2d fwd(std::cos(facing), std::sin(facing));
    const Eigen::Vector3d f3(fwd.x(), fwd.y(), 0.0), left(-fwd.y(), fwd.x(), 0.0);
    const Eigen::Vector3d at(seat.x(), seat.y(), 0.0);
    std::optional<double> front;
    for (const auto& t : metric.triangles) {
      double a = 0.0;
      const Eigen::Vector3d n = TriNormalArea(metric, t, &a);
      const double cz = Centroid(metric, t).z();
      if (a <= 0.0 || n.z() < finder.upward_cos || cz < seat_band.x() || cz > seat_band.y()) {
        continue;
      }
      Polygon p = Tri(metric, t);
      p = Clip(p, left, left.dot(at) - finder.back_half_width);
      p = Clip(p, -left, -left.dot(at) - finder.back_half_width);
      for (const Eigen::Vector3d& v : p) {
        const double x = f3.dot(v - at);
        if (!front || x > *front) front = x;
      }
    }
    if (front && *front > finder.max_front_depth) {
      info.seat_moved_forward_m = *front - finder.max_front_depth;
      seat.head<2>() += info.seat_moved_forward_m * fwd;
    }
  }
  // Chair frame: origin on the floor under the seat target, facing +x.
  Eigen::Isometry3d to_chair = Eigen::Isometry3d::Identity();
  to_chair.rotate(Eigen::AngleAxisd(-facing, Eigen::Vector3d::UnitZ()));
  to_chair.translate(-Eigen::Vector3d(seat.x(), seat.y(), 0.0));
  Eigen::Isometry3d floor_shift = Eigen::Isometry3d::Identity();
  floor_shift.translate(Eigen::Vector3d(0, 0, -floor_z));
  info.file_to_chair = to_chair * floor_shift;
  info.seat_file = to_metric.inverse() * (seat + Eigen::Vector3d(0, 0, floor_z));
  out.visual = metric.Transformed(to_chair);
  out.seat_target = Eigen::Vector3d(0.0, 0.0, seat.z());
  info.size = out.visual.Bounds().sizes();
  // Backrest front (for a start pose seated in front of it): the foremost surface point behind
  // the seat target (x <= 0), above the seat, within the seat's width.
  for (const auto& t : out.visual.triangles) {
    Polygon p =
        Clip(Tri(out.visual, t), Eigen::Vector3d::UnitZ(), seat.z() + finder.back_above_seat_min);
    p = Clip(p, Eigen::Vector3d::UnitY(), -finder.back_half_width);
    p = Clip(p, -Eigen::Vector3d::UnitY(), -finder.back_half_width);
    p = Clip(p, -Eigen::Vector3d::UnitX(), 0.0);
    for (const Eigen::Vector3d& v : p) {
      if (!out.backrest_front_x || v.x() > *out.backrest_front_x) out.backrest_front_x = v.x();
    }
  }

  // Collision: the file's collision mesh where given, else the visual mesh.
  std::optional<ObjFile> coll;
  if (j.contains("collision_mesh")) {
    std::string rel;
    GetRequired(j, "collision_mesh", rel, ctx);
    info.collision_mesh_path = ResolveBeside(ctx, rel);
    coll = ReadObj(info.collision_mesh_path, ctx);
  }
  auto to_chair_metric = [&](const std::vector<Eigen::Vector3d>& vs) {
    std::vector<Eigen::Vector3d> r;
    r.reserve(vs.size());
    for (const Eigen::Vector3d& v : vs) r.push_back(info.file_to_chair * (to_metric * v));
    return r;
  };
  if (coll) {
    out.collision_static.vertices = to_chair_metric(coll->vertices);
    for (const auto& p : coll->parts) {
      out.collision_static.triangles.insert(out.collision_static.triangles.end(), p.begin(),
                                            p.end());
    }
  } else {
    out.collision_static = out.visual;
  }
  info.collision = "triangle mesh";
  info.collision_parts = 1;
  info.collision_triangles = static_cast<int>(out.collision_static.triangles.size());
  if (info.collision_triangles > limits.max_static_triangles) {
    throw ConfigError(ctx + ": " + std::to_string(info.collision_triangles) +
                      " collision triangles, too many for real-time stepping (limit " +
                      std::to_string(limits.max_static_triangles) +
                      "); give a simpler \"collision_mesh\"");
  }
  if (need_convex) {
    if (coll) {
      if (static_cast<int>(coll->parts.size()) > limits.max_convex_parts) {
        throw ConfigError(ctx + ": " + info.collision_mesh_path + " has " +
                          std::to_string(coll->parts.size()) + " objects, more convex parts " +
                          "than real-time stepping allows (limit " +
                          std::to_string(limits.max_convex_parts) + ")");
      }
      const std::vector<Eigen::Vector3d> vs = to_chair_metric(coll->vertices);
      for (const auto& p : coll->parts) {
        std::vector<Eigen::Vector3d> pts;
        for (const auto& t : p) {
          for (int i : t) pts.push_back(vs[i]);
        }
        out.convex_parts.push_back(ConvexHull(pts));
      }
      info.collision = "file parts";
    } else {
      // HACD runs on the mesh as authored (usually axis-aligned): its result changes with a
      // fraction of a degree of rotation, and the hull of moved points is the moved hull.
      for (TriMesh part : ConvexDecomposition(metric, limits, ctx)) {
        for (Eigen::Vector3d& v : part.vertices) v = to_chair * v;
        out.convex_parts.push_back(std::move(part));
      }
      info.collision = "convex decomposition";
      CheckSeatKept(out.convex_parts, seat.z(), limits, ctx);
    }
    info.collision_parts = static_cast<int>(out.convex_parts.size());
    info.collision_triangles = 0;
    for (const TriMesh& p : out.convex_parts) {
      info.collision_triangles += static_cast<int>(p.triangles.size());
    }
  }
  return out;
}

}  // namespace perch
