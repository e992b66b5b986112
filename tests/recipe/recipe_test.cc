// The recipe format and its pure logic: validation, references and dependencies, scaling,
// fingerprints, the state file and what a change invalidates.
#include "recipe/recipe.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

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

// select.milestones: the whole run's kept checkpoints are candidates, not only the newest K.
TEST(Recipe, SelectionSearchesTheMilestonesWhenAsked) {
  const std::vector<std::string> ck{"c100", "c200", "c300", "c580", "c600", "c611"};
  StageSelect s;
  EXPECT_EQ(SelectionCandidates(ck, s), std::vector<std::string>{"c611"});  // last_k 0: newest
  s.last_k = 3;
  EXPECT_EQ(SelectionCandidates(ck, s), (std::vector<std::string>{"c580", "c600", "c611"}));
  s.last_k = 10;
  EXPECT_EQ(SelectionCandidates(ck, s), ck);
  s.last_k = 3;
  s.milestones = true;
  EXPECT_EQ(SelectionCandidates(ck, s), ck);
  // In the format: written only when on (older recipes keep their fingerprints), and it needs an
  // evaluation to choose by.
  Json r = ThreeStages();
  r["stages"][2]["select"] = {{"last_k", 3}, {"episodes", 10}};
  const Recipe before = RecipeFromJson(r, "r.json");
  RecipeRunOptions o;
  const std::string f = StageFingerprint(ScaledStage(before.stages[2], o), Json(), {});
  r["stages"][2]["select"]["milestones"] = false;
  EXPECT_EQ(f, StageFingerprint(ScaledStage(RecipeFromJson(r, "r.json").stages[2], o), Json(), {}));
  r["stages"][2]["select"]["milestones"] = true;
  EXPECT_NE(f, StageFingerprint(ScaledStage(RecipeFromJson(r, "r.json").stages[2], o), Json(), {}));
  r["stages"][2]["select"] = {{"milestones", true}};
  EXPECT_NE(ErrorOf(r).find(".milestones: needs last_k >= 1"), std::string::npos) << ErrorOf(r);
  // include_init likewise: read, written only when on, and only with a selection by evaluation.
  r["stages"][2]["select"] = {{"last_k", 3}, {"episodes", 10}, {"include_init", false}};
  EXPECT_EQ(f, StageFingerprint(ScaledStage(RecipeFromJson(r, "r.json").stages[2], o), Json(), {}));
  r["stages"][2]["select"]["include_init"] = true;
  EXPECT_TRUE(RecipeFromJson(r, "r.json").stages[2].select.include_init);
  EXPECT_NE(f, StageFingerprint(ScaledStage(RecipeFromJson(r, "r.json").stages[2], o), Json(), {}));
  r["stages"][2]["select"] = {{"include_init", true}};
  EXPECT_NE(ErrorOf(r).find(".include_init: needs last_k >= 1"), std::string::npos) << ErrorOf(r);
}

