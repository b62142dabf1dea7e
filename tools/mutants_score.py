#!/usr/bin/env python3
"""Combine cargo-mutants runs of one module into its score (docs/testing.md).

    tools/mutants_score.py target/mutants/sfr [target/mutants/sfr-shard-1-of-4 ...]

Each argument is an output directory of tools/mutants.sh: its runs/0, runs/1,
… (earlier runs, kept by the script) and mutants.out (the latest). Later runs
(e.g. the `--iterate` pass with the whole test set after a unit-test-only
pass) override earlier ones for the mutants they tested, so a mutant's final
outcome is that of the last run that tested it. Only the mutants of the code as
it is now count (`cargo mutants --list` of each file): a run of an earlier
version whose lines have since moved does not add stale names. Prints the
counts per source file, then every mutant not caught, for the reader to
match against the equivalent-mutant list in docs/testing.md.
"""
import glob
import json
import os
import subprocess
import sys
from collections import Counter, defaultdict

OUTCOME = {
    "CaughtMutant": "caught",
    "MissedMutant": "missed",
    "Timeout": "timeout",
    "Unviable": "unviable",
}


def outcomes(path):
    with open(f"{path}/outcomes.json") as f:
        data = json.load(f)
    for o in data["outcomes"]:
        scenario = o.get("scenario")
        if not isinstance(scenario, dict) or "Mutant" not in scenario:
            continue  # the baseline
        m = scenario["Mutant"]
        yield m["file"], m["name"], OUTCOME.get(o["summary"], o["summary"])


def main(dirs):
    final = {}
    for d in dirs:
        runs = glob.glob(f"{d}/runs/*/outcomes.json")
        runs.sort(key=lambda p: int(p.split("/")[-2]))
        runs = [os.path.dirname(p) for p in runs] + [f"{d}/mutants.out"]
        for run in runs:
            if not os.path.exists(f"{run}/outcomes.json"):
                continue
            for file, name, outcome in outcomes(run):
                final[name] = (file, outcome)
    files = sorted({file for file, _ in final.values()})
    current = set()
    for file in files:
        listed = subprocess.run(["cargo", "mutants", "--list", "-f", file],
                                capture_output=True, text=True, check=True).stdout
        current.update(line.strip() for line in listed.splitlines() if line.strip())
    untested = current - set(final)
    final = {k: v for k, v in final.items() if k in current}
    for name in untested:
        final[name] = (name.split(":")[0], "untested")
    per_file = defaultdict(Counter)
    for file, outcome in final.values():
        per_file[file][outcome] += 1
    for file in sorted(per_file):
        c = per_file[file]
        tested = c["caught"] + c["missed"] + c["timeout"]
        print(f"{file}: {sum(c.values())} mutants, caught {c['caught']}, missed {c['missed']}, "
              f"timeout {c['timeout']}, unviable {c['unviable']}, untested {c['untested']}; "
              f"caught or timed out {c['caught'] + c['timeout']}/{tested}")
    print()
    for name, (file, outcome) in sorted(final.items()):
        if outcome in ("missed", "timeout"):
            print(f"{outcome.upper():8} {name}")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
