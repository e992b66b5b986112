// The perch program's command line as a new user meets it (issue 18): typos are named with the
// nearest valid name, help shows defaults, --data-dir and `perch version` say where data comes
// from, and a mock training run ends by itself at --max-samples with its summary.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "common/json_util.h"
#include "tests/common/run_perch.h"

namespace perch {
namespace {

using Result = testing_util::PerchResult;

// stdout and stderr together (the messages under test go to stderr), or stdout alone.
Result Perch(const std::string& args, bool with_stderr = true) {
  return testing_util::RunPerch(args + (with_stderr ? " 2>&1" : " 2>/dev/null"));
}

bool Has(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

class CliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (std::getenv("PERCH_BIN") == nullptr) GTEST_SKIP() << "PERCH_BIN not set (run via ctest)";
  }
};

TEST_F(CliTest, MisspelledOptionsAndSubcommandsAreNamedWithTheNearestValidName) {
  Result r = Perch("train --conifg configs/default.json");
  EXPECT_EQ(r.code, 2);
  EXPECT_TRUE(Has(r.out, "--conifg: unknown option of 'perch train'; did you mean --config?"))
      << r.out;
  r = Perch("eval --model x.bin --episode 3");
  EXPECT_EQ(r.code, 2);
  EXPECT_TRUE(Has(r.out, "--episode: unknown option of 'perch eval'; did you mean --episodes?"))
      << r.out;
  r = Perch("evaluate --model x.bin");
  EXPECT_EQ(r.code, 2);
  EXPECT_TRUE(Has(r.out, "'evaluate': unknown subcommand of 'perch'; did you mean 'eval'?"))
      << r.out;
  r = Perch("bench clustr");
  EXPECT_TRUE(Has(r.out, "did you mean 'cluster'?")) << r.out;
  // Nothing near: named, no guess.
  r = Perch("train --zzzzzzzz 1");
  EXPECT_TRUE(Has(r.out, "--zzzzzzzz: unknown option")) << r.out;
  EXPECT_FALSE(Has(r.out, "did you mean")) << r.out;
  // An option's value that looks like a subcommand is not mistaken for one.
  r = Perch("train --config eval --check-nothing");
  EXPECT_TRUE(Has(r.out, "--check-nothing: unknown option")) << r.out;
}

TEST_F(CliTest, HelpShowsDefaults) {
  const Result r = Perch("train --help");
  EXPECT_EQ(r.code, 0);
  EXPECT_TRUE(Has(r.out, "--actors")) << r.out;
  EXPECT_TRUE(Has(r.out, "--actors INT=2")) << r.out;
  EXPECT_TRUE(Has(r.out, "--rollout-port INT=5555")) << r.out;
  EXPECT_TRUE(Has(Perch("--help").out, "--data-dir"));
}

TEST_F(CliTest, VersionNamesTheDataRootAndDataDirOverridesIt) {
  Result r = Perch("version --json");
  ASSERT_EQ(r.code, 0) << r.out;
  Json j = Json::parse(r.out);
  EXPECT_EQ(j["data_origin"], "source");  // a dev build run from its build tree
  EXPECT_EQ(std::filesystem::path(j["data_root"].get<std::string>()),
            std::filesystem::path(PERCH_SOURCE_DIR).lexically_normal());
  r = Perch(std::string("--data-dir ") + PERCH_SOURCE_DIR + " version --json");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(Json::parse(r.out)["data_origin"], "flag");
  r = Perch("version --json --data-dir /nonexistent");
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "--data-dir /nonexistent: no data/humanoid.json there")) << r.out;
}

TEST_F(CliTest, SetAndBaseComposeAndBadOverridesAreNamed) {
  // --set reaches the config: a value that breaks validation is reported with its field.
  Result r =
      Perch(std::string("learner --config ") + PERCH_SOURCE_DIR +
            "/configs/mock.json --run-dir /tmp/unused --check-config --set ppo.num_epochs=0");
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(Has(r.out, "ppo.num_epochs")) << r.out;
  r = Perch(std::string("learner --config ") + PERCH_SOURCE_DIR +
            "/configs/mock.json --run-dir /tmp/unused --check-config --set ppo.num_epochs=2");
  EXPECT_EQ(r.code, 0) << r.out;
  // A target on a task without a success test is refused by name.
  r = Perch(std::string("learner --config ") + PERCH_SOURCE_DIR +
            "/configs/default.json --run-dir /tmp/unused --check-config --target-success 0.9");
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(Has(r.out, "cluster.target_success: task \"walk\" has no success test")) << r.out;
}