// Sharded evaluations: consecutive trials per shard, none twice, none left out; only an eval
// stage of trials with no output but its result; and the shard count is not in the fingerprint
// (the merged result is the unsharded one).
TEST(Recipe, EvaluationShardsCoverEveryTrialOnce) {
  for (const auto& [trials, shards] :
       std::vector<std::pair<int64_t, int>>{{1000, 4}, {1000, 7}, {3, 4}, {1, 4}, {10, 1}}) {
    const std::vector<TrialShard> t = TrialShards(trials, shards);
    int64_t next = 0;
    for (const TrialShard& s : t) {
      EXPECT_EQ(s.first, next);
      EXPECT_GT(s.count, 0);
      next += s.count;
    }
    EXPECT_EQ(next, trials);
    EXPECT_LE(static_cast<int>(t.size()), shards);
  }
  EXPECT_EQ(TrialShards(3, 4).size(), 3u);  // an empty shard is left out
  Json r = ThreeStages();
  r["stages"][3]["counts"] = {{"--trials", 1000}};
  r["stages"][3]["shards"] = 4;
  const Recipe sharded = RecipeFromJson(r, "r.json");
  EXPECT_EQ(sharded.stages[3].shards, 4);
  r["stages"][3]["shards"] = 1;
  RecipeRunOptions o;
  EXPECT_EQ(StageFingerprint(ScaledStage(sharded.stages[3], o), Json(), {}),
            StageFingerprint(ScaledStage(RecipeFromJson(r, "r.json").stages[3], o), Json(), {}));
  r["stages"][3]["shards"] = 4;
  r["stages"][3]["outputs"] = {{"bank", "bank.bin"}};
  EXPECT_NE(ErrorOf(r).find(".shards: a sharded evaluation writes only its result"),
            std::string::npos)
      << ErrorOf(r);
  r["stages"][3].erase("outputs");
  r["stages"][3]["counts"] = {{"--episodes", 10}};
  EXPECT_NE(ErrorOf(r).find(".shards: only an eval stage of --trials"), std::string::npos);
  r["stages"][3]["shards"] = 0;
  EXPECT_NE(ErrorOf(r).find(".shards: must be in 1..1000"), std::string::npos);
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
  const Recipe main = LoadRecipe(path);
  EXPECT_GE(main.stages.size(), 10u);
  // Its variant for many chairs (issue 51): every stage of the main recipe, then its own.
  const Recipe chairs =
      LoadRecipe(std::string(PERCH_SOURCE_DIR) + "/recipes/sit_chair_many_chairs.json");
  ASSERT_GT(chairs.stages.size(), main.stages.size());
  for (size_t i = 0; i < main.stages.size(); ++i) {
    EXPECT_EQ(chairs.stages[i].name, main.stages[i].name);
  }
  EXPECT_THAT(StagesReading(chairs, "sit"), testing::Contains("eval_sit_chairs_heldout"));
  for (const Recipe& r : {main, chairs}) {
    for (const RecipeStage& s : r.stages) {
      for (const std::string& str : s.sets)
        EXPECT_EQ(str.find("models/"), std::string::npos) << s.name << ": " << str;
      for (const std::string& str : s.args)
        EXPECT_EQ(str.find("models/"), std::string::npos) << s.name << ": " << str;
      if (s.kind == "train") {
        EXPECT_GT(s.max_samples, 0) << s.name;
        EXPECT_TRUE(fs::exists(std::string(PERCH_SOURCE_DIR) + "/" + s.config)) << s.config;
      }
      // A folder of chairs an evaluation reads is in the tree.
      for (size_t k = 0; k + 1 < s.args.size(); ++k) {
        if (s.args[k] == "--chair" && s.args[k + 1] != "all") {
          EXPECT_TRUE(fs::is_directory(std::string(PERCH_SOURCE_DIR) + "/" + s.args[k + 1]))
              << s.name << ": " << s.args[k + 1];
        }
      }
    }
  }
}

