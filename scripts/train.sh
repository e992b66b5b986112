#!/usr/bin/env bash
# Builds Perch if needed, then runs the main training job with the default config.
#   scripts/train.sh [--actors N] [--resume] [extra perch train flags]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
BUILD_DIR=${BUILD_DIR:-build}
# CMake decides what to rebuild (a fixed list of folders missed tasks/, viz/ and CMakeLists.txt).
if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
  cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release
fi
cmake --build "$BUILD_DIR" -j "$(nproc)" --target perch
CONFIG=${CONFIG:-configs/default.json}
RUN_DIR=${RUN_DIR:-runs/default}
exec "$BUILD_DIR/app/perch" train --config "$CONFIG" --run-dir "$RUN_DIR" "$@"
