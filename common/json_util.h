// Strict JSON helpers for config and data files: every error names the file and the field.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace perch {

using Json = nlohmann::json;

// Thrown for any bad config/data input. The message always names where (file, field).
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Parses a JSON file; throws ConfigError "FILE: ..." when missing or malformed, or when an object
// has the same key twice (JSON parsers disagree on which one wins).
Json LoadJsonFile(const std::string& path);

// Writes `j` to `path` atomically (temporary file, fsync, rename). Never truncates an existing
// file on failure.
void SaveJsonFileAtomic(const std::string& path, const Json& j);

// Throws ConfigError "CTX: unknown field 'x'" if `j` has a key outside `known`.
void CheckKnownKeys(const Json& j, std::initializer_list<const char*> known,
                    const std::string& ctx);
void CheckKnownKeys(const Json& j, const std::vector<std::string>& known, const std::string& ctx);

// Reads j[key] into out when present (defaults stay otherwise). A wrong type throws
// ConfigError "CTX.key: expected <type>, got <json>". Integers are strict (issue 17): a
// fraction (1.5, 1024.0), a value outside the field's range (-1 for an unsigned seed, 2^70) or a
// number written as text is refused rather than rounded, wrapped or truncated.
template <typename T>
void GetOptional(const Json& j, const char* key, T& out, const std::string& ctx) {
  auto it = j.find(key);
  if (it == j.end()) return;
  if constexpr (std::is_integral_v<T> && !std::is_same_v<T, bool>) {
    const auto fail = [&](const char* what) {
      throw ConfigError(ctx + "." + key + ": expected " + what + ", got " + it->dump());
    };
    if (it->is_number_unsigned()) {
      const uint64_t v = it->template get<uint64_t>();
      if (v > static_cast<uint64_t>(std::numeric_limits<T>::max())) fail("an integer in range");
      out = static_cast<T>(v);
    } else if (it->is_number_integer()) {
      const int64_t v = it->template get<int64_t>();
      if (v < static_cast<int64_t>(std::numeric_limits<T>::min()) ||
          (v > 0 &&
           static_cast<uint64_t>(v) > static_cast<uint64_t>(std::numeric_limits<T>::max()))) {
        fail(std::is_unsigned_v<T> ? "a non-negative integer in range" : "an integer in range");
      }
      out = static_cast<T>(v);
    } else {
      fail("an integer");
    }
    return;
  }
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
