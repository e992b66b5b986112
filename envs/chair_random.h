// Generated chairs (env.chair_random): a four-legged parametric chair with sizes drawn from the
// config's ranges. The env draws one per episode; `perch chair generate` writes them as files (the
// held-out chairs of a seed nobody trained on).
#pragma once

#include "common/json_util.h"
#include "common/rng.h"
#include "envs/env_config.h"

namespace perch {

// The chair file (JSON, "parametric" kind) of one draw, named `name`.
Json RandomChairJson(const ChairRandomConfig& c, Rng& rng, const std::string& name = "random");

}  // namespace perch
