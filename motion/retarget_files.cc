#include "motion/retarget_files.h"

#include <filesystem>
#include <iostream>
#include <map>

#include "common/paths.h"
#include "envs/humanoid_model.h"
#include "motion/bvh.h"
#include "motion/reference_compare.h"
#include "motion/reference_motion.h"
#include "motion/retarget.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

std::string Basename(const std::string& p) { return fs::path(p).filename().string(); }

RetargetConfig LoadConfig(const RetargetFilesOptions& a) {
  if (a.config.empty()) return RetargetConfig();
  return RetargetConfig::FromJson(LoadJsonFile(a.config), a.config);
}

// Finds the BVH named `name` among the given paths, else in bvh_dir.
std::string FindBvh(const RetargetFilesOptions& a, const std::string& name) {
  for (const auto& p : a.bvh) {
    if (Basename(p) == name) return p;
  }
  const std::string p = ResolveProjectPath(a.bvh_dir) + "/" + name;
  if (fs::exists(p)) return p;
  throw ConfigError("source BVH '" + name + "' not given on the command line and not in " +
                    a.bvh_dir);
}

}  // namespace

Json RetargetFiles(const RetargetFilesOptions& a) {
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
  return report;
}

Json CheckClips(const RetargetFilesOptions& a) {
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
  return report;
}

}  // namespace perch
