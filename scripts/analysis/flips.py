#!/usr/bin/env python3
"""Where two evaluations of the same sit_chair trials part ways (perch eval --records files).

Usage: flips.py A.records.jsonl B.records.jsonl

Prints each file's success rate over the trials both hold, the trials whose outcome differs, and
for those whether the subtask sequence was the same (the last subtask's outcome flipped) or where
the two sequences diverged (a meta decision changed).
"""
import collections
import json
import sys

NAMES = {0: "turn_left", 1: "turn_right", 2: "sit", 3: "walk"}


def load(path):
    with open(path) as f:
        lines = f.read().splitlines()
    out = {}
    for line in lines[1:]:
        try:
            r = json.loads(line)
        except json.JSONDecodeError:
            break  # a torn last line (a run stopped mid-write)
        out[r["trial"]] = r
    return out


def name(seq):
    return " > ".join(NAMES.get(s, str(s)) for s in seq) or "(start)"


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    a, b = load(sys.argv[1]), load(sys.argv[2])
    trials = sorted(set(a) & set(b))
    if not trials:
        sys.exit("no trial in both files")
    rate = lambda d: sum(bool(d[t]["success"]) for t in trials) / len(trials)
    print(f"trials in both: {len(trials)}; success {rate(a):.3f} vs {rate(b):.3f}")
    kinds = collections.Counter()
    flips = 0
    for t in trials:
        ra, rb = a[t], b[t]
        if bool(ra["success"]) == bool(rb["success"]):
            continue
        flips += 1
        sa, sb = ra["sequence"], rb["sequence"]
        if sa == sb:
            kinds[f"same sequence, the last ({NAMES.get(sa[-1], sa[-1])}) flipped"] += 1
        else:
            k = 0
            while k < min(len(sa), len(sb)) and sa[k] == sb[k]:
                k += 1
            kinds[f"sequences diverge after {name(sa[:k])}"] += 1
    same_seq = sum(a[t]["sequence"] == b[t]["sequence"] for t in trials)
    print(f"outcome differs in {flips} of {len(trials)} trials; same sequence in {same_seq}")
    for k, n in kinds.most_common():
        print(f"  {n:4d}  {k}")


if __name__ == "__main__":
    main()