// perch config --fields prints the field tables: each field with its default, range and doc.
TEST_F(CliTest, ConfigFieldsListsEachSectionsFieldsWithDefaultsAndRanges) {
  Result r = Perch("config --fields ppo --json", false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json j = Json::parse(r.out);
  bool found = false;
  for (const Json& row : j["ppo"]) {
    if (row["name"] != "learning_rate") continue;
    found = true;
    EXPECT_NEAR(row["default"].get<double>(), 1e-4, 1e-9);
    EXPECT_EQ(row["rule"], "must be > 0");
  }
  EXPECT_TRUE(found) << r.out;
  // Text: nested fields dotted, one per line.
  r = Perch("config --fields env", false);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(Has(r.out, "env.physics.substeps")) << r.out;
  EXPECT_TRUE(Has(r.out, "env.spawn.zone1_deg")) << r.out;
  // A task's section, under env: the hierarchy's sit_chair with its meta and planner.
  r = Perch("config --fields sit_chair", false);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(Has(r.out, "env.sit_chair.meta.planner.side")) << r.out;
  EXPECT_TRUE(Has(r.out, "must be in [0, 120] control steps")) << r.out;
  r = Perch("config --fields bogus");
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "unknown section \"bogus\"")) << r.out;
  EXPECT_TRUE(Has(r.out, "sit_chair")) << r.out;
}

