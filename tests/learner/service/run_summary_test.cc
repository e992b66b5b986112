#include "learner/service/run_summary.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <utility>

#include "learner/service/learner.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

std::string Row(int update, double time_s, const char* ret, int actors = 2) {
  std::ostringstream o;
  o << "{\"update\":" << update << ",\"samples\":" << update * 100 << ",\"time_s\":" << time_s
    << ",\"samples_per_s\":" << 100.0 << ",\"policy_lag_mean\":0.5,\"actors\":" << actors
    << ",\"return_mean\":" << ret << ",\"episode_length_mean\":" << (ret[0] == 'n' ? "null" : "7")
    << ",\"ppo\":{\"log_std_mean\":-0.25}}";
  return o.str();
}

std::string RunDir(const std::string& tag, const std::string& metrics) {
  const std::string d = ::testing::TempDir() + "/run_summary_" + tag;
  fs::remove_all(d);
  fs::create_directories(d + "/checkpoints");
  std::ofstream(d + "/metrics.jsonl") << metrics;
  return d;
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// A run resumed from its update-2 checkpoint repeats update 3: the curve keeps one row per update
// (the later one) and the summary reads the last row.
TEST(RunSummary, ResumedRunGivesOneRowPerUpdateAndItsCsv) {
  const std::string d = RunDir(
      "resumed", Row(1, 1.0, "1.5", 1) + "\n" + Row(2, 2.0, "null") + "\n" + Row(3, 3.0, "9.0") +
                     "\n" + Row(3, 3.5, "4.0") + "\n" + Row(4, 4.5, "6.0") + "\n");
  std::ofstream(d + "/checkpoints/ckpt-0000000004.bin") << "x";
  std::ofstream(d + "/checkpoints/ckpt-0000000002.bin") << "x";
  std::ofstream(d + "/config.json") << "{\"seed\": 5}";
  const RunSummary s = SummarizeRun(d);
  ASSERT_EQ(s.curve.size(), 4u);
  EXPECT_EQ(s.curve[2].update, 3);
  EXPECT_DOUBLE_EQ(s.curve[2].return_mean, 4.0);
  EXPECT_FALSE(s.curve[1].has_episodes);
  EXPECT_EQ(s.updates, 4);
  EXPECT_EQ(s.samples, 400);
  EXPECT_DOUBLE_EQ(s.wall_time_s, 4.5);
  EXPECT_EQ(s.max_actors, 2);
  EXPECT_EQ(s.config["seed"], 5);
  ASSERT_EQ(s.checkpoints.size(), 2u);
  EXPECT_NE(s.checkpoints[0].find("ckpt-0000000002.bin"), std::string::npos);
  const Json j = ToJson(s);
  EXPECT_DOUBLE_EQ(j["samples_per_s"].get<double>(), 400 / 4.5);
  EXPECT_EQ(j["last"]["updates_averaged"], 3);  // update 2 had no finished episode
  EXPECT_DOUBLE_EQ(j["last"]["return_mean"].get<double>(), (1.5 + 4.0 + 6.0) / 3);

  const std::string csv = d + "/curve.csv";
  WriteCurveCsv(s, csv);
  std::ifstream in(csv);
  std::string header, line;
  std::getline(in, header);
  EXPECT_EQ(header.rfind("update,samples,time_s", 0), 0u);
  std::vector<std::string> lines;
  while (std::getline(in, line)) lines.push_back(line);
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(lines[1].rfind("2,200,", 0), 0u);
  EXPECT_NE(lines[1].find(",,,"), std::string::npos);  // blank return and length
  EXPECT_EQ(lines[3].rfind("4,400,4.5", 0), 0u);
}

TEST(RunSummary, TornLastLineIsIgnoredDamageElsewhereIsNamed) {
  const std::string torn = RunDir("torn", Row(1, 1.0, "1") + "\n" + Row(2, 2.0, "2") + "\n{\"upd");
  EXPECT_EQ(SummarizeRun(torn).updates, 2);
  const std::string bad = RunDir("bad", Row(1, 1.0, "1") + "\ngarbage\n" + Row(2, 2.0, "2") + "\n");
  try {
    SummarizeRun(bad);
    FAIL() << "accepted a damaged metrics.jsonl";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("metrics.jsonl:2"), std::string::npos) << e.what();
  }
  const std::string missing_field = RunDir("field", "{\"update\": 1}\n");
  try {
    SummarizeRun(missing_field);
    FAIL() << "accepted a row without samples";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("'samples'"), std::string::npos) << e.what();
  }
  EXPECT_THROW(SummarizeRun(::testing::TempDir() + "/no_such_run"), ConfigError);
}

