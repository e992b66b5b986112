// Where shipped files (data/, configs/, models/, web/viewer/dist) are found. There is one data
// root, the first of:
//  1. the --data-dir flag (SetDataRoot, from main),
//  2. $PERCH_DATA_DIR,
//  3. ../share/perch next to the running binary (cmake --install, the .deb, the image),
//  4. the source tree this binary was built from, only while the binary runs from its build tree
//     (so an installed or copied binary never depends on a source checkout).
// A root holds data/humanoid.json; a flag or variable naming the data/ folder itself is accepted.
#pragma once

#include <string>

namespace perch {

struct DataRootInfo {
  std::string root;    // absolute directory holding data/
  std::string origin;  // "flag" | "env" | "install" | "source"
};

// Sets (or, with "", clears) the --data-dir override. Throws std::runtime_error naming the
// directory when it holds no data/humanoid.json.
void SetDataRoot(const std::string& dir);

// The data root and where it came from. Throws std::runtime_error listing what was tried when
// there is none (an installed binary without its share/perch and no PERCH_DATA_DIR).
DataRootInfo FindDataRoot();

// Resolves a project-relative path such as "data/humanoid.json" or "configs/default.json":
// absolute paths, and relative paths that exist from the working directory, as given; otherwise
// under the data root.
std::string ResolveProjectPath(const std::string& path);

// The running executable (/proc/self/exe); empty if unknown.
std::string ExecutablePath();

// ../shared beside the data root (papers, mocap, reference arrays); empty if absent.
std::string SharedDir();

}  // namespace perch
