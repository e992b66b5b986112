#include "common/config_file.h"

#include <filesystem>

#include "common/paths.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

constexpr int kMaxBaseDepth = 16;

Json LoadWithBases(const std::string& path, std::vector<std::string>* chain) {
  std::error_code ec;
  const std::string key = fs::weakly_canonical(fs::absolute(path, ec), ec).string();
  std::string via;
  for (const std::string& c : *chain) via += c + " -> ";
  for (const std::string& c : *chain) {
    if (fs::weakly_canonical(fs::absolute(c, ec), ec).string() == key) {
      throw ConfigError(via + path + ": base: the configs name each other in a cycle");
    }
  }
  if (chain->size() >= static_cast<size_t>(kMaxBaseDepth)) {
    throw ConfigError(via + path + ": base: more than " + std::to_string(kMaxBaseDepth) + " levels");
  }
  Json j = LoadJsonFile(path);
  if (!j.is_object()) throw ConfigError(path + ": expected a JSON object");
  if (!j.contains("base")) return j;
  if (!j["base"].is_string() || j["base"].get<std::string>().empty()) {
    throw ConfigError(path + ".base: expected the path of another config (a string)");
  }
  const std::string base = j["base"].get<std::string>();
  // Beside this file first (configs/experiments/x.json naming "../turn_left.json" or
  // "turn_left.json" in its own folder), then as a project path ("configs/turn_left.json").
  fs::path p(base);
  if (!p.is_absolute()) {
    const fs::path beside = fs::path(path).parent_path() / p;
    p = fs::exists(beside, ec) ? beside : fs::path(ResolveProjectPath(base));
  }
  if (!fs::exists(p, ec)) throw ConfigError(path + ".base: \"" + base + "\": no such config");
  chain->push_back(path);
  Json merged = LoadWithBases(p.string(), chain);
  chain->pop_back();
  j.erase("base");
  MergeConfig(&merged, j);
  return merged;
}

}  // namespace

void MergeConfig(Json* base, const Json& over) {
  if (!base->is_object() || !over.is_object()) {
    *base = over;
    return;
  }
  for (auto it = over.begin(); it != over.end(); ++it) {
    if (it.value().is_null()) {
      base->erase(it.key());
    } else if (base->contains(it.key()) && (*base)[it.key()].is_object() && it.value().is_object()) {
      MergeConfig(&(*base)[it.key()], it.value());
    } else {
      (*base)[it.key()] = it.value();
    }
  }
}

void ApplySet(Json* j, const std::string& assignment) {
  const std::string ctx = "--set " + assignment;
  const size_t eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0) {
    throw ConfigError(ctx + ": expected section.field=VALUE (e.g. ppo.learning_rate=3e-5)");
  }
  const std::string path = assignment.substr(0, eq);
  const std::string text = assignment.substr(eq + 1);
  Json value = Json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (value.is_discarded()) value = text;  // a bare word: a string
  Json* node = j;
  size_t start = 0;
  while (true) {
    const size_t dot = path.find('.', start);
    const std::string key = path.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
    if (key.empty()) throw ConfigError(ctx + ": empty field name in \"" + path + "\"");
    if (!node->is_object()) {
      throw ConfigError(ctx + ": \"" + path.substr(0, start - 1) + "\" is not an object");
    }
    if (dot == std::string::npos) {
      (*node)[key] = value;
      return;
    }
    if (!node->contains(key)) (*node)[key] = Json::object();
    node = &(*node)[key];
    start = dot + 1;
  }
}

Json LoadComposedConfig(const std::string& path, const std::vector<std::string>& sets) {
  std::vector<std::string> chain;
  Json j = LoadWithBases(ResolveProjectPath(path), &chain);
  for (const std::string& s : sets) ApplySet(&j, s);
  return j;
}

}  // namespace perch
