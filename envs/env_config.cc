#include "envs/env_config.h"

#include <algorithm>
#include <cmath>

#include "common/paths.h"

namespace perch {
namespace {

std::string Resolve(const std::string& path) { return ResolveProjectPath(path); }

}  // namespace

EnvConfig EnvConfig::Load(const std::string& path) { return FromJson(LoadJsonFile(path), path); }

namespace {

// [lo, hi] degrees of a spawn zone's sector.
FieldRule<std::array<double, 2>> Sector() {
  return Satisfies<std::array<double, 2>>(
      [](const std::array<double, 2>& r) { return r[0] >= 0.0 && r[0] <= r[1] && r[1] <= 180.0; },
      "expected 0 <= lo <= hi <= 180 degrees");
}
// [lo, hi] metres of a random chair's dimension.
FieldRule<std::array<double, 2>> Metres() {
  return Satisfies<std::array<double, 2>>(
      [](const std::array<double, 2>& r) { return r[0] > 0 && r[0] <= r[1] && r[1] < 2.0; },
      "expected [lo, hi] with 0 < lo <= hi < 2 m");
}

const FieldTable<ChairPlacement>& PlacementFields() {
  using C = ChairPlacement;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("x", &C::x, "chair position [m]")
          .Add("y", &C::y, "chair position [m]")
          .Custom(
              "yaw_deg", "chair yaw [deg] (held in radians)",
              [](const Json& j, C& c, const std::string& ctx) {
                double deg = c.yaw * 180.0 / M_PI;
                GetOptional(j, "yaw_deg", deg, ctx);
                c.yaw = deg * M_PI / 180.0;
              },
              [](const C& c, Json& j) { j["yaw_deg"] = c.yaw * 180.0 / M_PI; });
  return t;
}

const FieldTable<ObsConfig>& ObsFields() {
  using C = ObsConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("initial_z", &C::initial_z, "subtracted from torso z [m]")
          .Add("velocity_scale", &C::velocity_scale, "torso velocity feature scale [s/m]")
          .Add("joint_speed_scale", &C::joint_speed_scale, "qdot_n = scale x qdot [s/rad]")
          .Add("clip", &C::clip, "every feature is clipped to [-clip, clip]", Positive<double>())
          .Add("foot_contact_lag", &C::foot_contact_lag,
               "the flags in an observation are one step old (authors)")
          .Add("chair_grid_spacing", &C::chair_grid_spacing,
               "proprio_chair_shape: spacing of the 5 x 5 chair height grid [m]",
               Positive<double>());
  return t;
}

const FieldTable<SpawnConfig>& SpawnFields() {
  using C = SpawnConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("zone", &C::zone, "0: the fixed pose x, y, yaw_deg; 1-3: the paper's zones",
               Satisfies<int>([](const int& z) { return z >= 0 && z <= 3; },
                              "expected 0, 1, 2 or 3"))
          .Add("x", &C::x, "zone 0 position [m]")
          .Add("y", &C::y, "zone 0 position [m]")
          .Add("yaw_deg", &C::yaw_deg, "zone 0 heading [deg]")
          .Add("center_x", &C::center_x, "Zone 1 centre [m]")
          .Add("center_y", &C::center_y, "Zone 1 centre [m]")
          .Add("radius", &C::radius, "zone radius [m]", NonNegative<double>())
          .Add("radius_max", &C::radius_max, "> 0: radius drawn in [radius, radius_max] [m]")
          .Add("yaw_noise_deg", &C::yaw_noise_deg, "heading noise [deg]",
               Satisfies<double>([](const double& v) { return v >= 0.0 && v <= 180.0; },
                                 "must be in [0, 180]"))
          .Add("zone1_deg", &C::zone1_deg, "Zone 1 sector [deg]", Sector())
          .Add("zone2_deg", &C::zone2_deg, "Zone 2 sector [deg]", Sector())
          .Add("zone3_deg", &C::zone3_deg, "Zone 3 sector [deg]", Sector())
          .Add("hard_center_x", &C::hard_center_x, "Hard zones' centre [m]")
          .Add("hard_center_y", &C::hard_center_y, "Hard zones' centre [m]")
          .Add("hard_radius", &C::hard_radius, "Hard zones' radius [m]", NonNegative<double>())
          .Add("zones", &C::zones, "each episode's zone drawn among these (1-3)")
          .Rule([](const C& c, const std::string& ctx) {
            for (int z : c.zones) {
              if (z < 1 || z > 3) return ctx + ".zones: each must be 1, 2 or 3";
            }
            if (!c.zones.empty() && c.zone == 0) {
              return ctx + ".zones: needs zone 1-3 (zone 0 is the fixed pose)";
            }
            if (!(c.radius_max == 0.0 || c.radius_max >= c.radius)) {
              return ctx + ".radius_max: must be 0 or >= radius";
            }
            return std::string();
          });
  return t;
}

const FieldTable<InitConfig>& InitFields() {
  using C = InitConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("qpos_file", &C::qpos_file, "start poses (.npz); empty: standing pose")
          .Add("qpos_array", &C::qpos_array, "the array in qpos_file")
          .Add("qpos_row", &C::qpos_row, "its row", NonNegative<int>())
          .Add("standing_clearance", &C::standing_clearance,
               "feet above the floor at a standing start [m]");
  return t;
}

const FieldTable<SafetyConfig>& SafetyFields() {
  using C = SafetyConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("max_joint_speed", &C::max_joint_speed, "beyond: invalid episode [rad/s]")
          .Add("max_root_speed", &C::max_root_speed, "[m/s]")
          .Add("max_root_ang_speed", &C::max_root_ang_speed, "[rad/s]")
          .Add("max_abs_position", &C::max_abs_position, "[m]");
  return t;
}

const FieldTable<PushConfig>& PushFields() {
  using C = PushConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("rate_hz", &C::rate_hz, "mean pushes per second of episode",
               Satisfies<double>([](const double& v) { return v >= 0.0 && v <= 100.0; },
                                 "must be in [0, 100] pushes per second"))
          .Add("force_min_n", &C::force_min_n, "[N]")
          .Add("force_max_n", &C::force_max_n, "[N]")
          .Add("duration_s", &C::duration_s, "[s]",
               Satisfies<double>([](const double& v) { return v > 0.0 && v <= 10.0; },
                                 "must be in (0, 10] s"))
          .Add("delay_s", &C::delay_s, "no push starts in the episode's first delay_s [s]",
               NonNegative<double>())
          .Add("until_s", &C::until_s, "> 0: nor from until_s on [s]")
          .Rule([](const C& c, const std::string& ctx) {
            if (!(c.force_min_n >= 0.0 && c.force_max_n >= c.force_min_n && c.force_max_n <= 1e4)) {
              return ctx + ".force_min_n / force_max_n: need 0 <= min <= max <= 10000 N";
            }
            if (!(c.until_s == 0.0 || c.until_s > c.delay_s)) {
              return ctx + ".until_s: must be 0 (no end) or > delay_s";
            }
            return std::string();
          });
  return t;
}

const FieldTable<ChairRandomConfig>& ChairRandomFields() {
  using C = ChairRandomConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("prob", &C::prob, "share of episodes on a random chair (0: always env.chair)",
               InRange<double>(0, 1, "must be in [0, 1]"))
          .Add("seat_height", &C::seat_height, "[lo, hi] m", Metres())
          .Add("seat_width", &C::seat_width, "[lo, hi] m", Metres())
          .Add("seat_depth", &C::seat_depth, "[lo, hi] m", Metres())
          .Add("seat_thickness", &C::seat_thickness, "[lo, hi] m", Metres())
          .Add("leg_size", &C::leg_size, "[lo, hi] m", Metres())
          .Add("backrest_prob", &C::backrest_prob, "share with a backrest",
               InRange<double>(0, 1, "must be in [0, 1]"))
          .Add("backrest_height", &C::backrest_height, "[lo, hi] m", Metres())
          .Add("armrest_prob", &C::armrest_prob, "share with armrests",
               InRange<double>(0, 1, "must be in [0, 1]"))
          .Add("armrest_height", &C::armrest_height, "[lo, hi] m", Metres())
          .Add("mass", &C::mass, "[kg]", Positive<double>())
          .Add("dynamic", &C::dynamic, "a body that can move (else static)")
          .Add("files", &C::files, "chair files (presets or .json) among the random chairs")
          .Add("files_prob", &C::files_prob, "share of random chairs drawn from files",
               InRange<double>(0, 1, "must be in [0, 1]"))
          .Rule([](const C& c, const std::string& ctx) {
            if (c.files_prob > 0 && c.files.empty()) return ctx + ".files_prob: no files given";
            if (c.seat_thickness[1] >= c.seat_height[0]) {
              return ctx + ".seat_thickness: must stay below seat_height";
            }
            if (2 * c.leg_size[1] >= std::min(c.seat_width[0], c.seat_depth[0])) {
              return ctx + ".leg_size: legs wider than the smallest seat";
            }
            return std::string();
          });
  return t;
}

const FieldTable<DomainRandomConfig>& DomainRandomFields() {
  using C = DomainRandomConfig;
  auto scale = Satisfies<std::array<double, 2>>(
      [](const std::array<double, 2>& r) { return r[0] > 0.0 && r[0] <= r[1] && r[1] <= 10.0; },
      "expected [lo, hi] with 0 < lo <= hi <= 10");
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("obs_noise_std", &C::obs_noise_std, "Gaussian noise on every observation entry",
               NonNegative<double>())
          .Add("act_noise_std", &C::act_noise_std,
               "Gaussian noise on every action entry (before clipping)", NonNegative<double>())
          .Add("friction_scale", &C::friction_scale,
               "[lo, hi]: per episode x floor, humanoid and chair friction", scale)
          .Add("mass_scale", &C::mass_scale,
               "[lo, hi]: per episode x the humanoid's body masses and inertias", scale);
  return t;
}

const FieldTable<StandTaskConfig>& StandFields() {
  using C = StandTaskConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("alive_bonus", &C::alive_bonus, "per control step while up")
          .Add("upright_weight", &C::upright_weight, "x (torso up-vector z)")
          .Add("action_cost", &C::action_cost, "x mean(a^2)")
          .Add("min_torso_z", &C::min_torso_z, "alive while the torso is above [m]")
          .Add("max_episode_steps", &C::max_episode_steps, "time limit [control steps]",
               Satisfies<int>([](const int& v) { return v >= 1; }, "must be >= 1"))
          .Add("walk_target", &C::walk_target, "goal features [m]");
  return t;
}

}  // namespace

const FieldTable<EnvConfig>& EnvConfigFields() {
  using C = EnvConfig;
  static const FieldTable<C> t =
      FieldTable<C>()
          .Ignored("_comment", "free text")
          .Add("humanoid_file", &C::humanoid_file, "the humanoid model (relative: source tree)")
          .Add("chair", &C::chair, "a preset in data/chairs/, a path to a .json, or \"none\"")
          .Nested("chair_placement", &C::chair_placement, PlacementFields(), "the chair's pose")
          .Nested("physics", &C::physics, PhysicsConfigFields(), "simulation settings")
          .Custom(
              "action_mode", "\"torque\" (authors) or \"pd\"",
              [](const Json& j, C& c, const std::string& ctx) {
                std::string mode;
                GetOptional(j, "action_mode", mode, ctx);
                if (mode == "torque") {
                  c.action_mode = ActionMode::kTorque;
                } else if (mode == "pd") {
                  c.action_mode = ActionMode::kPd;
                } else {
                  throw ConfigError(ctx + ".action_mode: expected \"torque\" or \"pd\", got \"" +
                                    mode + "\"");
                }
              },
              [](const C& c, Json& j) {
                j["action_mode"] = c.action_mode == ActionMode::kTorque ? "torque" : "pd";
              })
          .Add("pd_implicit", &C::pd_implicit, "pd: implicit (stable) PD")
          .Custom(
              "obs_layout", "proprio, proprio_goal, proprio_chair or proprio_chair_shape",
              [](const Json& j, C& c, const std::string& ctx) {
                std::string layout;
                GetOptional(j, "obs_layout", layout, ctx);
                c.obs_layout = ObsLayoutFromName(layout, ctx + ".obs_layout");
              },
              [](const C& c, Json& j) { j["obs_layout"] = ObsLayoutName(c.obs_layout); })
          .Nested("obs", &C::obs, ObsFields(), "observation features")
          .Nested("spawn", &C::spawn, SpawnFields(), "where episodes start")
          .Nested("init", &C::init, InitFields(), "the start pose")
          .Nested("safety", &C::safety, SafetyFields(), "limits beyond which an episode is invalid")
          .Nested("push", &C::push, PushFields(), "random pushes")
          .Nested("randomize", &C::randomize, DomainRandomFields(),
                  "training noise and per-episode physics scales")
          .Add("seat_contact_max_pelvis_z", &C::seat_contact_max_pelvis_z,
               "contact = pelvis touches chair and pelvis z < this [m]")
          .Add("seat_contact_relative", &C::seat_contact_relative,
               "seat_contact_max_pelvis_z relative to the seat")
          .Nested("chair_random", &C::chair_random, ChairRandomFields(), "random chairs")
          .Add("task", &C::task, "the task the env runs (tasks/registry.h)",
               Satisfies<std::string>([](const std::string& v) { return !v.empty(); },
                                      "must not be empty"))
          .Nested("stand", &C::stand, StandFields(), "the stand task");
  return t;
}

EnvConfig EnvConfig::FromJson(const Json& j, const std::string& ctx) {
  return EnvConfigFields().Read(j, ctx);
}

Json EnvConfig::ToJson() const { return EnvConfigFields().Write(*this); }

std::string EnvConfig::HumanoidPath() const { return Resolve(humanoid_file); }

std::string EnvConfig::ChairPath() const {
  if (chair == "none") return "";
  return ChairFilePath(chair);
}

std::string EnvConfig::ChairFilePath(const std::string& c) {
  if (c.size() > 5 && c.substr(c.size() - 5) == ".json") return Resolve(c);
  return Chair::PresetPath(c);
}

std::string EnvConfig::QposPath() const { return Resolve(init.qpos_file); }

ObsLayout ObsLayoutFromName(const std::string& name, const std::string& ctx) {
  if (name == "proprio") return ObsLayout::kProprio;
  if (name == "proprio_goal") return ObsLayout::kProprioGoal;
  if (name == "proprio_chair") return ObsLayout::kProprioChair;
  if (name == "proprio_chair_shape") return ObsLayout::kProprioChairShape;
  throw ConfigError(ctx +
                    ": expected \"proprio\", \"proprio_goal\", \"proprio_chair\" or "
                    "\"proprio_chair_shape\", got \"" +
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
    case ObsLayout::kProprioChairShape:
      return "proprio_chair_shape";
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
    case ObsLayout::kProprioChairShape:
      return 57 + kChairGridDim;
  }
  return 0;
}

}  // namespace perch
