// perch retarget: BVH -> data/motions/*.json (and --check: errors of the committed clips).
// perch motion ...: inspect reference motions.
#include <chrono>
#include <filesystem>
#include <iostream>
#include <map>

#include "app/commands.h"
#include "common/json_util.h"
#include "common/paths.h"
#include "envs/humanoid_env.h"
#include "envs/humanoid_model.h"
#include "motion/bvh.h"
#include "motion/bvh_export.h"
#include "motion/reference_compare.h"
#include "motion/reference_motion.h"
#include "motion/retarget.h"
#include "tasks/walk.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

std::string Basename(const std::string& p) { return fs::path(p).filename().string(); }

struct RetargetArgs {
  std::vector<std::string> bvh;
  std::string out;
  std::string config;
  std::string model = "data/humanoid.json";
  std::string motions = "data/motions";
  std::string bvh_dir = "../shared/mocap";  // beside the data root
  std::string reference_dir = "../shared/reference";
  bool check = false;
  bool compare = false;
  bool json = false;
};

RetargetConfig LoadConfig(const RetargetArgs& a) {
  if (a.config.empty()) return RetargetConfig();
  return RetargetConfig::FromJson(LoadJsonFile(a.config), a.config);
}

// Finds the BVH named `name` among the given paths, else in bvh_dir.
std::string FindBvh(const RetargetArgs& a, const std::string& name) {
  for (const auto& p : a.bvh) {
    if (Basename(p) == name) return p;
  }
  const std::string p = ResolveProjectPath(a.bvh_dir) + "/" + name;
  if (fs::exists(p)) return p;
  throw ConfigError("source BVH '" + name + "' not given on the command line and not in " +
                    a.bvh_dir);
}

void RunRetarget(const RetargetArgs& a) {
  const RetargetConfig cfg = LoadConfig(a);
  const HumanoidModel model = HumanoidModel::Load(ResolveProjectPath(a.model));
  if (a.bvh.empty()) throw ConfigError("retarget: give the source BVH files");
  if (a.out.empty()) throw ConfigError("retarget: --out DIR is required");
  std::map<std::string, BvhClip> clips;
  for (const auto& p : a.bvh) clips[Basename(p)] = ReadBvhFile(p);
  // Everything is computed first; files are written only when every clip succeeded.
  std::vector<RetargetOutput> outs;
  Json report = Json::array();
  for (const ClipSpec& spec : cfg.clips) {
    auto it = clips.find(spec.bvh);
    if (it == clips.end()) {
      std::cerr << "retarget: skipping '" << spec.name << "' (" << spec.bvh << " not given)\n";
      continue;
    }
    std::string path;
    for (const auto& p : a.bvh) {
      if (Basename(p) == spec.bvh) path = p;
    }
    RetargetOutput o = RetargetClip(it->second, path, spec, model, cfg, [&](int done, int total) {
      std::cerr << "\rretarget " << spec.name << ": frame " << done << "/" << total << std::flush;
      if (done == total) std::cerr << "\n";
    });
    for (const auto& f : o.motion.frames()) {
      if (!f.root_pos.allFinite() || !f.q.allFinite()) {
        throw ConfigError("retarget " + spec.name + ": non-finite result; nothing written");
      }
    }
    Json stats = EvaluateMotion(o.motion, o.targets, model, cfg);
    o.motion.meta()["measured"] = stats;
    report.push_back(stats);
    outs.push_back(std::move(o));
  }
  if (outs.empty()) throw ConfigError("retarget: no clip matches the given BVH files");
  fs::create_directories(a.out);
  for (const auto& o : outs) {
    const std::string p = a.out + "/" + o.motion.name() + ".json";
    o.motion.Save(p);
    std::cerr << "wrote " << p << "\n";
  }
  SaveJsonFileAtomic(a.out + "/retarget_config.json", cfg.ToJson());
  if (a.json) std::cout << report.dump(2) << "\n";
}

