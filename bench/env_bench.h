// perch bench env: the env's control steps per second against bare Bullet running the same
// physics (the same states, PD law and contacts), seated on the chair, per 100-step chunk the
// best of interleaved repeats on thread CPU time (a shared machine's other jobs filtered out).
#pragma once

#include "common/json_util.h"
#include "envs/env_config.h"

namespace perch {

struct EnvBenchOptions {
  int steps = 1000;  // control steps per timed run
  int repeats = 10;  // interleaved runs, best kept
};

// One JSON object: env and raw rates, their ratio, contact and agreement checks.
// ConfigError on bad options; std::runtime_error when the humanoid does not settle on the seat.
Json RunEnvBench(EnvConfig cfg, const EnvBenchOptions& a);

}  // namespace perch
