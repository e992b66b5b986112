// The AVX-512 variant of the dense-layer kernels, compiled with -march=x86-64-v4
// (learner/CMakeLists.txt). Eigen is compiled here under its own namespace name: the template
// instantiations of this file are AVX-512 code, and under Eigen's own name the linker could pick
// them for the portable code's identical-looking instantiations (one definition rule), which would
// then crash on CPUs without AVX-512. The test dense_kernels_symbols checks that this object
// defines no shared symbol outside that namespace but the entry point.
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>

#define Eigen perch_eigen_avx512
#include <Eigen/Core>

#include "policy/dense_kernels.h"
#include "policy/dense_kernels_impl.inc"

namespace perch {

extern const DenseKernels kDenseKernelsAvx512;
const DenseKernels kDenseKernelsAvx512 = {"avx512", &DenseForwardImpl, &DenseBackwardImpl};

}  // namespace perch
