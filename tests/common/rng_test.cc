#include "common/rng.h"

#include <cmath>

#include <gtest/gtest.h>

namespace perch {
namespace {

TEST(Rng, SameSeedSameStreamOtherSeedDiffers) {
  Rng a(42), b(42), c(43);
  for (int i = 0; i < 100; ++i) {
    const uint64_t x = a.NextU64();
    EXPECT_EQ(x, b.NextU64());
    if (i == 0) {
      EXPECT_NE(x, c.NextU64());
    }
  }
}

TEST(Rng, NormalMomentsAndStateRestore) {
  Rng r(7);
  double sum = 0, sq = 0;
  const int n = 200000;
  for (int i = 0; i < n; ++i) {
    const double x = r.Normal();
    sum += x;
    sq += x * x;
  }
  EXPECT_NEAR(sum / n, 0.0, 0.01);
  EXPECT_NEAR(sq / n, 1.0, 0.02);
  const Rng::State st = r.GetState();
  const double next = r.Normal();
  r.Uniform();
  r.SetState(st);
  EXPECT_EQ(next, r.Normal());
}

TEST(Rng, UniformRange) {
  Rng r(1);
  for (int i = 0; i < 10000; ++i) {
    const double u = r.Uniform(-2.0, 3.0);
    ASSERT_GE(u, -2.0);
    ASSERT_LT(u, 3.0);
  }
}

}  // namespace
}  // namespace perch
