"""`tensormass bench contact`: what IPC contact costs per Newton iteration and per step, on an organ pressed by a tool.

    tensormass bench contact [--quick] [--json FILE] [--repeats N]

The scene: the organ of examples/organ (organ.msh, tetra10, neo-Hookean gauss2, E 5 kPa, nu 0.45,
clamped underneath, under gravity), static, with a capsule tool tip standing on its top pole and
pressed into it by a translation, so that the barrier acts on a small patch of the surface (the
active share: surface vertices the contact pushes, over all surface vertices).  Sizes follow the
body's bounding-box diagonal D: tip radius 0.04 D, start gap 0.005 D, press 0.03 D.  --quick: a
small tetrahedral bar (hooke, gauss1) instead of the organ (a CI smoke test).

1. One Newton iteration, with and without contact, on the same model at the same pressed state
   (the end of the contact run): the pieces Newton calls, each timed with time.perf_counter, best
   of --repeats:
   - assembly: internal forces and stiffness (asm.forces, asm.stiffness);
   - linear solve: the Newton matrix alone, and with the contact Hessian added (extra=), each
     factorised anew (the matrix changes from one iteration to the next, and the runs' solves,
     printed by kind, are mostly new factorisations);
   - trial energy: the elastic energy at the line search's trial point;
   - contact: the barrier's gradient and PSD-projected Hessian on the iteration's collisions; the
     line search's broad phase and CCD (contact.max_step: boxes swept from the state to the trial
     point, inflated by the barrier's reach, then the narrow-phase CCD on those candidates), of
     which the broad phase alone is also reported; the trial state's collisions (the narrow
     phase's distance filter on the same candidates) and its barrier energy.
   The direction is the first Newton direction of one more load step (the external load's share
   of one step), as the next step would take.  One broad phase serves the whole iteration: the
   line search's trial states lie on the swept path, and the next iteration's gradient and
   Hessian reuse the accepted trial's collisions.
   Ratios: the iteration with contact over the one without; broad phase + CCD over the iteration with
   contact.  Targets (issue 32): at most 1.5x, and at most 20 %.
2. Whole steps through the public API (Scene, Simulation.run, output off): the contact scene, and
   a baseline without contact where the tool is a glued [[fixed]] group: the surface vertices the
   contact run left touching, their z displacement prescribed to its mean at the end of the
   contact run (the same indentation, no contact).  Reported: ms per step after the first (the
   first pays the symbolic analysis), Newton iterations.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..runtime.base.errors import TensormassError
from ..runtime.base.files import write_json_atomic
from ..runtime.run.simulation import Simulation
from ..runtime.scene.scene import Scene
from .machine import machine_info

__all__ = ["run_contact_bench", "add_contact_command", "TARGET_RATIO", "TARGET_SHARE"]

TARGET_RATIO = 1.5         # issue 32: a Newton iteration with contact at most 1.5x one without
TARGET_SHARE = 0.20        # issue 32: broad phase + CCD at most 20 % of the iteration
STEPS = 6
ORGAN = Path(__file__).resolve().parents[1] / "examples" / "organ" / "organ.msh"


def _case(quick: bool) -> dict:
    """The body's TOML (mesh, material, clamp, gravity) and its bounding box."""
    if quick:
        lo, hi = np.zeros(3), np.array([0.06, 0.06, 0.03])
        body = (f'[mesh]\ngenerate = "bar"\nsize = {hi.tolist()}\ncells = [6, 6, 3]\nelement = "tetra"\n'
                '[[material]]\nlaw = "hooke"\nquadrature = "gauss1"\nE = 5.0e3\nnu = 0.45\ndensity = 1050.0\n'
                '[[fixed]]\nbox = [[-1, -1, -1e-9], [1, 1, 1e-9]]\nname = "attached"\n')
        return {"name": "bar tetra (quick)", "body": body, "lo": lo, "hi": hi}
    if not ORGAN.is_file():
        raise TensormassError(f"bench contact: the organ mesh {ORGAN} is missing (examples/organ/organ.msh)")
    body = (f'[mesh]\nfile = "{ORGAN.as_posix()}"\n'
            '[[material]]\nregion = "organ"\nlaw = "neohookean"\nquadrature = "gauss2"\nE = 5.0e3\nnu = 0.45\n'
            'density = 1050.0\n[[fixed]]\nregion = "attached"\nname = "attached"\n')
    return {"name": "organ tetra10 (examples/organ)", "body": body,
            "lo": np.array([-0.04, -0.03, 0.0]), "hi": np.array([0.04, 0.03, 0.03])}


