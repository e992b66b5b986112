// `perch motion track`: plays a reference clip in the physics env with PD tracking only (no
// learning): how long the humanoid stays up following it, and how closely.
#pragma once

#include <string>

#include "common/json_util.h"

namespace perch {

struct TrackClipOptions {
  std::string name;
  std::string motions = "data/motions";
  std::string env_config;  // optional EnvConfig JSON (action mode is forced to PD)
  double seconds = 0.0;    // 0: the clip's duration (a loop: 5 cycles)
  // Fallen when the torso is below this height [m]; authors' alive tests (notes 4.2): 0.78 for
  // walk / turn, 0.54 for sit. < 0: chosen by clip ("sit" -> 0.54).
  double fall_z = -1.0;
  double walk_fall_z = 0.78;
  double sit_fall_z = 0.54;
};

// Plays the clip (the sit clip placed so that its final pelvis is over the seat); progress on
// stderr. JSON: seconds up, fell, mean joint and root errors (and the pelvis-seat contact at the
// end of a sit).
Json TrackClip(const TrackClipOptions& a);

}  // namespace perch
