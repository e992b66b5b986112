// Field-table rows that the clip tasks' configs share (sit, walk, turns): the reward variant
// (which sets other fields' defaults, so it is read first and also when absent), the
// imitation reward, the energy cost and the start bank. common/field_table.h.
#pragma once

#include <string>

#include "common/field_table.h"
#include "tasks/clip_task.h"
#include "tasks/imitation.h"

namespace perch {

// Use as table.With(RewardVariantField<C>).
template <class C>
void RewardVariantField(FieldTable<C>& t) {
  t.CustomAlways(
      "reward_variant", "\"paper\" or \"authors\" (notes 3.2-3.3): sets the reward defaults",
      [](const Json& j, C& c, const std::string& ctx) {
        std::string variant = c.reward_variant;
        GetOptional(j, "reward_variant", variant, ctx);
        c.ApplyVariant(variant, ctx);
      },
      [](const C& c, Json& j) { j["reward_variant"] = c.reward_variant; });
}

// Read over the variant's values (a partial section keeps the rest).
template <class C>
void SimilarityField(FieldTable<C>& t) {
  t.Custom(
      "similarity", "imitation reward (Eq. 2)",
      [](const Json& j, C& c, const std::string& ctx) {
        c.similarity =
            SimilarityRewardConfig::FromJson(j["similarity"], ctx + ".similarity", c.similarity);
      },
      [](const C& c, Json& j) { j["similarity"] = c.similarity.ToJson(); });
}

template <class C>
void EnergyField(FieldTable<C>& t) {
  t.Custom(
      "energy", "energy cost",
      [](const Json& j, C& c, const std::string& ctx) {
        c.energy = EnergyCostConfig::FromJson(j["energy"], ctx + ".energy");
      },
      [](const C& c, Json& j) { j["energy"] = c.energy.ToJson(); });
}

// A section given is read over BankStartConfig's own defaults (as it always was), not the task's.
template <class C>
void StartField(FieldTable<C>& t) {
  t.Custom(
      "start", "start states from a bank",
      [](const Json& j, C& c, const std::string& ctx) {
        c.start = BankStartConfig::FromJson(j["start"], ctx + ".start");
      },
      [](const C& c, Json& j) { j["start"] = c.start.ToJson(); });
}

}  // namespace perch
