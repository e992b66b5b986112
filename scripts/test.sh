#!/usr/bin/env bash
# Builds Perch in Release (warnings are errors) and runs every test through CTest (among them the
# guard rails of issue 50: the rooms' layering and clang-format on changed files), then the unit
# tests of an AddressSanitizer + UndefinedBehaviorSanitizer build (build-asan/): a quick set by
# default ($PERCH_SANITIZE_QUICK), every unit test with --sanitize (long: note its result).
# Usage: scripts/test.sh [--sanitize | --no-sanitize] [CTEST ARGS...]
set -euo pipefail
cd "$(dirname "$0")/.."
sanitize=quick
ctest_args=()
for a in "$@"; do
  case "$a" in
    --sanitize) sanitize=all ;;
    --no-sanitize) sanitize=none ;;
    *) ctest_args+=("$a") ;;
  esac
done
scripts/install-deps.sh
BUILD_DIR=${BUILD_DIR:-build}
JOBS=${JOBS:-$(nproc)}
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release
cmake --build "$BUILD_DIR" -j "$JOBS"
(cd "$BUILD_DIR" && ctest --output-on-failure -j "$JOBS" --timeout 600 "${ctest_args[@]}")

[ "$sanitize" = none ] && exit 0
ASAN_DIR=${ASAN_BUILD_DIR:-build-asan}
# The unit tests of the files every other room reads (configs, banks, checkpoints, NPZ: the
# quick set CI affords); with --sanitize, all of Perch and every unit test.
QUICK=${PERCH_SANITIZE_QUICK:-test_common}
cmake -S . -B "$ASAN_DIR" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPERCH_SANITIZE=ON > /dev/null
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:strict_string_checks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
if [ "$sanitize" = all ]; then
  cmake --build "$ASAN_DIR" -j "$JOBS"
  # Unit tests only: the scripted end-to-end tests would run the sanitized perch for minutes.
  (cd "$ASAN_DIR" && ctest --output-on-failure -j "$JOBS" --timeout 1800 \
    -E '^(viewer_browser|installed_binary|readme_commands|recipe_toy)$' "${ctest_args[@]}")
else
  # shellcheck disable=SC2086
  cmake --build "$ASAN_DIR" -j "$JOBS" --target $QUICK
  for t in $QUICK; do
    exe=$(find "$ASAN_DIR/tests" -type f -name "$t" -perm -u+x | head -1)
    [ -n "$exe" ] || { echo "test.sh: no $t in $ASAN_DIR" >&2; exit 1; }
    exe=$(realpath "$exe")  # the test runs in its own folder (its data paths are relative)
    echo "== sanitizers (ASan + UBSan): $t"
    (cd "$(dirname "$exe")" && "$exe" --gtest_brief=1)
  done
fi
echo "test.sh: sanitizer build ($sanitize) passed"
