#!/usr/bin/env bash
# Builds Perch if needed, then runs the main training job with the default config.
#   scripts/train.sh [--actors N] [--resume] [extra perch train flags]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
BUILD_DIR=${BUILD_DIR:-build}
if [ ! -x "$BUILD_DIR/app/perch" ] || [ -n "$(find app common envs motion learner actor data -newer "$BUILD_DIR/app/perch" -type f 2>/dev/null | head -1)" ]; then
  cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release
  cmake --build "$BUILD_DIR" -j "$(nproc)" --target perch
fi
CONFIG=${CONFIG:-configs/default.json}
RUN_DIR=${RUN_DIR:-runs/default}
exec "$BUILD_DIR/app/perch" train --config "$CONFIG" --run-dir "$RUN_DIR" "$@"
