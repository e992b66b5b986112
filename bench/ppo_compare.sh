#!/usr/bin/env bash
# Runs `perch bench ppo` and bench/ppo_torch.py alternately (same machine, same minute) and prints
# one JSON object with both medians and their ratio. Needs Debian's python3-torch (/usr/bin/python3).
# Usage: bench/ppo_compare.sh [PERCH_BIN] [ROUNDS] [extra args for both, e.g. --obs-dim 52]
set -euo pipefail
cd "$(dirname "$0")/.."
PERCH_BIN=${1:-build/app/perch}
ROUNDS=${2:-3}
shift $(( $# > 2 ? 2 : $# )) || true
TORCH_PY=${TORCH_PY:-/usr/bin/python3}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for i in $(seq "$ROUNDS"); do
  "$PERCH_BIN" bench ppo --json "$@" 2>/dev/null >>"$tmp/eigen.jsonl"
  "$TORCH_PY" bench/ppo_torch.py --json "$@" >>"$tmp/torch.jsonl"
done
"$TORCH_PY" - "$tmp/eigen.jsonl" "$tmp/torch.jsonl" <<'PY'
import json, statistics, sys
e = [json.loads(l) for l in open(sys.argv[1])]
t = [json.loads(l) for l in open(sys.argv[2])]
es = statistics.median(x["samples_per_s"] for x in e)
ts = statistics.median(x["samples_per_s"] for x in t)
print(json.dumps({"bench": "ppo_compare", "obs_dim": e[0]["obs_dim"], "batch": e[0]["batch"],
                  "rounds": len(e), "eigen_samples_per_s": es, "torch_samples_per_s": ts,
                  "ratio_eigen_over_torch": es / ts, "torch_version": t[0]["torch_version"],
                  "eigen_simd": e[0]["eigen_simd"]}))
PY
