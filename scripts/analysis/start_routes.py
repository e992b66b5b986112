#!/usr/bin/env python3
"""Can the lookahead's start route be learned? (docs/journal/meta.md "Stop 42")

Reads records of `perch eval --task sit_chair ... --record-routes` (each trial: the start
observation and the outcome of every start route the lookahead tried, the policy's own first)
for a training and a test set of trials, and prints:
  - the policy's own route, the best single route, and "some route succeeds" (the search);
  - a k-nearest-neighbour route picker fitted on the training trials (the start observation and
    the spawn angle, standardised), scored on the test trials by the picked route's recorded
    outcome: what a start-route policy that sees the state could reach;
  - how often the outcomes of the routes agree, against independent draws.
With --alone A.jsonl and --lookahead L.jsonl (records of the policy alone and of a lookahead run on
the same trials) it also counts the trials whose outcome differs between the policy alone and
the same policy with the lookahead's restores of the simulator (rules_success): how much an
imperceptible change to the simulation moves an outcome.

Pure Python (no numpy): python3 scripts/analysis/start_routes.py TRAIN.jsonl TEST.jsonl
"""
import argparse
import json
import math


def load(path, need_routes=True):
    out = {}
    with open(path) as f:
        lines = f.read().splitlines()[1:]  # line 1: the header
    for line in lines:
        try:
            r = json.loads(line)
        except json.JSONDecodeError:
            continue  # a torn last line (a killed run)
        if need_routes and not r.get("routes"):
            continue
        out[r["trial"]] = r
    return [out[t] for t in sorted(out)]


def name(route):
    d = route["detour_deg"]
    where = "ahead" if d is None else "%+.0f deg" % d
    return "policy" if route["straight_steps"] == 0 else "%d steps %s" % (route["straight_steps"], where)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("train")
    ap.add_argument("test")
    ap.add_argument("--alone", help="records of the policy alone on the lookahead run's trials")
    ap.add_argument("--lookahead", help="records of a lookahead run (rules_success per trial)")
    a = ap.parse_args()
    train, test = load(a.train), load(a.test)
    n_routes = len(train[0]["routes"])
    train = [r for r in train if len(r["routes"]) == n_routes]
    test = [r for r in test if len(r["routes"]) == n_routes]
    names = [name(x) for x in train[0]["routes"]]
    ok = lambda r: [1.0 if x["success"] else 0.0 for x in r["routes"]]
    ytr, yte = [ok(r) for r in train], [ok(r) for r in test]
    print("trials: %d to fit, %d to test; %d start routes each" % (len(train), len(test), n_routes))
    rate = [sum(y[i] for y in ytr) / len(ytr) for i in range(n_routes)]
    best = max(range(n_routes), key=lambda i: rate[i])
    for label, ys in (("fit", ytr), ("test", yte)):
        print("%-4s: policy's own route %.3f | best single route (%s, from the fit set) %.3f | "
              "some route succeeds %.3f | routes that succeed %.1f of %d" %
              (label, sum(y[0] for y in ys) / len(ys), names[best],
               sum(y[best] for y in ys) / len(ys), sum(max(y) for y in ys) / len(ys),
               sum(sum(y) for y in ys) / len(ys), n_routes))
    # Independence: the chance that no other route succeeds if each were its own coin.
    both = ytr + yte
    p = [sum(y[i] for y in both) / len(both) for i in range(n_routes)]
    none_indep = math.prod(1 - q for q in p[1:])
    none_seen = sum(1 - max(y[1:]) for y in both) / len(both)
    fail0 = [y for y in both if y[0] == 0]
    print("other routes: each succeeds %.3f on average (%.3f - %.3f); when the policy's own fails, "
          "some other succeeds in %.3f; no other succeeds %.4f (independent coins: %.4f)" %
          (sum(p[1:]) / (n_routes - 1), min(p[1:]), max(p[1:]),
           sum(max(y[1:]) for y in fail0) / max(1, len(fail0)), none_seen, none_indep))

    def feat(r):
        return r["start_obs"] + [math.sin(r["spawn_theta"]), math.cos(r["spawn_theta"])]

    xtr = [feat(r) for r in train]
    dim = len(xtr[0])
    mu = [sum(x[j] for x in xtr) / len(xtr) for j in range(dim)]
    sd = [math.sqrt(sum((x[j] - mu[j]) ** 2 for x in xtr) / len(xtr)) or 1.0 for j in range(dim)]
    z = lambda x: [(x[j] - mu[j]) / sd[j] for j in range(dim)]
    ztr = [z(x) for x in xtr]

    def pick(x, k, only_theta):
        if only_theta:
            d = sorted((abs(x[-2] - t[-2]) + abs(x[-1] - t[-1]), i) for i, t in enumerate(xtr))
        else:
            zx = z(x)
            d = sorted((sum((u - v) ** 2 for u, v in zip(zx, zt)), i) for i, zt in enumerate(ztr))
        score = [rate[j] + sum(ytr[i][j] for _, i in d[:k]) for j in range(n_routes)]
        return max(range(n_routes), key=lambda j: (score[j], j == 0))

    for only_theta in (False, True):
        row = []
        for k in (5, 10, 20, 40, 80):
            hit = sum(yte[t][pick(feat(r), k, only_theta)] for t, r in enumerate(test)) / len(test)
            row.append("k=%d %.3f" % (k, hit))
        print("route picked by the k nearest fit trials (by %s), success on the test trials: %s" %
              ("spawn angle" if only_theta else "start observation + spawn angle", ", ".join(row)))
    if a.alone and a.lookahead:
        alone = {r["trial"]: r for r in load(a.alone, need_routes=False)}
        la = {r["trial"]: r for r in load(a.lookahead, need_routes=False)}
        common = sorted(set(alone) & set(la))
        flips = sum(alone[t]["success"] != la[t]["lookahead"]["rules_success"] for t in common)
        print("policy alone %.3f vs the same policy with the simulator restored at its switches "
              "%.3f on %d trials: the outcome differs in %d (%.1f%%)" %
              (sum(alone[t]["success"] for t in common) / len(common),
               sum(la[t]["lookahead"]["rules_success"] for t in common) / len(common), len(common),
               flips, 100.0 * flips / len(common)))


if __name__ == "__main__":
    main()
