"""`tensormass bench laws`: what a step with history variables costs against the same step without.

The organ of `tensormass bench organ` (neo-Hookean, nu = 0.45, gravity and a tool's traction on
the unstructured gmsh organ) runs implicit Euler (dt = 10 ms, exact steps) as it is, with two
Prony branches (laws/viscous.py: its step kernel, plus the history's prepare and commit per step)
and as fibre-reinforced tissue (laws/hgo.py, fibres along x), one thread, best of `repeats`.
Reported per case: ms per step after the first (Summary.time: total - setup - first step), the
history's own share (prepare + commit), and the ratio to the elastic step measured in the same run.
Needs gmsh for the organ meshes (tensormass[mesh]); --quick runs without it, on the small organ
committed for the dynamics report.
"""
from __future__ import annotations

import re
import time

from ..runtime.base import parallel
from ..runtime.base.files import write_json_atomic
from .bench_organ import Case, organ_mesh, scene_text
from .reports.dynamics import QUICK_MESH
from .machine import machine_info
from ..runtime.scene.scene import Scene
from ..runtime.run.simulation import Simulation

__all__ = ["run_laws_bench", "add_laws_command"]

STEPS = 20
CASES = (Case("tetra_h6_dynamic", "organ", "tetra", "implicit_euler", STEPS, size=0.006),
         Case("tetra10_h8_dynamic", "organ", "tetra10", "implicit_euler", STEPS, size=0.008))
# quick (and without gmsh): the small tetra organ committed for the dynamics report (scale 1, h = 9 mm)
QUICK_CASES = (Case("quick_tetra_h9_dynamic", "organ", "tetra", "implicit_euler", 5, size=0.009, scale=1.0),)
VARIANTS = {"elastic": "",
            "viscous": "viscous = [{tau = 0.1, beta = 1.0}, {tau = 1.0, beta = 0.5}]",
            "hgo": None}         # the law changes: see _scene


def _mesh(case: Case):
    return QUICK_MESH if case in QUICK_CASES else organ_mesh(case)[0]


def _scene(case: Case, variant: str):
    text = scene_text(case, _mesh(case))
    if variant == "viscous":
        text = re.sub(r"(?m)^(nu = .*)$", rf"\1\n{VARIANTS['viscous']}", text, count=1)
    elif variant == "hgo":
        text = text.replace('law = "neohookean"', 'law = "hgo"')
        text = re.sub(r"(?m)^(nu = .*)$", r"\1\nk1 = 2.0e4\nk2 = 5.0\nfibres = [1, 0, 0]", text, count=1)
    return Scene.from_string(text)


def _measure(case: Case, variant: str, repeats: int) -> dict:
    best = None
    for _ in range(repeats):
        sim = Simulation(_scene(case, variant), output=False)
        history = {"s": 0.0}
        if variant == "viscous":
            _time_history(sim, history)
        s = sim.run()
        if s.status not in ("ok", "warnings"):
            raise RuntimeError(f"bench laws: {case.name} {variant} ended {s.status}: {s.message}")
        steps = max(1, case.steps - 1)
        after = s.time["total"] - s.time["setup"] - s.time["first_step"]
        row = {"ms_per_step": 1e3 * after / steps, "history_ms_per_step": 1e3 * history["s"] / case.steps,
               "newton": int(s.iterations.get("newton", 0)), "setup_s": s.time["setup"]}
        if best is None or row["ms_per_step"] < best["ms_per_step"]:
            best = row
    return best


def _time_history(sim, into: dict) -> None:
    """Time the history's prepare and commit (wrapped once the run has built its context)."""
    prepare = sim._prepare

    def wrapped():
        prepare()
        history = sim.ctx.history
        for name in ("prepare", "commit"):
            call = getattr(history, name)

            def timed(*args, _call=call):
                t0 = time.perf_counter()
                try:
                    return _call(*args)
                finally:
                    into["s"] += time.perf_counter() - t0
            setattr(history, name, timed)
    sim._prepare = wrapped


def run_laws_bench(quick=False, json_path=None, repeats=None, progress=print, cases=None) -> dict:
    cases = cases or (QUICK_CASES if quick else CASES)
    repeats = repeats or (1 if quick else 2)
    parallel.set_threads(1)
    report = {"machine": machine_info(), "quick": quick, "threads": 1, "repeats": repeats, "cases": {}}
    for case in cases:
        t0 = time.perf_counter()
        for variant in VARIANTS:                       # warm-up: every kernel generated and compiled
            _measure(case, variant, 1) if not quick else None
        rows = {variant: _measure(case, variant, repeats) for variant in VARIANTS}
        base = rows["elastic"]["ms_per_step"]
        entry = {"title": case.title, **rows,
                 "ratio_viscous": rows["viscous"]["ms_per_step"] / base, "ratio_hgo": rows["hgo"]["ms_per_step"] / base}
        report["cases"][case.name] = entry
        progress(f"{case.title}: elastic {base:.2f} ms/step, viscous {rows['viscous']['ms_per_step']:.2f} "
                 f"(history {rows['viscous']['history_ms_per_step']:.2f}) = {entry['ratio_viscous']:.2f}x, "
                 f"hgo {rows['hgo']['ms_per_step']:.2f} = {entry['ratio_hgo']:.2f}x  ({time.perf_counter() - t0:.0f} s)")
    if json_path is not None:
        write_json_atomic(json_path, report)
    return report


def cmd_laws(args) -> int:
    run_laws_bench(quick=args.quick, json_path=args.json)
    return 0


def add_laws_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("laws", help="cost of a step with history variables (Prony branches) and with "
                                    "fibres, against the elastic step (organ tetra / tetra10; needs gmsh)")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="a small organ, one repeat (CI smoke test)")
    p.set_defaults(run=cmd_laws)
