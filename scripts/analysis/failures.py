#!/usr/bin/env python3
"""What the failed trials of sit_chair evaluations did (perch eval --records files).

Usage: failures.py A.records.jsonl [B.records.jsonl ...]

Groups every failed trial by its subtask sequence and whether it fell (the grouping of
docs/journal/meta.md, stops 44-46):
  time out                      did not fall, never sat for 3 s
  fall walking before any turn  fell while walking, no turn in the sequence
  fall walking after hand-back  fell while walking after a turn handed control back
  fall in a turn                fell while a turn was active
  sit after at most one turn    fell in the sit; sequence walk [> turn] > sit
  longer chain ending in sit    fell in the sit after a longer chain
Several files (shards of one evaluation) are counted together.
"""
import collections
import json
import sys

TURNS = {0, 1}  # turn_left, turn_right (the subtask indices of the records)
SIT, WALK = 2, 3


def group(r):
    s = r["sequence"]
    last = s[-1] if s else None
    if not r["fell"]:
        return "time out"
    if last == WALK:
        if any(x in TURNS for x in s):
            return "fall walking after hand-back"
        return "fall walking before any turn"
    if last in TURNS:
        return "fall in a turn"
    if last == SIT:
        return "sit after at most one turn" if len(s) <= 3 else "longer chain ending in sit"
    return "other"


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    trials = {}
    for path in sys.argv[1:]:
        with open(path) as f:
            lines = f.read().splitlines()[1:]  # line 1: the header
        for i, line in enumerate(lines):
            try:
                r = json.loads(line)
            except json.JSONDecodeError:
                if i == len(lines) - 1:
                    continue  # a torn last line (a run stopped mid-write)
                sys.exit(f"{path}: line {i + 2} is not JSON: not a records file")
            if not isinstance(r, dict) or not {"trial", "success", "fell", "sequence"} <= r.keys():
                sys.exit(f"{path}: line {i + 2} is not a trial record")
            if r["trial"] in trials:
                sys.exit(f"trial {r['trial']} appears twice")
            trials[r["trial"]] = r
    if not trials:
        sys.exit("no trial records in " + ", ".join(sys.argv[1:]))
    failed = [r for r in trials.values() if not r["success"]]
    counts = collections.Counter(group(r) for r in failed)
    print(f"{len(trials)} trials, {len(failed)} failed")
    for name, n in counts.most_common():
        print(f"  {n:5d}  {name}")


if __name__ == "__main__":
    main()
