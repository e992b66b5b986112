#include "policy/dense_kernels.h"

#include <Eigen/Core>
#include <cstdlib>

#include "common/json_util.h"
#include "policy/dense_kernels_impl.inc"

namespace perch {

#ifdef PERCH_AVX512_KERNELS
extern const DenseKernels kDenseKernelsAvx512;  // dense_kernels_avx512.cc
#endif

namespace {

const DenseKernels kPortable = {"portable", &DenseForwardImpl, &DenseBackwardImpl};

bool CpuHasAvx512() {
#if defined(PERCH_AVX512_KERNELS) && (defined(__x86_64__) || defined(__i386__))
  // x86-64-v4: the AVX-512 subsets GCC may use at that level.
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
         __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl") &&
         __builtin_cpu_supports("avx512cd");
#else
  return false;
#endif
}

const DenseKernels& Choose() {
  const char* env = std::getenv("PERCH_SIMD");
  const std::string want = env ? env : "auto";
  const std::vector<const DenseKernels*> have = AvailableDenseKernels();
  if (want == "auto" || want.empty()) return *have.back();
  for (const DenseKernels* k : have) {
    if (want == k->name) return *k;
  }
  std::string names;
  for (const DenseKernels* k : have) names += std::string(names.empty() ? "" : ", ") + k->name;
  throw ConfigError("PERCH_SIMD=" + want +
                    ": not available in this build on this CPU (have: auto, " + names + ")");
}

}  // namespace

std::vector<const DenseKernels*> AvailableDenseKernels() {
  std::vector<const DenseKernels*> v{&kPortable};
#ifdef PERCH_AVX512_KERNELS
  if (CpuHasAvx512()) v.push_back(&kDenseKernelsAvx512);
#endif
  return v;
}

const DenseKernels& ActiveDenseKernels() {
  static const DenseKernels& k = Choose();
  return k;
}

}  // namespace perch
