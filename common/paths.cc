#include "common/paths.h"

#include <cstdlib>
#include <filesystem>
#include <stdexcept>

namespace perch {
namespace {

namespace fs = std::filesystem;

std::string& FlagRoot() {
  static std::string root;
  return root;
}

// dir itself when it holds data/humanoid.json; its parent when dir is the data/ folder (the
// image's PERCH_DATA_DIR=/opt/perch/data); "" otherwise.
std::string AsRoot(const fs::path& dir) {
  std::error_code ec;
  if (fs::exists(dir / "data" / "humanoid.json", ec)) return fs::absolute(dir, ec).lexically_normal().string();
  if (fs::exists(dir / "humanoid.json", ec) && dir.filename() == "data") {
    return fs::absolute(dir, ec).parent_path().lexically_normal().string();
  }
  return "";
}

bool IsUnder(const fs::path& p, const fs::path& dir) {
  const fs::path rel = p.lexically_normal().lexically_relative(dir.lexically_normal());
  return !rel.empty() && *rel.begin() != "..";
}

}  // namespace

void SetDataRoot(const std::string& dir) {
  if (dir.empty()) {
    FlagRoot().clear();
    return;
  }
  const std::string root = AsRoot(dir);
  if (root.empty()) throw std::runtime_error("--data-dir " + dir + ": no data/humanoid.json there");
  FlagRoot() = root;
}

std::string ExecutablePath() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string() : p.string();
}

DataRootInfo FindDataRoot() {
  if (!FlagRoot().empty()) return {FlagRoot(), "flag"};
  if (const char* env = std::getenv("PERCH_DATA_DIR"); env != nullptr && *env != '\0') {
    const std::string root = AsRoot(env);
    if (root.empty()) {
      throw std::runtime_error(std::string("PERCH_DATA_DIR=") + env + ": no data/humanoid.json there");
    }
    return {root, "env"};
  }
  const std::string exe = ExecutablePath();
  std::string tried;
  if (!exe.empty()) {
    const fs::path share = fs::path(exe).parent_path().parent_path() / "share" / "perch";
    if (const std::string root = AsRoot(share); !root.empty()) return {root, "install"};
    tried = share.string();
  }
#ifdef PERCH_BINARY_DIR
  if (exe.empty() || IsUnder(exe, PERCH_BINARY_DIR)) {
    if (const std::string root = AsRoot(PERCH_SOURCE_DIR); !root.empty()) return {root, "source"};
  }
#endif
  throw std::runtime_error("no Perch data directory: pass --data-dir DIR or set PERCH_DATA_DIR (tried " +
                           (tried.empty() ? std::string("nothing next to the binary") : tried) +
                           "; a dev build uses its source tree only when run from its build tree)");
}

std::string ResolveProjectPath(const std::string& path) {
  if (path.empty()) return path;
  const fs::path p(path);
  std::error_code ec;
  if (p.is_absolute() || fs::exists(p, ec)) return path;
  return (fs::path(FindDataRoot().root) / p).string();
}

std::string SharedDir() {
  std::error_code ec;
  fs::path p;
  try {
    p = fs::path(FindDataRoot().root).parent_path() / "shared";
  } catch (const std::exception&) {
    return "";
  }
  return fs::is_directory(p, ec) ? p.string() : std::string();
}

}  // namespace perch
