// The learner role's typed setup, resolved from an experiment config: the policy's sizes come from
// the experiment's env spec (one env is built to read them), the frozen subtasks from its files.
#pragma once

#include "experiment/experiment.h"
#include "learner/service/learner.h"

namespace perch {

LearnerSetup MakeLearnerSetup(const ExperimentConfig& cfg);

}  // namespace perch
