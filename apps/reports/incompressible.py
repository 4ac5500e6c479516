"""Newton near incompressibility (`tensormass report accuracy --benchmark incompressible`): how many
Newton iterations one static load step takes, and what it converges to.

Cases: the organ of `tensormass bench organ` (gmsh tetra10, neo-Hookean E 5 kPa, gravity and a
400 Pa traction on its cap, clamped underneath; scaled 2.2x, liver-sized; quick: scale 1) at
nu = 0.499 with the displacement formulation and with mean dilatation (P2/P0), mesh sizes 12 mm
and (not quick) 8 mm, one load step; and the hexahedral neo-Hookean cantilever of `bench organ`
(nu = 0.3, gravity; quick: 12 x 2 x 4 cells, else 48 x 8 x 8).  A row's value is the number of
Newton iterations; its case names the probe (u_z at the organ's top pole / the cantilever's free
end, mm).  Where FElupe is installed, its plain Newton (full steps, NeoHookeCompressible, the same
mesh, clamp, nodal loads and convergence test as tensormass; the displacement formulation) runs
the displacement cases it can afford (not the 8 mm organ) and its count goes into the notes.
Needs gmsh for the organ (without it only the cantilever runs, with a note).
"""
from __future__ import annotations

import time

import numpy as np

from .common import benchmark_row as _row
from .common import measure as _measure
from ...runtime.base.errors import TensormassError
from ...runtime.scene.scene import Scene

__all__ = ["incompressible", "INCOMPRESSIBLE"]

INCOMPRESSIBLE = {"nu": 0.499, "formulations": ["displacement", "mean_dilatation"]}
FULL = {"organ": [[0.012, 2.2], [0.008, 2.2]], "cantilever": [48, 8, 8], "felupe_max_dofs": 15_000}
QUICK = {"organ": [[0.012, 1.0]], "cantilever": [12, 2, 4], "felupe_max_dofs": 15_000}


# bench_organ and bench_steps are imported inside the functions: they load the simulation stack
# (scipy.sparse, pyamg), 0.47 s skipped by `tensormass report --help` (0.7 s) (python -X importtime, 2 shared cores)


def _organ_text(size, scale, nu, formulation):
    from .. import bench_organ as bo
    case = bo.Case("incompressible", "organ", "tetra10", "static", 1, size=size, scale=scale)
    path, _ = bo.organ_mesh(case)
    text = bo.organ_scene_text(case, path, nu, formulation)
    return text.replace("[solver]", "[solver]\nnewton_max_iterations = 60"), bo.probe_point(case)


def _cantilever_text(cells):
    from .. import bench_organ as bo
    case = bo.Case("incompressible_cantilever", "cantilever", "hexahedron", "static", 1, cells=tuple(cells))
    return bo.scene_text(case, None), bo.probe_point(case)


def _felupe(model, E, nu, tol):
    """FElupe's plain Newton on the model's mesh, clamp and loads: (iterations, converged, seconds)."""
    import felupe as fem
    part = model.parts[0]
    regions = {"tetra10": "RegionQuadraticTetra", "tetra": "RegionTetra", "hexahedron": "RegionHexahedron"}
    mu, lam = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
    f_ext = np.asarray(model.f_ext, dtype=float)
    fixed, free = np.asarray(model.fixed_dofs), np.asarray(model.free_dofs)
    t0 = time.perf_counter()
    mesh = fem.Mesh(np.array(model.mesh.points, dtype=float), np.array(part.cells), part.element)
    field = fem.FieldContainer([fem.Field(getattr(fem, regions[part.element])(mesh), dim=3)])
    solid = fem.SolidBody(fem.NeoHookeCompressible(mu=mu, lmbda=lam), field)
    load = max(float(np.linalg.norm(f_ext[free])), 1e-30)
    for it in range(61):
        r = np.asarray(solid.assemble.vector(field).todense()).ravel() - f_ext
        res = float(np.linalg.norm(r[free]))
        if res <= tol * max(load, float(np.linalg.norm(r[fixed]))):
            return it, True, time.perf_counter() - t0
        if not np.isfinite(res) or it == 60:
            break
        K = solid.assemble.matrix(field)
        field += fem.solve.solve(*fem.solve.partition(field, K, free, fixed, r), ext0=np.zeros(fixed.size))
    return it, False, time.perf_counter() - t0


