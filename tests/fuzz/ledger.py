#!/usr/bin/env python3
"""The fuzzing ledger: every `make fuzz` run's executions, added up per target.

tests/fuzz/run_fuzz.sh appends a row per target to the ledger (a CSV: target, executions,
seconds, outcome, where) when FUZZ_LEDGER names it; this rewrites the table between
`<!-- begin fuzz ledger -->` and `<!-- end fuzz ledger -->` in PAGE from it: per target the
runs, the executions and CPU time in total, the findings, and how far it is from the
1 million executions the project reports per target.

    ledger.py LEDGER_CSV PAGE            rewrite PAGE's table
    ledger.py LEDGER_CSV PAGE --check    exit 1 when PAGE's table is not the ledger's

Needs only the standard library.
"""

import csv
import sys

GOAL = 1_000_000
BEGIN, END = "<!-- begin fuzz ledger -->", "<!-- end fuzz ledger -->"


def fail(msg):
    sys.exit(f"ledger.py: {msg}")


def table(rows):
    targets = {}
    for r in rows:
        t = targets.setdefault(r["target"], {"runs": 0, "executions": 0, "seconds": 0, "findings": 0})
        t["runs"] += 1
        t["executions"] += int(r["executions"])
        t["seconds"] += int(r["seconds"])
        t["findings"] += r["outcome"] != "no finding"
    out = ["| target | runs | executions | time | findings | of 1 million |", "|---|---:|---:|---:|---:|---|"]
    for name in sorted(targets):
        t = targets[name]
        share = t["executions"] / GOAL
        reached = "reached" if share >= 1.0 else f"{100.0 * share:.0f} %"
        out.append(f"| `fuzz_{name}` | {t['runs']} | {t['executions']} | {t['seconds'] / 3600.0:.2f} h "
                   f"| {t['findings']} | {reached} |")
    return out


def main(argv):
    if len(argv) not in (3, 4) or (len(argv) == 4 and argv[3] != "--check"):
        fail("usage: ledger.py LEDGER_CSV PAGE [--check]")
    try:
        with open(argv[1], newline="") as f:
            rows = list(csv.DictReader(f))
        page = open(argv[2]).read().split("\n")
    except OSError as e:
        fail(f"{e.filename}: {e.strerror}")
    for i, r in enumerate(rows, start=2):
        for col in ("target", "executions", "seconds", "outcome"):
            if not r.get(col):
                fail(f"{argv[1]}: line {i}: no {col}")
        if not (r["executions"].isdigit() and r["seconds"].isdigit()):
            fail(f"{argv[1]}: line {i}: executions and seconds must be whole numbers")
    if BEGIN not in page or END not in page:
        fail(f"{argv[2]}: no {BEGIN} ... {END} block")
    b, e = page.index(BEGIN), page.index(END)
    new = page[: b + 1] + table(rows) + page[e:]
    if len(argv) == 4:
        if new != page:
            print("\n".join(table(rows)))
            fail(f"{argv[2]}: the fuzz ledger table is not the ledger's (run tests/fuzz/ledger.py)")
        return
    with open(argv[2], "w") as f:
        f.write("\n".join(new))


if __name__ == "__main__":
    main(sys.argv)
