// Strict JSON helpers for config and data files: every error names the file and the field.
#pragma once

#include <initializer_list>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace perch {

using Json = nlohmann::json;

// Thrown for any bad config/data input. The message always names where (file, field).
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Parses a JSON file; throws ConfigError "FILE: ..." when missing or malformed.
Json LoadJsonFile(const std::string& path);

// Writes `j` to `path` atomically (temporary file, fsync, rename). Never truncates an existing
// file on failure.
void SaveJsonFileAtomic(const std::string& path, const Json& j);

// Throws ConfigError "CTX: unknown field 'x'" if `j` has a key outside `known`.
void CheckKnownKeys(const Json& j, std::initializer_list<const char*> known, const std::string& ctx);

// Reads j[key] into out when present (defaults stay otherwise). A wrong type throws
// ConfigError "CTX.key: expected <type>, got <json>".
template <typename T>
void GetOptional(const Json& j, const char* key, T& out, const std::string& ctx) {
  auto it = j.find(key);
  if (it == j.end()) return;
  try {
    out = it->template get<T>();
  } catch (const nlohmann::json::exception& e) {
    throw ConfigError(ctx + "." + key + ": " + e.what() + " (value: " + it->dump() + ")");
  }
}

// As GetOptional, but the field must be present.
template <typename T>
void GetRequired(const Json& j, const char* key, T& out, const std::string& ctx) {
  if (!j.is_object() || j.find(key) == j.end()) {
    throw ConfigError(ctx + ": missing required field '" + key + "'");
  }
  GetOptional(j, key, out, ctx);
}

}  // namespace perch
