// Typed configuration of the humanoid-chair env. Defaults are the paper's / the authors' values
// (docs/env.md says where each comes from). Read from JSON strictly, written back in full.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "common/field_table.h"
#include "common/json_util.h"
#include "envs/humanoid_world.h"

namespace perch {

enum class ActionMode {
  kTorque,  // authors: torque = max_torque x clip(a, -1, 1), held over the physics sub-steps
  kPd,      // a in [-1, 1] -> target angle mid + a (hi - lo) / 2; PD torque every physics step
};

enum class ObsLayout {
  kProprio,       // more(6) joints(42) feet(2): 50, the paper's turn state (Sec. 4)
  kProprioGoal,   // more(6) joints(42) feet(2) goal(2): 52, walk policies
  kProprioChair,  // more(6) joints(42) feet(2) chair(7): 57, sit / meta policies
  // more(6) joints(42) feet(2) chair(7) shape(25): 82, a sit that sees the chair's shape (ours,
  // issue 51): the chair's top-surface heights on a 5 x 5 grid around the seat target.
  kProprioChairShape,
};

struct ObsConfig {
  double initial_z = 0.8;          // subtracted from torso z (authors' "initial_z") [m]
  double velocity_scale = 0.3;     // torso velocity feature scale [s/m]
  double joint_speed_scale = 0.1;  // qdot_n = scale x qdot [s/rad]
  double clip = 5.0;               // every feature is clipped to [-clip, clip]
  bool foot_contact_lag = true;    // authors: the flags in an observation are one step old
  // proprio_chair_shape: spacing of the 5 x 5 chair height grid around the seat target [m].
  double chair_grid_spacing = 0.15;
};

// Spawn positions in the chair frame (notes 6). zone 0: the fixed pose below; zones 1-3: on a
// circle around `center`, azimuth theta with |theta| uniform in the zone's [lo, hi] degrees and a
// random sign, facing the centre (yaw added = theta + pi to the initial pose's own yaw).
struct SpawnConfig {
  int zone = 0;
  double x = 1.5, y = 0.0, yaw_deg = 180.0;  // zone 0 [m, m, deg]
  double center_x = 0.45, center_y = 0.0;    // authors' Zone 1 centre [m]
  double radius = 1.5;                       // [m]
  // > radius: the radius is drawn from U(radius, radius_max) (the authors' walk-only meta spawns,
  // notes 4.7: U(2, 5) m). 0: always `radius`.
  double radius_max = 0.0;  // [m]
  // Facing the centre +- U(-yaw_noise_deg, yaw_noise_deg) (walk-only "easy": 45) [deg].
  double yaw_noise_deg = 0.0;
  std::array<double, 2> zone1_deg{0.0, 90.0};     // authors' code: theta ~ U(-90, 90) deg
  std::array<double, 2> zone2_deg{90.0, 135.0};   // our proposal (notes 6): lateral sides
  std::array<double, 2> zone3_deg{135.0, 180.0};  // our proposal: rear side
  // Zones 2 and 3 (ours, docs/meta.md): the paper puts the Hard starts "again roughly 2 meters
  // away" from the chair; Zone 1's circle is only 1.05 m from the chair centre at the rear. So
  // zones 2 and 3 use their own circle around (hard_center_x, hard_center_y), the chair centre.
  // hard_radius 0: Zone 1's circle (our reading before 2026-12-04, stop 34).
  double hard_center_x = 0.0, hard_center_y = 0.0;  // [m]
  double hard_radius = 2.0;                         // [m]
  // Ours: when not empty, each episode's zone is drawn uniformly from these (1-3) instead of
  // `zone`: a curriculum stage that keeps the earlier stages' zones (docs/meta.md).
  std::vector<int> zones;
};

// The circle a zone's starts lie on, chair frame: centre x, y and radius [m].
struct SpawnCircle {
  double center_x = 0.0, center_y = 0.0, radius = 0.0;
};
SpawnCircle ZoneCircle(const SpawnConfig& c, int zone);

// The initial pose that spawning moves around: standing (all angles 0 clipped to the limits),
// or a row of a 51-column qpos array in an npz file (notes 7.2), e.g. the authors' Zone 1 start
// frame: cmu_mocap_walk_plain.npz, qpos_03, row 31.
struct InitConfig {
  std::string qpos_file;  // empty: standing pose
  std::string qpos_array = "qpos_03";
  int qpos_row = 31;
  double standing_clearance = 0.002;  // feet above the floor at a standing start [m]
};

struct SafetyConfig {
  // Above Bullet's joint-speed clamp (physics.max_joint_speed, 100 rad/s): light links (feet,
  // hands) reach the clamp under random full torques without anything blowing up.
  double max_joint_speed = 150.0;    // [rad/s]; beyond: invalid episode
  double max_root_speed = 10.0;      // [m/s] (falling from 1.3 m: 5 m/s)
  double max_root_ang_speed = 60.0;  // [rad/s]
  double max_abs_position = 1000.0;  // [m]
};

// Random pushes on the pelvis, a training perturbation (ours; the paper has none): a push starts
// in a control step with probability rate_hz * control_dt, lasts duration_s, and has a horizontal
// force of a uniform magnitude in [force_min_n, force_max_n] in a uniform direction, starting
// between delay_s and until_s into the episode. Off (rate 0) by default and in every evaluation
// config; the env's RNG is only drawn from when on.
struct PushConfig {
  double rate_hz = 0.0;      // [1/s] mean pushes per second of episode
  double force_min_n = 0.0;  // [N]
  double force_max_n = 0.0;  // [N]
  double duration_s = 0.2;   // [s]
  double delay_s = 0.0;      // [s] no push starts in the episode's first delay_s
  double until_s = 0.0;      // [s] > 0: nor from until_s on (pushes only near the start)
};

// Training perturbations beyond pushes (issue 49; ours, all off by default): Gaussian noise on
// every observation entry and every action entry, and per-episode scales of the contact frictions
// and of the humanoid's body masses (one factor each per episode, uniform in [lo, hi]). The env's
// RNG is only drawn from for what is on, so a run without them draws as before.
struct DomainRandomConfig {
  double obs_noise_std = 0.0;                      // in each entry's own (observation) units
  double act_noise_std = 0.0;                      // in action units (before clipping to [-1, 1])
  std::array<double, 2> friction_scale{1.0, 1.0};  // x floor, humanoid and chair friction
  std::array<double, 2> mass_scale{1.0, 1.0};      // x every humanoid body's mass and inertia
  bool on() const {
    return obs_noise_std > 0 || act_noise_std > 0 ||
           friction_scale != std::array<double, 2>{1, 1} ||
           mass_scale != std::array<double, 2>{1, 1};
  }
};

// The `stand` task: reward for staying upright, early termination on falling, time limit.
struct StandTaskConfig {
  double alive_bonus = 1.0;                        // per control step while up
  double upright_weight = 1.0;                     // x (torso up-vector z), in [-1, 1]
  double action_cost = 0.01;                       // x mean(a^2)
  double min_torso_z = 0.78;                       // authors' alive test: torso z > 0.78 m
  int max_episode_steps = 1000;                    // 16.5 s
  std::array<double, 2> walk_target{1000.0, 0.0};  // goal features: Roboschool's default [m]
};

// Random chairs per episode (ours; the paper used one chair): with probability `prob` an episode's
// chair is a four-legged parametric chair (envs/chair.h) with sizes drawn uniformly from these
// ranges [m] and a backrest / armrests with the given probabilities, instead of env.chair.
struct ChairRandomConfig {
  double prob = 0.0;  // 0: always env.chair
  std::array<double, 2> seat_height{0.33, 0.52};
  std::array<double, 2> seat_width{0.36, 0.9};
  std::array<double, 2> seat_depth{0.33, 0.48};
  std::array<double, 2> seat_thickness{0.04, 0.08};
  std::array<double, 2> leg_size{0.03, 0.05};
  double backrest_prob = 0.6;
  std::array<double, 2> backrest_height{0.3, 0.5};
  double armrest_prob = 0.3;
  std::array<double, 2> armrest_height{0.15, 0.25};
  double mass = 1000.0;  // [kg], as the authors' chair
  bool dynamic = true;
  // Chair files (presets or .json paths, mesh chairs included) among the random chairs: of the
  // episodes on a random chair, files_prob sit on one of these (uniformly), the rest on a
  // generated one. Empty: generated only.
  std::vector<std::string> files;
  double files_prob = 0.0;
};

struct EnvConfig {
  std::string humanoid_file = "data/humanoid.json";  // relative paths: from the source tree
  std::string chair = "authors";  // a preset in data/chairs/, a path to a .json, or "none"
  ChairPlacement chair_placement;
  PhysicsConfig physics;
  ActionMode action_mode = ActionMode::kTorque;
  // pd mode: damp implicitly per joint (docs/env.md); false = the plain explicit PD law.
  bool pd_implicit = true;
  ObsLayout obs_layout = ObsLayout::kProprioGoal;
  ObsConfig obs;
  SpawnConfig spawn;
  InitConfig init;
  SafetyConfig safety;
  PushConfig push;
  DomainRandomConfig randomize;
  double seat_contact_max_pelvis_z = 0.54;  // contact = pelvis touches chair AND pelvis z < this
  // The threshold follows the seat: max_pelvis_z + (seat height - the authors' 0.4029 m), so it is
  // the authors' 0.54 m on their chair and the same height above the seat on any other (ours).
  bool seat_contact_relative = true;
  ChairRandomConfig chair_random;
  // The task by name: "stand" is built here; the others (walk, turn_left, turn_right, sit) by
  // tasks/ (tasks/registry.h), which checks the name.
  std::string task = "stand";
  StandTaskConfig stand;

