#!/usr/bin/env bash
# Builds Debian's Bullet 3.24 (the same source and patches as libbullet-dev) with -O3,
# -fno-semantic-interposition and -march=ARCH, as static single-precision libraries, into PREFIX.
# `cmake -DPERCH_FAST_BULLET=ON` runs it (docs/env.md "Fast Bullet"); nothing else does.
#   scripts/build-fast-bullet.sh [--march x86-64-v3] [--prefix DIR] [--jobs N]
# The source comes only from Debian's archive (`apt-get source`); a deb-src entry for the
# configured Debian mirror is added to /etc/apt/sources.list.d when there is none.
set -euo pipefail
cd "$(dirname "$0")/.."

MARCH=x86-64-v3
PREFIX="$PWD/build/bullet-fast-$MARCH"
PREFIX_SET=0
JOBS=$(nproc)
while [ $# -gt 0 ]; do
  case "$1" in
    --march) MARCH=$2; shift 2 ;;
    --prefix) PREFIX=$2; PREFIX_SET=1; shift 2 ;;
    --jobs) JOBS=$2; shift 2 ;;
    *) echo "build-fast-bullet: unknown argument $1" >&2; exit 2 ;;
  esac
done
[ "$PREFIX_SET" = 1 ] || PREFIX="$PWD/build/bullet-fast-$MARCH"
case "$PREFIX" in
  /*/*) ;;
  *) echo "build-fast-bullet: --prefix must be an absolute path below a directory" >&2; exit 2 ;;
esac
WORK="$PREFIX.work"  # source and build tree, kept for rebuilds
mkdir -p "$WORK"

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

# The installed package's source version, so that both builds are the same Bullet.
VERSION=$(dpkg-query -W -f='${source:Version}' libbullet-dev 2>/dev/null || true)
if [ -z "$VERSION" ]; then
  echo "build-fast-bullet: libbullet-dev is not installed (scripts/install-deps.sh)" >&2
  exit 1
fi
SRC=$(find "$WORK" -maxdepth 1 -type d -name 'bullet-3.24*' | head -1)
if [ -z "$SRC" ]; then
  if ! grep -rqs '^Types:.*deb-src\|^deb-src' /etc/apt/sources.list /etc/apt/sources.list.d/; then
    echo "build-fast-bullet: adding a deb-src entry (/etc/apt/sources.list.d/perch-deb-src.sources)"
    URIS=$(awk '/^URIs:/ {print $2; exit}' /etc/apt/sources.list.d/debian.sources 2>/dev/null || true)
    SUITE=$(awk '/^Suites:/ {print $2; exit}' /etc/apt/sources.list.d/debian.sources 2>/dev/null || true)
    printf 'Types: deb-src\nURIs: %s\nSuites: %s\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
      "${URIS:-http://deb.debian.org/debian}" "${SUITE:-bookworm}" |
      $SUDO tee /etc/apt/sources.list.d/perch-deb-src.sources >/dev/null
    $SUDO apt-get update -qq
  fi
  command -v dpkg-source >/dev/null || $SUDO apt-get install -y -qq --no-install-recommends dpkg-dev
  echo "build-fast-bullet: apt-get source bullet=$VERSION"
  (cd "$WORK" && apt-get source -qq "bullet=$VERSION")
  SRC=$(find "$WORK" -maxdepth 1 -type d -name 'bullet-3.24*' | head -1)
fi

FLAGS="-O3 -DNDEBUG -fno-semantic-interposition -march=$MARCH"
echo "build-fast-bullet: $SRC -> $PREFIX ($FLAGS)"
start=$(date +%s)
# Debian's own options (debian/rules) less the extras, demos and Bullet 3, which Perch never links.
cmake -S "$SRC" -B "$WORK/build" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_CXX_FLAGS_RELEASE="$FLAGS" -DCMAKE_C_FLAGS_RELEASE="$FLAGS" \
  -DBUILD_SHARED_LIBS=OFF -DUSE_DOUBLE_PRECISION=OFF \
  -DBUILD_EXTRAS=OFF -DBUILD_BULLET2_DEMOS=OFF -DBUILD_OPENGL3_DEMOS=OFF -DBUILD_CPU_DEMOS=OFF \
  -DBUILD_UNIT_TESTS=OFF -DBUILD_BULLET3=OFF -DBUILD_PYBULLET=OFF >"$WORK/cmake.log" 2>&1
# Only the three libraries Perch links (not the soft-body and inverse-dynamics ones).
cmake --build "$WORK/build" -j "$JOBS" --target LinearMath BulletCollision BulletDynamics \
  >"$WORK/build.log"
rm -rf "$PREFIX"
mkdir -p "$PREFIX/lib" "$PREFIX/include/bullet"
(cd "$SRC/src" && find . -name '*.h' -exec cp --parents {} "$PREFIX/include/bullet/" \;)
for lib in LinearMath BulletCollision BulletDynamics; do
  cp "$(find "$WORK/build/src" -name "lib$lib.a" | head -1)" "$PREFIX/lib/"
done
echo "build-fast-bullet: done in $(( $(date +%s) - start )) s"
