// `perch train`: one learner and N actor processes of this program on loopback, supervised: a
// crashed child is restarted (the learner with --resume) with backoff, given up after
// cluster.max_identical_failures identical failures; a learner that stops updating is reported;
// SIGINT/SIGTERM stop the learner first (its final checkpoint), then the actors.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace perch {

struct LocalTrainingOptions {
  std::string config;                     // the experiment config file
  std::vector<std::string> learner_sets;  // the learner's --set overrides (with the shorthands)
  std::vector<std::string> actor_sets;    // the actors' (they build the same env)
  int actors = 2;
  int envs = 0;         // envs per actor; 0: the config's
  std::string run_dir;  // empty: runs/<config name>
  bool resume = false;
  int64_t max_updates = 0;  // 0: the config's stop rules only
  int rollout_port = 5555;
  int weights_port = 5556;
  int metrics_port = 9100;
};

// Runs the training to its end (or a stop signal); returns the process exit code: the learner's
// (0 done, 2 a config error) or 1 when the learner or every actor failed beyond its restarts.
// ConfigError, before any process starts, for what the learner would refuse.
int RunLocalTraining(LocalTrainingOptions o);

}  // namespace perch