  static EnvConfig FromJson(const Json& j, const std::string& ctx);
  static EnvConfig Load(const std::string& path);
  Json ToJson() const;
  // Paths resolved against the source tree when relative.
  std::string HumanoidPath() const;
  std::string ChairPath() const;  // empty for "none"
  // A chair name (preset) or .json path as ChairPath resolves env.chair.
  static std::string ChairFilePath(const std::string& name_or_path);
  std::string QposPath() const;
};

// "proprio", "proprio_goal", "proprio_chair" and back; ConfigError naming ctx on another name.
// Every field of the "env" section, written once (common/field_table.h).
const FieldTable<EnvConfig>& EnvConfigFields();

ObsLayout ObsLayoutFromName(const std::string& name, const std::string& ctx);
std::string ObsLayoutName(ObsLayout layout);
int ObsLayoutDim(ObsLayout layout);  // 50, 52, 57, 82

// Where each block of the observation starts: more(6), joints(42), feet(2), then the layout's
// goal(2) or chair(7), then shape(25). The writer, the spec's slices and the mirror map share
// these.
constexpr int kObsMore = 0, kObsJoints = 6, kObsFeet = 48, kObsExtra = 50, kObsShape = 57;
// The shape block: kChairGridSide x kChairGridSide heights (envs/chair_grid.h).
constexpr int kChairGridSide = 5, kChairGridDim = kChairGridSide * kChairGridSide;

}  // namespace perch
