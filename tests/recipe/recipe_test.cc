// The recipe format and its pure logic: validation, references and dependencies, scaling,
// fingerprints, the state file and what a change invalidates.
#include "recipe/recipe.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/file_util.h"
#include "common/paths.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

Json Stage(const std::string& name, const std::string& kind) {
  Json s{{"name", name}, {"kind", kind}};
  if (kind == "train") {
    s["config"] = "configs/default.json";
    s["max_samples"] = 1000000;
  }
  return s;
}

Json ThreeStages() {
  Json walk = Stage("walk", "train");
  Json bank = Stage("bank", "sample");
  bank["args"] = {"--model", "${walk.policy}", "--out", "${out.bank}"};
  bank["counts"] = {{"--count", 5000}};
  Json turn = Stage("turn", "train");
  turn["set"] = {{"cluster.init_from", "${walk.policy}"}, {"env.start.bank", "${bank.bank}"}};
  Json ev = Stage("eval", "eval");
  ev["args"] = {"--model", "${turn.policy}"};
  return Json{{"name", "t"}, {"stages", {walk, bank, turn, ev}}};
}

std::string ErrorOf(const Json& j) {
  try {
    RecipeFromJson(j, "r.json");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(Recipe, DependenciesFollowTheReferences) {
  const Recipe r = RecipeFromJson(ThreeStages(), "r.json");
  ASSERT_EQ(r.stages.size(), 4u);
  EXPECT_TRUE(r.stages[0].deps.empty());
  EXPECT_THAT(r.stages[1].deps, ::testing::ElementsAre("walk"));
  EXPECT_THAT(r.stages[2].deps, ::testing::ElementsAre("walk", "bank"));
  EXPECT_THAT(r.stages[3].deps, ::testing::ElementsAre("turn"));
  EXPECT_EQ(r.Index("turn"), 2);
  EXPECT_EQ(r.Index("nope"), -1);
  // Sets are written as an object and become section.field=VALUE.
  EXPECT_THAT(r.stages[2].sets, ::testing::Contains("cluster.init_from=${walk.policy}"));
}

TEST(Recipe, RefusesBadStagesNamingThem) {
  Json j = ThreeStages();
  j["stages"][3]["args"] = {"--model", "${later.policy}"};
  EXPECT_THAT(ErrorOf(j), ::testing::HasSubstr("no earlier stage \"later\""));
  j = ThreeStages();
  j["stages"][1]["args"] = {"--model", "${turn.policy}"};  // a later stage
  EXPECT_THAT(ErrorOf(j), ::testing::HasSubstr("stage bank: ${turn.policy}: no earlier stage"));
  j = ThreeStages();
  j["stages"][2]["set"]["x"] = "${walk.bank}";
  EXPECT_THAT(ErrorOf(j), ::testing::HasSubstr("stage walk has no output \"bank\""));
  j = ThreeStages();
  j["stages"][1]["name"] = "walk";
  EXPECT_THAT(ErrorOf(j), ::testing::HasSubstr("used twice"));
  j = ThreeStages();
  j["stages"][0]["kind"] = "dance";
  EXPECT_THAT(ErrorOf(j), ::testing::HasSubstr("\"dance\" is not one of"));
  j = ThreeStages();
  j["stages"][0]["max_smaples"] = 3;
  EXPECT_THAT(ErrorOf(j), ::testing::HasSubstr("unknown field 'max_smaples'"));
  j = ThreeStages();
  j["stages"][0].erase("max_samples");
  EXPECT_THAT(ErrorOf(j), ::testing::HasSubstr("stop rule"));
  j = ThreeStages();
  j["stages"][1]["select"] = {{"last_k", 3}};
  EXPECT_THAT(ErrorOf(j), ::testing::HasSubstr("are for train stages"));
  j = ThreeStages();
  j["stages"][1]["args"] = {"${out.policy}"};
  EXPECT_THAT(ErrorOf(j), ::testing::HasSubstr("${out.policy}: the stage has no such output"));
  EXPECT_THAT(ErrorOf(Json{{"name", "x"}, {"stages", Json::array()}}),
              ::testing::HasSubstr("non-empty list"));
}

TEST(Recipe, SubstitutesReferences) {
  const std::string s = "a ${walk.policy} b ${dir} c ${out.bank}";
  EXPECT_EQ(FindRefs(s).size(), 3u);
  const std::string r = SubstituteRefs(s, [](const std::string& a, const std::string& b) {
    return "<" + a + (b.empty() ? "" : ":" + b) + ">";
  });
  EXPECT_EQ(r, "a <walk:policy> b <dir> c <out:bank>");
  EXPECT_EQ(SubstituteRefs("plain", [](auto&, auto&) { return std::string("x"); }), "plain");
}

TEST(Recipe, ScalesCountsAndBudgetsWithFloors) {
  EXPECT_EQ(ScaledCount(1000, 0.5, 3), 500);
  EXPECT_EQ(ScaledCount(1000, 0.0001, 3), 3);
  EXPECT_EQ(ScaledCount(2, 0.0001, 3), 2);  // never above the full count
  EXPECT_EQ(ScaledCount(1000, 1.0, 3), 1000);
  const Recipe r = RecipeFromJson(ThreeStages(), "r.json");
  RecipeRunOptions o;
  o.scale = 0.0001;
  o.sets = {"seed=4"};
  o.actors = 1;
  const RecipeStage bank = ScaledStage(r.stages[1], o);
  EXPECT_EQ(bank.counts.at("--count"), 3);
  const RecipeStage walk = ScaledStage(r.stages[0], o);
  EXPECT_EQ(walk.max_samples, 100);
  EXPECT_THAT(walk.sets, ::testing::Contains("seed=4"));
  EXPECT_EQ(walk.actors, 1);
}

TEST(Recipe, FingerprintChangesWithConfigInputsAndScale) {
  const Recipe r = RecipeFromJson(ThreeStages(), "r.json");
  RecipeRunOptions o;
  const RecipeStage s = ScaledStage(r.stages[2], o);
  const Json cfg{{"ppo", {{"learning_rate", 1e-4}}}};
  const std::map<std::string, std::string> in{{"walk.policy", "aa"}, {"bank.bank", "bb"}};
  const std::string f = StageFingerprint(s, cfg, in);
  EXPECT_EQ(f, StageFingerprint(s, cfg, in));  // deterministic
  EXPECT_NE(f, StageFingerprint(s, Json{{"ppo", {{"learning_rate", 2e-4}}}}, in));
  EXPECT_NE(f, StageFingerprint(s, cfg, {{"walk.policy", "ab"}, {"bank.bank", "bb"}}));
  o.scale = 0.5;
  EXPECT_NE(f, StageFingerprint(ScaledStage(r.stages[2], o), cfg, in));
  // What does not change the result does not change the fingerprint.
  RecipeStage t = s;
  t.doc = "other words";
  t.est_wall_s = 99;
  t.actors = 7;
  EXPECT_EQ(f, StageFingerprint(t, cfg, in));
}

TEST(Recipe, ChangeInvalidatesTheStageAndItsReaders) {
  const Recipe r = RecipeFromJson(ThreeStages(), "r.json");
  RecipeState st;
  for (const char* n : {"walk", "bank", "turn", "eval"}) {
    st.stages[n].state = "done";
    st.stages[n].fingerprint = std::string("f-") + n;
  }
  std::map<std::string, std::string> fp{
      {"walk", "f-walk"}, {"bank", "f-bank"}, {"turn", "f-turn"}, {"eval", "f-eval"}};
  EXPECT_TRUE(InvalidatedStages(r, st, fp).empty());
  fp["bank"] = "changed";
  EXPECT_THAT(InvalidatedStages(r, st, fp), ::testing::ElementsAre("bank", "turn", "eval"));
  fp["bank"] = "f-bank";
  fp["eval"] = "changed";
  EXPECT_THAT(InvalidatedStages(r, st, fp), ::testing::ElementsAre("eval"));
  // A stage that never ran has nothing to redo.
  st.stages["eval"].state = "pending";
  st.stages["eval"].fingerprint.clear();
  EXPECT_TRUE(InvalidatedStages(r, st, fp).empty());
}

TEST(Recipe, StateFileRoundTripsAndRefusesCorruption) {
  const std::string dir = ::testing::TempDir() + "perch_recipe_state";
  fs::remove_all(dir);
  fs::create_directories(dir);
  EXPECT_TRUE(LoadRecipeState(dir).stages.empty());  // absent: nothing ran
  RecipeState s;
  s.recipe_name = "t";
  s.scale = 0.25;
  StageRecord& w = s.stages["walk"];
  w.state = "done";
  w.samples = 123456;
  w.wall_s = 12.5;
  w.outputs["policy"] = "walk/policy.bin";
  w.output_sha256["policy"] = "abc";
  w.figures = Json{{"success_rate", 0.9}};
  SaveRecipeState(dir, s);
  const RecipeState back = LoadRecipeState(dir);
  EXPECT_EQ(back.scale, 0.25);
  EXPECT_EQ(back.stages.at("walk").samples, 123456);
  EXPECT_EQ(back.stages.at("walk").outputs.at("policy"), "walk/policy.bin");
  EXPECT_EQ(back.stages.at("walk").figures["success_rate"], 0.9);
  {
    std::ofstream out(StatePath(dir));
    out << "{\"format\": \"perch-recipe-state/1\", \"stages\": {\"walk\": {\"state\": "
           "\"dancing\"}}}";
  }
  try {
    LoadRecipeState(dir);
    FAIL() << "a bad state was read";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("stages.walk.state"));
  }
  {
    std::ofstream out(StatePath(dir));
    out << "{\"format\": \"perch";
  }
  EXPECT_THROW(LoadRecipeState(dir), ConfigError);
}

// The delivered recipe file is valid, reads no path under models/, and each training stage has
// a stop rule and names how its checkpoint is chosen.
TEST(Recipe, DeliveredRecipeIsValidAndSelfContained) {
  const std::string path = std::string(PERCH_SOURCE_DIR) + "/recipes/sit_chair.json";
  const Recipe r = LoadRecipe(path);
  EXPECT_GE(r.stages.size(), 10u);
  for (const RecipeStage& s : r.stages) {
    for (const std::string& str : s.sets)
      EXPECT_EQ(str.find("models/"), std::string::npos) << s.name << ": " << str;
    for (const std::string& str : s.args)
      EXPECT_EQ(str.find("models/"), std::string::npos) << s.name << ": " << str;
    if (s.kind == "train") {
      EXPECT_GT(s.max_samples, 0) << s.name;
      EXPECT_TRUE(fs::exists(std::string(PERCH_SOURCE_DIR) + "/" + s.config)) << s.config;
    }
  }
}

}  // namespace
}  // namespace perch