def _one(text, probe, label, progress):
    scene = Scene.from_string(text)
    t0 = time.perf_counter()
    try:
        summary, peak, sim = _measure(scene, trace=False)
    except TensormassError as error:
        progress(f"incompressible {label}: failed: {str(error).splitlines()[0]}")
        return None, f"{label}: failed after {time.perf_counter() - t0:.1f} s: {str(error).splitlines()[0]}", scene
    points = sim.model.mesh.points
    node = int(np.argmin(np.linalg.norm(points - np.asarray(probe), axis=1)))
    uz = float(sim.displacement[node][2])
    return (summary, peak, uz, sim.model), None, scene


def incompressible(quick, progress, sweep=None) -> dict:
    cfg = dict(QUICK if quick else FULL)
    cfg.update(INCOMPRESSIBLE)
    cfg.update(sweep or {})
    progress = progress or (lambda text: None)
    try:
        import felupe  # noqa: F401
        has_felupe = True
    except ImportError:
        has_felupe = False
    try:
        import gmsh  # noqa: F401
        organs = [tuple(x) for x in cfg["organ"]]
    except ImportError:
        organs = []
    rows, notes = [], []
    if not organs:
        notes.append("- organ cases skipped: gmsh is not installed (pip install gmsh)")
    if not has_felupe:
        notes.append("- FElupe is not installed (pip install tensormass[compare]): no FElupe counts")
    jobs = []
    for size, scale in organs:
        for formulation in cfg["formulations"]:
            text, probe = _organ_text(size, scale, cfg["nu"], formulation)
            jobs.append((f"organ x{scale:g} h{1e3 * size:g} mm nu {cfg['nu']} {formulation}", "tetra10",
                         formulation, text, probe, (5.0e3, cfg["nu"]), f"h{1e3 * size:g}x{scale:g}"))
    text, probe = _cantilever_text(cfg["cantilever"])
    from ..bench_steps import E as E_BAR, NU as NU_BAR
    jobs.append((f"cantilever {'x'.join(map(str, cfg['cantilever']))} nu {NU_BAR}", "hexahedron", "displacement",
                 text, probe, (E_BAR, NU_BAR), "x".join(map(str, cfg["cantilever"]))))
    for label, element, formulation, text, probe, (E, nu), cells in jobs:
        progress(f"incompressible: {label}")
        out, failure, scene = _one(text, probe, label, progress)
        if out is None:
            notes.append(f"- {failure}")
            continue
        summary, peak, uz, model = out
        its = int(summary.iterations["newton"]) if hasattr(summary, "iterations") else int(summary["iterations"]["newton"])
        row = _row("incompressible", element, "neohookean", "gauss2", (0,), f"{label}: u_z {1e3 * uz:.4f} mm",
                   summary, peak, its)
        row["formulation"], row["cells"] = formulation, cells
        rows.append(row)
        line = (f"- {label}: {its} Newton iterations, {summary.time['total'] - summary.time['setup']:.2f} s "
                f"stepping, u_z {1e3 * uz:.5f} mm")
        if has_felupe and formulation == "displacement" and model.free_dofs.size <= cfg["felupe_max_dofs"]:
            fe_its, ok, seconds = _felupe(model, E, nu, scene.solver.newton_tolerance)
            line += f"; FElupe plain Newton: {fe_its} iterations{'' if ok else ' (NOT converged)'}, {seconds:.1f} s"
        notes.append(line)
    return {"rows": rows,
            "reference": {"subject": "Newton iterations of one static load step near incompressibility",
                          "numerical": "FElupe's plain Newton on the same mesh and loads (displacement formulation)",
                          "analytic": "none: the value is an iteration count"},
            "compile_s": {}, "notes": notes}