// A run stopped mid-write, then resumed: the learner cuts the torn tail before appending, so the
// rows of the resumed run stay whole and the summary covers both parts (issue 17).
TEST(RunSummary, AResumeAfterATornLineKeepsTheRunReadable) {
  const std::string d =
      RunDir("torn-resume", Row(1, 1.0, "1") + "\n" + Row(2, 2.0, "2") + "\n{\"upd");
  RepairMetricsFile(d + "/metrics.jsonl");
  std::ofstream(d + "/metrics.jsonl", std::ios::app) << Row(3, 3.0, "3") << "\n";
  const RunSummary s = SummarizeRun(d);
  EXPECT_EQ(s.updates, 3);
  EXPECT_EQ(s.curve.size(), 3u);
  // Whole files are left alone.
  const std::string whole = RunDir("whole", Row(1, 1.0, "1") + "\n");
  const std::string before = ReadAll(whole + "/metrics.jsonl");
  RepairMetricsFile(whole + "/metrics.jsonl");
  EXPECT_EQ(ReadAll(whole + "/metrics.jsonl"), before);
  RepairMetricsFile(whole + "/no-such-file.jsonl");  // nothing to do, no error
}

// PNG width and height from the IHDR chunk (bytes 16-23, big-endian).
std::pair<int, int> PngSize(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string b((std::istreambuf_iterator<char>(in)), {});
  if (b.size() < 24 || b.compare(1, 3, "PNG") != 0) return {0, 0};
  auto be = [&](int at) {
    return (static_cast<uint8_t>(b[at]) << 24) | (static_cast<uint8_t>(b[at + 1]) << 16) |
           (static_cast<uint8_t>(b[at + 2]) << 8) | static_cast<uint8_t>(b[at + 3]);
  };
  return {be(16), be(20)};
}

TEST(RunSummary, PlotDrawsOneOrSeveralRunsWithGnuplot) {
  std::string a, b;
  for (int u = 1; u <= 30; ++u) {
    a += Row(u, u * 1.0, std::to_string(u * 0.5).c_str()) + "\n";
    b += Row(u, u * 2.0, std::to_string(30 - u * 0.3).c_str()) + "\n";
  }
  const RunSummary ra = SummarizeRun(RunDir("plot_a", a));
  const RunSummary rb = SummarizeRun(RunDir("plot_b", b));
  const std::string one = ::testing::TempDir() + "/plot_one.png";
  const std::string two = ::testing::TempDir() + "/plot_two.png";
  fs::remove(one);
  fs::remove(two);
  PlotRuns({ra}, one);
  PlotRuns({ra, rb}, two);
  EXPECT_EQ(PngSize(one), std::make_pair(1400, 1700));
  EXPECT_EQ(PngSize(two), std::make_pair(1400, 1700));
  EXPECT_NE(fs::file_size(one), fs::file_size(two));  // the second run's lines and key
  // Without gnuplot: a clear error naming it, and the old file is kept.
  const std::string path = std::getenv("PATH");
  ::setenv("PATH", "/nonexistent", 1);
  try {
    PlotRuns({ra}, two);
    ADD_FAILURE() << "plotted without gnuplot";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("gnuplot"), std::string::npos) << e.what();
  }
  ::setenv("PATH", path.c_str(), 1);
  EXPECT_EQ(PngSize(two), std::make_pair(1400, 1700));
}

}  // namespace
}  // namespace perch
