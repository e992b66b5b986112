#!/usr/bin/env bash
# clang-format check of the C++ files changed since the format base (.ci/format-base: the commit
# at which the check began; every file touched since must be formatted as .clang-format says).
# Usage: scripts/check-format.sh [--fix] [BASE]. Exit 1 naming each unformatted file, with the
# command that formats it. Without git history (a shallow clone), the last commit's files.
set -euo pipefail
cd "$(dirname "$0")/.."
fix=0
if [ "${1:-}" = "--fix" ]; then fix=1; shift; fi
base=${1:-$(cat .ci/format-base)}
CF=${CLANG_FORMAT:-$(command -v clang-format || command -v clang-format-14 || true)}
[ -n "$CF" ] || { echo "check-format: clang-format not found (apt-get install clang-format)" >&2; exit 2; }
if ! git rev-parse -q --verify "$base^{commit}" > /dev/null 2>&1; then
  echo "check-format: base $base not in this clone's history; checking the last commit's files" >&2
  base=$(git rev-parse -q --verify HEAD~1 || git hash-object -t tree /dev/null)
fi
# Changed (committed since base, staged, unstaged) and untracked, existing, C++ sources.
mapfile -t files < <({ git diff --name-only "$base" -- ; git ls-files --others --exclude-standard; } |
  grep -E '\.(cc|h|cpp|hpp)$' | grep -v '^third_party/' | sort -u | while read -r f; do
    [ -f "$f" ] && echo "$f"; done)
bad=()
for f in "${files[@]}"; do
  if [ $fix = 1 ]; then "$CF" -i --style=file "$f"; continue; fi
  if ! "$CF" --style=file --dry-run -Werror "$f" > /dev/null 2>&1; then bad+=("$f"); fi
done
if [ ${#bad[@]} -gt 0 ]; then
  echo "check-format: ${#bad[@]} of ${#files[@]} changed C++ file(s) are not clang-formatted:" >&2
  printf '  %s\n' "${bad[@]}" >&2
  echo "  fix: scripts/check-format.sh --fix   (or: $CF -i FILE)" >&2
  exit 1
fi
echo "check-format: ${#files[@]} changed C++ file(s) formatted (base $(git rev-parse --short "$base" 2>/dev/null || echo "$base"))"
