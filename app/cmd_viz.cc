// perch filmstrip: draws a reference motion (or any pose sequence file) as a side+top view PNG.
#include <iostream>
#include <string>

#include "app/commands.h"
#include "envs/chair.h"
#include "envs/humanoid_model.h"
#include "motion/reference_motion.h"
#include "viz/filmstrip.h"

namespace perch {

void RegisterVizCommands(CLI::App& root, CLI::App& bench) {
  struct Opts {
    std::string motion, out, chair, humanoid;
    int frames = 6;
    int panel_px = 220;
    double chair_x = 0, chair_y = 0, chair_yaw_deg = 0;
    bool follow = false;
  };
  auto opts = std::make_shared<Opts>();
  CLI::App* cmd = root.add_subcommand(
      "filmstrip", "Draw a reference motion as a PNG filmstrip (side view above top view)");
  cmd->add_option("--motion", opts->motion, "reference motion file (data/motions/*.json)")
      ->required();
  cmd->add_option("--out", opts->out, "output PNG path")->required();
  cmd->add_option("--frames", opts->frames, "number of frames drawn")->check(CLI::Range(1, 64));
  cmd->add_option("--panel-px", opts->panel_px, "panel size in pixels")
      ->check(CLI::Range(64, 1024));
  cmd->add_option("--chair", opts->chair,
                  "chair to draw: a preset (data/chairs/NAME.json) or a chair file");
  cmd->add_option("--chair-x", opts->chair_x, "chair position x [m]");
  cmd->add_option("--chair-y", opts->chair_y, "chair position y [m]");
  cmd->add_option("--chair-yaw-deg", opts->chair_yaw_deg, "chair yaw [deg]");
  cmd->add_option("--humanoid", opts->humanoid, "humanoid model file (default data/humanoid.json)");
  cmd->add_flag("--follow", opts->follow, "centre each panel on the humanoid");
  cmd->callback([opts]() {
    const HumanoidModel model =
        HumanoidModel::Load(opts->humanoid.empty() ? HumanoidModel::DefaultPath() : opts->humanoid);
    const ReferenceMotion motion = ReferenceMotion::Load(opts->motion);
    std::vector<PoseFrame> all;
    for (int i = 0; i < motion.num_frames(); ++i) {
      const MotionPose& p = motion.frame(i);
      PoseFrame f;
      f.root_pos = p.root_pos;
      f.root_quat = p.root_rot;
      f.q.assign(p.q.data(), p.q.data() + p.q.size());
      f.time_s = i * motion.frame_time();
      all.push_back(f);
    }
    std::unique_ptr<Chair> chair;
    if (!opts->chair.empty())
      chair = std::make_unique<Chair>(Chair::Load(Chair::ResolvePath(opts->chair)));
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translate(Eigen::Vector3d(opts->chair_x, opts->chair_y, 0));
    pose.rotate(Eigen::AngleAxisd(opts->chair_yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
    FilmstripOptions fo;
    fo.panel_px = opts->panel_px;
    fo.follow = opts->follow;
    const Canvas c = RenderFilmstrip(model, chair.get(), pose, PickFrames(all, opts->frames), fo);
    c.SavePng(opts->out);
    std::cerr << "filmstrip: " << motion.name() << ", " << opts->frames << " of "
              << motion.num_frames() << " frames -> " << opts->out << "\n";
  });
}

}  // namespace perch
