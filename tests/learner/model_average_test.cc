// AverageModels: params are the elementwise mean, the pooled observation statistics equal those of
// the union of equal-sized sample sets, and snapshots that do not fit together are refused by name.
#include "learner/model_average.h"

#include <gtest/gtest.h>

#include <vector>

#include "common/json_util.h"
#include "common/proto/model.pb.h"
#include "common/rng.h"
#include "policy/normalizer.h"

namespace perch {
namespace {

constexpr int kDim = 3;

proto::ModelWeights Model(uint64_t version, const std::vector<float>& params,
                          const RunningMeanStd& stats) {
  proto::ModelWeights m;
  m.mutable_shape()->set_kind("gaussian");
  m.mutable_shape()->set_obs_dim(kDim);
  m.mutable_shape()->set_act_dim(1);
  m.mutable_shape()->set_num_params(static_cast<int>(params.size()));
  m.set_version(version);
  for (float p : params) m.add_params(p);
  stats.ToProto(m.mutable_obs_stats());
  m.set_obs_clip(10.0f);
  m.set_obs_eps(1e-8f);
  m.set_normalize_obs(true);
  return m;
}

// n samples of kDim, offset so that the sets differ in mean and spread.
std::vector<float> Samples(uint64_t seed, int n, double offset, double scale) {
  Rng rng(seed);
  std::vector<float> x(static_cast<size_t>(n) * kDim);
  for (float& v : x) v = static_cast<float>(offset + scale * rng.Normal());
  return x;
}

TEST(AverageModels, ParamsAreTheElementwiseMeanAndVersionTheNewest) {
  RunningMeanStd s(kDim, 0.0);
  const std::vector<float> x = Samples(1, 10, 0.0, 1.0);
  s.UpdateBatch(x.data(), 10);
  const proto::ModelWeights avg =
      AverageModels({Model(7, {1.0f, -2.0f, 0.5f}, s), Model(9, {3.0f, 2.0f, 0.5f}, s),
                     Model(8, {2.0f, 3.0f, -1.0f}, s)});
  ASSERT_EQ(avg.params_size(), 3);
  EXPECT_FLOAT_EQ(avg.params(0), 2.0f);
  EXPECT_FLOAT_EQ(avg.params(1), 1.0f);
  EXPECT_FLOAT_EQ(avg.params(2), 0.0f);
  EXPECT_EQ(avg.version(), 9u);
  EXPECT_EQ(avg.shape().SerializeAsString(), Model(7, {1, 2, 3}, s).shape().SerializeAsString());
}

TEST(AverageModels, PooledStatisticsEqualThoseOfTheUnionOfTheSamples) {
  const int n = 500;
  const std::vector<float> a = Samples(2, n, -1.0, 0.5), b = Samples(3, n, 2.0, 2.0);
  RunningMeanStd sa(kDim, 0.0), sb(kDim, 0.0), all(kDim, 0.0);
  sa.UpdateBatch(a.data(), n);
  sb.UpdateBatch(b.data(), n);
  all.UpdateBatch(a.data(), n);
  all.UpdateBatch(b.data(), n);
  const proto::ModelWeights avg = AverageModels({Model(1, {0.0f}, sa), Model(2, {0.0f}, sb)});
  const RunningMeanStd pooled = RunningMeanStd::FromProto(avg.obs_stats(), kDim, "avg");
  for (int d = 0; d < kDim; ++d) {
    EXPECT_NEAR(pooled.mean()[d], all.mean()[d], 1e-9);
    EXPECT_NEAR(pooled.var()[d], all.var()[d], 1e-9);
    // The pooled variance includes the spread between the means, not only the mean variance.
    EXPECT_GT(pooled.var()[d], 0.5 * (sa.var()[d] + sb.var()[d]) + 1.0);
  }
  EXPECT_DOUBLE_EQ(avg.obs_stats().count(), n);
}

TEST(AverageModels, RefusesModelsThatDoNotFitTogether) {
  RunningMeanStd s(kDim, 0.0), other(kDim + 1, 0.0);
  const proto::ModelWeights m = Model(1, {1.0f, 2.0f}, s);
  EXPECT_THROW(AverageModels({}), ConfigError);

  proto::ModelWeights wider = m;
  wider.mutable_shape()->add_policy_hidden(64);
  try {
    AverageModels({m, m, wider});
    FAIL() << "a different shape was averaged";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("model 2: shape"), std::string::npos) << e.what();
  }
  proto::ModelWeights clip = m;
  clip.set_obs_clip(5.0f);
  EXPECT_THROW(AverageModels({m, clip}), ConfigError);
  const proto::ModelWeights dims = Model(1, {1.0f, 2.0f}, other);
  try {
    AverageModels({m, dims});
    FAIL() << "observation statistics of another dimension were averaged";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("model 1: observation statistics"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace perch
