"""`tensormass bench steps`: time per implicit Euler step and per Newton iteration on large bodies.

Bodies: a ~10 000-tetrahedron and a ~20 000-hexahedron bar (stvk and neohookean),
clamped at one end under gravity. For each: an implicit Euler step (one
linearisation, the thesis' scheme) and the Newton iterations of a static solve,
each split into assembly and linear solve, with the direct and the CG solver.

Then one Newton iteration (assembly + linear solve) of a compressible
neo-Hookean cantilever of 48 x 8 x 8 hexahedra (gauss2, 11 664 free dofs) with
every linear solver, and, when FElupe imports (`pip install tensormass[compare]`),
the same iteration in FElupe (same mesh, law, material, load and clamp; its
default solver) in the same run: the report gives the ratio FElupe / ours.
"""
from __future__ import annotations

import time

import numpy as np

from ..backends import BACKENDS
from ..runtime.base.files import write_json_atomic
from ..runtime.scene.scene import Scene
from .machine import machine_info
from ..runtime.run.simulation import Simulation
from ..runtime.physics.newton import Context
from ..runtime.model.model import Model
from ..runtime.solve.solvers import LinearSolver, has_pardiso

BODIES = {
    # name: (element, cells, size)
    "tetra_10k": ("tetra", (24, 6, 12), (2.0, 0.5, 1.0)),
    "hexahedron_20k": ("hexahedron", (60, 18, 18), (3.0, 0.9, 0.9)),
}
QUICK_BODIES = {
    "tetra_1k": ("tetra", (12, 3, 5), (2.0, 0.5, 1.0)),
    "hexahedron_2k": ("hexahedron", (24, 9, 9), (3.0, 0.9, 0.9)),
}
LAWS = ("stvk", "neohookean")
LINEAR = ("direct", "cg")

# One Newton iteration, compared with FElupe: (name, element, cells, size, law)
NEWTON_CASE = ("hexahedron_3k", "hexahedron", (48, 8, 8), (1.2, 0.2, 0.2), "neohookean")
QUICK_NEWTON_CASE = ("hexahedron_96", "hexahedron", (12, 2, 4), (1.2, 0.2, 0.2), "neohookean")
# LinearSolver settings timed on it: (label, method, preconditioner)
NEWTON_SOLVERS = (("auto", "auto", "ic"), ("band", "band", "ic"), ("pardiso", "pardiso", "ic"), ("lu", "lu", "ic"),
                  ("cg-ic", "cg", "ic"), ("cg-jacobi", "cg", "jacobi"), ("cg-amg", "amg", "ic"))
NEWTON_REPEATS, QUICK_NEWTON_REPEATS = 5, 2
FELUPE_REPEATS, QUICK_FELUPE_REPEATS = 3, 1

E, NU, DENSITY, GRAVITY = 1.0e6, 0.3, 1000.0, 9.81


def scene_text(element, cells, size, law, kind, linear, steps, backend="numba") -> str:
    quadrature = "gauss1" if element == "tetra" else "gauss2"
    return f"""
name = "bench_{element}_{law}_{kind}"
[mesh]
generate = "bar"
size = {list(size)}
cells = {list(cells)}
element = "{element}"
[[material]]
region = "all"
law = "{law}"
quadrature = "{quadrature}"
E = {E}
nu = {NU}
density = {DENSITY}
[[fixed]]
box = [[-1e-9, -10, -10], [1e-9, 10, 10]]
[loads]
gravity = [0.0, 0.0, {-GRAVITY}]
[solver]
kind = "{kind}"
dt = {1 / 60}
steps = {steps}
linear = "{linear}"
rayleigh = [0.1, 0.01]
backend = "{backend}"
"""


