"""`tensormass bench shells`: the implicit Euler step of a closed CST-DKT shell (thesis chapter 6).

A ball (an icosphere of radius 1 m, E = 3 kPa, nu = 0.49, h = 10 cm, rho = 100 kg/m^3: the thesis'
section 4.7 material) resting on its clamped bottom cap under gravity and an inward pressure of
50 Pa, run through the public API (Scene, Simulation) for a few implicit Euler steps (dt = 1/60 s).
Rows: the co-rotational shell with 1 and 2 threads, and the linear shell (corotational = 0: the
generated kernel alone, assembled by the compiled fused path) as the baseline measured in the same
run.  Also reported: the DSATUR colour count of the triangles (runtime/assembly/colouring.py; what a
colour-parallel assembly would run in sequence) and the thesis' 1.2-1.4 s per frame for 10 000
triangles (2013 hardware) as the floor to beat.  Each row: ms per step over the run's steps after
setup (best of `repeats`), the assembly's share, Newton iterations.
"""
from __future__ import annotations

import time

from ..runtime.base import parallel
from ..runtime.base.errors import TensormassError
from ..runtime.base.files import write_json_atomic
from .machine import machine_info
from ..runtime.scene.scene import Scene
from ..runtime.run.simulation import Simulation
from ..runtime.mesh import surfaces
from ..runtime.assembly.colouring import colour_cells

__all__ = ["run_shells_bench", "add_shells_command", "THESIS_S_PER_FRAME"]

THESIS_S_PER_FRAME = (1.2, 1.4)         # 10 000 triangles, thesis section 6.6 (2013 hardware)
STEPS, DT = 5, 1.0 / 60


def scene_text(subdivisions: int, corotational: int, threads: int) -> str:
    return f"""
name = "bench_shells"
[mesh]
generate = "sphere"
radius = 1.0
subdivisions = {subdivisions}
[[material]]
law = "cst_dkt"
E = 3000.0
nu = 0.49
thickness = 0.1
density = 100.0
corotational = {corotational}
[[fixed]]
box = [[-2, -2, -2], [2, 2, -0.95]]
[loads]
gravity = [0.0, 0.0, -9.81]
[[loads.pressure]]
box = [[-2, -2, -2], [2, 2, 2]]
value = 50.0
[solver]
kind = "implicit_euler"
steps = {STEPS}
dt = {DT}
backend = "c"
threads = {threads}
health_monitor = false
[[probe]]
name = "top"
point = [0.0, 0.0, 1.0]
"""


def _measure(subdivisions, corotational, threads, repeats) -> dict:
    best = None
    for _ in range(repeats):
        parallel.set_threads(threads)
        sim = Simulation(Scene.from_string(scene_text(subdivisions, corotational, threads)), output=False)
        try:
            s = sim.run()
        except TensormassError as exc:
            return {"status": "failed", "message": str(exc)}
        if s.status not in ("ok", "warnings"):
            return {"status": s.status, "message": s.message}
        steps = max(1, s.steps_done)
        row = {"status": s.status, "ms_per_step": 1e3 * (s.time["total"] - s.time["setup"]) / steps,
               "assembly_ms_per_step": 1e3 * s.time["assembly"] / steps,
               "newton": int(s.iterations.get("newton", 0)), "setup_s": s.time["setup"],
               "nodes": int(sim.model.n_points), "triangles": int(sim.model.n_elements),
               "top_uz": float(s.probes["top"][-1])}
        if best is None or row["ms_per_step"] < best["ms_per_step"]:
            best = row
    return best


def colour_count(subdivisions) -> dict:
    _, triangles = surfaces.icosphere(1.0, subdivisions)
    return {method: int(colour_cells(triangles, method=method).max()) + 1 for method in ("dsatur", "greedy")}


def run_shells_bench(quick=False, json_path=None, repeats=None, progress=print) -> dict:
    subdivisions = 2 if quick else 5                   # 320 / 20 480 triangles (>= the thesis' 10 000)
    repeats = repeats or (1 if quick else 2)
    rows = {"linear, 1 thread": (0, 1), "co-rotational, 1 thread": (1, 1), "co-rotational, 2 threads": (1, 2)}
    t0 = time.perf_counter()
    out = {name: _measure(subdivisions, c, t, repeats) for name, (c, t) in rows.items()}
    base = out["linear, 1 thread"].get("ms_per_step")
    for row in out.values():
        if base and "ms_per_step" in row:
            row["ratio_to_linear"] = row["ms_per_step"] / base
    colours = colour_count(subdivisions)
    first = next((r for r in out.values() if "triangles" in r), {})
    progress(f"closed shell: {first.get('triangles', '?')} triangles, {first.get('nodes', '?')} nodes, implicit Euler "
             f"dt = 1/60 s, {STEPS} steps; DSATUR colours {colours['dsatur']} (first-fit {colours['greedy']})")
    for name, row in out.items():
        if "ms_per_step" not in row:
            progress(f"  {name:26s} {row['status']}: {row['message']}")
            continue
        progress(f"  {name:26s} {row['ms_per_step']:9.1f} ms/step (assembly {row['assembly_ms_per_step']:7.1f}, "
                 f"Newton {row['newton']})  {row['ratio_to_linear']:5.2f}x linear  top u_z {row['top_uz']:.4g} m")
    progress(f"  thesis (10 000 triangles, 2013): {THESIS_S_PER_FRAME[0] * 1e3:.0f}-{THESIS_S_PER_FRAME[1] * 1e3:.0f} "
             f"ms per frame")
    report = {"machine": machine_info(), "quick": quick, "subdivisions": subdivisions, "steps": STEPS, "dt": DT,
              "rows": out, "colours": colours, "thesis_s_per_frame": list(THESIS_S_PER_FRAME),
              "seconds": time.perf_counter() - t0}
    progress(f"bench shells: {report['seconds']:.0f} s")
    if json_path is not None:
        write_json_atomic(json_path, report)
    return report


def cmd_shells(args) -> int:
    run_shells_bench(quick=args.quick, json_path=args.json)
    return 0


def add_shells_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("shells", help="implicit Euler step of a closed CST-DKT shell (20 480 triangles), "
                                    "co-rotational vs linear, 1 and 2 threads, colour count")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="a 320-triangle sphere, one repeat (CI smoke test)")
    p.set_defaults(run=cmd_shells)