TEST_F(CliTest, EvalUsesTheCheckpointsConfigAndWarnsWhenConfigDiffers) {
  // The stage-2 walker's checkpoint knows it walks toward targets: without --config, eval
  // measures that stage, not the forward stage of the defaults.
  const std::string model = std::string(PERCH_SOURCE_DIR) +
                            "/models/walk_stage2_fallrestart/checkpoints/ckpt-0000013900.bin";
  Result r = Perch("eval --model " + model + " --episodes 1 --json", /*with_stderr=*/false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json j = Json::parse(r.out);
  EXPECT_EQ(j["task"], "walk");
  EXPECT_EQ(j["config"]["walk"]["stage"], "target") << r.out;
  r = Perch("eval --model " + model + " --config " + PERCH_SOURCE_DIR +
            "/configs/default.json --episodes 1 --json");
  EXPECT_TRUE(Has(r.out, "differs from the config saved with")) << r.out;
}

TEST_F(CliTest, EvalOfAFineTunedSitFromTheFirstFrameIsTheSubtasksOwnStart) {
  // sit_from_turn lists start banks, and sit applies the banks' placement noise (10 cm across)
  // to every episode of such a config; its retention figure (issue 14) must start where the sit
  // subtask's own evaluation does: the clip's first frame at its placement, no noise.
  const std::string model = std::string(PERCH_SOURCE_DIR) + "/models/sit_from_turn/policy.bin";
  Result r = Perch("eval --model " + model + " --episodes 2 --seed 5 --json", false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json a = Json::parse(r.out);
  EXPECT_TRUE(a["config"]["sit"]["start"]["banks"].empty()) << a["config"]["sit"]["start"];
  // The same env without any banks gives the same episodes.
  Json plain = a["config"];
  plain["sit"]["start"] = Json{{"banks", Json::array()}, {"prob", 0.0}};
  const std::string path =
      ::testing::TempDir() + "/sit_plain_" + std::to_string(getpid()) + ".json";
  std::ofstream(path) << plain.dump();
  r = Perch("eval --model " + model + " --config " + path + " --episodes 2 --seed 5 --json", false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json b = Json::parse(r.out);
  EXPECT_DOUBLE_EQ(a["mean_return"].get<double>(), b["mean_return"].get<double>());
  EXPECT_DOUBLE_EQ(a["min_dist_mean_m"].get<double>(), b["min_dist_mean_m"].get<double>());
  std::filesystem::remove(path);
}

TEST_F(CliTest, SitEvalReportsWhereTheSeatedBodyIsAndTheBackrestPushesItForward) {
  // models/sit/README.md: the authors' backrest holds the seated pelvis forward of the target;
  // without the backrest it settles closer. The torso's pitch stays near the clip's (the pose
  // reward tracks joint angles, and the body is shifted, not tilted).
  const std::string src = PERCH_SOURCE_DIR;
  const std::string base =
      "eval --model " + src +
      "/models/sit/checkpoints/sit_contact-0000000296.bin --episodes 3 --seed 13 --json";
  Result r = Perch(base, false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json a = Json::parse(r.out);
  r = Perch(base + " --chair " + src + "/models/sit/chair_authors_nobackrest.json", false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json b = Json::parse(r.out);
  ASSERT_GT(a["success_rate"].get<double>(), 0.5);
  ASSERT_GT(b["success_rate"].get<double>(), 0.5);
  const double ax = a["seat_offset_cm_mean"][0].get<double>();
  const double bx = b["seat_offset_cm_mean"][0].get<double>();
  EXPECT_GT(ax, bx + 1.5) << ax << " vs " << bx;
  const double err = a["seat_position_error_cm_mean"].get<double>();
  EXPECT_GE(err + 1e-9, std::abs(ax));  // the horizontal error includes the forward offset
  for (const Json* j : {&a, &b}) {
    EXPECT_LT(std::abs((*j)["seat_torso_pitch_vs_clip_deg_mean"].get<double>()), 5.0) << *j;
    // Failures are counted by how they failed, and only failures are.
    const int failed = (*j)["episodes"].get<int>() - (*j)["successes"].get<int>();
    EXPECT_LE((*j)["failures"]["fell"].get<int>(), failed);
    EXPECT_LE((*j)["failures"]["never_in_seat_contact"].get<int>(), failed);
  }
}

TEST_F(CliTest, MetaEvalOverEveryChairPlansOnEachChair) {
  // Each chair gets its own row, planned on that chair (the planner's turns are measured in
  // its env); one trial per chair keeps it short.
  const std::string src = PERCH_SOURCE_DIR;
  const std::string base = "eval --task sit_chair --planner --config " + src +
                           "/configs/meta_zone1_plan2_30hz.json --zone 1 --trials 1 --seed 2 "
                           "--threads 1 --json --chair all";
  Result r = Perch(base, false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json j = Json::parse(r.out);
  ASSERT_TRUE(j.contains("per_chair")) << r.out;
  EXPECT_EQ(j["per_chair"].size(), 6u);
  EXPECT_EQ(j["chairs"], 6);
  EXPECT_LE(j["min_success_rate"].get<double>(), j["success_rate"].get<double>());
  EXPECT_TRUE(j["per_chair"].contains(j["min_success_chair"].get<std::string>()));
  for (const auto& [name, row] : j["per_chair"].items()) {
    EXPECT_EQ(row["chair"], name);
    EXPECT_EQ(row["trials"], 1);
    EXPECT_EQ(row["decider"], "planner");
    EXPECT_GE(row["planner"]["turn_left_calibration"]["runs"].get<int>(), 1) << name;
  }
  // Pictures are per chair: asking for one over all chairs is refused, naming the flag.
  r = Perch(base + " --filmstrip /tmp/perch_all_chairs.png");
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "--filmstrip")) << r.out;
}

TEST_F(CliTest, MetaEvalSavesItsHandOversToSitAsABankTheSitStartsFrom) {
  const std::string src = PERCH_SOURCE_DIR;
  const std::string bank = ::testing::TempDir() + "perch_plan_sit_starts.bin";
  const std::string failed = ::testing::TempDir() + "perch_plan_sit_starts_failed.bin";
  std::filesystem::remove(bank);
  std::filesystem::remove(failed);
  const std::string base = "eval --task sit_chair --planner --config " + src +
                           "/configs/meta_zone1_plan3_30hz.json --zone 1 --trials 4 --seed 2 "
                           "--threads 2 --json --start-bank data/banks/walk_end_poses.bin "
                           "--save-sit-starts " +
                           bank + " --save-failed-sit-starts " + failed;
  Result r = Perch(base, false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json j = Json::parse(r.out);
  EXPECT_EQ(j["start_bank"], "data/banks/walk_end_poses.bin");
  const int states = j["sit_starts"]["states"].get<int>();
  ASSERT_GT(states, 0) << r.out;
  EXPECT_LE(j["failed_sit_starts"]["states"].get<int>(), states);
  EXPECT_EQ(states, j["handover_values"]["sit"]["runs"].get<int>());
  // The sit starts from it (its clip kept where the hand-over put the body).
  r = Perch("eval --model " + src + "/models/sit_from_plan3/policy.bin --config " + src +
                "/configs/experiments/sit_from_plan2.json --start end-poses --bank " + bank +
                " --episodes 2 --seed 1 --json",
            false);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(Json::parse(r.out)["episodes"], 2);
  // An existing bank is not replaced without --force, before any trial runs.
  const auto size = std::filesystem::file_size(bank);
  r = Perch(base);
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "exists")) << r.out;
  EXPECT_TRUE(Has(r.out, bank)) << r.out;
  EXPECT_EQ(std::filesystem::file_size(bank), size);
}

// The meta policy with lookahead (--lookahead-delays-s): its JSON says how much it looked ahead
// and that the simulator was exact; the planner's lookahead is its config's, so the flag is
// refused with --planner; a bad delay and a sampling policy are refused by name.
TEST_F(CliTest, MetaEvalLooksAheadForAMetaPolicyOnlyWhenAsked) {
  const std::string src = PERCH_SOURCE_DIR;
  const std::string policy =
      "eval --task sit_chair --model " + src + "/models/sit_chair/policy.bin --trials 2 ";
  auto expect_refused = [&](const std::string& args, const std::string& why) {
    const Result r = Perch(args);
    EXPECT_NE(r.code, 0) << args;
    EXPECT_TRUE(Has(r.out, why)) << args << "\n" << r.out;
  };
  expect_refused(
      "eval --task sit_chair --planner --config " + src +
          "/configs/experiments/meta_zone1_plan5_30hz.json --trials 2 --lookahead-delays-s 0.3",
      "for a meta policy; the planner's lookahead is its config's");
  expect_refused(policy + "--lookahead-delays-s -1", "--lookahead-delays-s");
  // Its rollouts take the policy's mean action, so a sampling policy is refused.
  expect_refused(policy + "--stochastic --lookahead-delays-s 0.5", "needs its mean action");
  // A rank without a lookahead, or a rank that is none of the two, is refused.
  expect_refused(policy + "--lookahead-rank nearer", "--lookahead-rank: only with a lookahead");
  expect_refused(policy + "--lookahead-delays-s 0.5 --lookahead-rank far", "--lookahead-rank");
  // A detour needs to know for how long.
  expect_refused(policy + "--lookahead-delays-s 0.5 --lookahead-detour-deg 60",
                 "lookahead_detour_deg: needs lookahead_straight_s");
  const std::string dir = ::testing::TempDir() + "perch_eval_lookahead/";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string records = dir + "flags.jsonl";
  const std::string run = "eval --task sit_chair --model " + src +
                          "/models/sit_chair/policy.bin --zone 1 --trials 2 --seed 7 --threads 2 "
                          "--json --records " +
                          records + " ";
  Result r = Perch(run +
                       "--lookahead-delays-s 0.5 --lookahead-sides --lookahead-straight-s 0.3 "
                       "--lookahead-rank nearer",
                   false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json j = Json::parse(r.out);
  EXPECT_EQ(j["lookahead_delays_s"], Json({0.5}));
  EXPECT_EQ(j["lookahead_rank"], "nearer");
  EXPECT_EQ(j["lookahead_sides"], true);
  EXPECT_EQ(j["lookahead_straight_s"], Json({0.3}));
  EXPECT_EQ(j["lookahead"]["trials_as_predicted"].get<int>(),
            j["lookahead"]["trials_predicted"].get<int>());
  EXPECT_GE(j["lookahead"]["rollouts_per_trial"].get<double>(), 2.0);
  // The same lookahead from a file (--lookahead) is the same evaluation: it resumes the flags'
  // records (same header) and gives their result without running a trial.
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir + name) << text;
    return dir + name;
  };
  const std::string file = write("la.json",
                                 R"({"lookahead_delays_s": [0.5], "lookahead_sides": true,
                                     "lookahead_straight_s": [0.3], "lookahead_rank": "nearer"})");
  r = Perch(run + "--lookahead " + file);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(Has(r.out, "2 of 2 trials already run")) << r.out;
  const Json from_file = Json::parse(r.out.substr(r.out.find("{\"")));
  for (const char* k :
       {"success_rate", "min_dist_mean_m", "transitions", "lookahead", "lookahead_delays_s",
        "lookahead_sides", "lookahead_straight_s", "lookahead_rank", "lookahead_detour_deg"}) {
    EXPECT_EQ(from_file[k], j[k]) << k;
  }
  // Start routes are recorded only into records, and only with straight-on starts to record.
  expect_refused(policy + "--lookahead-straight-s 0.3 --record-routes",
                 "--record-routes: needs --records");
  expect_refused(policy + "--lookahead-delays-s 0.3 --record-routes --records " + dir + "x.jsonl",
                 "--record-routes: needs --records and a lookahead with straight-on starts");
  // Not with the flags; only lookahead fields; some lookahead; the file must exist.
  expect_refused(policy + "--lookahead " + file + " --lookahead-sides",
                 "not with --lookahead-delays-s");
  expect_refused(policy + "--lookahead " + write("bad.json", R"({"lookahead_m": 2})"),
                 "\"lookahead_m\" is not a lookahead field");
  expect_refused(policy + "--lookahead " + write("none.json", R"({"lookahead_rank": "nearer"})"),
                 "none.json: no lookahead");
  expect_refused(policy + "--lookahead " + dir + "missing.json", "missing.json: cannot open");
  // The shipped files are lookaheads (configs/lookahead/; 8x3 is stop 41's).
  expect_refused("eval --task sit_chair --planner --config " + src +
                     "/configs/experiments/meta_zone1_plan5_30hz.json --trials 2 --lookahead " +
                     src + "/configs/lookahead/8x3.json",
                 "for a meta policy; the planner's lookahead is its config's");
}

// A long evaluation in pieces: --records resumes a killed run (its torn last line dropped) and
// shards (--first-trial) merge (perch eval-merge), both to the result of one run; records of
// other trials, overlapping shards and a gap are refused by name, and nothing saved is lost.
TEST_F(CliTest, MetaEvalResumesFromItsRecordsAndShardsMergeToOneRun) {
  const std::string src = PERCH_SOURCE_DIR;
  const std::string dir = ::testing::TempDir() + "perch_eval_records/";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string base = "eval --task sit_chair --model " + src +
                           "/models/sit_chair/policy.bin --zone 2 --seed 5 --threads 2 --json ";
  Result r = Perch(base + "--trials 6", false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json one = Json::parse(r.out);
  auto same = [&](const Json& j) {
    for (const char* k : {"trials", "first_trial", "success_rate", "success_ci95",
                          "min_dist_mean_m", "min_dist_std_m", "fall_rate", "transitions",
                          "sequences", "by_side", "handover_values", "model", "seed", "zone"}) {
      EXPECT_EQ(j[k], one[k]) << k;
    }
  };
  // A run of 4 of the 6, killed mid-line, then resumed to 6: only the missing trials run.
  const std::string rec = dir + "resumed.jsonl";
  ASSERT_EQ(Perch(base + "--trials 4 --records " + rec, false).code, 0);
  std::string text;
  {
    std::ifstream f(rec, std::ios::binary);
    text.assign(std::istreambuf_iterator<char>(f), {});
  }
  ASSERT_EQ(std::count(text.begin(), text.end(), '\n'), 5) << text;  // the header and 4 trials
  // As if another build had run them: each trial names its build.
  int renamed = 0;
  for (size_t at = text.find("\"build\":\""); at != std::string::npos;
       at = text.find("\"build\":\"", at + 1)) {
    const size_t v = at + 9, end = text.find('"', v);
    text.replace(v, end - v, "perch other");
    ++renamed;
  }
  ASSERT_EQ(renamed, 4) << text;
  { std::ofstream(rec, std::ios::binary) << text.substr(0, text.size() - 30); }
  r = Perch(base + "--trials 6 --records " + rec);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(Has(r.out, "cut short")) << r.out;
  EXPECT_TRUE(Has(r.out, "3 of 6 trials already run")) << r.out;
  EXPECT_TRUE(Has(r.out, "3 of its trials were run by another build")) << r.out;
  // Progress: the time a trial takes in this run (not counting the resumed ones), and what is
  // left.
  EXPECT_TRUE(Has(r.out, "4/6 trials")) << r.out;
  EXPECT_TRUE(Has(r.out, " s a trial, about ")) << r.out;
  const Json resumed = Json::parse(r.out.substr(r.out.find("{\"")));
  EXPECT_EQ(resumed["resumed_trials"], 3);
  EXPECT_EQ(resumed["builds"]["perch other"], 3);
  EXPECT_EQ(one["builds"].size(), 1u);
  EXPECT_EQ(resumed["builds"][one["builds"].begin().key()], 3);
  same(resumed);
  // Other trials (another seed, another zone) are refused, naming the field; the file is kept.
  const auto size = std::filesystem::file_size(rec);
  r = Perch("eval --task sit_chair --model " + src +
            "/models/sit_chair/policy.bin --zone 2 --seed 6 --trials 6 --records " + rec);
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "another \"seed\" (5, now 6)")) << r.out;
  r = Perch("eval --task sit_chair --model " + src +
            "/models/sit_chair/policy.bin --zone 1 --seed 5 --trials 6 --records " + rec);
  EXPECT_TRUE(Has(r.out, "another \"env.spawn.zone\" (2, now 1)")) << r.out;
  r = Perch(base + "--trials 3 --records " + rec);
  EXPECT_TRUE(Has(r.out, "outside this run's trials 0 .. 2")) << r.out;
  EXPECT_EQ(std::filesystem::file_size(rec), size);
  // Two shards merge to the one run; a shard twice or a gap is refused.
  const std::string a = dir + "a.jsonl", b = dir + "b.jsonl";
  r = Perch(base + "--trials 2 --records " + a, false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json first_two = Json::parse(r.out);
  ASSERT_EQ(Perch(base + "--trials 4 --first-trial 2 --records " + b, false).code, 0);
  r = Perch("eval-merge " + b + " " + a + " --json", false);
  ASSERT_EQ(r.code, 0) << r.out;
  same(Json::parse(r.out));
  // The first N of the merged trials: the figure so far of a run still going.
  r = Perch("eval-merge " + b + " " + a + " --trials 2 --json", false);
  ASSERT_EQ(r.code, 0) << r.out;
  for (const char* k : {"trials", "success_rate", "min_dist_mean_m", "transitions"}) {
    EXPECT_EQ(Json::parse(r.out)[k], first_two[k]) << k;
  }
  // --so-far: up to the first missing trial (here a and c hold 0, 1 and 4, 5: the first two).
  ASSERT_EQ(Perch(base + "--trials 2 --first-trial 4 --records " + dir + "c.jsonl", false).code, 0);
  r = Perch("eval-merge " + a + " " + dir + "c.jsonl --so-far --json", false);
  ASSERT_EQ(r.code, 0) << r.out;
  for (const char* k : {"trials", "success_rate", "min_dist_mean_m", "transitions"}) {
    EXPECT_EQ(Json::parse(r.out)[k], first_two[k]) << k;
  }
  r = Perch("eval-merge " + b + " " + a + " --so-far --trials 2");
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "excludes")) << r.out;
  r = Perch("eval-merge " + b + " " + a + " --trials 7");
  EXPECT_TRUE(Has(r.out, "hold 6 of trials 0 .. 6")) << r.out;
  r = Perch("eval-merge " + a + " " + rec);
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "overlapping shards")) << r.out;
  r = Perch("eval-merge " + a + " " + dir + "c.jsonl");
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "lack 2, the first 2")) << r.out;
}

