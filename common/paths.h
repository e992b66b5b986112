// Where shipped files (data/, configs/) are found: the source tree in development and tests, an
// installed data directory in the container image (PERCH_DATA_DIR).
#pragma once

#include <string>

namespace perch {

// Resolves a project-relative path such as "data/humanoid.json":
//  1. absolute paths, and relative paths that exist from the working directory, as given;
//  2. "data/..." under $PERCH_DATA_DIR when that is set and the file exists there;
//  3. otherwise under the source tree this binary was built from.
std::string ResolveProjectPath(const std::string& path);

// ../shared beside the source tree (papers, mocap, reference arrays); empty if absent.
std::string SharedDir();

}  // namespace perch
