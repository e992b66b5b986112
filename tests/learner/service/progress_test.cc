#include "learner/service/progress.h"

#include <gtest/gtest.h>

namespace perch {
namespace {

TEST(RunProgress, BudgetGivesPercentDoneAnEtaAndTheStop) {
  ProgressConfig c;
  c.max_samples = 1000;
  c.control_dt = 1.0 / 60;
  RunProgress p(c, /*samples_at_start=*/200, /*start_s=*/10.0);
  EXPECT_FALSE(p.EtaSeconds().has_value());  // no rate yet
  p.OnUpdate(400, 20.0);                      // 200 samples in 10 s: 20/s
  EXPECT_DOUBLE_EQ(*p.FractionDone(), 0.4);
  EXPECT_DOUBLE_EQ(*p.EtaSeconds(), 30.0);  // 600 left at 20/s
  EXPECT_EQ(p.StopReason(), "");
  p.AddEpisode(120, true, false, false);
  p.AddEpisode(60, false, false, false);
  const std::string line = p.ConsoleLine(3, 20.0);
  EXPECT_NE(line.find("40% of 1000"), std::string::npos) << line;
  EXPECT_NE(line.find("ETA 30s"), std::string::npos) << line;
  EXPECT_NE(line.find("episode 1.5 s"), std::string::npos) << line;  // 90 steps at 60 Hz
  EXPECT_NE(line.find("falls 50%"), std::string::npos) << line;
  EXPECT_EQ(line.find("success"), std::string::npos) << line;  // no judged episodes
  p.OnUpdate(1000, 40.0);
  EXPECT_EQ(p.StopReason(), "max_samples");
  const std::string s = p.Summary(9, "max_samples", "runs/x/checkpoints/ckpt-9.bin", 100);
  EXPECT_NE(s.find("Run ended (max_samples) at update 9"), std::string::npos) << s;
  EXPECT_NE(s.find("perch eval --model runs/x/checkpoints/ckpt-9.bin"), std::string::npos) << s;
}

TEST(RunProgress, TargetNeedsAFullWindowOfJudgedEpisodes) {
  ProgressConfig c;
  c.target_success = 0.75;
  c.target_window = 4;
  RunProgress p(c, 0, 0.0);
  for (int i = 0; i < 3; ++i) p.AddEpisode(100, false, true, true);
  EXPECT_DOUBLE_EQ(*p.SuccessRate(), 1.0);
  EXPECT_EQ(p.StopReason(), "");  // 3 of a 4-episode window: too few to judge
  p.AddEpisode(100, true, true, false);
  EXPECT_DOUBLE_EQ(*p.SuccessRate(), 0.75);
  EXPECT_EQ(p.StopReason(), "target_success");
  p.AddEpisode(100, true, true, false);  // the window slides: 2 of the newest 4
  EXPECT_DOUBLE_EQ(*p.SuccessRate(), 0.5);
  EXPECT_EQ(p.StopReason(), "");
  p.AddEpisode(100, false, false, false);  // an unjudged episode changes falls, not success
  EXPECT_DOUBLE_EQ(*p.SuccessRate(), 0.5);
  EXPECT_NE(p.ConsoleLine(1, 0).find("success 50% of last 4 (target 75%)"), std::string::npos);
  EXPECT_FALSE(p.FractionDone().has_value());
}

TEST(RunProgress, HumanUnits) {
  EXPECT_EQ(HumanCount(512), "512");
  EXPECT_EQ(HumanCount(82000), "82k");
  EXPECT_EQ(HumanCount(1.234e6), "1.23M");
  EXPECT_EQ(HumanDuration(42), "42s");
  EXPECT_EQ(HumanDuration(720), "12m");
  EXPECT_EQ(HumanDuration(3 * 3600 + 5 * 60), "3h05m");
}

}  // namespace
}  // namespace perch
