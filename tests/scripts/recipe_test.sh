#!/usr/bin/env bash
# The delivered recipe (recipes/sit_chair.json) end to end at toy scale (issue 48), with real
# processes, real training and real files:
#  A. a training stage killed (kill -9 of the runner) after its first checkpoint continues from it
#     with its counters when the same command runs again;
#  B. the whole recipe at --scale 0.0001, killed inside a training stage and resumed: every stage
#     ends done, each stage's inputs are the recorded outputs of the stages it names, status reports
#     every stage; then a changed stage config and a changed output are refused before anything
#     runs, and --force-from accepts the change; --adopt-from: a second directory takes the
#     finished stages of the same definition and inputs;
# Usage: recipe_test.sh SOURCE_DIR PERCH_BIN
set -euo pipefail
src=$(cd "$1" && pwd)
bin=$(realpath "$2")
tmp=$(mktemp -d /tmp/perch-recipe.XXXXXX)
trap 'kill -9 $(jobs -p) 2>/dev/null || true; rm -rf "$tmp"' EXIT
cd "$src"
fail() { echo "FAIL: $*" >&2; exit 1; }
state() { python3 -c "import json,sys; d=json.load(open('$1/recipe-state.json')); $2"; }

# Waits until $2 (a python expression on the state `d`) holds for dir $1, up to $3 seconds.
wait_for() {
  local t=0
  until [ -f "$1/recipe-state.json" ] && state "$1" "sys.exit(0 if ($2) else 1)" 2>/dev/null; do
    sleep 0.2
    t=$((t + 1))
    [ $t -lt $(($3 * 5)) ] || fail "timed out waiting for: $2"
  done
}

# ---- A: kill -9 inside a training stage after its first checkpoint, resume -------------------
A=$tmp/a
argsA=(recipe run recipes/sit_chair.json --dir "$A" --actors 1 --scale 0.002 --until walk1
  --set cluster.checkpoint_every=1 --progress-s 1)
"$bin" "${argsA[@]}" >> "$tmp/a.log" 2>&1 &
pid=$!
t=0
until ls "$A"/walk1/run/checkpoints/ckpt-*.bin > /dev/null 2>&1; do
  sleep 0.1
  t=$((t + 1))
  [ $t -lt 600 ] || fail "A: no checkpoint after 60 s"