def measure(element, cells, size, law, kind, linear, steps) -> dict:
    scene = Scene.from_string(scene_text(element, cells, size, law, kind, linear, steps))
    t0 = time.perf_counter()
    sim = Simulation(scene, output=False)
    summary = sim.run().to_dict()
    elapsed = time.perf_counter() - t0
    t, it = summary["time"], summary["iterations"]
    newton = max(it["newton"], 1)
    per = steps if kind != "static" else newton
    wall = summary["per_step"]["wall"]
    return {
        "kind": kind, "linear": linear, "law": law, "element": element,
        "elements": summary.get("n_elements"), "free_dofs": summary.get("n_free_dofs"),
        "steps": steps, "newton": it["newton"], "linear_iterations": it["linear"],
        "solver_used": sim.ctx.linear.last,
        "setup_s": t["setup"], "wall_s": elapsed,
        "assembly_per_unit_s": t["assembly"] / per, "solve_per_unit_s": t["linear_solve"] / per,
        "per_unit_s": (t["total"] - t["setup"]) / per,
        # the health monitor's own checks (finite state, balance, displacement, min det F per step)
        "health_per_step_s": t.get("health", 0.0) / steps,
        "health_fraction": t.get("health", 0.0) / max(t["total"] - t["setup"], 1e-12),
        "unit": "step" if kind != "static" else "newton iteration",
        # dynamic runs: the first step also orders the unknowns and factors afresh
        "first_step_s": wall[0] if wall else None,
        "later_steps_s": float(np.mean(wall[1:])) if len(wall) > 1 else None,
    }


def health_overhead(element, cells, size, law, steps=30) -> dict:
    """The health monitor's own time per implicit Euler step against the step (30 steps, direct):
    measured by the monitor in the same run, so machine load hits both alike."""
    scene = Scene.from_string(scene_text(element, cells, size, law, "implicit_euler", "direct", steps))
    summary = Simulation(scene, output=False).run()
    wall = summary.per_step["wall"]
    later = float(np.mean(wall[1:]))
    per = summary.time["health"] / steps
    return {"element": element, "law": law, "elements": summary.n_elements, "steps": steps,
            "later_step_s": later, "health_per_step_s": per, "health_fraction_of_later_step": per / later}


def _best(call, repeats):
    """(best seconds, result of the last call)."""
    best, out = np.inf, None
    for _ in range(max(repeats, 1)):
        t0 = time.perf_counter()
        out = call()
        best = min(best, time.perf_counter() - t0)
    return best, out


def newton_iteration(element, cells, size, law, repeats=NEWTON_REPEATS, solvers=NEWTON_SOLVERS,
                     backend="numba") -> dict:
    """One Newton iteration at rest (u = 0) of the static cantilever: assembly, then each linear solver.

    Times are the best of `repeats`; a solver's first solve (which also orders the
    unknowns for the band Cholesky, once per sparsity pattern) is reported apart.
    The assembly with the other kernel backend is timed too (`assembly_s_by_backend`).
    """
    by_backend = {}
    for other in BACKENDS:
        if other == backend:
            continue
        try:
            m = Model.from_scene(Scene.from_string(scene_text(element, cells, size, law, "static", "auto", 1, other)))
            c = Context(m)
            m.warm_up()
            c.asm.warm_up()
            zero = np.zeros(m.n_dofs)
            by_backend[other] = _best(lambda: c.asm.forces_and_stiffness(zero), repeats)[0]
        except Exception as exc:                  # e.g. no C compiler: report, do not fail the bench
            by_backend[other] = f"unavailable ({exc})"
    model = Model.from_scene(Scene.from_string(scene_text(element, cells, size, law, "static", "auto", 1, backend)))
    ctx = Context(model)
    model.warm_up()
    ctx.asm.warm_up()
    u = np.zeros(model.n_dofs)
    assembly, (f_int, K) = _best(lambda: ctx.asm.forces_and_stiffness(u), repeats)
    by_backend[backend] = assembly
    rhs = f_int + model.f_ext                     # -gradient of the potential
    s = model.solver
    out = {"element": element, "cells": list(cells), "size": list(size), "law": law,
           "elements": sum(len(p) for p in model.parts), "free_dofs": int(model.free_dofs.size),
           "backend": backend, "assembly_s": assembly, "assembly_s_by_backend": by_backend, "solvers": {}}
    ref = None
    for label, method, preconditioner in solvers:
        if method == "pardiso" and not has_pardiso():
            continue
        # reuse=False: every repeat factors afresh (a kept factor would solve the same matrix at once)
        solver = LinearSolver(method, s.cg_tolerance, s.cg_max_iterations, preconditioner, reuse=False)

        def solve():
            return ctx.system.solve(solver, K, rhs)

        first, _ = _best(solve, 1)
        seconds, (x, its) = _best(solve, repeats)
        A = ctx.system._block(K, ctx.system.ff)
        residual = float(np.linalg.norm(A @ x[model.free_dofs] - rhs[model.free_dofs])
                         / np.linalg.norm(rhs[model.free_dofs]))
        if ref is None:
            ref = x
        out["solvers"][label] = {
            "method": method, "preconditioner": preconditioner, "used": solver.last,
            "solve_s": seconds, "first_solve_s": first, "total_s": assembly + seconds,
            "iterations": its, "relative_residual": residual,
            "max_displacement": float(np.abs(x).max()),
            "difference_to_first": float(np.abs(x - ref).max() / max(np.abs(ref).max(), 1e-300)),
        }
    return out


