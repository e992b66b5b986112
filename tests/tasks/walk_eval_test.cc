#include "tasks/walk_eval.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "common/proto/model.pb.h"
#include "common/proto/wire.pb.h"
#include "learner/ppo.h"
#include "motion/reference_motion.h"
#include "viz/canvas.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

proto::ModelWeights Untrained(uint64_t seed) {
  PpoLearner learner(PolicyConfig::Subtask(52), PpoConfig::Subtask(), seed);
  proto::ModelWeights w;
  learner.ExportWeights(&w);
  return w;
}

std::string Write(const std::string& name, const std::string& bytes) {
  const std::string path = ::testing::TempDir() + "/" + name;
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

TEST(WalkEval, WellFormedAndReproducible) {
  TaskEnvConfig c = TaskEnvConfig::Defaults("walk");
  c.walk.stage = WalkStage::kTarget;
  const proto::ModelWeights w = Untrained(1);
  EvalOptions o;
  o.episodes = 2;
  o.seed = 4;
  EvalRecording rec;
  const Json j = EvaluateWalk(c, w, o, &rec);
  EXPECT_EQ(j["episodes"], 2);
  for (const char* k : {"no_fall_rate", "mean_imitation_reward", "targets_reached_per_min",
                        "mean_heading_error_deg", "mean_episode_steps"}) {
    ASSERT_TRUE(j.contains(k)) << k;
    EXPECT_TRUE(std::isfinite(j[k].get<double>())) << k;
  }
  EXPECT_GE(j["no_fall_rate"].get<double>(), 0.0);
  EXPECT_LE(j["no_fall_rate"].get<double>(), 1.0);
  EXPECT_GE(j["mean_heading_error_deg"].get<double>(), 0.0);
  EXPECT_LE(j["mean_heading_error_deg"].get<double>(), 180.0);
  // The similarity reward per step is within [0, w_pose + w_vel].
  EXPECT_GE(j["mean_imitation_reward"].get<double>(), 0.0);
  EXPECT_LE(j["mean_imitation_reward"].get<double>(), 0.55);
  EXPECT_TRUE(j["foot_sliding"].contains("mean_toe_speed_mps"));
  // Episode 0 recorded: one frame per step plus the start, and its targets.
  EXPECT_GE(rec.frames.size(), 2u);
  EXPECT_FALSE(rec.targets.empty());
  // Same seed, same result; another seed may differ only through the env (targets).
  EXPECT_EQ(EvaluateWalk(c, w, o, nullptr).dump(), j.dump());
  // Forward stage has no target metrics.
  c.walk.stage = WalkStage::kForward;
  EXPECT_FALSE(EvaluateWalk(c, w, o, nullptr).contains("targets_reached_per_min"));
}

// Reach fraction at its two ends: targets reached on the spot (reach radius larger than their
// distance) and targets that always time out (one step to reach a point 1 cm wide).
TEST(WalkEval, TargetReachFractionCountsReachedAgainstTimedOut) {
  TaskEnvConfig c = TaskEnvConfig::Defaults("walk");
  c.walk.stage = WalkStage::kTarget;
  c.walk.min_root_z = -10.0;  // no falls: every episode runs to the time limit
  c.walk.max_episode_steps = 60;
  const proto::ModelWeights w = Untrained(2);
  EvalOptions o;
  o.episodes = 1;
  o.no_fall_s = 1.0;
  c.walk.target_reach_m = 100.0;
  Json j = EvaluateWalk(c, w, o, nullptr);
  EXPECT_GT(j["targets_reached"].get<int>(), 50);
  EXPECT_EQ(j["targets_missed"], 0);
  EXPECT_EQ(j["target_reach_fraction"], 1.0);
  c.walk.target_reach_m = 0.01;
  c.walk.target_redraw_s = 1.0 / 60.0;
  j = EvaluateWalk(c, w, o, nullptr);
  EXPECT_EQ(j["targets_reached"], 0);
  EXPECT_GT(j["targets_missed"].get<int>(), 50);
  EXPECT_EQ(j["target_reach_fraction"], 0.0);
}

// Resolved targets are binned by their distance when drawn; the bins add up to the totals.
TEST(WalkEval, TargetReachByDistanceBinsEachResolvedTarget) {
  TaskEnvConfig c = TaskEnvConfig::Defaults("walk");
  c.walk.stage = WalkStage::kTarget;
  c.walk.min_root_z = -10.0;
  c.walk.max_episode_steps = 60;
  const proto::ModelWeights w = Untrained(2);
  EvalOptions o;
  o.episodes = 2;
  o.no_fall_s = 1.0;
  auto one_bin = [](const Json& j) {
    EXPECT_EQ(j["target_reach_by_distance"].size(), 1u) << j["target_reach_by_distance"].dump();
    return j["target_reach_by_distance"][0];
  };
  c.walk.target_min_dist_m = 1.4;  // all near, all reached
  c.walk.target_max_dist_m = 1.6;
  c.walk.target_reach_m = 100.0;
  Json j = EvaluateWalk(c, w, o, nullptr);
  Json b = one_bin(j);
  EXPECT_EQ(b["from_m"], 1);
  EXPECT_EQ(b["to_m"], 2);
  EXPECT_EQ(b["resolved"], j["targets_reached"]);
  EXPECT_EQ(b["reach_fraction"], 1.0);
  c.walk.target_min_dist_m = 3.4;  // all far, all timed out
  c.walk.target_max_dist_m = 3.6;
  c.walk.target_reach_m = 0.01;
  c.walk.target_redraw_s = 1.0 / 60.0;
  j = EvaluateWalk(c, w, o, nullptr);
  b = one_bin(j);
  EXPECT_EQ(b["from_m"], 3);
  EXPECT_EQ(b["resolved"], j["targets_missed"]);
  EXPECT_EQ(b["reached"], 0);
}

// Each fall is listed with its time, and in target mode with the age of its target.
TEST(WalkEval, FallsAreListedWithTheirTimeAndTargetAge) {
  TaskEnvConfig c = TaskEnvConfig::Defaults("walk");
  c.walk.stage = WalkStage::kTarget;
  c.walk.max_episode_steps = 600;
  c.walk.reference_state_init = true;
  EvalOptions o;
  o.episodes = 3;
  o.no_fall_s = 10.0;
  const Json j = EvaluateWalk(c, Untrained(4), o, nullptr);  // an untrained policy falls
  const double dt = c.env.physics.physics_dt * c.env.physics.substeps;
  ASSERT_EQ(j["fall_times_s"].size(), 3u);
  EXPECT_EQ(j["fall_episodes"], (Json{0, 1, 2}));
  // Start phases: within the clip, and different episodes start at different phases.
  const double clip_s = ReferenceMotion::Load(c.walk.MotionPath()).duration();
  ASSERT_EQ(j["fall_start_phase_s"].size(), 3u);
  for (const Json& ph : j["fall_start_phase_s"]) {
    EXPECT_GE(ph.get<double>(), 0.0);
    EXPECT_LT(ph.get<double>(), clip_s);
  }
  EXPECT_NE(j["fall_start_phase_s"][0], j["fall_start_phase_s"][1]);
  ASSERT_EQ(j["fall_seconds_since_target"].size(), 3u);
  ASSERT_EQ(j["fall_heading_error_deg"].size(), 3u);
  double sum_t = 0;
  for (int i = 0; i < 3; ++i) {
    const double t = j["fall_times_s"][i].get<double>();
    sum_t += t;
    EXPECT_GT(t, 0.0);
    const double age = j["fall_seconds_since_target"][i].get<double>();
    EXPECT_GE(age, 0.0);
    EXPECT_LE(age, std::min(t, c.walk.target_redraw_s) + 1e-9);
    EXPECT_GE(j["fall_heading_error_deg"][i].get<double>(), 0.0);
    EXPECT_LE(j["fall_heading_error_deg"][i].get<double>(), 180.0);
  }
  EXPECT_NEAR(sum_t / 3.0, j["mean_episode_steps"].get<double>() * dt, 1e-9);
}

TEST(WalkEval, ReadsWeightsAndLearnerStateAndRefusesCorruptFiles) {
  const proto::ModelWeights w = Untrained(2);
  const std::string wpath = Write("walk_w.bin", w.SerializeAsString());
  EXPECT_EQ(LoadModelFile(wpath).SerializeAsString(), w.SerializeAsString());

  PpoLearner learner(PolicyConfig::Subtask(52), PpoConfig::Subtask(), 3);
  proto::LearnerState s;
  learner.ExportState(&s);
  const std::string spath = Write("walk_s.bin", s.SerializeAsString());
  EXPECT_EQ(LoadModelFile(spath).SerializeAsString(), s.model().SerializeAsString());

  const std::string bytes = w.SerializeAsString();
  for (const auto& [name, content] : std::vector<std::pair<std::string, std::string>>{
           {"walk_garbage.bin", "not a model at all"},
           {"walk_trunc.bin", bytes.substr(0, bytes.size() / 2)},
           {"walk_empty.bin", ""},
           {"walk_ckpt.bin", std::string("PERCHCKP\x01\x00\x00\x00", 12) + bytes}}) {
    const std::string path = Write(name, content);
    try {
      LoadModelFile(path);
      ADD_FAILURE() << name << " was accepted";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(LoadModelFile(::testing::TempDir() + "/walk_missing.bin"), ConfigError);

  // A model of another shape is refused by the evaluation.
  PpoLearner other(PolicyConfig::Subtask(57), PpoConfig::Subtask(), 3);
  proto::ModelWeights ow;
  other.ExportWeights(&ow);
  EXPECT_THROW(EvaluateWalk(TaskEnvConfig::Defaults("walk"), ow, EvalOptions(), nullptr),
               ConfigError);
}

// The cluster's frame (learner/service/checkpoint.h), written independently here.
uint32_t TestCrc32(const std::string& s) {
  uint32_t crc = 0xFFFFFFFFu;
  for (unsigned char b : s) {
    crc ^= b;
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

std::string Frame(const std::string& payload) {
  std::string out = "PERCHCKP";
  auto put = [&out](uint64_t v, int bytes) {
    for (int i = 0; i < bytes; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
  };
  put(1, 4);
  put(payload.size(), 8);
  put(TestCrc32(payload), 4);
  return out + payload;
}

TEST(WalkEval, ReadsClusterCheckpointsAndRefusesDamagedOnes) {
  ASSERT_EQ(TestCrc32("123456789"), 0xCBF43926u);  // the CRC-32 check value
  PpoLearner learner(PolicyConfig::Subtask(52), PpoConfig::Subtask(), 6);
  proto::Checkpoint ck;
  learner.ExportState(ck.mutable_trainer());
  ck.set_seed(6);
  const std::string framed = Frame(ck.SerializeAsString());
  EXPECT_EQ(LoadModelFile(Write("walk_ck.bin", framed)).SerializeAsString(),
            ck.trainer().model().SerializeAsString());
  std::string flipped = framed;
  flipped[framed.size() / 2] ^= 0x10;
  const std::string fpath = Write("walk_ck_flip.bin", flipped);
  try {
    LoadModelFile(fpath);
    ADD_FAILURE() << "flipped byte accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("CRC"), std::string::npos) << e.what();
  }
  EXPECT_THROW(LoadModelFile(Write("walk_ck_trunc.bin", framed.substr(0, framed.size() - 3))),
               ConfigError);
}

std::string RunPerch(const std::string& args, int* rc, std::string* err) {
  // CTest runs each test in its own process, in parallel: the capture files carry the test's name
  // and pid so that concurrent tests never read each other's output.
  const std::string tag =
      std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" +
      std::to_string(::getpid());
  const std::string out = ::testing::TempDir() + "/walk_cli_out_" + tag + ".txt";
  const std::string errp = ::testing::TempDir() + "/walk_cli_err_" + tag + ".txt";
  *rc = WEXITSTATUS(std::system(
      (std::string(std::getenv("PERCH_BIN")) + " " + args + " >" + out + " 2>" + errp).c_str()));
  std::stringstream a, b;
  a << std::ifstream(out).rdbuf();
  b << std::ifstream(errp).rdbuf();
  *err = b.str();
  return a.str();
}

TEST(EvalCommand, JsonAndFilmstripOfTheRightSize) {
  if (!std::getenv("PERCH_BIN")) GTEST_SKIP() << "PERCH_BIN not set";
  const std::string model = Write("walk_cli_w.bin", Untrained(5).SerializeAsString());
  const std::string png = ::testing::TempDir() + "/walk_cli.png";
  fs::remove(png);
  int rc = 0;
  std::string err;
  const std::string out =
      RunPerch("eval --task walk --stage target --model " + model +
                   " --episodes 2 --json --filmstrip " + png + " --frames 4 --panel-px 100",
               &rc, &err);
  ASSERT_EQ(rc, 0) << err;
  const Json j = Json::parse(out);  // exactly one JSON object on stdout
  EXPECT_EQ(j["episodes"], 2);
  EXPECT_TRUE(j.contains("targets_reached_per_min"));
  EXPECT_EQ(j["config"]["walk"]["stage"], "target");
  const Canvas c = Canvas::LoadPng(png);
  EXPECT_EQ(c.width(), 4 * 100);
  EXPECT_EQ(c.height(), 2 * 100 + 1 + 16);  // with the caption row

  const std::string bad = Write("walk_cli_bad.bin", "garbage");
  RunPerch("eval --task walk --model " + bad + " --json", &rc, &err);
  EXPECT_EQ(rc, 2);
  EXPECT_NE(err.find("perch: error: " + bad), std::string::npos) << err;
}

// A run's config.json (experiment config) works as --config: eval takes its env section, and
// --start overrides how episodes begin.
TEST(EvalCommand, ReadsTheEnvOfAnExperimentConfigAndOverridesTheStart) {
  if (!std::getenv("PERCH_BIN")) GTEST_SKIP() << "PERCH_BIN not set";
  const std::string model = Write("walk_cli_exp_w.bin", Untrained(6).SerializeAsString());
  const Json exp{{"seed", 3},
                 {"env",
                  {{"task", "walk"},
                   {"walk",
                    {{"stage", "forward"},
                     {"reference_state_init", false},
                     {"min_root_z", 0.7},
                     {"target_turn_prob", 0.3}}}}},
                 {"cluster", {{"task", "walk"}}}};
  const std::string cfg = Write("walk_cli_exp.json", exp.dump());
  int rc = 0;
  std::string err;
  Json j = Json::parse(
      RunPerch("eval --task walk --model " + model + " --config " + cfg + " --episodes 1 --json",
               &rc, &err));
  ASSERT_EQ(rc, 0) << err;
  EXPECT_EQ(j["config"]["walk"]["min_root_z"], 0.7);  // from the file's env section
  EXPECT_EQ(j["config"]["walk"]["reference_state_init"], false);
  // A training curriculum is not evaluated unless asked for.
  EXPECT_EQ(j["config"]["walk"]["target_turn_prob"], 0.0);
  j = Json::parse(RunPerch("eval --task walk --model " + model + " --config " + cfg +
                               " --target-turn-prob 0.3 --episodes 1 --json",
                           &rc, &err));
  ASSERT_EQ(rc, 0) << err;
  EXPECT_EQ(j["config"]["walk"]["target_turn_prob"], 0.3);
  j = Json::parse(RunPerch("eval --task walk --model " + model + " --config " + cfg +
                               " --start reference --episodes 1 --json",
                           &rc, &err));
  ASSERT_EQ(rc, 0) << err;
  EXPECT_EQ(j["config"]["walk"]["reference_state_init"], true);
  // An unknown field in the env section is named, as for a plain task config.
  Json bad = exp;
  bad["env"]["walk"]["min_rootz"] = 0.7;
  const std::string bad_cfg = Write("walk_cli_exp_bad.json", bad.dump());
  RunPerch("eval --task walk --model " + model + " --config " + bad_cfg + " --json", &rc, &err);
  EXPECT_EQ(rc, 2);
  EXPECT_NE(err.find("min_rootz"), std::string::npos) << err;
}

TEST(EvalCommand, TrainLocalWritesWeightsThatEvalReads) {
  if (!std::getenv("PERCH_BIN")) GTEST_SKIP() << "PERCH_BIN not set";
  const std::string dir = ::testing::TempDir() + "/walk_train_local";
  fs::remove_all(dir);
  int rc = 0;
  std::string err;
  const Json s = Json::parse(RunPerch(
      "train-local --task walk --samples 256 --steps-per-update 128 --out " + dir + " --json", &rc,
      &err));
  ASSERT_EQ(rc, 0) << err;
  EXPECT_EQ(s["updates"], 2);
  std::ifstream csv(dir + "/curve.csv");
  std::string line;
  int lines = 0;
  while (std::getline(csv, line)) ++lines;
  EXPECT_EQ(lines, 1 + 2);  // header + one row per update
  const Json j = Json::parse(RunPerch(
      "eval --task walk --model " + dir + "/learner_state.bin --episodes 1 --json", &rc, &err));
  ASSERT_EQ(rc, 0) << err;
  EXPECT_EQ(j["model_version"], 2);
}

// perch average-models: reads any policy file kind, writes the mean that eval reads, and never
// replaces an existing output.
TEST(EvalCommand, AverageModelsWritesTheMeanAndNeverOverwrites) {
  if (!std::getenv("PERCH_BIN")) GTEST_SKIP() << "PERCH_BIN not set";
  const proto::ModelWeights a = Untrained(11), b = Untrained(12);
  const std::string pa = Write("walk_avg_a.bin", a.SerializeAsString());
  const std::string pb = Write("walk_avg_b.bin", b.SerializeAsString());
  const std::string out = ::testing::TempDir() + "/walk_avg_out.bin";
  fs::remove(out);
  int rc = 0;
  std::string err;
  const Json s = Json::parse(
      RunPerch("average-models " + pa + " " + pb + " --out " + out + " --json", &rc, &err));
  ASSERT_EQ(rc, 0) << err;
  EXPECT_EQ(s["versions"].size(), 2u);
  const proto::ModelWeights avg = LoadModelFile(out);
  ASSERT_EQ(avg.params_size(), a.params_size());
  for (int k = 0; k < a.params_size(); k += 97) {
    EXPECT_FLOAT_EQ(avg.params(k), 0.5f * (a.params(k) + b.params(k))) << k;
  }
  const Json j =
      Json::parse(RunPerch("eval --task walk --model " + out + " --episodes 1 --json", &rc, &err));
  ASSERT_EQ(rc, 0) << err;
  EXPECT_EQ(j["episodes"], 1);

  const std::string before = LoadModelFile(out).SerializeAsString();
  RunPerch("average-models " + pa + " " + pa + " --out " + out, &rc, &err);
  EXPECT_EQ(rc, 2);
  EXPECT_NE(err.find("exists"), std::string::npos) << err;
  EXPECT_EQ(LoadModelFile(out).SerializeAsString(), before);
  const std::string bad = Write("walk_avg_bad.bin", "garbage");
  fs::remove(out + ".2");
  RunPerch("average-models " + pa + " " + bad + " --out " + out + ".2", &rc, &err);
  EXPECT_EQ(rc, 2);
  EXPECT_NE(err.find(bad), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(out + ".2"));
}

}  // namespace
}  // namespace perch
