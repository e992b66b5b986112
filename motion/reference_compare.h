// Comparison of our retargeted clips with the authors' arrays (shared/reference/*.npz, notes 7):
// per-joint RMS joint-angle difference after time alignment.
#pragma once

#include <string>

#include "common/json_util.h"
#include "motion/reference_motion.h"

namespace perch {

// Finds the best time offset (and time scale, from a small set) of the authors' trajectory for
// this clip and returns {file, time_scale, offset_s, rms_rad, per_joint_rms_rad{...}}; an object
// with "skipped" when the file is absent or the clip has no counterpart.
Json CompareWithReference(const ReferenceMotion& motion, const std::string& reference_dir);

}  // namespace perch