TEST_F(CliTest, MetaEvalSavesTheHandOversToATurnOrTheWalkerAsABankTheyStartFrom) {
  const std::string src = PERCH_SOURCE_DIR;
  const std::string bank = ::testing::TempDir() + "perch_plan_turn_starts.bin";
  std::filesystem::remove(bank);
  const std::string base = "eval --task sit_chair --planner --config " + src +
                           "/configs/meta_zone1_plan3_30hz.json --zone 1 --trials 4 --seed 2 "
                           "--threads 2 --json --start-bank data/banks/walk_end_poses.bin "
                           "--save-sit-starts " +
                           bank + " --hand-overs-to ";
  // A name that is no subtask is refused before any trial, and nothing is written.
  Result r = Perch(base + "stand_up");
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "--hand-overs-to \"stand_up\": not a subtask")) << r.out;
  EXPECT_FALSE(std::filesystem::exists(bank));
  r = Perch(base + "turn_left", false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json j = Json::parse(r.out);
  EXPECT_EQ(j["sit_starts"]["hand_overs_to"], "turn_left");
  const int states = j["sit_starts"]["states"].get<int>();
  ASSERT_GT(states, 0) << r.out;
  EXPECT_EQ(states, j["handover_values"]["turn_left"]["runs"].get<int>());
  // The left turn starts from it.
  r = Perch("eval --model " + src + "/models/turn_left_from_walk/policy.bin --config " + src +
                "/configs/turn_left_from_walk.json --start end-poses --bank " + bank +
                " --episodes 2 --seed 1 --json",
            false);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(Json::parse(r.out)["episodes"], 2);
  // The walker starts from any bank too (its hand-backs in training, walk.start.banks).
  const std::string walker = "eval --task walk --model " + src +
                             "/models/walk_stage2_fallrestart/checkpoints/ckpt-0000013900.bin "
                             "--episodes 2 --seed 1 --json";
  r = Perch(walker + " --start end-poses --bank " + bank, false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json from_bank = Json::parse(r.out);
  EXPECT_EQ(from_bank["episodes"], 2);
  r = Perch(walker, false);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(Json::parse(r.out)["mean_return"], from_bank["mean_return"]);
  // The walker's hand-overs are its hand-backs: the runs that began at the spawn are not banked.
  std::filesystem::remove(bank);
  r = Perch(base + "walk", false);
  ASSERT_EQ(r.code, 0) << r.out;
  const Json w = Json::parse(r.out);
  int first = 0;
  for (const auto& [side, rows] : w["transitions"].items()) {
    if (rows["start"].contains("walk")) first += rows["start"]["walk"].get<int>();
  }
  EXPECT_GT(first, 0);
  EXPECT_EQ(w["sit_starts"]["states"].get<int>(),
            w["handover_values"]["walk"]["runs"].get<int>() - first);
}

TEST_F(CliTest, MetaCloneStageStartsFromTheConfigsPreviousStageOrSaysWhy) {
  const std::string src = PERCH_SOURCE_DIR;
  const std::string out = ::testing::TempDir() + "perch_stage_clone.bin";
  std::filesystem::remove(out);
  // The Zone 1 config's cluster.init_from is the PPO meta of 57 inputs (the planner's configs
  // observe 62): a clone stage cannot continue from it, and the message names file and field.
  Result r = Perch("meta-clone --config " + src +
                   "/configs/meta_zone1_plan2_30hz.json --stage --out " + out + " --episodes 1");
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "meta_zone1/policy.bin: does not fit")) << r.out;
  EXPECT_TRUE(Has(r.out, "obs_dim")) << r.out;
  EXPECT_FALSE(std::filesystem::exists(out));
  // Without an init_from there is no previous stage to name.
  const std::string cfg = ::testing::TempDir() + "perch_stage_none.json";
  std::ofstream(cfg) << R"({"base": ")" << src
                     << R"(/configs/meta_zone1_plan2_30hz.json", "cluster": {"init_from": ""}})";
  r = Perch("meta-clone --config " + cfg + " --stage --out " + out);
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "--stage needs cluster.init_from")) << r.out;
  // Both ways at once is ambiguous.
  r = Perch("meta-clone --config " + cfg + " --stage --init-from x.bin --out " + out);
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "--stage or --init-from")) << r.out;
}

