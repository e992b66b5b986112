// The actor role's typed setup, resolved from an experiment config (the learner's:
// learner/service/learner_setup.h). `perch actor`, `perch train` and the in-process tests build
// their roles through these, so a cluster run and an inproc:// test differ only in addresses.
#pragma once

#include "actor/actor.h"
#include "experiment/experiment.h"

namespace perch {

ActorSetup MakeActorSetup(const ExperimentConfig& cfg);

}  // namespace perch