def _tool(case: dict) -> dict:
    D = float(np.linalg.norm(case["hi"] - case["lo"]))
    r, gap, press = 0.04 * D, 0.005 * D, 0.03 * D
    centre = 0.5 * (case["lo"] + case["hi"])
    tip = [float(centre[0]), float(centre[1]), float(case["hi"][2] + r + gap)]
    return {"radius": r, "gap": gap, "press": press, "a": tip, "b": [tip[0], tip[1], tip[2] + 4 * r]}


def _scene(case: dict, tool: dict | None, glued: str = "") -> str:
    text = f'name = "bench_contact"\n{case["body"]}{glued}[loads]\ngravity = [0.0, 0.0, -9.81]\n' \
           f'[solver]\nkind = "static"\nsteps = {STEPS}\n'
    if tool is not None:
        text += (f'[contact]\nmethod = "ipc"\n[[obstacle]]\nname = "tool"\nshape = "capsule"\n'
                 f'a = {tool["a"]}\nb = {tool["b"]}\nradius = {tool["radius"]!r}\n'
                 f'translation = [0.0, 0.0, {-(tool["gap"] + tool["press"])!r}]\n')
    return text


def _best(fn, repeats: int) -> float:
    """Seconds of fn(), the best of repeats (a noisy neighbour only ever adds time)."""
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def _run(text: str):
    sim = Simulation(Scene.from_string(text, source="bench_contact"), output=False)
    start = time.perf_counter()
    summary = sim.run()
    total = time.perf_counter() - start
    if summary.status != "ok":
        raise TensormassError(f"bench contact: the scene ended {summary.status!r}: {summary.message}")
    wall = np.asarray(summary.per_step["wall"]) * 1e3
    return sim, summary, {"status": summary.status, "run_s": total, "steps_s": 1e-3 * float(wall.sum()),
                          "first_step_ms": float(wall[0]),
                          "step_ms": float(np.mean(wall[1:])), "steps": len(wall),
                          "newton_iterations": int(sim.ctx.newton_iterations), "solves": dict(sim.ctx.linear.counts)}


