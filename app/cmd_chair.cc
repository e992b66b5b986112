// perch chair inspect: what a chair file holds and what was found from a mesh's geometry (seat
// target, facing, collision), as text or JSON, with a top + side picture. perch chair generate:
// chair files drawn from a chair_random distribution on a seed (held-out chairs).
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>

#include "app/commands.h"
#include "common/config_file.h"
#include "common/json_util.h"
#include "common/rng.h"
#include "envs/chair.h"
#include "envs/chair_random.h"
#include "viz/filmstrip.h"

namespace perch {
namespace {

Json Vec(const Eigen::Vector3d& v) { return Json::array({v.x(), v.y(), v.z()}); }

Json InspectJson(const Chair& c, const std::string& path) {
  Json j{{"file", path},
         {"name", c.name},
         {"kind", c.mesh ? "mesh" : "boxes"},
         {"seat_target", Vec(c.seat_target)},
         {"seat_height_m", c.seat_height()},
         {"dynamic", c.dynamic},
         {"mass_kg", c.mass},
         {"backrest_front_x", c.backrest_front_x() ? Json(*c.backrest_front_x()) : Json()}};
  if (!c.source.empty()) j["source"] = c.source;
  if (!c.mesh) {
    j["boxes"] = static_cast<int>(c.boxes.size());
    return j;
  }
  const MeshChairInfo& m = c.mesh->info;
  j["mesh"] = {{"path", m.mesh_path},           {"scale", m.scale},
               {"up_axis", m.up_axis},          {"vertices", m.mesh_vertices},
               {"triangles", m.mesh_triangles}, {"size_m", Vec(m.size)}};
  j["seat"] = {{"source", m.seat_source},
               {"file_coords", Vec(m.seat_file)},
               {"area_m2", m.seat_area_m2},
               {"moved_forward_m", m.seat_moved_forward_m}};
  j["facing"] = {{"source", m.facing_source}, {"deg", m.facing_deg}};
  j["collision"] = {{"kind", m.collision},
                    {"parts", m.collision_parts},
                    {"triangles", m.collision_triangles},
                    {"mesh", m.collision_mesh_path.empty() ? Json() : Json(m.collision_mesh_path)}};
  return j;
}

void PrintText(const Json& j) {
  std::cout << "chair " << j["name"].get<std::string>() << " (" << j["file"].get<std::string>()
            << "), " << j["kind"].get<std::string>() << "\n";
  if (j.contains("source"))
    std::cout << "  source       " << j["source"].get<std::string>() << "\n";
  std::cout << "  seat target  " << j["seat_target"].dump() << " m (chair frame), height "
            << j["seat_height_m"].get<double>() << " m\n";
  std::cout << "  backrest     "
            << (j["backrest_front_x"].is_null()
                    ? std::string("none")
                    : "front at x = " + j["backrest_front_x"].dump() + " m")
            << "\n  body         " << (j["dynamic"].get<bool>() ? "dynamic, " : "static, ")
            << j["mass_kg"].get<double>() << " kg\n";
  if (j["kind"] == "mesh") {
    const Json& m = j["mesh"];
    std::cout << "  mesh         " << m["path"].get<std::string>() << ": " << m["vertices"]
              << " vertices, " << m["triangles"] << " triangles, scale " << m["scale"] << ", up "
              << m["up_axis"].get<std::string>() << ", size " << m["size_m"].dump() << " m\n";
    std::cout << "  seat         " << j["seat"]["source"].get<std::string>() << " at "
              << j["seat"]["file_coords"].dump() << " (file units and axes), upward area "
              << j["seat"]["area_m2"] << " m2";
    if (j["seat"]["moved_forward_m"].get<double>() > 0.0) {
      std::cout << ", moved " << j["seat"]["moved_forward_m"]
                << " m forward from its centre (a deep seat)";
    }
    std::cout << "\n";
    std::cout << "  facing       " << j["facing"]["deg"] << " deg from the file's +x ("
              << j["facing"]["source"].get<std::string>() << ")\n";
    std::cout << "  collision    " << j["collision"]["kind"].get<std::string>() << ", "
              << j["collision"]["parts"] << " part(s), " << j["collision"]["triangles"]
              << " triangles\n";
  }
}

}  // namespace

void RegisterChairCommands(CLI::App& root, CLI::App& /*bench*/) {
  CLI::App* chair = root.add_subcommand("chair", "Chair files: inspect what a file describes");
  chair->require_subcommand(1);
  struct Opts {
    std::string file, png;
    bool json = false;
    int px = 320;
  };
  auto o = std::make_shared<Opts>();
  CLI::App* ins = chair->add_subcommand(
      "inspect",
      "Load a chair file (a preset name or a .json, boxes or mesh) and print its seat "
      "target, facing and collision, as found from the mesh where not given");
  ins->add_option("file", o->file, "chair preset or chair file (.json)")->required();
  ins->add_flag("--json", o->json, "print one JSON object on stdout");
  ins->add_option("--png", o->png, "write a picture: top and side views, seat target, facing");
  ins->add_option("--px", o->px, "size of each view in pixels")->check(CLI::Range(64, 2048));
  ins->callback([o] {
    const std::string path = Chair::ResolvePath(o->file);
    const Chair c = Chair::Load(path);
    const Json j = InspectJson(c, path);
    if (o->json) {
      std::cout << j.dump(2) << "\n";
    } else {
      PrintText(j);
    }
    if (!o->png.empty()) {
      RenderChairViews(c, o->px).SavePng(o->png);
      std::cerr << "chair inspect: picture -> " << o->png << "\n";
    }
  });

  struct GenOpts {
    std::string dir, config;
    uint64_t seed = 0;
    int count = 20;
    bool json = false;
  };
  auto g = std::make_shared<GenOpts>();
  CLI::App* gen = chair->add_subcommand(
      "generate",
      "Write chair files drawn from a chair_random distribution (a config's env.chair_random, "
      "or the defaults) on a seed: held-out chairs for perch eval --chair DIR");
  gen->add_option("--dir", g->dir, "folder to write gen_<seed>_<k>.json into")->required();
  gen->add_option("--seed", g->seed, "the draw's seed")->required();
  gen->add_option("--count", g->count, "how many chairs")->check(CLI::Range(1, 10000));
  gen->add_option("--config", g->config,
                  "an experiment or env config whose env.chair_random gives the ranges");
  gen->add_flag("--json", g->json, "print the written files as one JSON object");
  gen->callback([g] {
    Json section = Json::object();
    if (!g->config.empty()) {
      const Json j = LoadComposedConfig(g->config);
      const Json& env = j.contains("env") && j["env"].is_object() ? j["env"] : j;
      if (env.contains("chair_random")) section = env["chair_random"];
    }
    const ChairRandomConfig ranges = EnvConfig::FromJson(Json{{"chair_random", section}},
                                                         g->config.empty() ? "defaults" : g->config)
                                         .chair_random;
    namespace fs = std::filesystem;
    fs::create_directories(g->dir);
    Rng rng(g->seed);
    Json files = Json::array();
    for (int k = 0; k < g->count; ++k) {
      const std::string name = "gen_" + std::to_string(g->seed) + "_" + std::to_string(k);
      const std::string path = (fs::path(g->dir) / (name + ".json")).string();
      if (fs::exists(path)) {
        throw ConfigError(path + ": exists; perch chair generate never overwrites a chair file");
      }
      Json c = RandomChairJson(ranges, rng, name);
      c["_comment"] = "Drawn by perch chair generate --seed " + std::to_string(g->seed) +
                      " (chair " + std::to_string(k) + ")";
      Chair::FromJson(c, path);  // what is written loads
      std::ofstream(path) << c.dump(2) << "\n";
      files.push_back(path);
    }
    if (g->json) {
      std::cout << Json{{"seed", g->seed}, {"count", g->count}, {"files", files}}.dump(2) << "\n";
    } else {
      std::cerr << "chair generate: " << g->count << " chair file(s) -> " << g->dir << "\n";
    }
  });
}

}  // namespace perch
