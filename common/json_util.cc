#include "common/json_util.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <set>

#include "common/file_util.h"

namespace perch {

Json LoadJsonFile(const std::string& path) {
  const std::string text = ReadFileBytes(path);
  // Keys seen so far in each object being parsed, innermost last.
  std::vector<std::set<std::string>> keys;
  const Json::parser_callback_t no_duplicates = [&](int, Json::parse_event_t ev, Json& parsed) {
    if (ev == Json::parse_event_t::object_start) {
      keys.emplace_back();
    } else if (ev == Json::parse_event_t::object_end) {
      if (!keys.empty()) keys.pop_back();
    } else if (ev == Json::parse_event_t::key && !keys.empty()) {
      const std::string k = parsed.get<std::string>();
      if (!keys.back().insert(k).second) throw ConfigError(path + ": duplicate key \"" + k + "\"");
    }
    return true;
  };
  try {
    return Json::parse(text, no_duplicates);
  } catch (const nlohmann::json::parse_error& e) {
    throw ConfigError(path + ": malformed JSON: " + e.what());
  }
}

void SaveJsonFileAtomic(const std::string& path, const Json& j) {
  WriteFileAtomic(path, j.dump(2) + "\n");
}

void CheckKnownKeys(const Json& j, std::initializer_list<const char*> known,
                    const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected an object, got " + j.dump());
  for (auto it = j.begin(); it != j.end(); ++it) {
    bool ok = false;
    for (const char* k : known) ok = ok || it.key() == k;
    if (!ok) throw ConfigError(ctx + ": unknown field '" + it.key() + "'");
  }
}

void CheckKnownKeys(const Json& j, const std::vector<std::string>& known, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected an object, got " + j.dump());
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (std::find(known.begin(), known.end(), it.key()) == known.end()) {
      throw ConfigError(ctx + ": unknown field '" + it.key() + "'");
    }
  }
}

}  // namespace perch