void RunCheck(const RetargetArgs& a) {
  const RetargetConfig cfg = LoadConfig(a);
  const HumanoidModel model = HumanoidModel::Load(ResolveProjectPath(a.model));
  const std::string dir = a.out.empty() ? ResolveProjectPath(a.motions) : a.out;
  Json report = Json::array();
  for (const ClipSpec& spec : cfg.clips) {
    const std::string p = dir + "/" + spec.name + ".json";
    if (!fs::exists(p)) throw ConfigError(p + ": committed clip missing");
    const ReferenceMotion m = ReferenceMotion::Load(p);
    const std::string src = m.meta().at("source").at("bvh").get<std::string>();
    const BvhClip bvh = ReadBvhFile(FindBvh(a, src));
    std::cerr << "check " << spec.name << " (" << src << ")\n";
    Json stats = EvaluateMotion(m, TargetsForMotion(m, bvh, model, cfg), model, cfg);
    if (a.compare)
      stats["compare_reference"] = CompareWithReference(m, ResolveProjectPath(a.reference_dir));
    report.push_back(stats);
  }
  if (a.json) {
    std::cout << report.dump(2) << "\n";
  } else {
    for (const auto& s : report) {
      std::cout << s["name"].get<std::string>() << ": mean " << s["mean_err_m"].get<double>()
                << " m, max " << s["max_err_m"].get<double>() << " m\n";
    }
  }
}

// `perch motion track`: plays a clip in the physics env with PD tracking only (no learning).
struct TrackArgs {
  std::string name;
  std::string motions = "data/motions";
  std::string env_config;  // optional EnvConfig JSON (action mode is forced to PD)
  double seconds = 0.0;    // 0: the clip's duration (a loop: 5 cycles)
  // Fallen when the torso is below this height [m]; authors' alive tests (notes 4.2): 0.78 for
  // walk / turn, 0.54 for sit. < 0: chosen by clip ("sit" -> 0.54).
  double fall_z = -1.0;
  double walk_fall_z = 0.78;
  double sit_fall_z = 0.54;
  bool json = false;
};

void RunTrack(const TrackArgs& a) {
  const std::string path = ResolveProjectPath(a.motions) + "/" + a.name + ".json";
  ReferenceMotion ref = ReferenceMotion::Load(path);
  EnvConfig cfg = a.env_config.empty() ? EnvConfig() : EnvConfig::Load(a.env_config);
  cfg.action_mode = ActionMode::kPd;
  const bool sit = a.name == "sit";
  if (!sit && a.env_config.empty()) cfg.chair = "none";
  HumanoidChairEnv env(cfg);
  env.Seed(0);
  std::vector<float> obs(env.spec().obs_dim), act(env.spec().act_dim);
  env.Reset(obs.data());
  // Place the clip: the sit clip so that its final pelvis is over the seat centre.
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();
  if (sit && cfg.chair != "none") {
    const auto& pe = ref.meta().at("pelvis_end_m");
    const Eigen::Vector3d seat = env.SeatTargetWorld();
    shift = Eigen::Vector3d(seat.x() - pe[0].get<double>(), seat.y() - pe[1].get<double>(), 0);
  }
  auto pose_at = [&](double t) {
    MotionPose p = ref.At(t);
    p.root_pos += shift;
    return p;
  };
  env.ResetToState(HumanoidStateFromPose(pose_at(0.0)), obs.data());
  const double dt = env.spec().control_dt;
  const double seconds =
      a.seconds > 0 ? a.seconds : (ref.loop() ? 5 * ref.duration() : ref.duration());
  const double fall_z = a.fall_z >= 0 ? a.fall_z : (sit ? a.sit_fall_z : a.walk_fall_z);
  const int steps = static_cast<int>(std::ceil(seconds / dt));
  double joint_err = 0, root_err = 0, up_s = 0;
  bool fell = false;
  int done = 0;
  for (int i = 1; i <= steps; ++i) {
    const MotionPose target = pose_at(i * dt);
    env.HoldPoseAction(target.q.data(), act.data());
    const StepResult r = env.Step(act.data(), obs.data());
    const HumanoidState& s = env.humanoid_state();
    double se = 0;
    for (int j = 0; j < HumanoidModel::kNumJoints; ++j) se += std::pow(s.q[j] - target.q[j], 2);
    joint_err += std::sqrt(se / HumanoidModel::kNumJoints);
    root_err += (s.root_pos - target.root_pos).norm();
    done = i;
    if (r.invalid || s.root_pos.z() < fall_z) {
      fell = true;
      break;
    }
    up_s = i * dt;
    if (i % 120 == 0) std::cerr << "track " << a.name << ": " << up_s << " s\n";
  }
  Json out{{"name", a.name},
           {"action_mode", "pd"},
           {"control_dt_s", dt},
           {"seconds_requested", seconds},
           {"seconds_up", up_s},
           {"fell", fell},
           {"fall_z_m", fall_z},
           {"steps", done},
           {"mean_joint_rms_err_rad", done ? joint_err / done : 0.0},
           {"mean_root_pos_err_m", done ? root_err / done : 0.0}};
  if (sit && cfg.chair != "none") out["pelvis_seat_contact_at_end"] = env.PelvisSeatContact();
  if (a.json) {
    std::cout << out.dump(2) << "\n";
  } else {
    std::cout << a.name << ": up " << up_s << " s of " << seconds << " s" << (fell ? " (fell)" : "")
              << "\n";
  }
}

}  // namespace