def _iteration(sim, repeats: int, broad_rate: float) -> dict:
    """The pieces of one Newton iteration at the run's end state, with and without contact (ms)."""
    ctx, model, contact = sim.ctx, sim.model, sim.model.contact
    asm, ipc = ctx.asm, contact.ipc
    u = ctx.u.copy()
    contact.set_pose(1.0)
    contact.target = None                  # the obstacles rest at their end pose: no move within Newton
    fixed = model.fixed_dofs
    zero_c = np.zeros(len(fixed))
    project = bool(ctx.project)
    # the next load step's first direction: K d = (its share of the external load) - residual
    f1 = sim.integrator.external_force(1.0)
    df = f1 / STEPS
    g = contact.gradient(u) - asm.forces(u) - f1
    data = asm.stiffness(u, project)
    H = contact.hessian(u, True)
    d = ctx.solve(data, df - g, zero_c, extra=H)
    trial = u + d
    V, Vt = contact.vertices(u), contact.vertices(trial)
    active = np.any(contact.gradient(u)[contact.dofs].reshape(-1, 3) != 0.0, axis=1)

    cache = contact.candidates
    candidates = cache.along(V, Vt)        # the line search's candidates (swept or near: see below)

    def broad():                           # one broad phase: boxes swept from the state to the trial point
        c = ipc.Candidates()
        c.build(contact.mesh, V, Vt, cache.swept_reach, broad_phase=contact.broad)

    def ccd():                             # the narrow-phase CCD on the line search's candidates
        candidates.compute_collision_free_stepsize(contact.mesh, V, Vt, min_distance=contact.dmin,
                                                   narrow_phase_ccd=contact.ccd)

    def trial_collisions():                # the distance filter at the trial state, same candidates
        contact._cache = None
        contact.collisions(Vt)

    def fresh_solve(extra):                # a new factorisation: Newton's matrix changes between iterations
        ctx.linear._factor = None          # (the run's solves by kind are printed: most factor anew)
        ctx.solve(data, df - g, zero_c, extra=extra)

    def barrier():
        contact.collisions(V)              # cached: the accepted trial's collisions
        contact.gradient(u)
        contact.hessian(u, True)

    contact.collisions(V)
    ms = {
        "assembly": _best(lambda: (asm.forces(u), asm.stiffness(u, project)), repeats),
        "solve": _best(lambda: fresh_solve(None), repeats),
        "solve_with_contact": _best(lambda: fresh_solve(H), repeats),
        "trial_energy": _best(lambda: asm.energy(trial), repeats),
        "broad_phase": _best(broad, repeats),
        "ccd": _best(ccd, repeats),
        "trial_collisions": _best(trial_collisions, repeats),
        "barrier_gradient_hessian": _best(barrier, repeats),
    }
    contact.collisions(Vt)
    ms["contact_trial_energy"] = _best(lambda: contact.energy(trial), repeats)
    ms = {k: 1e3 * v for k, v in ms.items()}
    without = ms["assembly"] + ms["solve"] + ms["trial_energy"]
    rest = ms["solve_with_contact"] - ms["solve"] + ms["barrier_gradient_hessian"] + ms["ccd"] + \
        ms["trial_collisions"] + ms["contact_trial_energy"]
    rate = broad_rate                      # broad phases per Newton iteration, as the run built them
    with_ = without + rest + rate * ms["broad_phase"]
    worst = without + rest + ms["broad_phase"]
    return {"ms": ms, "iteration_ms_without": without, "iteration_ms_with": with_, "ratio": with_ / without,
            "broad_phases_per_iteration": rate, "iteration_ms_with_broad_phase": worst, "ratio_with_broad_phase": worst / without,
            "broad_phase_ccd_share": (rate * ms["broad_phase"] + ms["ccd"]) / with_,
            "surface_vertices": int(contact.surface.size), "active_vertices": int(active.sum()),
            "active_share": float(active.mean()), "pairs": int(len(contact.collisions(V))),
            "ccd_step": float(contact.max_step(u, d)), "dofs": int(model.n_dofs), "cells": int(model.mesh.n_cells)}


def _glued(sim, summary) -> tuple:
    """A [[fixed]] group in place of the tool: the vertices the contact left touching, their z
    displacement prescribed to its mean at the end of the contact run."""
    contact, u = sim.model.contact, sim.ctx.u
    touched = np.any(contact.gradient(u)[contact.dofs].reshape(-1, 3) != 0.0, axis=1)
    if not touched.any():
        raise TensormassError("bench contact: the tool touches nothing at the end of the run")
    nodes = contact.surface.nodes[touched]
    X = np.asarray(sim.model.mesh.points, dtype=float)[nodes]
    uz = float(u.reshape(-1, sim.model.dofs_per_node)[nodes, 2].mean())
    lo, hi = X.min(axis=0) - 1e-9, X.max(axis=0) + 1e-9
    text = (f'[[fixed]]\nname = "tool"\nbox = [{lo.tolist()}, {hi.tolist()}]\ncomponents = [2]\n'
            f'displacement = [0.0, 0.0, {uz!r}]\n')
    return text, {"glued_nodes_in_box": int(len(nodes)), "glued_uz_m": uz}


