"""`tensormass bench history`: what the per-step history costs a run.

The history keeps, for every kept row, the elastic energy (explicit runs evaluate it only for
kept rows and frames), every probe and every reaction (runtime.run.history). The same scene runs
with every row kept and with almost none kept (the row limit set to 4: the stride doubles until
rows are rare), on one thread, best of `repeats`; the ratio of the stepping time (total minus
setup) per step is the history's cost. Explicit and implicit Euler, a 384-hexahedron StVK
cantilever with a probe and a clamp, frames only at the end.
"""
from __future__ import annotations

from ..runtime.base import parallel
from ..runtime.run import simulation
from ..runtime.base.files import write_json_atomic
from ..runtime.scene.scene import Scene
from .machine import machine_info

__all__ = ["run_history_bench", "add_history_command"]

SCENE = """
[mesh]
generate = "bar"
size = [1.2, 0.2, 0.2]
cells = {cells}
element = "hexahedron"
[[material]]
law = "stvk"
quadrature = "gauss2"
E = 1.0e6
nu = 0.3
density = 1000.0
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "{kind}"
dt = {dt}
steps = {steps}
[[probe]]
name = "tip"
point = [1.2, 0.1, 0.1]
[output]
every = 1000000          # frames (which evaluate the energy too) only at the last step
"""
CASES = (("explicit", 2e-5, 3000), ("implicit_euler", 0.01, 200))
QUICK = {"cells": [6, 1, 1], "steps": 20, "repeats": 1}
FULL = {"cells": [24, 4, 4], "steps": None, "repeats": 3}
FEW_ROWS = 4


def _per_step(kind, dt, steps, cells, repeats, limit) -> tuple:
    """(best stepping seconds per step, rows kept) with the history limited to `limit` rows."""
    saved = simulation.HISTORY_MAX
    simulation.HISTORY_MAX = limit
    try:
        best, rows = float("inf"), 0
        for _ in range(repeats):
            text = SCENE.format(cells=list(cells), kind=kind, dt=dt, steps=steps)
            s = simulation.Simulation(Scene.from_string(text), output=False).run()
            best = min(best, (s.time["total"] - s.time["setup"]) / steps)
            rows = len(s.per_step["step"])
    finally:
        simulation.HISTORY_MAX = saved
    return best, rows


def run_history_bench(quick=False, json_path=None, progress=print) -> dict:
    cfg = QUICK if quick else FULL
    parallel.set_threads(1)
    report = {"machine": machine_info(), "quick": quick, "threads": 1, "cells": cfg["cells"], "cases": {}}
    for kind, dt, steps in CASES:
        steps = cfg["steps"] or steps
        kept, kept_rows = _per_step(kind, dt, steps, cfg["cells"], cfg["repeats"], 1 << 30)
        few, few_rows = _per_step(kind, dt, steps, cfg["cells"], cfg["repeats"], FEW_ROWS)
        report["cases"][kind] = {"steps": steps, "every_row_s_per_step": kept, "rows": kept_rows,
                                 "few_rows_s_per_step": few, "few_rows": few_rows, "ratio": kept / few}
        progress(f"{kind:15s} every row kept ({kept_rows}) {1e3 * kept:.4f} ms/step, {few_rows} rows kept "
                 f"{1e3 * few:.4f} ms/step: the history costs {kept / few:.3f}x")
    if json_path is not None:
        write_json_atomic(json_path, report)
    return report


def cmd_history(args) -> int:
    run_history_bench(quick=args.quick, json_path=args.json)
    return 0


def add_history_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("history", help="what the per-step history (energy, probes, reactions) "
                                    "costs an explicit and an implicit Euler run")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="a tiny bar, 20 steps (CI smoke test)")
    p.set_defaults(run=cmd_history)
