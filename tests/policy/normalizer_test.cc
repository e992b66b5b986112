// Running statistics (update, batch update and merge agree with a direct computation), the
// observation transform (clip 10, var + 1e-8), and reward scaling by the return's running std.
#include "policy/normalizer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "common/proto/model.pb.h"
#include "common/rng.h"

namespace perch {
namespace {

std::vector<float> Data(int n, int d, uint64_t seed) {
  Rng rng(seed);
  std::vector<float> x(n * d);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < d; ++j) x[i * d + j] = static_cast<float>(rng.Normal(j - 1.0, 0.5 + j));
  return x;
}

TEST(RunningMeanStdTest, UpdateBatchAndMergeMatchDirectMoments) {
  const int n = 500, d = 3;
  const std::vector<float> x = Data(n, d, 1);
  RunningMeanStd one(d, 0.0), batch(d, 0.0), left(d, 0.0), right(d, 0.0);
  for (int i = 0; i < n; ++i) one.Update(&x[i * d]);
  batch.UpdateBatch(x.data(), n);
  left.UpdateBatch(x.data(), 200);
  for (int i = 200; i < n; ++i) right.Update(&x[i * d]);
  left.Merge(right);
  for (int j = 0; j < d; ++j) {
    double m = 0, v = 0;
    for (int i = 0; i < n; ++i) m += x[i * d + j];
    m /= n;
    for (int i = 0; i < n; ++i) v += (x[i * d + j] - m) * (x[i * d + j] - m);
    v /= n;
    EXPECT_NEAR(one.mean()[j], m, 1e-9);
    EXPECT_NEAR(one.var()[j], v, 1e-9 * (1 + v));
    EXPECT_NEAR(batch.mean()[j], m, 1e-9);
    EXPECT_NEAR(batch.var()[j], v, 1e-9 * (1 + v));
    EXPECT_NEAR(left.mean()[j], m, 1e-9);
    EXPECT_NEAR(left.var()[j], v, 1e-9 * (1 + v));
  }
  EXPECT_DOUBLE_EQ(left.count(), n);
}

TEST(RunningMeanStdTest, AuthorsPriorIsCountOneEMinus4AtMeanZeroVarOne) {
  RunningMeanStd s(2);  // default prior
  EXPECT_DOUBLE_EQ(s.count(), 1e-4);
  EXPECT_EQ(s.mean()[0], 0.0);
  EXPECT_EQ(s.var()[1], 1.0);
  const float x[2] = {3.0f, -1.0f};
  s.Update(x);
  // Merge of (1e-4, 0, 1) with (1, x, 0).
  const double tot = 1 + 1e-4;
  EXPECT_NEAR(s.mean()[0], 3.0 / tot, 1e-12);
  EXPECT_NEAR(s.var()[0], (1e-4 + 9.0 * 1e-4 / tot) / tot, 1e-12);
}

TEST(RunningMeanStdTest, MergeOfEmptyDeltaChangesNothingAndProtoRoundTrips) {
  RunningMeanStd s(3);
  const std::vector<float> x = Data(10, 3, 2);
  s.UpdateBatch(x.data(), 10);
  const RunningMeanStd before = s;
  s.Merge(RunningMeanStd(3, 0.0));
  EXPECT_EQ(s.mean(), before.mean());
  proto::RunningStats p;
  s.ToProto(&p);
  const RunningMeanStd back = RunningMeanStd::FromProto(p, 3, "stats");
  EXPECT_EQ(back.mean(), s.mean());
  EXPECT_EQ(back.var(), s.var());
  EXPECT_EQ(back.count(), s.count());
  EXPECT_THROW(RunningMeanStd::FromProto(p, 4, "stats"), ConfigError);
  p.set_var(1, -1.0);
  EXPECT_THROW(RunningMeanStd::FromProto(p, 3, "stats"), ConfigError);
}

TEST(ObsNormalizerTest, CentersScalesAndClips) {
  NormalizerConfig c;
  ObsNormalizer norm(2, c);
  const std::vector<float> x = {1.0f, 10.0f, 3.0f, 30.0f};
  norm.stats().Reset(0.0);
  norm.stats().UpdateBatch(x.data(), 2);  // mean (2, 20), var (1, 100)
  norm.Refresh();
  float in[2] = {4.0f, 20.0f + 1e4f}, out[2];
  norm.Normalize(in, out);
  EXPECT_NEAR(out[0], 2.0f / std::sqrt(1.0f + 1e-8f), 1e-6);
  EXPECT_EQ(out[1], c.obs_clip);
  float neg[2] = {-1e6f, 20.0f};
  norm.Normalize(neg, out);
  EXPECT_EQ(out[0], -c.obs_clip);
  EXPECT_NEAR(out[1], 0.0f, 1e-6);
  c.normalize_obs = false;
  norm.set_config(c);
  norm.Normalize(neg, out);
  EXPECT_EQ(out[0], neg[0]);
}

TEST(RewardScalerTest, DividesByRunningStdOfDiscountedReturnPerStream) {
  RewardScalingConfig c;
  const float gamma = 0.9f;
  RewardScaler scaler(c, gamma);
  std::vector<float> a = {1.0f, 2.0f, -1.0f}, b = {5.0f, 5.0f};
  const std::vector<float> a0 = a, b0 = b;
  scaler.ScaleInPlace(/*stream=*/1, a.data(), nullptr, 3);
  scaler.ScaleInPlace(/*stream=*/2, b.data(), nullptr, 2);
  // Independent reference: returns per stream, variance over all returns seen so far with the
  // 1e-4 prior at mean 0 / var 1, Welford-style.
  double count = 1e-4, mean = 0, m2 = 1e-4;
  auto push = [&](double r) {
    const double tot = count + 1, d = r - mean;
    mean += d / tot;
    m2 += d * d * count / tot;
    count = tot;
    return std::sqrt(m2 / count + 1e-8);
  };
  double ret = 0;
  for (int t = 0; t < 3; ++t) {
    ret = ret * gamma + a0[t];
    EXPECT_NEAR(a[t], std::clamp(a0[t] / push(ret), -10.0, 10.0), 1e-5) << t;
  }
  EXPECT_NEAR(scaler.streams().at(1), ret, 1e-6);
  ret = 0;
  for (int t = 0; t < 2; ++t) {
    ret = ret * gamma + b0[t];
    EXPECT_NEAR(b[t], std::clamp(b0[t] / push(ret), -10.0, 10.0), 1e-5) << t;
  }
  EXPECT_NEAR(scaler.streams().at(2), ret, 1e-6);
  EXPECT_NEAR(scaler.return_stats().count(), 5 + 1e-4, 1e-9);
}

TEST(RewardScalerTest, ClipsSkipsNanAndCanBeDisabled) {
  RewardScalingConfig c;
  c.clip = 0.5f;
  RewardScaler s(c, 0.99f);
  std::vector<float> r = {100.0f, std::nanf(""), -100.0f};
  s.ScaleInPlace(0, r.data(), nullptr, 3);
  EXPECT_LE(r[0], 0.5f);
  EXPECT_TRUE(std::isnan(r[1]));
  EXPECT_NEAR(s.return_stats().count(), 2 + 1e-4, 1e-9);
  c.enabled = false;
  RewardScaler off(c, 0.99f);
  std::vector<float> q = {100.0f};
  off.ScaleInPlace(0, q.data(), nullptr, 1);
  EXPECT_EQ(q[0], 100.0f);
}

TEST(RewardScalerTest, ResetAtEpisodeEndIsOptional) {
  RewardScalingConfig c;
  c.reset_at_episode_end = true;
  RewardScaler s(c, 0.5f);
  std::vector<float> r = {1.0f, 1.0f};
  const uint8_t done[2] = {0, 1};
  s.ScaleInPlace(0, r.data(), done, 2);
  EXPECT_EQ(s.streams().at(0), 0.0);
  RewardScaler authors(RewardScalingConfig(), 0.5f);
  std::vector<float> q = {1.0f, 1.0f};
  authors.ScaleInPlace(0, q.data(), done, 2);
  EXPECT_NEAR(authors.streams().at(0), 1.5, 1e-9);  // never reset (notes §9.6)
}

}  // namespace
}  // namespace perch
