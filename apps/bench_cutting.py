"""`tensormass bench cutting`: the time to cut a running body and resume, against rebuilding it whole.

A body under gravity, clamped at one end, runs implicit Euler steps through the public API
(Scene, Simulation); after step CUT_STEP a [[cut]] opens about a thousand faces (a plane through the
body, limited by a box), and the run goes on.  Per mesh:

- the cut's own record (Summary.topology): the topology change (incidence, node splitting), the
  model's local update (runtime.change.cutting) and the new solver state (assembly pattern, constrained
  system), and their sum — what a surgical simulator waits for between two frames;
- the baseline measured in the same run: the same cut mesh built from scratch (Model from the
  scene's materials, loads and constraints, then the same solver state), what a remesh-and-restart
  costs;
- the step time before the cut and after it, means over the steps 2 .. CUT_STEP - 1 and
  CUT_STEP + 2 .. STEPS (the first step after the cut also pays the new matrix's symbolic analysis
  and first factorisation; it is reported on its own, like the run's first step before it).

Meshes: a structured bar of 50 400 tetrahedra (the issue's size), a bar of quadratic tetrahedra
(tetra10), and, when gmsh is installed, an unstructured organ (the liver-sized ellipsoid of
apps/organ_mesh.py, linear tetrahedra).  --quick: small bars only (a CI smoke test).

--scale: the thesis' cutting scene at its size (B6: 10 cuts through an 85 405-element body): ten
incisions, one every other step, from the top of a 106 000-tetra organ 30 mm deep, in a dynamic run;
per cut, its record against a full rebuild of the body as it is after that cut (the last one measured).
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from ..runtime.base.errors import TensormassError
from ..runtime.base.files import write_json_atomic
from . import organ_mesh
from .machine import machine_info
from ..runtime.physics.newton import Context
from ..runtime.model.model import Model
from ..runtime.scene.scene import Scene
from ..runtime.run.simulation import Simulation

__all__ = ["run_cutting_bench", "add_cutting_command", "TARGET_MS"]

TARGET_MS = 50.0           # issue 18: a ~1 000-face cut on ~50 000 tetrahedra applied and resumed
CUT_STEP, STEPS = 8, 16


def _scene(mesh_toml: str, cut: str, fixed: str, element_law: str, steps: int = STEPS, cuts: str | None = None) -> str:
    """The bench's scene; cuts: the [[cut]] tables (default: one, `cut`, after step CUT_STEP)."""
    cuts = f"[[cut]]\nstep = {CUT_STEP}\n{cut}\n" if cuts is None else cuts
    return f"""
name = "bench_cutting"
{mesh_toml}
[[material]]
region = "all"
{element_law}
E = 1.0e5
nu = 0.3
density = 1000.0
[[fixed]]
box = {fixed}
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "implicit_euler"
dt = 0.01
steps = {steps}
""" + cuts


def _bar(cells, element, law, quad) -> str:
    return _scene(f'[mesh]\ngenerate = "bar"\nsize = [1.2, 0.4, 0.4]\ncells = {list(cells)}\nelement = "{element}"',
                  'plane = [[0.0, 0.2, 0.0], [0.0, 1.0, 0.0]]\nbox = [[0.4, -1, -1], [2, 1, 1]]',
                  "[[-1, -1, -1], [1e-9, 1, 1]]", f'law = "{law}"\nquadrature = "{quad}"')


def _organ(folder: Path) -> str | None:
    try:
        path = organ_mesh.make(folder / "organ.msh", size=0.0042, order=1, scale=2.2)
    except Exception:                 # gmsh missing or failing: the bars only
        return None
    return _scene(f'[mesh]\nfile = "{path.as_posix()}"',
                  'plane = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]\nbox = [[-1, -1, 0.025], [1, 1, 1]]',
                  "[[-1, -1, -1], [1, 1, 1e-9]]", 'law = "stvk"\nquadrature = "gauss1"')


SCALE_SIZE = 0.0033        # mesh size (m) of the --scale organ: 106 032 tetrahedra
SCALE_CUTS, SCALE_FIRST = 10, 3


def _organ_scale(folder: Path) -> str | None:
    """The organ of 106 032 tetrahedra with SCALE_CUTS incisions: planes x = const 11 mm apart,
    30 mm deep from the top (the box z > 36 mm), at steps 3, 5, ..., 21 of 23."""
    try:
        path = organ_mesh.make(folder / "organ_scale.msh", size=SCALE_SIZE, order=1, scale=2.2)
    except Exception:
        return None
    steps = SCALE_FIRST + 2 * SCALE_CUTS
    cuts = "".join(f"[[cut]]\nstep = {SCALE_FIRST + 2 * k}\nname = \"incision {k + 1}\"\n"
                   f"plane = [[{-0.0495 + 0.011 * k:.4f}, 0.0, 0.0], [1.0, 0.0, 0.0]]\nbox = [[-1, -1, 0.036], [1, 1, 1]]\n"
                   for k in range(SCALE_CUTS))
    return _scene(f'[mesh]\nfile = "{path.as_posix()}"', "", "[[-1, -1, -1], [1, 1, 1e-9]]",
                  'law = "stvk"\nquadrature = "gauss1"', steps=steps, cuts=cuts)


def _measure_scale(text: str) -> dict:
    sim = Simulation(Scene.from_string(text), output=False)
    s = sim.run()
    wall = np.asarray(s.per_step["wall"]) * 1e3
    cuts = [{"name": r.get("name"), "step": r.get("step"), "faces": r["faces"], "nodes_added": r["nodes_added"],
             "cells_changed": r["cells_changed"], "ms": {k: 1e3 * v for k, v in r["seconds"].items()}}
            for r in s.topology]
    return {"status": s.status, "cells": int(sim.model.mesh.n_cells), "dofs": int(sim.model.n_dofs), "cuts": cuts,
            "full_rebuild_ms": 1e3 * min(_full_rebuild(sim) for _ in range(2)),
            "step_ms_median": float(np.median(wall[1:])), "run_s": float(wall.sum() / 1e3)}