// The readers of a stage, through other stages too; a stage that reads nothing of it is not one.
// A variant names a base recipe: its stages of the same name replace the base's in place, new
// ones follow; a missing base or an unknown key is refused by name.
TEST(Recipe, AVariantReplacesAndAppendsStagesOfItsBase) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("perch_recipe_base_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir / "v");
  std::ofstream(dir / "base.json") << ThreeStages().dump();
  Json bank = Stage("bank", "sample");
  bank["args"] = {"--model", "${walk.policy}", "--out", "${out.bank}"};
  bank["counts"] = {{"--count", 99}};
  Json extra = Stage("eval2", "eval");
  extra["args"] = {"--model", "${turn.policy}"};
  std::ofstream(dir / "v" / "variant.json")
      << Json{{"base", "../base.json"}, {"name", "v"}, {"stages", {bank, extra}}}.dump();
  const Recipe r = LoadRecipe((dir / "v" / "variant.json").string());
  EXPECT_EQ(r.name, "v");
  ASSERT_EQ(r.stages.size(), 5u);
  EXPECT_EQ(r.stages[1].name, "bank");
  EXPECT_EQ(r.stages[1].counts.at("--count"), 99);  // replaced in place
  EXPECT_EQ(r.stages[4].name, "eval2");
  EXPECT_THAT(StagesReading(r, "walk"), testing::Contains("eval2"));
  // A step put into the lineage: a new stage that a replaced one reads goes just before it.
  Json pre = Stage("pre", "train");
  pre["set"] = {{"cluster.init_from", "${walk.policy}"}};
  Json turn = Stage("turn", "train");
  turn["set"] = {{"cluster.init_from", "${pre.policy}"}};
  std::ofstream(dir / "v" / "step.json")
      << Json{{"base", "../base.json"}, {"name", "s"}, {"stages", {pre, turn}}}.dump();
  const Recipe step = LoadRecipe((dir / "v" / "step.json").string());
  std::vector<std::string> order;
  for (const RecipeStage& st : step.stages) order.push_back(st.name);
  EXPECT_THAT(order, testing::ElementsAre("walk", "bank", "pre", "turn", "eval"));
  EXPECT_THAT(StagesReading(step, "pre"), testing::ElementsAre("turn", "eval"));
  // A variant of a variant.
  std::ofstream(dir / "v" / "v2.json")
      << Json{{"base", "variant.json"}, {"name", "v2"}, {"stages", Json::array()}}.dump();
  EXPECT_EQ(LoadRecipe((dir / "v" / "v2.json").string()).stages.size(), 5u);
  std::ofstream(dir / "v" / "bad.json") << Json{{"base", "nope.json"}, {"name", "b"}}.dump();
  try {
    LoadRecipe((dir / "v" / "bad.json").string());
    ADD_FAILURE() << "a missing base was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("nope.json does not exist"), std::string::npos)
        << e.what();
  }
  std::ofstream(dir / "v" / "odd.json")
      << Json{{"base", "variant.json"}, {"name", "o"}, {"stagez", Json::array()}}.dump();
  try {
    LoadRecipe((dir / "v" / "odd.json").string());
    ADD_FAILURE() << "an unknown key was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("stagez"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

TEST(Recipe, StagesReadingFollowsReadersTransitively) {
  const Recipe r = RecipeFromJson(ThreeStages(), "r.json");
  EXPECT_THAT(StagesReading(r, "walk"), testing::ElementsAre("bank", "turn", "eval"));
  EXPECT_THAT(StagesReading(r, "turn"), testing::ElementsAre("eval"));
  EXPECT_TRUE(StagesReading(r, "eval").empty());
  // In the delivered recipe the sit's first runs read nothing of the walker.
  const Recipe d = LoadRecipe(std::string(PERCH_SOURCE_DIR) + "/recipes/sit_chair.json");
  const std::vector<std::string> w = StagesReading(d, "walk2");
  EXPECT_THAT(w, testing::Contains("walk"));
  EXPECT_THAT(w, testing::Contains("turn_left"));
  EXPECT_THAT(w, testing::Not(testing::Contains("sit_scratch")));
  EXPECT_THAT(w, testing::Not(testing::Contains("walk1")));
}

// --extend accepts a larger budget and learning rates past what was trained, nothing else.
TEST(Recipe, ExtensionAcceptsOnlyWhatLeavesTheTrainedPrefixAlone) {
  const Json prev = Json::parse(R"({"cluster": {"max_samples": 100, "seed": 0},
    "ppo": {"learning_rate": 1e-4, "lr_schedule": [[50, 3e-5], [70, 1e-5]]}})");
  auto with = [&](const std::string& key, const std::string& field, const Json& v) {
    Json n = prev;
    n[key][field] = v;
    return n;
  };
  const int64_t trained = 100;
  EXPECT_EQ(ExtensionMismatch(prev, prev, trained), "");
  // A larger budget, and a new rate from 100 samples on (past the trained prefix).
  Json longer = with("cluster", "max_samples", 150);
  longer["ppo"]["lr_schedule"] = Json::parse("[[50, 3e-5], [70, 1e-5], [100, 3e-5], [130, 1e-5]]");
  EXPECT_EQ(ExtensionMismatch(prev, longer, trained), "");
  // The same schedule written with a redundant entry at an unchanged rate still agrees.
  Json same = longer;
  same["ppo"]["lr_schedule"] = Json::parse("[[50, 3e-5], [60, 3e-5], [70, 1e-5], [100, 3e-5]]");
  EXPECT_EQ(ExtensionMismatch(prev, same, trained), "");
  // A rate changed inside the trained prefix, directly or by moving a breakpoint.
  Json moved = longer;
  moved["ppo"]["lr_schedule"] = Json::parse("[[50, 3e-5], [80, 1e-5], [100, 3e-5]]");
  EXPECT_THAT(ExtensionMismatch(prev, moved, trained),
              testing::HasSubstr("learning rate at 70 samples"));
  EXPECT_THAT(ExtensionMismatch(prev, with("ppo", "learning_rate", 3e-4), trained),
              testing::HasSubstr("learning rate at 0 samples"));
  // A new entry before the trained end changes the prefix too.
  Json early = longer;
  early["ppo"]["lr_schedule"] = Json::parse("[[50, 3e-5], [70, 1e-5], [90, 3e-5]]");
  EXPECT_THAT(ExtensionMismatch(prev, early, trained),
              testing::HasSubstr("learning rate at 90 samples"));
  // A budget below what was trained, or any other field, is refused naming it.
  EXPECT_THAT(ExtensionMismatch(prev, with("cluster", "max_samples", 80), trained),
              testing::HasSubstr("below the 100 samples"));
  EXPECT_THAT(ExtensionMismatch(prev, with("cluster", "seed", 1), trained),
              testing::HasSubstr("cluster.seed changed"));
  Json extra = prev;
  extra["reward"]["w_target"] = 0.5;
  EXPECT_THAT(ExtensionMismatch(prev, extra, trained), testing::HasSubstr("reward.w_target"));
}

}  // namespace
}  // namespace perch

