// perch retarget: BVH -> data/motions/*.json, and --check: the committed clips' errors
// (motion/retarget_files.h). perch motion track / export-bvh / straighten: reference motions.
// perch bench retarget (bench/retarget_bench.h).
#include <filesystem>
#include <iostream>
#include <memory>

#include "app/commands.h"
#include "bench/retarget_bench.h"
#include "common/json_util.h"
#include "common/paths.h"
#include "envs/humanoid_model.h"
#include "motion/bvh.h"
#include "motion/bvh_export.h"
#include "motion/reference_motion.h"
#include "motion/retarget_files.h"
#include "tasks/track_clip.h"

namespace perch {
namespace {

void RegisterRetarget(CLI::App& root) {
  auto a = std::make_shared<RetargetFilesOptions>();
  auto check = std::make_shared<bool>(false);
  auto json = std::make_shared<bool>(false);
  CLI::App* rt = root.add_subcommand(
      "retarget", "Retarget CMU BVH clips onto the humanoid (writes DIR/<clip>.json), or --check");
  rt->add_option("bvh", a->bvh, "source BVH files (matched to clips by file name)");
  rt->add_option("--out", a->out, "output directory (for --check: the clips to check)");
  rt->add_option("--config", a->config, "retarget config JSON (defaults: the paper's clips)");
  rt->add_option("--model", a->model, "humanoid model JSON");
  rt->add_option("--bvh-dir", a->bvh_dir, "where --check finds source BVH files not given");
  rt->add_flag("--check", *check, "measure the committed clips against their sources");
  rt->add_flag("--compare-reference", a->compare,
               "with --check: compare joint angles with the authors' arrays");
  rt->add_option("--reference-dir", a->reference_dir, "the authors' npz files");
  rt->add_flag("--json", *json, "print one JSON list on stdout");
  rt->callback([a, check, json] {
    if (!*check) {
      const Json report = RetargetFiles(*a);
      if (*json) std::cout << report.dump(2) << "\n";
      return;
    }
    const Json report = CheckClips(*a);
    if (*json) {
      std::cout << report.dump(2) << "\n";
    } else {
      for (const auto& s : report) {
        std::cout << s["name"].get<std::string>() << ": mean " << s["mean_err_m"].get<double>()
                  << " m, max " << s["max_err_m"].get<double>() << " m\n";
      }
    }
  });
}

void RegisterTrack(CLI::App& motion) {
  auto t = std::make_shared<TrackClipOptions>();
  auto json = std::make_shared<bool>(false);
  CLI::App* tr = motion.add_subcommand(
      "track", "Play a clip in the physics env with PD tracking only; report how long it stays up");
  tr->add_option("name", t->name, "clip name (data/motions/NAME.json)")->required();
  tr->add_option("--motions", t->motions, "directory of the clips");
  tr->add_option("--env-config", t->env_config, "EnvConfig JSON (action mode forced to pd)");
  tr->add_option("--seconds", t->seconds,
                 "how long to play (default: the clip, 5 cycles for walk)");
  tr->add_option("--fall-z", t->fall_z, "torso height counted as fallen [m] (default by clip)");
  tr->add_flag("--json", *json, "print one JSON object on stdout");
  tr->callback([t, json] {
    const Json out = TrackClip(*t);
    if (*json) {
      std::cout << out.dump(2) << "\n";
    } else {
      std::cout << t->name << ": up " << out["seconds_up"].get<double>() << " s of "
                << out["seconds_requested"].get<double>() << " s"
                << (out["fell"].get<bool>() ? " (fell)" : "") << "\n";
    }
  });
}

void RegisterExportBvh(CLI::App& motion) {
  struct ExportArgs {
    std::string name, out;
    std::string motions = "data/motions";
    double seconds = 0.0;
  };
  auto e = std::make_shared<ExportArgs>();
  CLI::App* ex =
      motion.add_subcommand("export-bvh", "Write a clip as BVH (humanoid skeleton, metres, Y up)");
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
}

void RegisterStraighten(CLI::App& motion) {
  struct StraightenArgs {
    std::string name, out;
    std::string motions = "data/motions";
    double deg = 20.0, t0 = 1.4, t1 = 2.2;
    std::string keep = "torso";
  };
  auto st = std::make_shared<StraightenArgs>();
  CLI::App* sg = motion.add_subcommand(
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
}

void RegisterRetargetBench(CLI::App& bench) {
  auto o = std::make_shared<RetargetBenchOptions>();
  auto json = std::make_shared<bool>(false);
  CLI::App* br = bench.add_subcommand(
      "retarget", "IK retargeting speed, as a ratio to one humanoid forward-kinematics call");
  br->add_option("--bvh", o->bvh, "walk BVH (08_01)");
  br->add_option("--last-frame", o->last_frame, "retarget source frames 1..N");
  br->add_flag("--json", *json, "print one JSON object on stdout");
  br->callback([o, json] {
    const Json j = RunRetargetBench(*o);
    if (*json) {
      std::cout << j.dump(2) << "\n";
    } else {
      std::cout << j["frames_per_s"].get<double>() << " frames/s ("
                << j["frame_cost_in_fk_calls"].get<double>() << " FK calls per frame)\n";
    }
  });
}

}  // namespace

void RegisterMotionCommands(CLI::App& root, CLI::App& bench) {
  RegisterRetarget(root);
  CLI::App* motion = root.add_subcommand("motion", "Reference motions");
  motion->require_subcommand(1);
  RegisterTrack(*motion);
  RegisterExportBvh(*motion);
  RegisterStraighten(*motion);
  RegisterRetargetBench(bench);
}

}  // namespace perch
