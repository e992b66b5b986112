// Draws a few frames of an episode as a filmstrip PNG, side view (x right, z up) above top view
// (x right, y up), a time stamp (and the frame's label) under each, with the humanoid's capsules,
// the chair (boxes or mesh) and walk targets, so a person can
// see a gait or a sit without a 3D viewer. Pure C++ (FK from the model), no Bullet.
#pragma once

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "envs/chair.h"
#include "envs/humanoid_model.h"
#include "envs/humanoid_world.h"  // HumanoidState (plain data, no Bullet)
#include "envs/pose_frame.h"
#include "viz/canvas.h"

namespace perch {

struct FilmstripOptions {
  int panel_px = 220;         // each panel is panel_px x panel_px
  double margin_m = 0.6;      // world margin around the humanoid and chair [m]
  double min_extent_m = 2.2;  // smallest world width a panel shows [m]
  bool follow = false;        // centre each panel on its frame's root instead of one fixed window
  std::vector<Eigen::Vector2d> targets;  // walk targets to mark in the top view, world xy [m]
};

// The chair is drawn when `chair` is not null, at `chair_pose` (chair frame -> world).
Canvas RenderFilmstrip(const HumanoidModel& model, const Chair* chair,
                       const Eigen::Isometry3d& chair_pose, const std::vector<PoseFrame>& frames,
                       const FilmstripOptions& options = {});

// A chair alone in its frame: top view (x right, y up) beside side view (x right, z up), with the
// seat target (a cross) and the facing (+x, an arrow); `perch chair inspect --png`.
Canvas RenderChairViews(const Chair& chair, int panel_px = 320);

// Picks `count` frames evenly spaced over `all` (first and last included).
std::vector<PoseFrame> PickFrames(const std::vector<PoseFrame>& all, int count);

}  // namespace perch