void RegisterMotionCommands(CLI::App& root, CLI::App& bench) {
  auto a = std::make_shared<RetargetArgs>();
  CLI::App* rt = root.add_subcommand(
      "retarget", "Retarget CMU BVH clips onto the humanoid (writes DIR/<clip>.json), or --check");
  rt->add_option("bvh", a->bvh, "source BVH files (matched to clips by file name)");
  rt->add_option("--out", a->out, "output directory (for --check: the clips to check)");
  rt->add_option("--config", a->config, "retarget config JSON (defaults: the paper's clips)");
  rt->add_option("--model", a->model, "humanoid model JSON");
  rt->add_option("--bvh-dir", a->bvh_dir, "where --check finds source BVH files not given");
  rt->add_flag("--check", a->check, "measure the committed clips against their sources");
  rt->add_flag("--compare-reference", a->compare,
               "with --check: compare joint angles with the authors' arrays");
  rt->add_option("--reference-dir", a->reference_dir, "the authors' npz files");
  rt->add_flag("--json", a->json, "print one JSON list on stdout");
  auto t = std::make_shared<TrackArgs>();
  CLI::App* motion = root.add_subcommand("motion", "Reference motions");
  motion->require_subcommand(1);
  CLI::App* tr = motion->add_subcommand(
      "track", "Play a clip in the physics env with PD tracking only; report how long it stays up");
  tr->add_option("name", t->name, "clip name (data/motions/NAME.json)")->required();
  tr->add_option("--motions", t->motions, "directory of the clips");
  tr->add_option("--env-config", t->env_config, "EnvConfig JSON (action mode forced to pd)");
  tr->add_option("--seconds", t->seconds,
                 "how long to play (default: the clip, 5 cycles for walk)");
  tr->add_option("--fall-z", t->fall_z, "torso height counted as fallen [m] (default by clip)");
  tr->add_flag("--json", t->json, "print one JSON object on stdout");
  tr->callback([t] { RunTrack(*t); });
  struct ExportArgs {
    std::string name, out;
    std::string motions = "data/motions";
    double seconds = 0.0;
  };
  auto e = std::make_shared<ExportArgs>();
  CLI::App* ex =
      motion->add_subcommand("export-bvh", "Write a clip as BVH (humanoid skeleton, metres, Y up)");
  ex->add_option("name", e->name, "clip name (data/motions/NAME.json)")->required();
  ex->add_option("out", e->out, "output .bvh")->required();
  ex->add_option("--motions", e->motions, "directory of the clips");
  ex->add_option("--seconds", e->seconds, "how long (default: the clip; a loop can run longer)");
  ex->callback([e] {
    const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
    const ReferenceMotion m =
        ReferenceMotion::Load(ResolveProjectPath(e->motions) + "/" + e->name + ".json");
    SaveBvhFile(e->out, HumanoidMotionToBvh(model, m, m.frame_time(), e->seconds));
    std::cerr << "wrote " << e->out << "\n";
  });
  struct StraightenArgs {
    std::string name, out;
    std::string motions = "data/motions";
    double deg = 20.0, t0 = 1.4, t1 = 2.2;
    std::string keep = "torso";
  };
  auto st = std::make_shared<StraightenArgs>();
  CLI::App* sg = motion->add_subcommand(
      "straighten",
      "Write a clip with the abdomen turned by DEG: --keep torso: abdomen_y + DEG, hip_y - DEG, "
      "the pelvis rotates under the torso, kept in place; --keep pelvis: abdomen_y - DEG, the "
      "torso pitches forward (sits up) and nothing below the waist moves");
  sg->add_option("name", st->name, "clip name (data/motions/NAME.json)")->required();
  sg->add_option("out", st->out, "output clip JSON (must not exist)")->required();
  sg->add_option("--motions", st->motions, "directory of the clips");
  sg->add_option("--deg", st->deg, "abdomen extension at the end of the ramp [deg]")
      ->capture_default_str()
      ->check(CLI::Range(-60.0, 60.0));
  sg->add_option("--from-s", st->t0, "ramp start [s]")->capture_default_str();
  sg->add_option("--to-s", st->t1, "ramp end [s]; held after")->capture_default_str();
  sg->add_option("--keep", st->keep, "what keeps its world pose: torso or pelvis")
      ->capture_default_str()
      ->check(CLI::IsMember({"torso", "pelvis"}));
  sg->callback([st] {
    if (std::filesystem::exists(st->out)) throw ConfigError(st->out + ": exists; not overwritten");
    const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
    ReferenceMotion m =
        ReferenceMotion::Load(ResolveProjectPath(st->motions) + "/" + st->name + ".json");
    ReferenceMotion out = m.Straightened(model, st->deg, st->t0, st->t1, st->keep);
    out.set_name(std::filesystem::path(st->out).stem().string());
    out.Save(st->out);
    const MotionPose& a = m.frame(m.num_frames() - 1);
    const MotionPose& b = out.frame(out.num_frames() - 1);
    std::cerr << "wrote " << st->out << "; last frame, reach behind the pelvis [cm]:";
    for (const char* body : {"torso", "lwaist"}) {
      std::cerr << " " << body << " " << 100 * ReferenceMotion::ReachBehindPelvis(model, a, body)
                << " -> " << 100 * ReferenceMotion::ReachBehindPelvis(model, b, body);
    }
    std::cerr << "\n";
  });
  struct BenchArgs {
    std::string bvh = "../shared/mocap/08_01.bvh";
    int last_frame = 30;
    bool json = false;
  };
  auto bb = std::make_shared<BenchArgs>();
  CLI::App* br = bench.add_subcommand(
      "retarget", "IK retargeting speed, as a ratio to one humanoid forward-kinematics call");
  br->add_option("--bvh", bb->bvh, "walk BVH (08_01)");
  br->add_option("--last-frame", bb->last_frame, "retarget source frames 1..N");
  br->add_flag("--json", bb->json, "print one JSON object on stdout");
  br->callback([bb] {
    using Clock = std::chrono::steady_clock;
    const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
    const BvhClip bvh = ReadBvhFile(ResolveProjectPath(bb->bvh));
    RetargetConfig cfg;
    ClipSpec spec = cfg.clips[0];
    spec.loop = false;
    spec.last_frame = bb->last_frame;
    // Baseline: forward kinematics of the humanoid, the IK's inner operation.
    const int fk_calls = 20000;
    std::vector<double> q(model.num_joints(), 0.1);
    double sink = 0;
    const auto f0 = Clock::now();
    for (int i = 0; i < fk_calls; ++i) {
      q[i % q.size()] += 1e-9;
      sink += ForwardKinematics(model, Eigen::Vector3d(0, 0, 1), Eigen::Quaterniond::Identity(),
                                q.data())
                  .body_world[5]
                  .translation()
                  .z();
    }
    const double fk_s = std::chrono::duration<double>(Clock::now() - f0).count() / fk_calls;
    const auto r0 = Clock::now();
    const RetargetOutput out = RetargetClip(bvh, bb->bvh, spec, model, cfg);
    const double rt_s = std::chrono::duration<double>(Clock::now() - r0).count();
    const int frames = out.motion.num_frames();
    Json j{{"frames", frames},
           {"retarget_s", rt_s},
           {"frames_per_s", frames / rt_s},
           {"fk_call_us", fk_s * 1e6},
           {"frame_cost_in_fk_calls", rt_s / frames / fk_s},
           {"checksum", sink}};
    if (bb->json) {
      std::cout << j.dump(2) << "\n";
    } else {
      std::cout << frames / rt_s << " frames/s (" << rt_s / frames / fk_s
                << " FK calls per frame)\n";
    }
  });
  rt->callback([a] {
    if (a->check) {
      RunCheck(*a);
    } else {
      RunRetarget(*a);
    }
  });
}

}  // namespace perch
