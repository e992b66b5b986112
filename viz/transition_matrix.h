// The meta controller's transition matrix (which subtask follows which, per start side) drawn as
// a PNG from the "transitions" object of a meta evaluation's JSON (hierarchy/meta_eval.h).
#pragma once

#include <string>

#include "common/json_util.h"

namespace perch {

// Fig. 7: the `transitions` of an EvaluateMeta result as a PNG, one matrix per start side; rows
// are where a run of one subtask came from (start or a subtask), columns what followed (a subtask
// or the episode's end); cells shaded by the row's share, labelled with the count.
void SaveTransitionMatrixPng(const Json& result, const std::string& path);

}  // namespace perch
