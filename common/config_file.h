// Config files that compose (issue 18): an experiment branch names a `base` config and overrides
// a few fields, and `--set section.field=VALUE` overrides one field from the command line.
#pragma once

#include <string>
#include <vector>

#include "common/json_util.h"

namespace perch {

// Loads `path` (through ResolveProjectPath). When it has "base": "OTHER.json" (relative to this
// file's folder, else to the project), OTHER is loaded first, recursively, and this file's fields
// override it: objects merge key by key, any other value replaces, and null removes the key. Then
// each `sets` entry is applied in order. The result has no "base". Throws ConfigError naming the
// file (and the chain of bases) or the --set that is wrong; a cycle of bases is an error.
Json LoadComposedConfig(const std::string& path, const std::vector<std::string>& sets = {});

// Overrides `base` with `over` as described above.
void MergeConfig(Json* base, const Json& over);

// One "a.b.c=VALUE": VALUE is read as JSON when it parses (3, 1e-4, true, "x", [1,2], {...}),
// else as a string. Intermediate objects are created; a non-object on the path is an error.
void ApplySet(Json* j, const std::string& assignment);

}  // namespace perch
