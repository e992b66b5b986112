// The typed setups of the two cluster roles, resolved from one experiment config. `perch learner`,
// `perch actor`, `perch train` and the in-process tests build their roles through these, so a
// cluster run and an inproc:// test differ only in addresses.
#pragma once

#include "actor/actor.h"
#include "actor/experiment.h"
#include "learner/service/learner.h"

namespace perch {

LearnerSetup MakeLearnerSetup(const ExperimentConfig& cfg);
ActorSetup MakeActorSetup(const ExperimentConfig& cfg);

}  // namespace perch