TEST_F(CliTest, TrainEndsByItselfAtMaxSamplesWithASummary) {
  // A fresh clone has no runs/: train creates the run dir's parents.
  const std::string dir = ::testing::TempDir() + "perch_cli_train/nested/run";
  std::filesystem::remove_all(::testing::TempDir() + "perch_cli_train");
  const int port = 21000 + (getpid() % 2000) * 3;
  const Result r = Perch(std::string("train --config ") + PERCH_SOURCE_DIR +
                         "/configs/mock.json --actors 1 --run-dir " + dir +
                         " --max-samples 3000 --set ppo.steps_per_update=1024 --rollout-port " +
                         std::to_string(port) + " --weights-port " + std::to_string(port + 1) +
                         " --metrics-port " + std::to_string(port + 2));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(Has(r.out, "Run ended (max_samples)")) << r.out;
  EXPECT_TRUE(Has(r.out, "of 3000")) << r.out;  // the console's budget
  const Json cfg = LoadJsonFile(dir + "/config.json");
  EXPECT_EQ(cfg["cluster"]["max_samples"], 3000);
  EXPECT_EQ(cfg["ppo"]["steps_per_update"], 1024);
  EXPECT_TRUE(std::filesystem::exists(dir + "/logs"));
  // The run stopped at the first update past the budget, not long after.
  int64_t samples = 0;
  std::ifstream in(dir + "/metrics.jsonl");
  for (std::string line; std::getline(in, line);)
    samples = Json::parse(line)["samples"].get<int64_t>();
  EXPECT_GE(samples, 3000);
  EXPECT_LT(samples, 3000 + 4 * 1024);
}

