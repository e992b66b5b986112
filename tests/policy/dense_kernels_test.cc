#include "policy/dense_kernels.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "common/rng.h"

namespace perch {
namespace {

// Plain loops in double: what every kernel variant must compute.
struct Reference {
  static void Forward(const std::vector<float>& w, const std::vector<float>& b, int out, int in,
                      const std::vector<float>& x, int batch, DenseAct act,
                      std::vector<double>* y) {
    y->assign(static_cast<size_t>(out) * batch, 0.0);
    for (int j = 0; j < batch; ++j) {
      for (int i = 0; i < out; ++i) {
        double s = b[i];
        for (int p = 0; p < in; ++p) s += double(w[i + p * out]) * x[p + j * in];
        if (act == DenseAct::kTanh) s = std::tanh(s);
        if (act == DenseAct::kRelu) s = s > 0 ? s : 0;
        (*y)[i + j * out] = s;
      }
    }
  }
};

std::vector<float> Random(Rng& rng, size_t n) {
  std::vector<float> v(n);
  for (float& x : v) x = static_cast<float>(rng.Normal());
  return v;
}

class DenseKernelsTest : public ::testing::TestWithParam<DenseAct> {};

TEST_P(DenseKernelsTest, EveryVariantMatchesPlainLoops) {
  const DenseAct act = GetParam();
  // Odd sizes: the vectorised paths' remainders (no size a multiple of 8 or 16).
  const int out = 21, in = 53, batch = 37;
  Rng rng(7);
  const std::vector<float> w = Random(rng, out * in), b = Random(rng, out),
                           x = Random(rng, in * batch), g = Random(rng, out * batch);
  std::vector<float> xin = x;  // an input that an activation produced, for the derivative
  for (float& v : xin)
    v = act == DenseAct::kTanh ? std::tanh(v) : (act == DenseAct::kRelu ? std::max(v, 0.0f) : v);
  std::vector<double> y_ref;
  Reference::Forward(w, b, out, in, x, batch, act, &y_ref);
  // Backward reference: dw = g xin^T, db = rowsum g, gin = (W^T g) * act'(xin).
  std::vector<double> dw_ref(out * in, 0.0), db_ref(out, 0.0), gin_ref(in * batch, 0.0);
  for (int j = 0; j < batch; ++j) {
    for (int i = 0; i < out; ++i) {
      const double gij = g[i + j * out];
      db_ref[i] += gij;
      for (int p = 0; p < in; ++p) {
        dw_ref[i + p * out] += gij * xin[p + j * in];
        gin_ref[p + j * in] += double(w[i + p * out]) * gij;
      }
    }
  }
  for (int k = 0; k < in * batch; ++k) {
    const double v = xin[k];
    if (act == DenseAct::kTanh) gin_ref[k] *= 1.0 - v * v;
    if (act == DenseAct::kRelu) gin_ref[k] *= v > 0 ? 1.0 : 0.0;
  }
  const std::vector<const DenseKernels*> all = AvailableDenseKernels();
  ASSERT_FALSE(all.empty());
  EXPECT_STREQ(all.front()->name, "portable");
  for (const DenseKernels* k : all) {
    SCOPED_TRACE(k->name);
    std::vector<float> y(out * batch, 99.0f);
    k->forward(w.data(), b.data(), out, in, x.data(), batch, y.data(), act);
    for (int i = 0; i < out * batch; ++i)
      ASSERT_NEAR(y[i], y_ref[i], 2e-5 * (1 + std::abs(y_ref[i]))) << i;
    // Backward accumulates into dw and db: start them at 1.
    std::vector<float> dw(out * in, 1.0f), db(out, 1.0f), gin(in * batch, 99.0f);
    k->backward(w.data(), out, in, xin.data(), batch, g.data(), dw.data(), db.data(), gin.data(),
                act);
    for (int i = 0; i < out * in; ++i)
      ASSERT_NEAR(dw[i], 1.0 + dw_ref[i], 1e-4 * (1 + std::abs(dw_ref[i]))) << i;
    for (int i = 0; i < out; ++i)
      ASSERT_NEAR(db[i], 1.0 + db_ref[i], 1e-4 * (1 + std::abs(db_ref[i]))) << i;
    for (int i = 0; i < in * batch; ++i)
      ASSERT_NEAR(gin[i], gin_ref[i], 1e-4 * (1 + std::abs(gin_ref[i]))) << i;
    // Without gin only the parameter gradients change.
    std::vector<float> dw2(out * in, 0.0f), db2(out, 0.0f);
    k->backward(w.data(), out, in, xin.data(), batch, g.data(), dw2.data(), db2.data(), nullptr,
                act);
    for (int i = 0; i < out * in; ++i)
      ASSERT_NEAR(dw2[i] + 1.0f, dw[i], 1e-4f * (1 + std::abs(dw[i])));
  }
}

INSTANTIATE_TEST_SUITE_P(Activations, DenseKernelsTest,
                         ::testing::Values(DenseAct::kNone, DenseAct::kTanh, DenseAct::kRelu));

TEST(DenseKernels, TheActiveVariantIsTheBestAvailableUnlessForced) {
  const char* forced = std::getenv("PERCH_SIMD");
  const std::vector<const DenseKernels*> all = AvailableDenseKernels();
  if (forced == nullptr || std::string(forced) == "auto") {
    EXPECT_EQ(&ActiveDenseKernels(), all.back());
  } else {
    EXPECT_STREQ(ActiveDenseKernels().name, forced);
  }
#if defined(__x86_64__)
  __builtin_cpu_init();
  const bool avx512 = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
                      __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl");
  // An AVX-512 CPU gets the AVX-512 kernels (when built with them: PERCH_AVX512_KERNELS).
  if (avx512 && all.size() > 1) {
    EXPECT_STREQ(all.back()->name, "avx512");
  }
  if (!avx512) {
    EXPECT_EQ(all.size(), 1u);
  }
#endif
}

}  // namespace
}  // namespace perch
