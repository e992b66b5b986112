#include "envs/env_config.h"

#include <algorithm>
#include <cmath>

#include "common/paths.h"

namespace perch {
namespace {

std::string Resolve(const std::string& path) { return ResolveProjectPath(path); }

void CheckRange(const std::array<double, 2>& r, const std::string& where) {
  if (!(r[0] >= 0.0 && r[0] <= r[1] && r[1] <= 180.0)) {
    throw ConfigError(where + ": expected 0 <= lo <= hi <= 180 degrees");
  }
}

}  // namespace

EnvConfig EnvConfig::Load(const std::string& path) { return FromJson(LoadJsonFile(path), path); }

EnvConfig EnvConfig::FromJson(const Json& j, const std::string& ctx) {
  CheckKnownKeys(
      j,
      {"_comment", "humanoid_file", "chair", "chair_placement", "physics", "action_mode",
       "pd_implicit", "obs_layout", "obs", "spawn", "init", "safety", "push",
       "seat_contact_max_pelvis_z", "seat_contact_relative", "chair_random", "task", "stand"},
      ctx);
  EnvConfig c;
  GetOptional(j, "humanoid_file", c.humanoid_file, ctx);
  GetOptional(j, "chair", c.chair, ctx);
  if (j.contains("chair_placement")) {
    const Json& p = j["chair_placement"];
    const std::string pc = ctx + ".chair_placement";
    CheckKnownKeys(p, {"x", "y", "yaw_deg"}, pc);
    GetOptional(p, "x", c.chair_placement.x, pc);
    GetOptional(p, "y", c.chair_placement.y, pc);
    double yaw_deg = c.chair_placement.yaw * 180.0 / M_PI;
    GetOptional(p, "yaw_deg", yaw_deg, pc);
    c.chair_placement.yaw = yaw_deg * M_PI / 180.0;
  }
  if (j.contains("physics")) c.physics = PhysicsConfig::FromJson(j["physics"], ctx + ".physics");
  std::string mode = "torque";
  GetOptional(j, "action_mode", mode, ctx);
  if (mode == "torque") {
    c.action_mode = ActionMode::kTorque;
  } else if (mode == "pd") {
    c.action_mode = ActionMode::kPd;
  } else {
    throw ConfigError(ctx + ".action_mode: expected \"torque\" or \"pd\", got \"" + mode + "\"");
  }
  GetOptional(j, "pd_implicit", c.pd_implicit, ctx);
  std::string layout = "proprio_goal";
  GetOptional(j, "obs_layout", layout, ctx);
  c.obs_layout = ObsLayoutFromName(layout, ctx + ".obs_layout");
  if (j.contains("obs")) {
    const Json& o = j["obs"];
    const std::string oc = ctx + ".obs";
    CheckKnownKeys(
        o, {"initial_z", "velocity_scale", "joint_speed_scale", "clip", "foot_contact_lag"}, oc);
    GetOptional(o, "initial_z", c.obs.initial_z, oc);
    GetOptional(o, "velocity_scale", c.obs.velocity_scale, oc);
    GetOptional(o, "joint_speed_scale", c.obs.joint_speed_scale, oc);
    GetOptional(o, "clip", c.obs.clip, oc);
    GetOptional(o, "foot_contact_lag", c.obs.foot_contact_lag, oc);
    if (!(c.obs.clip > 0.0)) throw ConfigError(oc + ".clip: must be > 0");
  }
  if (j.contains("spawn")) {
    const Json& s = j["spawn"];
    const std::string sc = ctx + ".spawn";
    CheckKnownKeys(s,
                   {"zone", "x", "y", "yaw_deg", "center_x", "center_y", "radius", "radius_max",
                    "yaw_noise_deg", "zone1_deg", "zone2_deg", "zone3_deg", "hard_center_x",
                    "hard_center_y", "hard_radius", "zones"},
                   sc);
    GetOptional(s, "zone", c.spawn.zone, sc);
    GetOptional(s, "x", c.spawn.x, sc);
    GetOptional(s, "y", c.spawn.y, sc);
    GetOptional(s, "yaw_deg", c.spawn.yaw_deg, sc);
    GetOptional(s, "center_x", c.spawn.center_x, sc);
    GetOptional(s, "center_y", c.spawn.center_y, sc);
    GetOptional(s, "radius", c.spawn.radius, sc);
    GetOptional(s, "radius_max", c.spawn.radius_max, sc);
    GetOptional(s, "yaw_noise_deg", c.spawn.yaw_noise_deg, sc);
    GetOptional(s, "zone1_deg", c.spawn.zone1_deg, sc);
    GetOptional(s, "zone2_deg", c.spawn.zone2_deg, sc);
    GetOptional(s, "zone3_deg", c.spawn.zone3_deg, sc);
    GetOptional(s, "hard_center_x", c.spawn.hard_center_x, sc);
    GetOptional(s, "hard_center_y", c.spawn.hard_center_y, sc);
    GetOptional(s, "hard_radius", c.spawn.hard_radius, sc);
    if (!(c.spawn.hard_radius >= 0.0)) throw ConfigError(sc + ".hard_radius: must be >= 0");
    GetOptional(s, "zones", c.spawn.zones, sc);
    for (int z : c.spawn.zones) {
      if (z < 1 || z > 3) throw ConfigError(sc + ".zones: each must be 1, 2 or 3");
    }
    if (!c.spawn.zones.empty() && c.spawn.zone == 0) {
      throw ConfigError(sc + ".zones: needs zone 1-3 (zone 0 is the fixed pose)");
    }
    if (c.spawn.zone < 0 || c.spawn.zone > 3)
      throw ConfigError(sc + ".zone: expected 0, 1, 2 or 3");
    if (!(c.spawn.radius >= 0.0)) throw ConfigError(sc + ".radius: must be >= 0");
    if (!(c.spawn.radius_max == 0.0 || c.spawn.radius_max >= c.spawn.radius)) {
      throw ConfigError(sc + ".radius_max: must be 0 or >= radius");
    }
    if (!(c.spawn.yaw_noise_deg >= 0.0 && c.spawn.yaw_noise_deg <= 180.0)) {
      throw ConfigError(sc + ".yaw_noise_deg: must be in [0, 180]");
    }
    CheckRange(c.spawn.zone1_deg, sc + ".zone1_deg");
    CheckRange(c.spawn.zone2_deg, sc + ".zone2_deg");
    CheckRange(c.spawn.zone3_deg, sc + ".zone3_deg");
  }
  if (j.contains("init")) {
    const Json& i = j["init"];
    const std::string ic = ctx + ".init";
    CheckKnownKeys(i, {"qpos_file", "qpos_array", "qpos_row", "standing_clearance"}, ic);
    GetOptional(i, "qpos_file", c.init.qpos_file, ic);
    GetOptional(i, "qpos_array", c.init.qpos_array, ic);
    GetOptional(i, "qpos_row", c.init.qpos_row, ic);
    GetOptional(i, "standing_clearance", c.init.standing_clearance, ic);
    if (c.init.qpos_row < 0) throw ConfigError(ic + ".qpos_row: must be >= 0");
  }
  if (j.contains("safety")) {
    const Json& s = j["safety"];
    const std::string sc = ctx + ".safety";
    CheckKnownKeys(
        s, {"max_joint_speed", "max_root_speed", "max_root_ang_speed", "max_abs_position"}, sc);
    GetOptional(s, "max_joint_speed", c.safety.max_joint_speed, sc);
    GetOptional(s, "max_root_speed", c.safety.max_root_speed, sc);
    GetOptional(s, "max_root_ang_speed", c.safety.max_root_ang_speed, sc);
    GetOptional(s, "max_abs_position", c.safety.max_abs_position, sc);
  }
  if (j.contains("push")) {
    const Json& p = j["push"];
    const std::string pc = ctx + ".push";
    CheckKnownKeys(p, {"rate_hz", "force_min_n", "force_max_n", "duration_s", "delay_s", "until_s"},
                   pc);
    GetOptional(p, "rate_hz", c.push.rate_hz, pc);
    GetOptional(p, "force_min_n", c.push.force_min_n, pc);
    GetOptional(p, "force_max_n", c.push.force_max_n, pc);
    GetOptional(p, "duration_s", c.push.duration_s, pc);
    GetOptional(p, "delay_s", c.push.delay_s, pc);
    GetOptional(p, "until_s", c.push.until_s, pc);
    if (!(c.push.rate_hz >= 0.0 && c.push.rate_hz <= 100.0)) {
      throw ConfigError(pc + ".rate_hz: must be in [0, 100] pushes per second");
    }
    if (!(c.push.force_min_n >= 0.0 && c.push.force_max_n >= c.push.force_min_n &&
          c.push.force_max_n <= 1e4)) {
      throw ConfigError(pc + ".force_min_n / force_max_n: need 0 <= min <= max <= 10000 N");
    }
    if (!(c.push.duration_s > 0.0 && c.push.duration_s <= 10.0)) {
      throw ConfigError(pc + ".duration_s: must be in (0, 10] s");
    }
    if (!(c.push.delay_s >= 0.0)) throw ConfigError(pc + ".delay_s: must be >= 0");
    if (!(c.push.until_s == 0.0 || c.push.until_s > c.push.delay_s)) {
      throw ConfigError(pc + ".until_s: must be 0 (no end) or > delay_s");
    }
  }
  GetOptional(j, "seat_contact_max_pelvis_z", c.seat_contact_max_pelvis_z, ctx);
  GetOptional(j, "seat_contact_relative", c.seat_contact_relative, ctx);
  if (j.contains("chair_random")) {
    const Json& r = j["chair_random"];
    const std::string rc = ctx + ".chair_random";
    ChairRandomConfig& cr = c.chair_random;
    CheckKnownKeys(
        r,
        {"prob", "seat_height", "seat_width", "seat_depth", "seat_thickness", "leg_size",
         "backrest_prob", "backrest_height", "armrest_prob", "armrest_height", "mass", "dynamic"},
        rc);
    GetOptional(r, "prob", cr.prob, rc);
    GetOptional(r, "backrest_prob", cr.backrest_prob, rc);
    GetOptional(r, "armrest_prob", cr.armrest_prob, rc);
    GetOptional(r, "mass", cr.mass, rc);
    GetOptional(r, "dynamic", cr.dynamic, rc);
    for (const char* p : {"prob", "backrest_prob", "armrest_prob"}) {
      const double v = r.value(p, 0.0);
      if (!(v >= 0 && v <= 1)) throw ConfigError(rc + "." + p + ": must be in [0, 1]");
    }
    if (!(cr.mass > 0)) throw ConfigError(rc + ".mass: must be > 0");
    struct Range {
      const char* name;
      std::array<double, 2>* v;
    };
    for (const Range& x :
         {Range{"seat_height", &cr.seat_height}, Range{"seat_width", &cr.seat_width},
          Range{"seat_depth", &cr.seat_depth}, Range{"seat_thickness", &cr.seat_thickness},
          Range{"leg_size", &cr.leg_size}, Range{"backrest_height", &cr.backrest_height},
          Range{"armrest_height", &cr.armrest_height}}) {
      GetOptional(r, x.name, *x.v, rc);
      if (!((*x.v)[0] > 0 && (*x.v)[0] <= (*x.v)[1] && (*x.v)[1] < 2.0)) {
        throw ConfigError(rc + "." + x.name + ": expected [lo, hi] with 0 < lo <= hi < 2 m");
      }
    }
    if (cr.seat_thickness[1] >= cr.seat_height[0]) {
      throw ConfigError(rc + ".seat_thickness: must stay below seat_height");
    }
    if (2 * cr.leg_size[1] >= std::min(cr.seat_width[0], cr.seat_depth[0])) {
      throw ConfigError(rc + ".leg_size: legs wider than the smallest seat");
    }
  }
  GetOptional(j, "task", c.task, ctx);
  // Tasks other than "stand" are built and their names checked by tasks/ (tasks/registry.h).
  if (c.task.empty()) throw ConfigError(ctx + ".task: must not be empty");
  if (j.contains("stand")) {
    const Json& s = j["stand"];
    const std::string sc = ctx + ".stand";
    CheckKnownKeys(s,
                   {"alive_bonus", "upright_weight", "action_cost", "min_torso_z",
                    "max_episode_steps", "walk_target"},
                   sc);
    GetOptional(s, "alive_bonus", c.stand.alive_bonus, sc);
    GetOptional(s, "upright_weight", c.stand.upright_weight, sc);
    GetOptional(s, "action_cost", c.stand.action_cost, sc);
    GetOptional(s, "min_torso_z", c.stand.min_torso_z, sc);
    GetOptional(s, "max_episode_steps", c.stand.max_episode_steps, sc);
    GetOptional(s, "walk_target", c.stand.walk_target, sc);
    if (c.stand.max_episode_steps < 1) throw ConfigError(sc + ".max_episode_steps: must be >= 1");
  }
  return c;
}

Json EnvConfig::ToJson() const {
  return Json{
      {"humanoid_file", humanoid_file},
      {"chair", chair},
      {"chair_placement",
       {{"x", chair_placement.x},
        {"y", chair_placement.y},
        {"yaw_deg", chair_placement.yaw * 180.0 / M_PI}}},
      {"physics", physics.ToJson()},
      {"action_mode", action_mode == ActionMode::kTorque ? "torque" : "pd"},
      {"pd_implicit", pd_implicit},
      {"obs_layout", ObsLayoutName(obs_layout)},
      {"obs",
       {{"initial_z", obs.initial_z},
        {"velocity_scale", obs.velocity_scale},
        {"joint_speed_scale", obs.joint_speed_scale},
        {"clip", obs.clip},
        {"foot_contact_lag", obs.foot_contact_lag}}},
      {"spawn",
       {{"zone", spawn.zone},
        {"x", spawn.x},
        {"y", spawn.y},
        {"yaw_deg", spawn.yaw_deg},
        {"center_x", spawn.center_x},
        {"center_y", spawn.center_y},
        {"radius", spawn.radius},
        {"radius_max", spawn.radius_max},
        {"yaw_noise_deg", spawn.yaw_noise_deg},
        {"zone1_deg", spawn.zone1_deg},
        {"zone2_deg", spawn.zone2_deg},
        {"zone3_deg", spawn.zone3_deg},
        {"hard_center_x", spawn.hard_center_x},
        {"hard_center_y", spawn.hard_center_y},
        {"hard_radius", spawn.hard_radius},
        {"zones", spawn.zones}}},
      {"init",
       {{"qpos_file", init.qpos_file},
        {"qpos_array", init.qpos_array},
        {"qpos_row", init.qpos_row},
        {"standing_clearance", init.standing_clearance}}},
      {"safety",
       {{"max_joint_speed", safety.max_joint_speed},
        {"max_root_speed", safety.max_root_speed},
        {"max_root_ang_speed", safety.max_root_ang_speed},
        {"max_abs_position", safety.max_abs_position}}},
      {"push",
       {{"rate_hz", push.rate_hz},
        {"force_min_n", push.force_min_n},
        {"force_max_n", push.force_max_n},
        {"duration_s", push.duration_s},
        {"delay_s", push.delay_s},
        {"until_s", push.until_s}}},
      {"seat_contact_max_pelvis_z", seat_contact_max_pelvis_z},
      {"seat_contact_relative", seat_contact_relative},
      {"chair_random",
       {{"prob", chair_random.prob},
        {"seat_height", chair_random.seat_height},
        {"seat_width", chair_random.seat_width},
        {"seat_depth", chair_random.seat_depth},
        {"seat_thickness", chair_random.seat_thickness},
        {"leg_size", chair_random.leg_size},
        {"backrest_prob", chair_random.backrest_prob},
        {"backrest_height", chair_random.backrest_height},
        {"armrest_prob", chair_random.armrest_prob},
        {"armrest_height", chair_random.armrest_height},
        {"mass", chair_random.mass},
        {"dynamic", chair_random.dynamic}}},
      {"task", task},
      {"stand",
       {{"alive_bonus", stand.alive_bonus},
        {"upright_weight", stand.upright_weight},
        {"action_cost", stand.action_cost},
        {"min_torso_z", stand.min_torso_z},
        {"max_episode_steps", stand.max_episode_steps},
        {"walk_target", stand.walk_target}}},
  };
}

std::string EnvConfig::HumanoidPath() const { return Resolve(humanoid_file); }

std::string EnvConfig::ChairPath() const {
  if (chair == "none") return "";
  if (chair.size() > 5 && chair.substr(chair.size() - 5) == ".json") return Resolve(chair);
  return Chair::PresetPath(chair);
}

std::string EnvConfig::QposPath() const { return Resolve(init.qpos_file); }

ObsLayout ObsLayoutFromName(const std::string& name, const std::string& ctx) {
  if (name == "proprio") return ObsLayout::kProprio;
  if (name == "proprio_goal") return ObsLayout::kProprioGoal;
  if (name == "proprio_chair") return ObsLayout::kProprioChair;
  throw ConfigError(ctx + ": expected \"proprio\", \"proprio_goal\" or \"proprio_chair\", got \"" +
                    name + "\"");
}

std::string ObsLayoutName(ObsLayout layout) {
  switch (layout) {
    case ObsLayout::kProprio:
      return "proprio";
    case ObsLayout::kProprioGoal:
      return "proprio_goal";
    case ObsLayout::kProprioChair:
      return "proprio_chair";
  }
  return "?";
}

int ObsLayoutDim(ObsLayout layout) {
  switch (layout) {
    case ObsLayout::kProprio:
      return 50;
    case ObsLayout::kProprioGoal:
      return 52;
    case ObsLayout::kProprioChair:
      return 57;
  }
  return 0;
}

}  // namespace perch
