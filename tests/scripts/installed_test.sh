#!/usr/bin/env bash
# The installed perch with the source tree out of sight (issue 18). `cmake --install` into a temp
# prefix; then, from an empty working directory:
#  - `perch version --json` reports the data root next to the binary (origin "install");
#  - every k8s manifest's command line passes `--check-config` with the ConfigMap's config;
#  - a short real training run (learner + actor processes) ends by itself at --max-samples with a
#    checkpoint and its summary.
# Where the kernel allows it (root, unshare), the checks run in a private mount namespace with an
# empty tmpfs over the source tree (which holds the build tree); otherwise the binary still never
# looks there, as it is not in its build tree (common/paths.h), and the test says which mode ran.
# Usage: installed_test.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
build=$(cd "$1" && pwd)
src=$(cd "$2" && pwd)

if [[ "${PERCH_INSTALLED_TEST_INSIDE:-}" != 1 ]]; then
  tmp=$(mktemp -d /tmp/perch-installed.XXXXXX)
  trap 'rm -rf "$tmp"' EXIT
  cmake --install "$build" --prefix "$tmp/prefix" > "$tmp/install.log"
  cp "$0" "$tmp/checks.sh"
  # The image's runtime stage and the .deb install every library the binary links directly
  # (their own dependencies come with them); the C and C++ runtimes are in every Debian.
  runtime=$(sed -n '/^FROM debian:12$/,$p' "$src/Dockerfile" | tr -s ' \\\n' ' ')
  debdeps=$(grep -A2 'CPACK_DEBIAN_PACKAGE_DEPENDS' "$src/CMakeLists.txt" | tr -d '"')
  for lib in $(readelf -d "$tmp/prefix/bin/perch" | sed -n 's/.*Shared library: \[\(.*\)\]/\1/p'); do
    path=$(ldconfig -p | awk -v l="$lib" '$1 == l && !found {print $NF; found = 1}')
    [[ -n "$path" ]] || { echo "FAIL: $lib not found by ldconfig" >&2; exit 1; }
    real=$(readlink -f "$path")
    pkg=$(dpkg -S "$real" 2> /dev/null | head -1 | cut -d: -f1 || true)
    # Merged /usr: dpkg may know the file under /lib.
    [[ -n "$pkg" ]] || pkg=$(dpkg -S "${real#/usr}" 2> /dev/null | head -1 | cut -d: -f1 || true)
    [[ -n "$pkg" ]] || { echo "FAIL: no Debian package owns $real ($lib)" >&2; exit 1; }
    case "$pkg" in libc6 | libstdc++6 | libgcc-s1) continue ;; esac
    grep -qw -- "$pkg" <<< "$runtime" || { echo "FAIL: Dockerfile runtime stage lacks $pkg ($lib)" >&2; exit 1; }
    grep -qw -- "$pkg" <<< "$debdeps" || { echo "FAIL: CPACK_DEBIAN_PACKAGE_DEPENDS lacks $pkg ($lib)" >&2; exit 1; }
    echo "runtime library $lib: $pkg in the image and the .deb"
  done
  # The manifests and the ConfigMap, copied out before the source tree is hidden.
  mkdir -p "$tmp/k8s" && cp "$src"/k8s/*.yaml "$tmp/k8s/"
  export PERCH_INSTALLED_TEST_INSIDE=1 PERCH_TMP="$tmp" PERCH_SRC="$src"
  unset PERCH_DATA_DIR
  if unshare --mount --propagation private true 2> /dev/null; then
    exec unshare --mount --propagation private bash -c \
      'mount -t tmpfs tmpfs "$PERCH_SRC" && PERCH_HIDDEN=1 bash "$PERCH_TMP/checks.sh" "$PERCH_TMP" "$PERCH_SRC"'
  fi
  PERCH_HIDDEN=0 bash "$tmp/checks.sh" "$tmp" "$src"
  exit $?
fi

# ---- inside: $1 is the temp dir, $2 the (maybe hidden) source tree ----
tmp=$PERCH_TMP
perch="$tmp/prefix/bin/perch"
fail() { echo "FAIL: $*" >&2; exit 1; }
if [[ "$PERCH_HIDDEN" == 1 ]]; then
  [[ ! -e "$PERCH_SRC/CMakeLists.txt" ]] || fail "the source tree is still visible"
  echo "mode: source tree hidden by a private tmpfs mount"
else
  echo "mode: source tree visible (no mount namespace here); the binary is outside its build tree"
fi
mkdir -p "$tmp/work" && cd "$tmp/work"

version=$("$perch" version --json)
echo "$version"
grep -q '"data_origin":"install"' <<< "$version" || fail "data root not found next to the binary"
grep -q "\"data_root\":\"$tmp/prefix/share/perch\"" <<< "$version" || fail "wrong data root"

# The ConfigMap's config.json, de-indented.
python3 - "$tmp/k8s/configmap.yaml" "$tmp/config.json" << 'PY'
import sys
lines = open(sys.argv[1]).read().split("\n")
start = next(i for i, l in enumerate(lines) if l.strip() == "config.json: |") + 1
body = [l for l in lines[start:]]
indent = min(len(l) - len(l.lstrip()) for l in body if l.strip())
open(sys.argv[2], "w").write("\n".join(l[indent:] for l in body) + "\n")
PY
checked=0
for manifest in "$tmp"/k8s/*.yaml; do
  while IFS= read -r cmd; do
    mapfile -t argv < <(python3 -c '
import json, sys
a = json.loads(sys.argv[1])
for x in a: print(x)' "$cmd")
    # Probes' exec commands (sh -c ...) are not perch command lines.
    [[ "${argv[0]}" == perch || "${argv[0]}" == */perch ]] || continue
    args=()
    for a in "${argv[@]:1}"; do
      case "$a" in
        /etc/perch/config.json) args+=("$tmp/config.json") ;;
        /runs/*) args+=("$tmp/runs/${a#/runs/}") ;;
        *) args+=("$a") ;;
      esac
    done
    echo "check: $(basename "$manifest"): perch ${args[*]} --check-config"
    "$perch" "${args[@]}" --check-config || fail "$(basename "$manifest"): --check-config failed"
    checked=$((checked + 1))
  done < <(grep -o 'command: \[.*\]' "$manifest" | sed 's/^command: //')
done
[[ $checked -ge 2 ]] || fail "expected the learner and actor command lines, checked $checked"

# Three consecutive free ports (a random pick could meet a port another test or run holds).
port=$(python3 -c '
import random, socket
for _ in range(200):
    p = random.randrange(20000, 40000)
    try:
        for q in (p, p + 1, p + 2):
            s = socket.socket(); s.bind(("127.0.0.1", q)); s.close()
        print(p); break
    except OSError:
        pass
')
"$perch" train --config configs/default.json --run-dir runs/smoke --actors 1 --max-samples 4096 \
  --set ppo.steps_per_update=2048 --set cluster.checkpoint_every=1 \
  --rollout-port "$port" --weights-port $((port + 1)) --metrics-port $((port + 2)) \
  > "$tmp/train.log" 2>&1 || { cat "$tmp/train.log"; fail "training run failed"; }
grep -q "Run ended (max_samples)" "$tmp/train.log" || { cat "$tmp/train.log"; fail "no summary"; }
ls runs/smoke/checkpoints/*.bin > /dev/null || fail "no checkpoint"
[[ -s runs/smoke/config.json ]] || fail "no resolved config in the run dir"
echo "installed binary OK ($checked manifest command lines, one training run)"