def felupe_newton_iteration(cells, size, repeats=FELUPE_REPEATS) -> dict | None:
    """One FElupe Newton iteration at rest on the same cantilever, or None without FElupe.

    NeoHookeCompressible is the same law (mu/2 (I1 - 3) - mu ln J + lam/2 ln^2 J);
    RegionHexahedron integrates with 2 x 2 x 2 Gauss points (gauss2); the nodes at
    x = 0 are clamped; gravity as a SolidBodyForce.  Timed: stiffness and residual
    assembly, partition and felupe.solve.solve with its default linear solver.
    """
    try:
        import felupe as fem
    except ImportError:
        return None
    mu = E / (2 * (1 + NU))
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    mesh = fem.Cube(a=(0.0, 0.0, 0.0), b=tuple(size), n=tuple(c + 1 for c in cells))
    region = fem.RegionHexahedron(mesh)
    field = fem.FieldContainer([fem.Field(region, dim=3)])
    boundaries = {"clamped": fem.Boundary(field[0], fx=0.0)}
    solid = fem.SolidBody(fem.NeoHookeCompressible(mu=mu, lmbda=lam), field)
    gravity = fem.SolidBodyForce(field, values=[0.0, 0.0, -GRAVITY], scale=DENSITY)
    dof0, dof1 = fem.dof.partition(field, boundaries)
    ext0 = fem.dof.apply(field, boundaries, dof0)
    timings = {"assembly": np.inf, "solve": np.inf, "total": np.inf}
    du = None
    for _ in range(max(repeats, 1)):
        t0 = time.perf_counter()
        K = solid.assemble.matrix(field)
        r = solid.assemble.vector(field) + gravity.assemble.vector(field)
        t1 = time.perf_counter()
        system = fem.solve.partition(field, K, dof1, dof0, r)
        du = fem.solve.solve(*system, ext0=ext0)
        t2 = time.perf_counter()
        timings = {"assembly": min(timings["assembly"], t1 - t0), "solve": min(timings["solve"], t2 - t1),
                   "total": min(timings["total"], t2 - t0)}
    return {"version": fem.__version__, "elements": int(mesh.ncells), "free_dofs": int(len(dof1)),
            "assembly_s": timings["assembly"], "solve_s": timings["solve"], "total_s": timings["total"],
            "max_displacement": float(np.abs(np.asarray(du)).max())}


