#!/usr/bin/env bash
# The starting line of issue 49: the delivered subtasks and the delivered hierarchy (sit_chair,
# Zone 1, the policy alone) under each perturbation of perch eval,
# N episodes each (default 200) on seed 21 (nobody tuned on it), mean actions; one JSON per cell in
# OUT (default models/robustness_baseline/), resumable (a cell whose JSON exists is skipped).
# Usage: scripts/robustness_baseline.sh [PERCH_BIN] [OUT] [N]
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:-build/app/perch}
out=${2:-models/robustness_baseline}
n=${3:-200}
mkdir -p "$out"
declare -A model=(
  [walk]="--model models/walk_stage2_fallrestart/checkpoints/ckpt-0000013900.bin --config models/walk_stage2/config.json --no-fall-seconds 20 --reward-variant paper"
  [turn_left]="--model models/turn_left/policy.bin"
  [turn_right]="--model models/turn_right/policy.bin"
  [sit]="--model models/sit/policy.bin"
  [sit_chair]="--task sit_chair --model models/sit_chair/policy.bin --zone 1 --threads 1")
declare -A perturb=(
  [push1]="--push 1" [push20]="--push 20" [obs0.01]="--obs-noise 0.01" [act0.05]="--act-noise 0.05"
  [restore]="--restore")
for task in sit turn_left turn_right sit_chair walk; do
  for p in push1 push20 obs0.01 act0.05 restore; do
    f="$out/${task}_${p}.json"
    [ -s "$f" ] && continue
    # shellcheck disable=SC2086
    "$bin" eval ${model[$task]} --episodes "$n" --seed 21 ${perturb[$p]} --json > "$f.tmp"
    mv "$f.tmp" "$f"
    echo "$task $p: $(python3 -c "import json; d=json.load(open('$f')); print(d['success_rate'], d['unperturbed_success_rate'], d['flip_rate'])")"
  done
done
