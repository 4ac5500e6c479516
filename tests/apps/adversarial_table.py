"""Replay the adversarial suite (tests/apps/adversarial_cases.py) and print the README table.

    python tests/apps/adversarial_table.py                 # every case: the table, per family, failures
    python tests/apps/adversarial_table.py --json F        # also the counts and every case's outcome as JSON
    python tests/apps/adversarial_table.py --case NAME     # replay one case and describe how it ended
    python tests/apps/adversarial_table.py --family run    # only one family

Exit code 0 when every case met its expectation, 1 otherwise (the failures are listed).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from adversarial_cases import CASES, FAMILIES, by_name, replay  # noqa: E402

COLUMNS = (
    ("inputs", "inputs tried"),
    ("error", "clear errors (exit 2)"),
    ("untrusted", "untrusted runs reported (exit 3)"),
    ("warning", "warnings (exit 0)"),
    ("interrupted", "interrupted (exit 130)"),
    ("ok", "ok (exit 0, result checked)"),
    ("crash", "crashes"),
    ("traceback", "tracebacks"),
    ("silent_wrong", "silent wrong results"),
    ("half_written", "half-written outputs"),
    ("unmet", "other unmet expectations"),
)


def count(results) -> dict:
    """How the results ended. An exit-2/3/0/130 outcome is counted in its class only when the case
    met its expectation; every other departure falls in exactly one failure column."""
    c = {key: 0 for key, _ in COLUMNS}
    c["inputs"] = len(results)
    for r in results:
        c["crash"] += r.crash
        c["traceback"] += r.traceback
        c["silent_wrong"] += r.silent_wrong
        c["half_written"] += bool(r.half_written)
        if r.passed:
            c[r.outcome] += 1
        elif not (r.crash or r.traceback or r.silent_wrong or r.half_written):
            c["unmet"] += 1
    return c


def table(columns: list) -> str:
    """Markdown: one row per count, one column per (label, counts) (all cases, then each family)."""
    lines = ["| | " + " | ".join(label for label, _ in columns) + " |", "|---|" + "---:|" * len(columns)]
    for key, label in COLUMNS:
        lines.append(f"| {label} | " + " | ".join(str(c[key]) for _, c in columns) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", metavar="F", help="write the counts and every case's outcome to F")
    parser.add_argument("--case", action="append", help="replay only the case(s) with this name")
    parser.add_argument("--family", choices=FAMILIES, action="append", help="replay only this family")
    args = parser.parse_args(argv)
    cases = [by_name(n) for n in args.case] if args.case else CASES
    if args.family:
        cases = [c for c in cases if c.family in args.family]
    results = []
    t0 = time.perf_counter()
    for i, case in enumerate(cases, 1):
        r = replay(case)
        results.append(r)
        mark = "ok  " if r.passed else "FAIL"
        print(f"[{i:3d}/{len(cases)}] {mark} {case.family:9s} {case.name}: {r.outcome} (exit {r.code}, "
              f"{r.seconds:.2f} s)", file=sys.stderr)
    seconds = time.perf_counter() - t0
    overall = count(results)
    per_family = [(f, count([r for r in results if r.case.family == f]))
                  for f in FAMILIES if any(r.case.family == f for r in results)]
    print(table([("all", overall)] + per_family))
    failures = [r for r in results if not r.passed]
    print(f"\n{len(results)} inputs replayed in {seconds:.1f} s; {len(failures)} missed their expectation")
    for r in failures:
        print()
        print(r.describe())
    if args.json:
        data = {"counts": overall, "families": dict(per_family), "seconds": seconds,
                "cases": [{"family": r.case.family, "name": r.case.name, "expect": r.case.expect,
                           "outcome": r.outcome, "exit_code": r.code, "passed": r.passed, "problems": r.problems,
                           "half_written": r.half_written, "crash": r.crash, "traceback": r.traceback,
                           "silent_wrong": r.silent_wrong, "why": r.case.why, "argv": list(r.case.argv)}
                          for r in results]}
        Path(args.json).write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    return 0 if not failures else 1


if __name__ == "__main__":
    sys.exit(main())
