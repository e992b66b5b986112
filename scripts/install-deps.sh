#!/usr/bin/env bash
# Installs the Debian 12 packages Perch needs. Idempotent: does nothing when all are present.
set -euo pipefail

PACKAGES=(
  build-essential cmake pkg-config git
  libbullet-dev libbullet-extras-dev libtinyobjloader-dev
  libzmq3-dev cppzmq-dev
  prometheus-cpp-dev
  libprotobuf-dev protobuf-compiler
  libeigen3-dev
  libspdlog-dev libfmt-dev
  libcli11-dev
  nlohmann-json3-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libpng-dev zlib1g-dev clang-format
  libssl-dev
  nodejs chromium fonts-dejavu-core
  libcpp-httplib-dev gnuplot-nox
  iproute2 procps
)

# Debian's nodejs leaves npm to its own package; a NodeSource nodejs brings npm and conflicts
# with Debian's npm, so it is added only when no npm is on the PATH.
if ! command -v npm >/dev/null 2>&1; then PACKAGES+=(npm); fi

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi

echo "install-deps: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