def run_contact_bench(quick=False, json_path=None, repeats=None, progress=print) -> dict:
    t0 = time.perf_counter()
    repeats = repeats or (3 if quick else 20)
    case = _case(quick)
    tool = _tool(case)
    sim, summary, with_run = _run(_scene(case, tool))
    cache = sim.model.contact.candidates
    builds = cache.builds["near"] + cache.builds["swept"]
    with_run.update(broad_phases=dict(cache.builds), broad_phase_s=cache.seconds, ccd_s=sim.model.contact.ccd_seconds,
                    broad_phase_ccd_share=(cache.seconds + sim.model.contact.ccd_seconds) / with_run["steps_s"])
    it = _iteration(sim, repeats, builds / max(with_run["newton_iterations"], 1))
    glued, glue = _glued(sim, summary)
    _, _, without_run = _run(_scene(case, None, glued))
    step_ratio = with_run["step_ms"] / without_run["step_ms"]
    ms = it["ms"]
    progress(f"bench contact: {case['name']}, {it['cells']} cells, {it['dofs']} dofs; capsule tip r = "
             f"{1e3 * tool['radius']:.1f} mm pressed {1e3 * tool['press']:.1f} mm; best of {repeats}")
    progress(f"  active: {it['active_vertices']} of {it['surface_vertices']} surface vertices "
             f"({100 * it['active_share']:.1f} %), {it['pairs']} pairs, CCD step {it['ccd_step']:.3f}")
    progress("  one Newton iteration (ms)          without    with")
    rows = (("assembly (forces + stiffness)", ms["assembly"], ms["assembly"]),
            ("linear solve", ms["solve"], ms["solve_with_contact"]),
            ("line search: elastic energy", ms["trial_energy"], ms["trial_energy"]),
            ("barrier gradient + Hessian", None, ms["barrier_gradient_hessian"]),
            ("line search: broad phase", None, ms["broad_phase"]),
            ("line search: CCD (narrow phase)", None, ms["ccd"]),
            ("line search: trial collisions", None, ms["trial_collisions"]),
            ("line search: contact energy", None, ms["contact_trial_energy"]))
    for name, a, b in rows:
        progress(f"    {name:<32}{'' if a is None else f'{a:8.2f}':>8}{b:8.2f}")
    progress(f"    {'iteration, broad phase built':<32}{it['iteration_ms_without']:8.2f}{it['iteration_ms_with_broad_phase']:8.2f}"
             f"   {it['ratio_with_broad_phase']:.2f}x")
    progress(f"    {'iteration, as the run went':<32}{it['iteration_ms_without']:8.2f}{it['iteration_ms_with']:8.2f}"
             f"   {it['ratio']:.2f}x  ({it['broad_phases_per_iteration']:.2f} broad phases per iteration: "
             f"{with_run['broad_phases']['swept']} swept, {with_run['broad_phases']['near']} near, "
             f"{with_run['newton_iterations']} iterations)")
    progress(f"  ratio with / without {it['ratio']:.2f}x (target <= {TARGET_RATIO}x); broad phase + CCD "
             f"{100 * it['broad_phase_ccd_share']:.1f} % of the iteration, "
             f"{100 * with_run['broad_phase_ccd_share']:.1f} % of the run's steps (target <= {100 * TARGET_SHARE:.0f} %)")
    progress(f"  the runs' linear solves by kind: contact {with_run['solves']}, glued tool {without_run['solves']}")
    progress(f"  whole step (static, {STEPS} steps): contact {with_run['step_ms']:.1f} ms/step "
             f"({with_run['newton_iterations']} Newton iterations), glued tool {without_run['step_ms']:.1f} ms/step "
             f"({without_run['newton_iterations']} iterations): {step_ratio:.2f}x")
    report = {"machine": machine_info(), "quick": quick, "case": case["name"], "repeats": repeats,
              "tool": tool, "targets": {"ratio": TARGET_RATIO, "broad_phase_ccd_share": TARGET_SHARE},
              "iteration": it, "step": {"contact": with_run, "glued_tool": without_run, "ratio": step_ratio, **glue},
              "seconds": time.perf_counter() - t0}
    if json_path is not None:
        write_json_atomic(json_path, report)
    return report


def cmd_contact(args) -> int:
    run_contact_bench(quick=args.quick, json_path=args.json, repeats=args.repeats)
    return 0


def add_contact_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("contact", help="IPC contact on the organ pressed by a tool: a Newton "
                                    "iteration's pieces and whole steps, against no contact")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="a small tetrahedral bar instead of the organ (CI smoke test)")
    p.add_argument("--repeats", type=int, default=None, metavar="N", help="timings: best of N (default 20; quick 3)")
    p.set_defaults(run=cmd_contact)
