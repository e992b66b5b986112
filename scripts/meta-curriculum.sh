#!/usr/bin/env bash
# The meta controller's curriculum (issue 15; paper §6, Fig. 4, Table 6), trained by cloning the
# planner with DAgger (perch meta-clone, docs/meta.md): Zone 1, then Zone 2 starting from the
# Zone 1 stage, then Zone 3 starting from the Zone 2 stage (each stage config names the previous
# stage's checkpoint in cluster.init_from; --stage starts from it). Then Zones 2 and 3 without the
# curriculum (a fresh network, the same budget); then ours, stages that keep the earlier zones
# (Zones 1+2, then 1+2+3: spawn.zones), whose last stage is the delivered policy.bin; and an
# evaluation of each in its zone(s).
#
# Resumable: a stage whose checkpoint exists is skipped, so a run cut short goes on where it
# stopped. stages.json in the output dir says which stages are done.
#
#   scripts/meta-curriculum.sh               # all stages, then the evaluations
#   TRIALS=1000 ROUNDS=3 scripts/meta-curriculum.sh
#   PLAN=plan3 OUT=models/sit_chair/critic OURS_ONLY=1 SWITCH_WEIGHT=10 scripts/meta-curriculum.sh
#     # the planner with the subtasks' critics (configs/meta_*_plan3_30hz.json), only the stages
#     # that keep the earlier zones
set -euo pipefail
cd "$(dirname "$0")/.."
PERCH=${PERCH:-build/app/perch}
OUT=${OUT:-models/sit_chair}  # the stage configs' cluster.init_from point here
PLAN=${PLAN:-plan2}            # configs/meta_*_${PLAN}_30hz.json
OURS_ONLY=${OURS_ONLY:-0}      # 1: skip the paper's curriculum and Table 6's w/o-CL stages
SWITCH_WEIGHT=${SWITCH_WEIGHT:-1}  # meta-clone --switch-weight: the hand-overs' weight in the fit
EPISODES=${EPISODES:-300}
ROUNDS=${ROUNDS:-3}
ZONE1_ROUNDS=${ZONE1_ROUNDS:-5}
EPOCHS=${EPOCHS:-30}
TRIALS=${TRIALS:-1000}
SEED=${SEED:-2}
mkdir -p "$OUT"

stage() {  # config output rounds [meta-clone flags]
  local cfg=$1 out=$2 rounds=$3
  shift 3
  if [ -f "$out" ]; then
    echo "meta-curriculum: $out exists, skipped"
    return
  fi
  echo "meta-curriculum: $out from $cfg $*"
  "$PERCH" meta-clone --config "$cfg" --out "$out" --episodes "$EPISODES" --rounds "$rounds" \
    --epochs "$EPOCHS" --switch-weight "$SWITCH_WEIGHT" "$@" >/dev/null
}

evaluate() {  # model zone
  local model=$1 zone=$2 json=${1%.bin}_eval_zone$2_seed${SEED}_${TRIALS}.json
  if [ -f "$json" ]; then return; fi
  "$PERCH" eval --task sit_chair --model "$model" --zone "$zone" --trials "$TRIALS" \
    --seed "$SEED" --json >"$json.tmp"
  mv "$json.tmp" "$json"
}

C=configs/meta
stage "${C}_zone1_${PLAN}_30hz.json" "$OUT/stage_zone1.bin" "$ZONE1_ROUNDS"
if [ "$OURS_ONLY" != 1 ]; then
  stage "${C}_zone2_${PLAN}_30hz.json" "$OUT/stage_zone2.bin" "$ROUNDS" --stage
  stage "${C}_zone3_${PLAN}_30hz.json" "$OUT/stage_zone3.bin" "$ROUNDS" --stage
  # Table 6's "w/o CL": the same configs and budget from a fresh network.
  stage "${C}_zone2_${PLAN}_30hz.json" "$OUT/nocl_zone2.bin" "$ROUNDS"
  stage "${C}_zone3_${PLAN}_30hz.json" "$OUT/nocl_zone3.bin" "$ROUNDS"
fi
# Ours: each stage keeps the earlier zones, so the last one still sits from the front.
stage "${C}_zones12_${PLAN}_30hz.json" "$OUT/stage_zones12.bin" "$ROUNDS" --stage
stage "${C}_zones123_${PLAN}_30hz.json" "$OUT/stage_zones123.bin" "$ROUNDS" --stage
[ -f "$OUT/policy.bin" ] || cp "$OUT/stage_zones123.bin" "$OUT/policy.bin"

evaluate "$OUT/stage_zone1.bin" 1
for z in 1 2 3; do
  [ "$OURS_ONLY" = 1 ] || evaluate "$OUT/stage_zone3.bin" $z
  evaluate "$OUT/policy.bin" $z
done
if [ "$OURS_ONLY" != 1 ]; then
  evaluate "$OUT/stage_zone2.bin" 2
  evaluate "$OUT/nocl_zone2.bin" 2
  evaluate "$OUT/nocl_zone3.bin" 3
fi
evaluate "$OUT/stage_zones12.bin" 1
evaluate "$OUT/stage_zones12.bin" 2

# Which stages are done, for a reader of the directory.
{
  echo "{"
  sep=""
  for f in stage_zone1 stage_zone2 stage_zone3 nocl_zone2 nocl_zone3 stage_zones12 stage_zones123; do
    [ -f "$OUT/$f.bin" ] && printf '%s  "%s": "%s"' "$sep" "$f" "$f.bin.json" && sep=$',\n'
  done
  echo
  echo "}"
} >"$OUT/stages.json"
echo "meta-curriculum: done ($OUT/stages.json)"