def _full_rebuild(sim) -> float:
    """Seconds to build the cut model from scratch and its solver state (the baseline)."""
    m, scene = sim.model, sim.model.scene
    start = time.perf_counter()
    model = Model(m.mesh, scene.materials, scene.fixed, scene.loads, scene.probes, scene.solver, scene.output,
                  check=False, amplitudes=scene.amplitudes)
    ctx = Context(model)
    model.warm_up()
    ctx.asm.warm_up()
    return time.perf_counter() - start


def _measure(text: str) -> dict:
    sim = Simulation(Scene.from_string(text), output=False)
    s = sim.run()
    (record,) = s.topology
    wall = np.asarray(s.per_step["wall"]) * 1e3
    sec = record["seconds"]
    return {"status": s.status, "cells": int(sim.model.mesh.n_cells), "dofs": int(sim.model.n_dofs),
            "faces": record["faces"], "nodes_added": record["nodes_added"], "cells_changed": record["cells_changed"],
            "cut_ms": {k: 1e3 * v for k, v in sec.items()},
            "full_rebuild_ms": 1e3 * min(_full_rebuild(sim) for _ in range(2)),
            "step_ms_before": float(np.mean(wall[1:CUT_STEP - 1])),
            "first_step_after_ms": float(wall[CUT_STEP]),
            "step_ms_after": float(np.mean(wall[CUT_STEP + 1:]))}


def run_cutting_scale(json_path=None, progress=print) -> dict:
    """--scale: ten incisions through the 106 000-tetra organ (needs gmsh)."""
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        text = _organ_scale(Path(tmp))
        if text is None:
            raise TensormassError("bench cutting --scale: the organ mesh needs gmsh (pip install 'tensormass[mesh]')")
        row = _measure_scale(text)
    progress(f"organ tetra (gmsh, h = {1e3 * SCALE_SIZE:g} mm): {row['cells']} cells, {row['dofs']} dofs after the cuts; "
             f"status {row['status']}; {len(row['cuts'])} cuts; median step {row['step_ms_median']:.0f} ms")
    for c in row["cuts"]:
        ms = c["ms"]
        progress(f"  {c['name']} (step {c['step']}): {c['faces']} faces, +{c['nodes_added']} nodes: cut and resume "
                 f"{ms['total']:.1f} ms (topology {ms['topology']:.1f}, model {ms['model']:.1f}, solver state "
                 f"{ms['solver']:.1f}) against a full rebuild of {row['full_rebuild_ms']:.0f} ms "
                 f"({ms['total'] / row['full_rebuild_ms']:.2f}x)")
    report = {"machine": machine_info(), "scale": row, "seconds": time.perf_counter() - t0}
    progress(f"bench cutting --scale: {report['seconds']:.0f} s")
    if json_path is not None:
        write_json_atomic(json_path, report)
    return report


def run_cutting_bench(quick=False, json_path=None, progress=print) -> dict:
    t0 = time.perf_counter()
    meshes = {"bar tetra 1 440": _bar((10, 4, 6), "tetra", "stvk", "gauss1")} if quick else {
        "bar tetra 50 400": _bar((40, 15, 14), "tetra", "stvk", "gauss1"),
        "bar tetra10 10 080": _bar((24, 7, 10), "tetra10", "stvk", "gauss2")}
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        organ = None if quick else _organ(Path(tmp))
        if organ is not None:
            meshes["organ tetra (gmsh)"] = organ
        for name, text in meshes.items():
            rows[name] = row = _measure(text)
            cut = row["cut_ms"]
            row["ratio_to_full_rebuild"] = cut["total"] / row["full_rebuild_ms"]
            progress(f"{name}: {row['cells']} cells, {row['dofs']} dofs; cut of {row['faces']} faces "
                     f"(+{row['nodes_added']} nodes, {row['cells_changed']} cells renumbered)")
            progress(f"  cut and resume {cut['total']:7.1f} ms (topology {cut['topology']:.1f}, model "
                     f"{cut['model']:.1f}, solver state {cut['solver']:.1f}); full rebuild {row['full_rebuild_ms']:.1f} ms "
                     f"({row['ratio_to_full_rebuild']:.2f}x); target {TARGET_MS:.0f} ms")
            progress(f"  step {row['step_ms_before']:.1f} ms before, {row['first_step_after_ms']:.1f} ms for the "
                     f"first after (new symbolic analysis), {row['step_ms_after']:.1f} ms after")
    report = {"machine": machine_info(), "quick": quick, "target_ms": TARGET_MS, "rows": rows,
              "seconds": time.perf_counter() - t0}
    progress(f"bench cutting: {report['seconds']:.0f} s")
    if json_path is not None:
        write_json_atomic(json_path, report)
    return report


def cmd_cutting(args) -> int:
    if args.scale:
        run_cutting_scale(json_path=args.json)
    else:
        run_cutting_bench(quick=args.quick, json_path=args.json)
    return 0


def add_cutting_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("cutting", help="cut a running 50 000-tetra body (~1 000 faces) and resume, "
                                    "against a full rebuild; step times before and after")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="a 1 440-tetra bar only (CI smoke test)")
    p.add_argument("--scale", action="store_true", help="ten incisions through a 106 000-tetra organ in a dynamic "
                   "run (the thesis' B6 size; needs gmsh)")
    p.set_defaults(run=cmd_cutting)
