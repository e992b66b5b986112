#!/usr/bin/env bash
# README.md's commands, run as a reader would (issue 18): every command line of its `sh` code
# blocks, in order, with `perch` on the PATH, in a copy of the repository (so runs/ and outputs
# stay out of the source tree). `bash` blocks (the long main job, a cluster, a browser) are not
# run. Fails naming the first command that fails, with its output.
# Usage: readme_test.sh SOURCE_DIR PERCH_BIN
set -euo pipefail
src=$(cd "$1" && pwd)
bin=$2
tmp=$(mktemp -d /tmp/perch-readme.XXXXXX)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/repo" "$tmp/bin"
tar -C "$src" --exclude=./build --exclude='./build-*' --exclude=./runs --exclude=./.git \
  --exclude=node_modules -cf - . | tar -C "$tmp/repo" -xf -
ln -s "$bin" "$tmp/bin/perch"
export PATH="$tmp/bin:$PATH"

python3 - "$src/README.md" > "$tmp/commands.txt" << 'PY'
import sys
lines = open(sys.argv[1]).read().split("\n")
inside, cmd = False, ""
for line in lines:
    s = line.strip()
    if not inside:
        inside = s == "```sh"
        continue
    if s.startswith("```"):
        inside = False
        continue
    if not s or s.startswith("#"):
        continue
    if s.endswith("\\"):
        cmd += s[:-1] + " "
        continue
    print(cmd + s)
    cmd = ""
PY
n=$(wc -l < "$tmp/commands.txt")
[[ $n -ge 8 ]] || { echo "FAIL: expected the README's runnable commands, found $n" >&2; exit 1; }
i=0
while IFS= read -r cmd; do
  i=$((i + 1))
  echo "[$i/$n] $cmd"
  if ! (cd "$tmp/repo" && bash -c "$cmd") > "$tmp/out.log" 2>&1 < /dev/null; then
    tail -n 40 "$tmp/out.log" >&2
    echo "FAIL: README command $i failed: $cmd" >&2
    exit 1
  fi
done < "$tmp/commands.txt"
echo "README: $n commands ran"
