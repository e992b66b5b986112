// How an episode may start from a start-state bank (transition fine-tuning, notes 4.3): the
// config shared by every task that has one (turns, sit, walk). Kept apart from state_bank.h so
// that task configs can hold it without the env's headers.
#pragma once

#include <string>
#include <vector>

#include "common/field_table.h"
#include "common/json_util.h"

namespace perch {

struct StartBank;  // tasks/state_bank.h

// Episode starts from a start-state bank (transition fine-tuning, notes 4.3 "*_from_*"): with
// probability `prob` an episode starts from a random bank state instead of the clip.
struct BankStartConfig {
  std::vector<std::string> banks;  // bank files (their union); empty: never
  double prob = 1.0;
  // The authors restore a 51-number state into a freshly loaded humanoid, so the torso's angular
  // velocity is zero (notes 1.6); ours keeps the recorded one unless this is set.
  bool zero_root_ang_vel = false;
  // The state where it was relative to its chair (a bank sampled in the chain, whose states
  // hold the chair), instead of moved to the clip's first frame.
  bool keep_pose = false;
  static BankStartConfig FromJson(const Json& j, const std::string& ctx);
  Json ToJson() const;
};
const FieldTable<BankStartConfig>& BankStartConfigFields();

}  // namespace perch
