#!/bin/bash
# The AVX-512 dense kernels (policy/dense_kernels_avx512.cc) are compiled with -march=x86-64-v4
# into the same program as portable code. Any symbol they define that the linker could merge with
# another object's copy (weak template instantiations, inline functions) would let AVX-512 code
# run on CPUs without it. Checks that the object's global and weak definitions are only the entry
# point and Eigen under its renamed namespace.
# Usage: avx512_symbols_test.sh LIBPERCH_LEARNER.a
set -euo pipefail
lib=$1
member=dense_kernels_avx512.cc.o
if ! ar t "$lib" | grep -qx "$member"; then
  echo "FAIL: $member is not in $lib"
  exit 1
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
(cd "$tmp" && ar x "$lib" "$member")
# Defined symbols that are not local: T/D/B/R (global), W/V (weak), u (unique), i (indirect).
nm -C --defined-only "$tmp/$member" | awk '$2 ~ /^[TDBRWVui]$/ { $1=""; $2=""; sub(/^  /, ""); print }' \
  > "$tmp/defined"
total=$(wc -l < "$tmp/defined")
# Allowed: the entry point (and, in a sanitizer build, ASan's ODR indicator for it), and anything in
# the renamed namespace whatever its return type (a sanitizer build inlines less, so vector-typed
# helpers such as "float __vector(16) perch_eigen_avx512::...tanh" appear).
bad=$(grep -v -E '^(perch::kDenseKernelsAvx512|__odr_asan\._ZN5perch19kDenseKernelsAvx512E|DW\.ref\.__gxx_personality_v0|(guard variable for )?([A-Za-z_][A-Za-z0-9_]*( __vector\([0-9]+\))? )?perch_eigen_avx512::)' \
  "$tmp/defined" || true)
if [ -n "$bad" ]; then
  echo "FAIL: $member defines shared symbols outside perch_eigen_avx512:"
  echo "$bad" | head -20
  exit 1
fi
if ! grep -q '^perch::kDenseKernelsAvx512$' "$tmp/defined"; then
  echo "FAIL: entry point perch::kDenseKernelsAvx512 not defined"
  exit 1
fi
# No other object may define the renamed namespace.
others=$(nm -C --defined-only -A "$lib" | grep "perch_eigen_avx512::" | grep -v ":$member:" || true)
if [ -n "$others" ]; then
  echo "FAIL: other objects define perch_eigen_avx512 symbols:"
  echo "$others" | head -5
  exit 1
fi
echo "OK: $total shared definitions in $member, all in perch_eigen_avx512 or the entry point"
