#!/usr/bin/env bash
# Builds Perch if needed, puts `perch` on the PATH, then runs the main training job with the
# default config (walk stage 1, ends by itself at cluster.max_samples).
#   scripts/train.sh [--actors N] [--resume] [--max-samples N] [other perch train flags]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
BUILD_DIR=${BUILD_DIR:-build}
# CMake decides what to rebuild (a fixed list of folders missed tasks/, viz/ and CMakeLists.txt).
if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
  cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release
fi
cmake --build "$BUILD_DIR" -j "$(nproc)" --target perch
PERCH_BIN="$(pwd)/$BUILD_DIR/app/perch"
# `perch` for the README's commands: a link to this build (it stays a dev build, so it keeps
# finding data/, configs/ and models/ here). An existing perch that is not such a link is left.
LINK=/usr/local/bin/perch
if [ -w "$(dirname "$LINK")" ] && { [ ! -e "$LINK" ] || [ -L "$LINK" ]; }; then
  ln -sfn "$PERCH_BIN" "$LINK"
  echo "train.sh: perch -> $PERCH_BIN ($LINK)"
elif [ "$(command -v perch || true)" != "$PERCH_BIN" ]; then
  echo "train.sh: to run perch by name: export PATH=\"$(dirname "$PERCH_BIN"):\$PATH\""
fi
CONFIG=${CONFIG:-configs/default.json}
RUN_DIR=${RUN_DIR:-runs/default}
exec "$PERCH_BIN" train --config "$CONFIG" --run-dir "$RUN_DIR" "$@"
