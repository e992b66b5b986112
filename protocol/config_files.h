// The files an experiment config names that an actor's image does not hold (start-state banks
// made by a recipe in its own directory), shipped with the config in the weights stream so that a
// cluster actor needs no files of its own (issue 48; wire.proto Weights.config_files).
#pragma once

#include <string>
#include <vector>

#include "common/json_util.h"
#include "common/proto/wire.pb.h"

namespace perch {

// Every absolute path in `config` (the "cluster" section aside: the learner's own business) that
// names an existing regular file, with its bytes. Relative paths name the data root's files,
// which every actor's image holds. ConfigError when they add up to more than max_bytes (they
// travel in one message).
std::vector<proto::ConfigFile> CollectConfigFiles(const Json& config, size_t max_bytes);

// `config` with every string equal to a shipped file's path replaced by a copy of that file in
// cache_dir (written atomically, named by a hash of its path and size). ConfigError when
// cache_dir cannot be written.
Json LocalizeConfigFiles(const Json& config, const std::vector<proto::ConfigFile>& files,
                         const std::string& cache_dir);

}  // namespace perch
