#include "envs/chair.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "common/paths.h"

namespace perch {
namespace {

Eigen::Vector3d ReadVec3(const Json& j, const char* key, const std::string& ctx) {
  std::vector<double> v;
  GetRequired(j, key, v, ctx);
  if (v.size() != 3) throw ConfigError(ctx + "." + key + ": expected 3 numbers");
  for (double x : v) {
    if (!std::isfinite(x)) throw ConfigError(ctx + "." + key + ": not finite");
  }
  return Eigen::Vector3d(v[0], v[1], v[2]);
}

double ReadLength(const Json& j, const char* key, double fallback, bool allow_zero,
                  const std::string& ctx) {
  double v = fallback;
  GetOptional(j, key, v, ctx);
  if (!std::isfinite(v) || v < 0.0 || (!allow_zero && v == 0.0)) {
    throw ConfigError(ctx + "." + key + ": must be " + (allow_zero ? ">= 0" : "> 0"));
  }
  return v;
}

ChairBox Box(const char* role, double x0, double x1, double y0, double y1, double z0, double z1) {
  ChairBox b;
  b.role = role;
  b.min = Eigen::Vector3d(x0, y0, z0);
  b.max = Eigen::Vector3d(x1, y1, z1);
  return b;
}

// Boxes of a four-legged chair centred under the seat, facing +x.
std::vector<ChairBox> BuildParametric(const Json& p, const std::string& ctx) {
  CheckKnownKeys(
      p,
      {"seat_height", "seat_width", "seat_depth", "seat_thickness", "leg_size", "leg_clearance",
       "backrest_height", "backrest_thickness", "armrest_height", "armrest_width"},
      ctx);
  const double h = ReadLength(p, "seat_height", 0.4029, false, ctx);
  const double w = ReadLength(p, "seat_width", 0.378, false, ctx);
  const double d = ReadLength(p, "seat_depth", 0.342, false, ctx);
  const double t = ReadLength(p, "seat_thickness", 0.062, false, ctx);
  const double leg = ReadLength(p, "leg_size", 0.042, false, ctx);
  const double gap = ReadLength(p, "leg_clearance", 0.001, true, ctx);
  const double back_h = ReadLength(p, "backrest_height", 0.0, true, ctx);
  const double back_t = ReadLength(p, "backrest_thickness", 0.05, false, ctx);
  const double arm_h = ReadLength(p, "armrest_height", 0.0, true, ctx);
  const double arm_w = ReadLength(p, "armrest_width", 0.05, false, ctx);
  if (t >= h) throw ConfigError(ctx + ".seat_thickness: must be below seat_height");
  if (2 * leg >= std::min(w, d)) throw ConfigError(ctx + ".leg_size: legs wider than the seat");
  std::vector<ChairBox> boxes;
  const double x0 = -d / 2, x1 = d / 2, y0 = -w / 2, y1 = w / 2;
  boxes.push_back(Box("seat", x0, x1, y0, y1, h - t, h));
  for (int sx : {0, 1}) {
    for (int sy : {0, 1}) {
      const double lx = sx ? x1 - leg : x0, ly = sy ? y1 - leg : y0;
      boxes.push_back(Box("leg", lx, lx + leg, ly, ly + leg, gap, h - t));
    }
  }
  if (back_h > 0) boxes.push_back(Box("backrest", x0 - back_t, x0, y0, y1, h - t, h + back_h));
  if (arm_h > 0) {
    boxes.push_back(Box("armrest", x0, x1, y0 - arm_w, y0, h - t, h + arm_h));
    boxes.push_back(Box("armrest", x0, x1, y1, y1 + arm_w, h - t, h + arm_h));
  }
  return boxes;
}

// Inertia of a solid filling [lo, hi] unless the file gives com / inertia.
void SetMassProperties(const Json& j, const std::string& ctx, const Eigen::Vector3d& lo,
                       const Eigen::Vector3d& hi, Chair* c) {
  const Eigen::Vector3d e = hi - lo;
  c->inertia = c->mass / 12.0 *
               Eigen::Vector3d(e.y() * e.y() + e.z() * e.z(), e.x() * e.x() + e.z() * e.z(),
                               e.x() * e.x() + e.y() * e.y());
  if (j.contains("com")) c->com = ReadVec3(j, "com", ctx);
  if (j.contains("inertia")) {
    c->inertia = ReadVec3(j, "inertia", ctx);
    if (c->inertia.minCoeff() <= 0.0) throw ConfigError(ctx + ".inertia: must be > 0");
  }
}

}  // namespace

std::string Chair::PresetPath(const std::string& preset) {
  return ResolveProjectPath("data/chairs/" + preset + ".json");
}

std::string Chair::ResolvePath(const std::string& preset_or_path) {
  const std::string& p = preset_or_path;
  if (p.find('/') != std::string::npos || (p.size() > 5 && p.substr(p.size() - 5) == ".json")) {
    return p;
  }
  return PresetPath(p);
}

std::vector<std::string> Chair::PresetNames() {
  std::vector<std::string> names;
  const std::filesystem::path dir = std::filesystem::path(ResolveProjectPath("data/chairs"));
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (e.path().extension() == ".json") names.push_back(e.path().stem().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

// A chair from the mesh keys of `j`; `c` holds what FromJson read already.
static Chair FromMeshJson(const Json& j, const std::string& ctx, Chair c) {
  if (j.contains("seat_target")) {
    throw ConfigError(ctx + ".seat_target: a mesh chair takes 'seat' (file units and axes)");
  }
  auto mesh = std::make_shared<MeshChair>(LoadMeshChair(j, ctx, c.dynamic));
  const Eigen::AlignedBox3d box = mesh->visual.Bounds();
  c.com = box.center();  // the bounding box's centre: a mesh need not be closed to have a volume
  SetMassProperties(j, ctx, box.min(), box.max(), &c);
  c.seat_target = mesh->seat_target;
  c.mesh = std::move(mesh);
  return c;
}

Chair Chair::Load(const std::string& path) { return FromJson(LoadJsonFile(path), path); }

std::optional<double> Chair::backrest_front_x() const {
  if (mesh) return mesh->backrest_front_x;
  std::optional<double> x;
  for (const ChairBox& b : boxes) {
    if (b.role == "backrest" && (!x || b.max.x() > *x)) x = b.max.x();
  }
  return x;
}

Chair Chair::FromJson(const Json& j, const std::string& ctx) {
  CheckKnownKeys(j,
                 {"_comment", "name", "source", "boxes", "parametric", "mesh", "scale", "up_axis",
                  "collision_mesh", "seat", "facing_deg", "mass", "dynamic", "static", "com",
                  "inertia", "seat_target"},
                 ctx);
  Chair c;
  GetRequired(j, "name", c.name, ctx);
  GetOptional(j, "source", c.source, ctx);
  const int kinds = j.contains("boxes") + j.contains("parametric") + j.contains("mesh");
  if (kinds != 1) throw ConfigError(ctx + ": give exactly one of 'boxes', 'parametric' or 'mesh'");
  if (j.contains("dynamic") && j.contains("static")) {
    throw ConfigError(ctx + ": give one of 'dynamic' or 'static', not both");
  }
  GetOptional(j, "dynamic", c.dynamic, ctx);
  if (j.contains("static")) {
    bool is_static = false;
    GetRequired(j, "static", is_static, ctx);
    c.dynamic = !is_static;
  }
  GetOptional(j, "mass", c.mass, ctx);
  if (!(c.mass > 0.0)) throw ConfigError(ctx + ".mass: must be > 0");
  if (j.contains("mesh")) return FromMeshJson(j, ctx, std::move(c));
  for (const char* key : {"scale", "up_axis", "collision_mesh", "seat", "facing_deg"}) {
    if (j.contains(key)) throw ConfigError(ctx + "." + key + ": only a 'mesh' chair takes it");
  }
  if (j.contains("boxes")) {
    const Json& jb = j["boxes"];
    if (!jb.is_array() || jb.empty()) throw ConfigError(ctx + ".boxes: expected a non-empty array");
    for (size_t i = 0; i < jb.size(); ++i) {
      const std::string bctx = ctx + ".boxes[" + std::to_string(i) + "]";
      CheckKnownKeys(jb[i], {"role", "min", "max"}, bctx);
      ChairBox b;
      GetRequired(jb[i], "role", b.role, bctx);
      b.min = ReadVec3(jb[i], "min", bctx);
      b.max = ReadVec3(jb[i], "max", bctx);
      if ((b.max - b.min).minCoeff() <= 0.0) throw ConfigError(bctx + ".max: must exceed min");
      c.boxes.push_back(b);
    }
  } else {
    c.boxes = BuildParametric(j["parametric"], ctx + ".parametric");
  }
  for (size_t i = 0; i < c.boxes.size(); ++i) {
    const std::string& r = c.boxes[i].role;
    if (r != "seat" && r != "leg" && r != "backrest" && r != "armrest") {
      throw ConfigError(ctx + ".boxes[" + std::to_string(i) + "].role: unknown role '" + r + "'");
    }
    if (r == "seat") {
      if (c.seat_box >= 0) throw ConfigError(ctx + ".boxes: more than one seat");
      c.seat_box = static_cast<int>(i);
    }
  }
  if (c.seat_box < 0) throw ConfigError(ctx + ".boxes: no box has role 'seat'");
  // Defaults: com at the volume centroid, inertia of a solid of the boxes' bounding box.
  double vol = 0.0;
  Eigen::Vector3d moment = Eigen::Vector3d::Zero();
  Eigen::Vector3d lo = c.boxes[0].min, hi = c.boxes[0].max;
  for (const ChairBox& b : c.boxes) {
    const double v = (b.max - b.min).prod();
    vol += v;
    moment += v * b.center();
    lo = lo.cwiseMin(b.min);
    hi = hi.cwiseMax(b.max);
  }
  c.com = moment / vol;
  SetMassProperties(j, ctx, lo, hi, &c);
  const ChairBox& seat = c.boxes[c.seat_box];
  c.seat_target = Eigen::Vector3d(seat.center().x(), seat.center().y(), seat.max.z());
  if (j.contains("seat_target")) c.seat_target = ReadVec3(j, "seat_target", ctx);
  return c;
}

}  // namespace perch
