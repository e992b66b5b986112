// Dense-layer kernels of the MLPs (the learner's PPO epochs spend most of their time here), over
// raw column-major float arrays so that they can be compiled once per instruction set and chosen
// at run time: the portable build (PERCH_MARCH, x86-64-v3 by default) and, on x86-64, an AVX-512
// variant (x86-64-v4) used when the CPU has it. This header must stay free of Eigen: the AVX-512
// translation unit compiles Eigen under another namespace (docs/env.md "Build options").
#pragma once

#include <string>
#include <vector>

namespace perch {

enum class DenseAct { kNone = 0, kTanh = 1, kRelu = 2 };

struct DenseKernels {
  const char* name;  // "portable" or "avx512"
  // y [out x B] = act(W [out x in] * x [in x B] + b [out]).
  void (*forward)(const float* w, const float* b, int out, int in, const float* x, int batch,
                  float* y, DenseAct act);
  // With g = dL/d(pre-activation) [out x B] and x the layer's input [in x B]:
  // dw [out x in] += g x^T, db [out] += row sums of g; when gin != nullptr, gin [in x B] = W^T g,
  // multiplied by the derivative of x_act (the activation that produced x; kNone: none).
  void (*backward)(const float* w, int out, int in, const float* x, int batch, const float* g,
                   float* dw, float* db, float* gin, DenseAct x_act);
};

// The kernels in use: chosen once, from PERCH_SIMD ("portable", "avx512"; unset or "auto": the
// best the CPU runs). An unknown or unsupported PERCH_SIMD value is refused by name (ConfigError).
const DenseKernels& ActiveDenseKernels();
// Every variant this build has and this CPU runs, best last (tests compare them).
std::vector<const DenseKernels*> AvailableDenseKernels();

}  // namespace perch
