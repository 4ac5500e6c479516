"""`tensormass bench springs`: the step time of the spring models against finite elements at
equal node count.

Mass-spring models exist because they are cheap: this measures how cheap, through the public API
(Scene, Simulation) on the same mesh for every model.  A block of N x N x N cubic hexahedra (5 cm
cells, E = 1 MPa, nu = 0.3, rho = 1000: strains of a few 1e-3 under gravity), clamped at x = 0, under gravity, runs with

    mss            Baudet's lattice (12 edges + 4 inner diagonals per cube)
    hybmss         HybMSS, A = 1 (+ 12 face diagonals and the volume correction)
    hooke_gauss2, stvk_gauss2, stvk_gauss1      hexahedral finite elements

and, on a bar of tetrahedra, `mss` (edge springs) against stvk gauss1.  Per model and integrator
(explicit: forces only; implicit Euler: forces, stiffness and a linear solve per step; static: Newton)
it reports ms per step (the run's wall time after setup, over its steps; best of `repeats`), the
assembly's share, and the ratio to the baseline (stvk_gauss2 on the hexahedra, stvk_gauss1 on the
tetrahedra) measured in the same run.  One thread; backend "c" (numba compiles the 28-spring cube
for ~36 s on first use: the "numba" rows are measured after that, only with --numba).
"""
from __future__ import annotations

import time

from ..runtime.base import parallel
from ..runtime.base.errors import TensormassError
from ..runtime.base.files import write_json_atomic
from .machine import machine_info
from ..runtime.scene.scene import Scene
from ..runtime.run.simulation import Simulation

__all__ = ["run_springs_bench", "add_springs_command", "MODELS"]

CELL = 0.05
# name -> (law, quadrature, extra material lines)
MODELS = {
    "mss": ("mss", "discrete", ""),
    "hybmss": ("hybmss", "discrete", "A = 1.0"),
    "hooke_gauss2": ("hooke", "gauss2", ""),
    "stvk_gauss2": ("stvk", "gauss2", ""),
    "stvk_gauss1": ("stvk", "gauss1", ""),
}
HEX_BASELINE, TET_BASELINE = "stvk_gauss2", "stvk_gauss1"
# integrator -> (steps, dt)
KINDS = {"explicit": (200, 2e-4), "implicit_euler": (10, 1e-3), "static": (4, 1.0)}


def scene_text(model: str, kind: str, n: int, element: str = "hexahedron", backend: str = "c") -> str:
    law, quadrature, extra = MODELS[model]
    steps, dt = KINDS[kind]
    cells = [n, n, n] if element == "hexahedron" else [2 * n, max(1, n // 2), max(1, n // 2)]
    size = [round(c * CELL, 12) for c in cells]
    return f"""
name = "bench_springs_{model}_{kind}"
[mesh]
generate = "bar"
size = {size}
cells = {cells}
element = "{element}"
[[material]]
law = "{law}"
quadrature = "{quadrature}"
E = 1.0e6
nu = 0.3
density = 1000.0
{extra}
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 100, 100]]
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "{kind}"
steps = {steps}
dt = {dt}
backend = "{backend}"
health_monitor = false
[[probe]]
name = "tip"
point = [{size[0]}, {size[1] / 2}, {size[2] / 2}]
"""


def _measure(model: str, kind: str, n: int, element: str, backend: str, repeats: int) -> dict:
    best = None
    for _ in range(repeats):
        sim = Simulation(Scene.from_string(scene_text(model, kind, n, element, backend)), output=False)
        try:
            s = sim.run()
        except TensormassError as exc:            # a model that cannot run this case is a row, not an abort
            return {"status": "failed", "message": str(exc)}
        if s.status not in ("ok", "warnings"):
            return {"status": s.status, "message": s.message}
        steps = max(1, s.steps_done)
        run_s = s.time["total"] - s.time["setup"]
        row = {"status": s.status, "ms_per_step": 1e3 * run_s / steps, "assembly_ms_per_step": 1e3 * s.time["assembly"] / steps,
               "newton": int(s.iterations.get("newton", 0)), "setup_s": s.time["setup"],
               "nodes": int(sim.model.n_points), "cells": int(sim.model.n_elements),
               "tip_uz": float(s.probes["tip"][-1])}
        if best is None or row["ms_per_step"] < best["ms_per_step"]:
            best = row
    return best


def _block(element: str, n: int, models, kinds, backend: str, repeats: int, progress) -> dict:
    baseline = HEX_BASELINE if element == "hexahedron" else TET_BASELINE
    out = {}
    for kind in kinds:
        rows = {m: _measure(m, kind, n, element, backend, repeats) for m in models}
        base = rows.get(baseline, {}).get("ms_per_step")
        for m, row in rows.items():
            if base and "ms_per_step" in row:
                row["ratio_to_" + baseline] = row["ms_per_step"] / base
        out[kind] = rows
        cells = next((r["cells"] for r in rows.values() if "cells" in r), "?")
        nodes = next((r["nodes"] for r in rows.values() if "nodes" in r), "?")
        progress(f"{element} {cells} cells, {nodes} nodes, {kind} ({backend}):")
        for m, row in rows.items():
            if "ms_per_step" not in row:
                progress(f"  {m:14s} {row['status']}: {row['message']}")
                continue
            ratio = row.get("ratio_to_" + baseline)
            progress(f"  {m:14s} {row['ms_per_step']:9.2f} ms/step (assembly {row['assembly_ms_per_step']:8.2f})"
                     + (f"  {ratio:5.2f}x {baseline}" if ratio is not None else "")
                     + f"  tip u_z {row['tip_uz']:.4g} m")
    return out


def run_springs_bench(quick=False, json_path=None, repeats=None, numba=False, progress=print) -> dict:
    sizes = (4,) if quick else (10, 20)
    repeats = repeats or (1 if quick else 3)
    kinds = ("explicit", "implicit_euler") if quick else tuple(KINDS)
    parallel.set_threads(1)
    backends = ("c", "numba") if numba else ("c",)
    report = {"machine": machine_info(), "quick": quick, "threads": 1, "repeats": repeats, "cell": CELL,
              "hexahedra": {}, "tetrahedra": {}}
    t0 = time.perf_counter()
    for backend in backends:
        for n in sizes:
            report["hexahedra"][f"{n}^3 {backend}"] = _block("hexahedron", n, tuple(MODELS), kinds, backend,
                                                            repeats, progress)
        n = sizes[-1]
        report["tetrahedra"][f"{2 * n}x{max(1, n // 2)}^2 {backend}"] = _block(
            "tetra", n, ("mss", TET_BASELINE), kinds, backend, repeats, progress)
    progress(f"bench springs: {time.perf_counter() - t0:.0f} s")
    if json_path is not None:
        write_json_atomic(json_path, report)
    return report


def cmd_springs(args) -> int:
    run_springs_bench(quick=args.quick, json_path=args.json, numba=args.numba)
    return 0


def add_springs_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("springs", help="step time of the mass-spring models (mss, hybmss) against "
                                    "hexahedral and tetrahedral finite elements on the same meshes")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="a 4^3 block, one repeat (CI smoke test)")
    p.add_argument("--numba", action="store_true", help="also the numba backend (compiles the spring kernels first)")
    p.set_defaults(run=cmd_springs)
