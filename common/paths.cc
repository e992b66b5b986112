#include "common/paths.h"

#include <cstdlib>
#include <filesystem>

namespace perch {

std::string ResolveProjectPath(const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty()) return path;
  const fs::path p(path);
  std::error_code ec;
  if (p.is_absolute() || fs::exists(p, ec)) return path;
  if (const char* data_dir = std::getenv("PERCH_DATA_DIR")) {
    const std::string prefix = "data/";
    if (path.compare(0, prefix.size(), prefix) == 0) {
      const fs::path q = fs::path(data_dir) / path.substr(prefix.size());
      if (fs::exists(q, ec)) return q.string();
    }
  }
  return (fs::path(PERCH_SOURCE_DIR) / p).string();
}

std::string SharedDir() {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path p = fs::path(PERCH_SOURCE_DIR).parent_path() / "shared";
  return fs::is_directory(p, ec) ? p.string() : std::string();
}

}  // namespace perch