namespace perch {
namespace {

// The recipe format's fields are written once, in RecipeStageFields(): every key the delivered
// recipe uses is a row; what the table writes reads back to the same stage; a key it does not
// list is refused naming it; and the rows are what `perch recipe fields` prints.
TEST(RecipeFormat, EveryStageFieldIsReadAndWrittenByItsTable) {
  const std::string path = std::string(PERCH_SOURCE_DIR) + "/recipes/sit_chair.json";
  const Json file = LoadJsonFile(path);
  const Recipe r = LoadRecipe(path);
  const std::vector<std::string> names = RecipeStageFields().Names();
  ASSERT_EQ(r.stages.size(), file["stages"].size());
  for (size_t i = 0; i < r.stages.size(); ++i) {
    for (auto it = file["stages"][i].begin(); it != file["stages"][i].end(); ++it) {
      EXPECT_THAT(names, ::testing::Contains(it.key())) << r.stages[i].name;
    }
    const Json written = RecipeStageFields().Write(r.stages[i]);
    const RecipeStage again = RecipeStageFields().Read(written, "again");
    EXPECT_EQ(RecipeStageFields().Write(again), written) << r.stages[i].name;
    EXPECT_EQ(again.sets, r.stages[i].sets) << r.stages[i].name;
    EXPECT_EQ(again.toy_sets, r.stages[i].toy_sets) << r.stages[i].name;
    EXPECT_EQ(again.has_toy_args, r.stages[i].has_toy_args) << r.stages[i].name;
    EXPECT_EQ(again.select.milestones, r.stages[i].select.milestones) << r.stages[i].name;
    EXPECT_EQ(again.counts, r.stages[i].counts) << r.stages[i].name;
  }
  Json bad = ThreeStages();
  bad["stages"][1]["select"] = {{"last_k", 2}, {"episdoes", 5}};
  EXPECT_THAT(ErrorOf(bad), ::testing::HasSubstr("unknown field 'episdoes'"));
  bad = ThreeStages();
  bad["stages"][0]["select"] = {{"last_k", 51}};
  EXPECT_THAT(ErrorOf(bad), ::testing::HasSubstr("(walk).select.last_k: must be in 0..50"));
  bad = ThreeStages();
  bad["stages"][0]["actors"] = 300;
  EXPECT_THAT(ErrorOf(bad), ::testing::HasSubstr("(walk).actors: must be in 0..256"));
  // The printed table: one line per field, select's nested.
  const std::string text = RecipeFieldsText(false);
  for (const std::string& n : names) {
    if (n == "select") continue;
    EXPECT_THAT(text, ::testing::HasSubstr("stages[]." + n + "  ")) << n;
  }
  // Aligned columns as perch config --fields prints them: name, default, doc (rule).
  EXPECT_THAT(text, ::testing::ContainsRegex("stages\\[\\]\\.select\\.last_k +0 +evaluate the "
                                             "newest K[^\n]*\\(must be in 0\\.\\.50\\)\n"));
  EXPECT_EQ(Json::parse(RecipeFieldsText(true))["stage"].size(), names.size());
}

}  // namespace
}  // namespace perch
