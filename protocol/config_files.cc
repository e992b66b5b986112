#include "protocol/config_files.h"

#include <filesystem>
#include <functional>
#include <map>

#include "common/file_util.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

void Walk(const Json& j, const std::function<void(const std::string&)>& f) {
  if (j.is_string()) {
    f(j.get<std::string>());
  } else if (j.is_array() || j.is_object()) {
    for (const Json& e : j) Walk(e, f);
  }
}

void Replace(Json* j, const std::map<std::string, std::string>& to) {
  if (j->is_string()) {
    auto it = to.find(j->get<std::string>());
    if (it != to.end()) *j = it->second;
  } else if (j->is_array() || j->is_object()) {
    for (Json& e : *j) Replace(&e, to);
  }
}

}  // namespace

std::vector<proto::ConfigFile> CollectConfigFiles(const Json& config, size_t max_bytes) {
  std::vector<proto::ConfigFile> out;
  std::map<std::string, bool> seen;
  size_t total = 0;
  for (auto it = config.begin(); config.is_object() && it != config.end(); ++it) {
    if (it.key() == "cluster") continue;
    Walk(*it, [&](const std::string& s) {
      if (s.empty() || s.size() > 4096 || seen.count(s)) return;
      seen[s] = true;
      std::error_code ec;
      const fs::path p(s);
      if (!p.is_absolute() || !fs::is_regular_file(p, ec)) return;
      proto::ConfigFile f;
      f.set_path(s);
      f.set_content(ReadFileBytes(s, "config file"));
      total += f.content().size();
      if (total > max_bytes) {
        throw ConfigError("the files the config names add up to more than " +
                          std::to_string(max_bytes) + " bytes (at " + s +
                          "); they cannot travel to the actors with the weights");
      }
      out.push_back(std::move(f));
    });
  }
  return out;
}

Json LocalizeConfigFiles(const Json& config, const std::vector<proto::ConfigFile>& files,
                         const std::string& cache_dir) {
  std::error_code ec;
  fs::create_directories(cache_dir, ec);
  if (ec) throw ConfigError(cache_dir + ": cannot create: " + ec.message());
  std::map<std::string, std::string> to;
  for (const proto::ConfigFile& f : files) {
    const std::string name = std::to_string(std::hash<std::string>{}(f.path())) + "-" +
                             std::to_string(f.content().size()) + "-" +
                             fs::path(f.path()).filename().string();
    const std::string local = (fs::path(cache_dir) / name).string();
    try {
      WriteFileAtomic(local, f.content());
    } catch (const std::exception& e) {
      throw ConfigError(std::string("cannot keep a file the learner sent: ") + e.what());
    }
    to[f.path()] = local;
  }
  Json j = config;
  Replace(&j, to);
  return j;
}

}  // namespace perch