def compare_newton(case, repeats, felupe_repeats, progress=print) -> dict:
    name, element, cells, size, law = case
    ours = newton_iteration(element, cells, size, law, repeats)
    report = {"body": name, **ours}
    if progress:
        progress(f"{name}: one Newton iteration, {law}, {ours['elements']} {element} elements, "
                 f"{ours['free_dofs']} free dofs; assembly {1e3 * ours['assembly_s']:.1f} ms ({ours['backend']} kernels)")
        for other, seconds in ours["assembly_s_by_backend"].items():
            if other != ours["backend"]:
                text = f"{1e3 * seconds:.1f} ms" if isinstance(seconds, float) else seconds
                progress(f"  assembly with {other} kernels: {text}")
        for label, r in ours["solvers"].items():
            progress(f"  {label:10s} ({r['used']:9s}) solve {1e3 * r['solve_s']:8.1f} ms (first {1e3 * r['first_solve_s']:7.1f}), "
                     f"assembly + solve {1e3 * r['total_s']:8.1f} ms; {r['iterations']} iterations, "
                     f"residual {r['relative_residual']:.1e}")
    felupe = felupe_newton_iteration(cells, size, felupe_repeats) if element == "hexahedron" else None
    report["felupe"] = felupe
    if felupe is None:
        report["felupe_ratio"] = None
        if progress:
            progress("  FElupe comparison skipped: felupe is not installed (pip install tensormass[compare])")
        return report
    best = ours["solvers"]["auto"]
    report["felupe_ratio"] = felupe["total_s"] / best["total_s"]
    report["felupe_ratio_first_solve"] = felupe["total_s"] / (ours["assembly_s"] + best["first_solve_s"])
    report["displacement_ratio"] = felupe["max_displacement"] / best["max_displacement"]
    if progress:
        progress(f"  FElupe {felupe['version']}: {1e3 * felupe['total_s']:.1f} ms (assembly {1e3 * felupe['assembly_s']:.1f} ms, "
                 f"solve {1e3 * felupe['solve_s']:.1f} ms, {felupe['free_dofs']} free dofs); "
                 f"FElupe / ours (auto) = {report['felupe_ratio']:.1f}x "
                 f"({report['felupe_ratio_first_solve']:.1f}x counting the one-off ordering); "
                 f"max |du| FElupe / ours = {report['displacement_ratio']:.6f}")
    return report


def run_steps_bench(quick=False, json_path=None, progress=print, bodies=None, newton=True) -> dict:
    """bodies: names from BODIES / QUICK_BODIES to run (default all); newton: also the FElupe case."""
    table = QUICK_BODIES if quick else BODIES
    results = []
    for body, (element, cells, size) in table.items():
        if bodies is not None and body not in bodies:
            continue
        for law in LAWS:
            for kind, steps in (("implicit_euler", 3), ("static", 1)):
                for linear in LINEAR:
                    r = {"body": body, **measure(element, cells, size, law, kind, linear, steps)}
                    results.append(r)
                    if progress:
                        progress(f"{body:15s} {law:11s} {kind:15s} {linear:6s} {r['elements']:6d} el {r['free_dofs']:6d} dofs: "
                                 f"{1e3 * r['per_unit_s']:8.1f} ms per {r['unit']} (assembly {1e3 * r['assembly_per_unit_s']:.1f} ms, "
                                 f"solve {1e3 * r['solve_per_unit_s']:.1f} ms with {r['solver_used']}; "
                                 f"{r['linear_iterations']} linear iterations; health monitor "
                                 f"{1e3 * r['health_per_step_s']:.2f} ms per step = {100 * r['health_fraction']:.2f} %)"
                                 + (f"; first step {1e3 * r['first_step_s']:.1f} ms, later steps {1e3 * r['later_steps_s']:.1f} ms"
                                    if r["later_steps_s"] is not None else ""))
    report = {"machine": machine_info(), "quick": quick, "results": results, "health": []}
    for body, (element, cells, size) in table.items():
        if element != "tetra" or (bodies is not None and body not in bodies):
            continue
        for law in LAWS:
            h = health_overhead(element, cells, size, law, steps=10 if quick else 30)
            report["health"].append({"body": body, **h})
            if progress:
                progress(f"{body:15s} {law:11s} health monitor: {1e3 * h['health_per_step_s']:.3f} ms per implicit "
                         f"Euler step = {100 * h['health_fraction_of_later_step']:.2f} % of a later step "
                         f"({1e3 * h['later_step_s']:.1f} ms, direct, {h['steps']} steps)")
    if newton:
        case = QUICK_NEWTON_CASE if quick else NEWTON_CASE
        report["newton_iteration"] = compare_newton(
            case, QUICK_NEWTON_REPEATS if quick else NEWTON_REPEATS,
            QUICK_FELUPE_REPEATS if quick else FELUPE_REPEATS, progress)
    if json_path:
        write_json_atomic(json_path, report)
    return report


def cmd_steps(args) -> int:
    run_steps_bench(quick=args.quick, json_path=args.json)
    return 0


def add_steps_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("steps", help="time per implicit Euler step and per Newton iteration "
                                    "(10k tets, 20k hexes; 3072 hexes against FElupe)")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="small bodies (CI smoke test)")
    p.set_defaults(run=cmd_steps)