TEST_F(CliTest, TrainEndsByItselfAtItsSuccessTarget) {
  // The delivered left turn, fine-tuned on: its training episodes pass the success test most of
  // the time, so a target of 50% over 4 judged episodes ends the run after a few updates.
  const std::string dir = ::testing::TempDir() + "perch_cli_target";
  std::filesystem::remove_all(dir);
  const int port = 23000 + (getpid() % 2000) * 3;
  const Result r = Perch(std::string("train --config ") + PERCH_SOURCE_DIR +
                         "/configs/turn_left_heading4.json --actors 1 --run-dir " + dir +
                         " --target-success 0.5 --set cluster.target_window=4"
                         " --set cluster.init_from=models/turn_left/policy.bin"
                         " --set ppo.steps_per_update=1024 --set ppo.learning_rate=1e-6"
                         " --rollout-port " +
                         std::to_string(port) + " --weights-port " + std::to_string(port + 1) +
                         " --metrics-port " + std::to_string(port + 2));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(Has(r.out, "Run ended (target_success)")) << r.out;
  EXPECT_TRUE(Has(r.out, "over the last 4 judged episodes")) << r.out;  // the summary
  EXPECT_TRUE(std::filesystem::exists(dir + "/checkpoints")) << r.out;
}

// perch chair inspect reports what a file gives and what was found; perch chair generate writes
// held-out chairs of a seed (the same seed the same files; never over an existing file).
TEST_F(CliTest, ChairInspectAndGenerateWriteWhatLoads) {
  Result r = Perch("chair inspect armchair --json", false);
  ASSERT_EQ(r.code, 0) << r.out;
  Json j = Json::parse(r.out);
  EXPECT_EQ(j["kind"], "boxes");
  EXPECT_NEAR(j["seat_height_m"].get<double>(), 0.42, 1e-9);
  const std::string shared = std::string(PERCH_SOURCE_DIR) + "/../shared/chairs";
  if (std::filesystem::exists(shared)) {
    // The sofa's deep seat: its target moved forward from the seat's centre.
    r = Perch(std::string("chair inspect ") + PERCH_SOURCE_DIR +
                  "/data/chairs/meshes/sofa_scenic.json --json",
              false);
    ASSERT_EQ(r.code, 0) << r.out;
    j = Json::parse(r.out);
    EXPECT_EQ(j["seat"]["source"], "found");
    EXPECT_GT(j["seat"]["moved_forward_m"].get<double>(), 0.05);
  }
  const std::string dir =
      (std::filesystem::temp_directory_path() / ("perch_gen_" + std::to_string(::getpid())))
          .string();
  std::filesystem::remove_all(dir);
  r = Perch("chair generate --seed 7 --count 4 --dir " + dir + "/a --json", false);
  ASSERT_EQ(r.code, 0) << r.out;
  j = Json::parse(r.out);
  ASSERT_EQ(j["files"].size(), 4u);
  ASSERT_EQ(Perch("chair generate --seed 7 --count 4 --dir " + dir + "/b").code, 0);
  ASSERT_EQ(Perch("chair generate --seed 8 --count 4 --dir " + dir + "/c").code, 0);
  auto text = [](const std::string& p) {
    std::ifstream f(p);
    return std::string(std::istreambuf_iterator<char>(f), {});
  };
  int differ = 0;
  for (int k = 0; k < 4; ++k) {
    const std::string name = "/gen_7_" + std::to_string(k) + ".json";
    EXPECT_EQ(text(dir + "/a" + name), text(dir + "/b" + name));
    differ += text(dir + "/a" + name) != text(dir + "/c/gen_8_" + std::to_string(k) + ".json");
    // Each file is a chair the eval loads.
    r = Perch("chair inspect " + dir + "/a" + name + " --json", false);
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_GE(Json::parse(r.out)["seat_height_m"].get<double>(), 0.33 - 1e-9);
  }
  EXPECT_GT(differ, 0);
  // perch eval --chair DIR: one row per generated chair, their mean and their worst.
  r = Perch("eval --task sit --model " + std::string(PERCH_SOURCE_DIR) +
                "/models/sit/policy.bin --episodes 2 --seed 3 --json --chair " + dir + "/a",
            false);
  ASSERT_EQ(r.code, 0) << r.out;
  j = Json::parse(r.out);
  ASSERT_EQ(j["per_chair"].size(), 4u) << r.out;
  double sum = 0.0, worst = 1.0;
  for (const auto& [name, row] : j["per_chair"].items()) {
    EXPECT_EQ(row["episodes"], 2) << name;
    sum += row["success_rate"].get<double>();
    worst = std::min(worst, row["success_rate"].get<double>());
  }
  EXPECT_EQ(j["chairs"], 4);
  EXPECT_NEAR(j["success_rate"].get<double>(), sum / 4, 1e-12);
  EXPECT_EQ(j["min_success_rate"].get<double>(), worst);
  EXPECT_EQ(j["per_chair"][j["min_success_chair"].get<std::string>()]["success_rate"].get<double>(),
            worst);
  // A second run into the same folder is refused by name and leaves the files as they were.
  const std::string before = text(dir + "/a/gen_7_0.json");
  r = Perch("chair generate --seed 7 --count 4 --dir " + dir + "/a");
  EXPECT_NE(r.code, 0);
  EXPECT_TRUE(Has(r.out, "gen_7_0.json: exists")) << r.out;
  EXPECT_EQ(text(dir + "/a/gen_7_0.json"), before);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace perch
