// learner/local/meta_clone_stage.h: a clone stage from an experiment config, refused early and by
// name where it cannot run (the full clone is exercised by meta_clone_test.cc and the CLI tests).
#include "learner/local/meta_clone_stage.h"

#include <gtest/gtest.h>

#include <string>

namespace perch {
namespace {

std::string ErrorOf(const MetaCloneStageOptions& o) {
  try {
    RunMetaCloneStage(o);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(MetaCloneStage, RefusesWhatCannotBeAStageBeforeAnyEpisode) {
  const std::string src = PERCH_SOURCE_DIR;
  MetaCloneStageOptions o;
  o.config = src + "/configs/walk_stage2_authors.json";
  EXPECT_NE(ErrorOf(o).find("meta-clone needs sit_chair"), std::string::npos) << ErrorOf(o);
  o.config = src + "/configs/meta_zone1_plan2_30hz.json";
  o.from_config_init = true;
  o.init_from = "x.bin";
  EXPECT_NE(ErrorOf(o).find("--stage or --init-from"), std::string::npos) << ErrorOf(o);
  o.init_from.clear();
  o.sets = {"cluster.init_from=\"\""};
  EXPECT_NE(ErrorOf(o).find("--stage needs cluster.init_from"), std::string::npos) << ErrorOf(o);
}

}  // namespace
}  // namespace perch
