"""What running a report's sweep on dask workers buys: `report accuracy` on 1 worker (this process,
one case after the other) against N worker processes (a LocalCluster, one thread each), same run.

    tensormass bench batch [--workers 2] [--benchmark cantilever cook volume] [--json F]
    python -m tensormass.apps.bench_batch ...          (the same)

Both runs follow a warm-up (the --quick sweep, so numba and C caches are filled and neither run pays
for compilation); the parallel time includes starting the cluster. The results.csv of both runs must
agree outside the timing columns (checked, printed). Prints the times and the ratio, writes JSON.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys
import tempfile
import time
from pathlib import Path

from ..runtime.base.files import write_json_atomic

TIMING = ("time_setup", "time_assembly", "time_solve", "time_total", "peak_memory_mb")


def _rows(path):
    with open(path, newline="") as fh:
        return [{k: v for k, v in r.items() if k not in TIMING} for r in csv.DictReader(fh)]


def run(workers: int, benchmarks, quick: bool) -> dict:
    from .reports.accuracy import run_accuracy      # deferred: meshio, 0.13 s that the other `tensormass bench` commands skip
    with tempfile.TemporaryDirectory(prefix="tm-bench-batch-") as tmp:
        run_accuracy(Path(tmp) / "warm", quick=True, benchmarks=benchmarks, progress=None)     # caches
        times = {}
        for n in (1, workers):
            t0 = time.perf_counter()
            run_accuracy(Path(tmp) / str(n), quick=quick, benchmarks=benchmarks, progress=None, workers=n)
            times[n] = time.perf_counter() - t0
        rows = _rows(Path(tmp) / "1" / "results.csv")
        same = rows == _rows(Path(tmp) / str(workers) / "results.csv")
    return {"benchmarks": list(benchmarks), "quick": quick, "rows": len(rows), "cores": os.cpu_count(),
            "seconds_1_worker": times[1], f"seconds_{workers}_workers": times[workers], "workers": workers,
            "speedup": times[1] / times[workers], "identical_results": same}


def _arguments(p) -> None:
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--benchmark", nargs="+", default=["cantilever", "cook", "volume"])
    p.add_argument("--quick", action="store_true", help="the reports' --quick sweeps (a smoke test)")
    p.add_argument("--json", help="write the numbers here")


def add_batch_command(bench_subparsers) -> None:
    """`tensormass bench batch`: the same as `python -m tensormass.apps.bench_batch`."""
    p = bench_subparsers.add_parser("batch", help="report accuracy's sweep on N dask workers against 1, "
                                    "results compared (needs tensormass[distributed])")
    _arguments(p)
    p.set_defaults(run=cmd_batch)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m tensormass.apps.bench_batch", description=__doc__.split("\n\n")[0])
    _arguments(p)
    return cmd_batch(p.parse_args(argv))


def cmd_batch(args) -> int:
    res = run(args.workers, args.benchmark, args.quick)
    parallel = res[f"seconds_{res['workers']}_workers"]
    print(f"report accuracy --benchmark {' '.join(res['benchmarks'])}{' --quick' if res['quick'] else ''} "
          f"({res['rows']} rows, {res['cores']} cores): 1 worker {res['seconds_1_worker']:.1f} s, "
          f"{res['workers']} workers {parallel:.1f} s, speed-up "
          f"{res['speedup']:.2f}x; results identical outside timings: {res['identical_results']}")
    if args.json:
        write_json_atomic(args.json, res)
    return 0 if res["identical_results"] else 1


if __name__ == "__main__":
    sys.exit(main())