done
kill -9 $pid
wait $pid 2>/dev/null || true
sleep 1  # the children end on their parent's death (PR_SET_PDEATHSIG)
state "$A" "assert d['stages']['walk1']['state']=='running', d['stages']['walk1']"
first=$(ls "$A"/walk1/run/checkpoints/ckpt-*.bin | head -1)
"$bin" recipe status --dir "$A" --json | python3 -c "
import json,sys; s=json.load(sys.stdin)
w=[x for x in s['stages'] if x['name']=='walk1'][0]
assert w['state']=='running' and w.get('interrupted'), w
assert not s['runner_alive'], s" || fail "A: status after the kill"
"$bin" "${argsA[@]}" >> "$tmp/a.log" 2>&1 || fail "A: the resumed run failed: $(tail -20 "$tmp/a.log")"
state "$A" "
w=d['stages']['walk1']
assert w['state']=='done', w
assert w['attempts']==2, w
assert w['samples']>=32000, w   # 0.002 x 16.5 M = 33,000: the budget, counted across both attempts
assert w['figures']['stop_reason']=='max_samples', w" || fail "A: walk1 after resume"
grep -q -- "--resume" "$A/walk1/stage.log" || fail "A: the second attempt did not resume"
grep -q "resum" "$A/walk1/stage.log" || fail "A: the learner did not say it resumed"
# It continued from a checkpoint that was there when it was killed (or a newer one), not from 0.
resumed=$(grep -o "resumed from [^ ]*ckpt-[0-9]*" "$A/walk1/stage.log" | head -1 | grep -o "[0-9]*$")
[ -n "$resumed" ] || fail "A: the stage log names no checkpoint it resumed from"
first_update=$(basename "$first" .bin | sed 's/^ckpt-//')
[ $((10#$resumed)) -ge $((10#$first_update)) ] ||
  fail "A: resumed from update $resumed, older than the checkpoint $first left by the killed run"

# --extend: a larger budget continues the finished stage from its newest checkpoint; a change
# inside what it trained (here its learning rate) is refused, naming it, with nothing written.
python3 - "$src/recipes/sit_chair.json" "$tmp/longer.json" "$tmp/other_lr.json" << 'PY'
import json, sys
r = json.load(open(sys.argv[1]))
w = [s for s in r["stages"] if s["name"] == "walk1"][0]
w["max_samples"] *= 2
json.dump(r, open(sys.argv[2], "w"))
w.setdefault("set", {})["ppo.learning_rate"] = 3e-4
json.dump(r, open(sys.argv[3], "w"))
PY
trained=$(state "$A" "print(d['stages']['walk1']['samples'])")
before=$(stat -c %Y "$A/recipe-state.json")
argsX=(--dir "$A" --actors 1 --scale 0.002 --until walk1 --set cluster.checkpoint_every=1)
if "$bin" recipe run "$tmp/other_lr.json" "${argsX[@]}" --extend walk1 > "$tmp/x.log" 2>&1; then
  fail "A: --extend accepted a changed learning rate"
fi
grep -q "learning rate at 0 samples" "$tmp/x.log" || fail "A: the refusal does not say why: $(cat "$tmp/x.log")"
[ "$(stat -c %Y "$A/recipe-state.json")" = "$before" ] || fail "A: the refused --extend wrote the state"
"$bin" recipe run "$tmp/longer.json" "${argsX[@]}" --extend walk1 > "$tmp/x.log" 2>&1 ||
  fail "A: --extend: $(tail -20 "$tmp/x.log")"
state "$A" "
w=d['stages']['walk1']
assert w['state']=='done', w
assert w['attempts']==3, w
assert w['samples']>=66000, w   # the new budget: 0.002 x 33 M
assert w['figures']['extended_from_samples']==$trained, w" || fail "A: walk1 after --extend"
resumed=$(grep -o "resumed from [^ ]*ckpt-[0-9]*" "$A/walk1/stage.log" | tail -1 | grep -o "[0-9]*$")
last_before=$(grep -o "Run ended (max_samples) at update [0-9]*" "$A/walk1/stage.log" | head -1 | grep -o "[0-9]*$")
[ $((10#$resumed)) -eq $((10#$last_before)) ] ||
  fail "A: --extend resumed from update $resumed, not the finished run's last ($last_before)"

# --extend with only the selection changed: the finished run is not trained further, and every
# checkpoint it kept (select.milestones) is evaluated on the selection seed, one chosen.
python3 - "$tmp/longer.json" "$tmp/reselect.json" << 'PY'
import json, sys
r = json.load(open(sys.argv[1]))
w = [s for s in r["stages"] if s["name"] == "walk1"][0]
w["select"] = {"last_k": 1, "milestones": True, "episodes": 2, "seed": 1,
               "metric": "no_fall_rate"}
json.dump(r, open(sys.argv[2], "w"))
PY
samples=$(state "$A" "print(d['stages']['walk1']['samples'])")
kept=$(ls "$A"/walk1/run/checkpoints/ckpt-*.bin | wc -l)
"$bin" recipe run "$tmp/reselect.json" "${argsX[@]}" --extend walk1 > "$tmp/x.log" 2>&1 ||
  fail "A: --extend (reselect): $(tail -20 "$tmp/x.log")"
grep -q "chosen again" "$tmp/x.log" || fail "A: reselect message: $(cat "$tmp/x.log")"
state "$A" "
w=d['stages']['walk1']
assert w['state']=='done', w
assert w['samples']==$samples, w   # not trained further
assert len(w['figures']['selection'])==$kept, w
assert w['figures']['chosen'] in [r['checkpoint']+'.bin' for r in w['figures']['selection']], w
" || fail "A: walk1 after reselect"
# Each kept checkpoint evaluated again with the new selection's episodes (the cached results of
# the earlier selection are not reused).
for c in "$A"/walk1/run/checkpoints/ckpt-*.bin; do
  r="$A/walk1/select/$(basename "$c" .bin).json"
  python3 -c "import json; j=json.load(open('$r')); assert j['episodes']==2 and j['seed']==1, j" ||
    fail "A: $r is not the new selection's"
done

# ---- B: the whole recipe at toy scale, killed in a training stage, resumed -------------------
B=$tmp/b
argsB=(recipe run recipes/sit_chair.json --dir "$B" --actors 1 --scale 0.0001 --progress-s 5)
"$bin" "${argsB[@]}" >> "$tmp/b.log" 2>&1 &
pid=$!
wait_for "$B" "d['stages'].get('walk2',{}).get('state')=='running'" 120
kill -9 $pid
wait $pid 2>/dev/null || true
sleep 1
# --check-config names what a run would do: from the interrupted stage on, not the done ones.
"$bin" "${argsB[@]}" --check-config > "$tmp/check1.log" 2>&1 || fail "B: --check-config after the kill"
grep -q "would run [0-9]* stage(s), walk2 \.\. " "$tmp/check1.log" ||
  fail "B: --check-config after the kill: $(cat "$tmp/check1.log")"
"$bin" "${argsB[@]}" >> "$tmp/b.log" 2>&1 || fail "B: the resumed recipe failed: $(tail -30 "$tmp/b.log")"
"$bin" "${argsB[@]}" --check-config > "$tmp/check2.log" 2>&1 || fail "B: --check-config when done"
grep -q "nothing to run" "$tmp/check2.log" || fail "B: --check-config when done: $(cat "$tmp/check2.log")"
"$bin" recipe status --dir "$B" --json > "$tmp/status.json"
python3 - "$B" "$tmp/status.json" "$src/recipes/sit_chair.json" << 'PY' || fail "B: checks"
import hashlib, json, os, re, sys
d, status_file, recipe_file = sys.argv[1:]
state = json.load(open(os.path.join(d, "recipe-state.json")))
status = json.load(open(status_file))
recipe = json.load(open(recipe_file))
names = [s["name"] for s in recipe["stages"]]
# Status reports every stage, in the recipe's order, all done, with the JSON the issue names.
assert [s["name"] for s in status["stages"]] == names, "status lists the stages in order"
for s in status["stages"]:
    assert s["state"] == "done", s
    for k in ("samples", "wall_s", "outputs", "figures"):
        assert k in s, (s["name"], k)
assert status["total_samples"] == sum(s["samples"] for s in status["stages"])
assert status["total_wall_s"] > 0
assert state["stages"]["walk2"]["attempts"] == 2, state["stages"]["walk2"]
# Every recorded output is there with its SHA-256.
for n, rec in state["stages"].items():
    for o, rel in rec["outputs"].items():
        p = os.path.join(d, rel)
        assert hashlib.sha256(open(p, "rb").read()).hexdigest() == rec["output_sha256"][o], p
# Each reference ${stage.output} in a stage reached it as that stage's recorded file.
ref = re.compile(r"\$\{([A-Za-z0-9_-]+)\.([A-Za-z0-9_-]+)\}")
checked = 0
for s in recipe["stages"]:
    log = open(os.path.join(d, s["name"], "stage.log")).read()
    cfg_path = os.path.join(d, s["name"], "config.json")
    cfg = open(cfg_path).read() if os.path.exists(cfg_path) else ""
    refs = set()
    # At toy scale toy_args stand in for args (docs/recipe.md).
    args = s["toy_args"] if "toy_args" in s else s.get("args", [])
    for v in list(s.get("set", {}).values()) + list(s.get("toy_set", {}).values()) + args + \
            s.get("select", {}).get("args", []):
        refs |= set(ref.findall(json.dumps(v)))
    for a, b in refs:
        if a in ("out",):
            continue
        rec = state["stages"][a]
        if b not in rec["outputs"]:
            continue  # an optional output the toy did not write
        path = os.path.join(d, rec["outputs"][b])
        assert path in log or path in cfg, (s["name"], a, b, path)
        checked += 1
assert checked >= 40, checked
# Training stages chose a checkpoint and delivered exactly it; with select.include_init the
# policy the run started from was a candidate ("init", its result cached like the others), and
# delivered when chosen.
inits = 0
for s in recipe["stages"]:
    if s["kind"] == "train":
        f = state["stages"][s["name"]]["figures"]
        if f["chosen"] == "init":
            cfg = json.load(open(os.path.join(d, s["name"], "config.json")))
            chosen = cfg["cluster"]["init_from"]
        else:
            chosen = os.path.join(d, s["name"], "run", "checkpoints", f["chosen"])
        assert open(chosen, "rb").read() == open(os.path.join(d, s["name"], "policy.bin"), "rb").read()
        if s.get("select", {}).get("include_init"):
            rows = [r["checkpoint"] for r in f["selection"]]
            assert rows[0] == "init" and rows.count("init") == 1, (s["name"], rows)
            assert os.path.isfile(os.path.join(d, s["name"], "select", "init.json")), s["name"]
            inits += 1
assert inits >= 1, "no stage of the recipe selects with include_init"
print("B: %d stages done, %d references checked" % (len(names), checked))
PY

# --adopt-from: another directory takes B's finished stages whose definition and inputs are the
# same, without running them (no stage log of its own); with another seed none is the same, so
# walk1 trains there.
AD=$tmp/adopt
"$bin" recipe run recipes/sit_chair.json --dir "$AD" --actors 1 --scale 0.0001 --until eval_sit \
  --adopt-from "$B" > "$tmp/adopt.log" 2>&1 || fail "adopt: --adopt-from: $(tail -20 "$tmp/adopt.log")"
python3 - "$B" "$AD" << 'PY' || fail "adopt: adopted stages"
import json, os, sys
b, c = sys.argv[1:]
sb = json.load(open(os.path.join(b, "recipe-state.json")))["stages"]
sc = json.load(open(os.path.join(c, "recipe-state.json")))["stages"]
names = [s["name"] for s in json.load(open(os.path.join(c, "recipe.json")))["stages"]]
upto = names[: names.index("eval_sit") + 1]
for n in upto:
    assert sc[n]["state"] == "done", (n, sc[n])
    assert sc[n]["fingerprint"] == sb[n]["fingerprint"], n
    assert sc[n]["output_sha256"] == sb[n]["output_sha256"], n
    assert sc[n]["figures"]["adopted_from"] == os.path.realpath(b), (n, sc[n]["figures"])
    for rel in sc[n]["outputs"].values():
        assert os.path.isfile(os.path.join(c, rel)), rel
for n in names[len(upto):]:
    assert sc.get(n, {}).get("state", "pending") == "pending", n
PY
grep -q "stage(s) adopted" "$tmp/adopt.log" || fail "adopt: no adoption summary"
"$bin" recipe run recipes/sit_chair.json --dir "$tmp/adopt7" --actors 1 --scale 0.0001 --until walk1 \
  --set seed=7 --adopt-from "$B" > "$tmp/adopt7.log" 2>&1 || fail "adopt (seed 7): $(tail -20 "$tmp/adopt7.log")"
state "$tmp/adopt7" "
w=d['stages']['walk1']
assert w['state']=='done' and 'adopted_from' not in w['figures'], w
" || fail "adopt (seed 7): walk1 of another seed was adopted"
grep -q "0 stage(s) adopted" "$tmp/adopt7.log" || fail "adopt (seed 7): $(cat "$tmp/adopt7.log")"

# A changed stage config is refused before anything runs, naming the stage and what follows it.
python3 - "$src/recipes/sit_chair.json" "$tmp/changed.json" << 'PY'
import json, sys
r = json.load(open(sys.argv[1]))
for s in r["stages"]:
    if s["name"] == "sit_final":
        s["set"]["ppo.learning_rate"] = 5e-6
json.dump(r, open(sys.argv[2], "w"))
PY
before=$(stat -c %Y "$B/recipe-state.json")
if "$bin" recipe run "$tmp/changed.json" --dir "$B" --actors 1 --scale 0.0001 > "$tmp/c.log" 2>&1; then
  fail "a changed stage ran without --force-from"
fi
grep -q "stage sit_final changed" "$tmp/c.log" || fail "the refusal does not name sit_final: $(cat "$tmp/c.log")"
grep -q "eval_meta_zone1_lookahead" "$tmp/c.log" || fail "the refusal does not list the later stages"
[ "$(stat -c %Y "$B/recipe-state.json")" = "$before" ] || fail "the refused run wrote the state"
# A changed output is refused too.
cp "$B/eval_meta_zone3/eval.json" "$tmp/keep.json"
echo " " >> "$B/eval_meta_zone3/eval.json"
if "$bin" recipe run recipes/sit_chair.json --dir "$B" --actors 1 --scale 0.0001 > "$tmp/o.log" 2>&1; then
  fail "a changed output was accepted"
fi
grep -q "eval_meta_zone3: output result" "$tmp/o.log" || fail "the refusal does not name the output: $(cat "$tmp/o.log")"
# The sharded evaluations (recipes/sit_chair.json: eval_meta_* in 4 shards) ran here in B:
# every shard's records merged into the stage's result, as many trials as one run.
python3 - "$B" << 'PY' || fail "B: sharded evaluation"
import glob, json, os, sys
d = sys.argv[1]
for st in ("eval_meta_zone1", "eval_meta_zone2", "eval_meta_zone3"):
    plan = json.load(open(os.path.join(d, st, "shards", "plan.json")))
    result = json.load(open(os.path.join(d, st, "eval.json")))
    trials = sum(int(s["args"][s["args"].index("--trials") + 1]) for s in plan["shards"])
    assert len(plan["shards"]) >= 2, plan
    assert result["shards"] == len(plan["shards"]) and result["trials"] == trials, (st, result)
    for s in plan["shards"]:
        assert os.path.exists(s["result"]), s
PY
# --force-from redoes that stage (and only the stages that read it), moving its old files aside. Here
# its shards are taken only by a worker in another process (--local-shards 0), as a worker pod
# sharing the directory would (k8s/recipe-eval-workers.yaml).
"$bin" recipe worker --dir "$B" --exit-when-idle-s 20 > "$tmp/worker.log" 2>&1 &
worker=$!
"$bin" recipe run recipes/sit_chair.json --dir "$B" --actors 1 --scale 0.0001 --local-shards 0 \
  --force-from eval_meta_zone3 > "$tmp/f.log" 2>&1 || fail "--force-from: $(tail -20 "$tmp/f.log")"
wait $worker || fail "the worker failed: $(tail -20 "$tmp/worker.log")"
ls "$B"/superseded/*/eval_meta_zone3/eval.json > /dev/null || fail "the old files were not kept"
# Later stages that read nothing of eval_meta_zone3 kept what they made.
for later in eval_meta_zone1_lookahead paper_meta_walk; do
  if ls -d "$B"/superseded/*/$later > /dev/null 2>&1; then
    fail "--force-from eval_meta_zone3 redid $later, which does not read it"
  fi
done
python3 - "$B" "$worker" "$tmp/keep.json" << 'PY' || fail "worker shards: $(cat "$tmp/worker.log")"
import json, os, sys
d, worker, before = sys.argv[1], sys.argv[2], sys.argv[3]
plan = json.load(open(os.path.join(d, "eval_meta_zone3", "shards", "plan.json")))
for s in plan["shards"]:
    ran_by = open(s["result"][:-5] + ".ran-by").read().split()
    assert ran_by[1] == worker, (s["index"], ran_by, worker)  # the worker ran every shard
# The same trials give the same figures, sharded by another process or not.
a, b = json.load(open(before)), json.load(open(os.path.join(d, "eval_meta_zone3", "eval.json")))
for k in ("success_rate", "trials", "fall_rate"):
    assert a[k] == b[k], (k, a[k], b[k])
PY
state "$B" "
assert d['stages']['eval_meta_zone3']['attempts']==1
assert d['stages']['walk1']['attempts']==1
assert all(s['state']=='done' for s in d['stages'].values())" || fail "after --force-from"

# ---- C: on a cluster: learners per stage, one long-lived actor without config or files --------
C=$tmp/c
"$bin" keygen --out "$tmp/keys" > /dev/null
export PERCH_KEYS_DIR=$tmp/keys
base=$((20000 + RANDOM % 20000))
ports=(--rollout-port $base --weights-port $((base + 1)))
mkdir -p "$tmp/actor-cwd"
# The actor runs elsewhere (another directory) and knows nothing of the recipe or its files.
(cd "$tmp/actor-cwd" && exec "$bin" actor --learner-host 127.0.0.1 "${ports[@]}" --actor-id 7 \
  > "$tmp/actor.log" 2>&1) &
actor=$!
"$bin" recipe run recipes/sit_chair.json --dir "$C" --cluster --actors 0 --bind 127.0.0.1 \
  "${ports[@]}" --metrics-port $((base + 2)) --scale 0.0001 --until turn_left_fw \
  > "$tmp/c-run.log" 2>&1 || fail "C: the cluster recipe failed: $(tail -30 "$tmp/c-run.log") $(tail -20 "$tmp/actor.log")"
kill -0 $actor 2> /dev/null || fail "C: the actor did not stay up across stages: $(tail -20 "$tmp/actor.log")"
kill $actor
wait $actor 2> /dev/null || true
state "$C" "
for n in ('walk1','walk2','walk','turn_left','turn_right','turn_left_fw'):
    assert d['stages'][n]['state']=='done', n
    assert d['stages'][n]['samples']>0, n" || fail "C: stages"
# It followed the learner from stage to stage (six training stages, five changes of experiment),
# and the stage that trains from a bank got the bank from the learner.
[ "$(grep -c "the learner's experiment changed" "$tmp/actor.log")" -ge 5 ] ||
  fail "C: the actor did not rebuild at each stage: $(grep -c changed "$tmp/actor.log")"
grep -q "task turn_left (1 files from the learner)" "$tmp/actor.log" ||
  fail "C: the turn stage's bank did not come with the config: $(grep 'files from' "$tmp/actor.log")"
grep -q "learner" "$C/walk1/stage.log" || fail "C: no learner in the stage log"
echo "recipe_test: OK"
