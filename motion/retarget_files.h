// `perch retarget`: CMU BVH files -> data/motions/<clip>.json, and --check: the committed clips
// measured against their sources (and the authors' arrays).
#pragma once

#include <string>
#include <vector>

#include "common/json_util.h"

namespace perch {

struct RetargetFilesOptions {
  std::vector<std::string> bvh;
  std::string out;
  std::string config;
  std::string model = "data/humanoid.json";
  std::string motions = "data/motions";
  std::string bvh_dir = "../shared/mocap";  // beside the data root
  std::string reference_dir = "../shared/reference";
  bool compare = false;
};

// Retargets every clip of the config whose BVH is among a.bvh into a.out (each clip's
// "measured" errors in its meta, and retarget_config.json). Everything is computed before
// anything is written; ConfigError names the clip on a non-finite result. JSON: one object per
// clip written.
Json RetargetFiles(const RetargetFilesOptions& a);

// The committed clips (a.out, else a.motions) against their source BVH (a.bvh, else a.bvh_dir);
// with a.compare also against the authors' arrays. JSON: one object per clip.
Json CheckClips(const RetargetFilesOptions& a);

}  // namespace perch
