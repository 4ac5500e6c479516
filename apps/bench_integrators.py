"""`tensormass bench integrators`: energy kept by each dynamic integrator on one undamped benchmark.

The case: the soft cantilever of the tests (1.2 x 0.2 x 0.2 m, 12 x 2 x 2 hexahedra,
gauss2, neo-Hookean, E = 1 MPa, nu = 0.3, 800 kg/m^3, clamped at x = 0), bent
statically by 5 m/s^2 of gravity (tip ~0.27 m down) and released with the load
removed and rayleigh = [0, 0]: the exact motion keeps its energy for ever.  Every
dynamic integrator runs from that state; reported: the total energy (elastic +
kinetic) at the end over the initial one, the loss per first-mode period (the
period measured from the tip's oscillation in the generalized-alpha rho_inf = 1
run at the smallest dt), the largest deviation over the run, Newton iterations
and wall time.  Implicit schemes run at dt = 10 ms and 1 ms (1000 steps each);
the explicit one at half its stable step at rest, over the 10 ms runs' time.
Then the order of accuracy: end-state errors (relative 2-norm of u and T v) of a
large release (tip 0.84 m) for halved steps against a fine generalized-alpha
reference (ratio 4: second order) and the observed order (least-squares slope).

    tensormass bench integrators [--json FILE] [--quick]
    from tensormass.apps.bench_integrators import run_integrator_bench
"""
from __future__ import annotations

import time

import numpy as np

from ..runtime.assembly.assembly import assemble
from ..runtime.physics.newton import Context
from ..runtime.physics.integrators import stable_time_step
from ..runtime.model.model import Model
from ..runtime.base.files import write_json_atomic
from ..runtime.scene.types import Fixed, Loads, Material, MeshSpec, Output, Probe, Solver
from ..runtime.scene.scene import Scene
from ..runtime.run.simulation import Simulation
from .machine import machine_info

SIZE = (1.2, 0.2, 0.2)
CELLS, QUICK_CELLS = (12, 2, 2), (6, 1, 1)
LAW = "neohookean"
BEND_GRAVITY = 5.0
STEPS, QUICK_STEPS = 1000, 200
DTS = (0.01, 0.001)
# (label, solver kind, extra solver keys)
RUNS = (("implicit_euler", "implicit_euler", {}),
        ("backward_euler", "backward_euler", {}),
        ("generalized_alpha rho_inf=1", "generalized_alpha", {"rho_inf": 1.0}),
        ("generalized_alpha rho_inf=0.5", "generalized_alpha", {"rho_inf": 0.5}),
        ("generalized_alpha rho_inf=0", "generalized_alpha", {"rho_inf": 0.0}))


def _scene(cells, gravity, every=1, **solver) -> Scene:
    return Scene(name="released cantilever", output=Output(every=every),
                 mesh=MeshSpec(generate="bar", size=SIZE, cells=cells, element="hexahedron"),
                 materials=[Material(law=LAW, quadrature="gauss2", E=1e6, nu=0.3, density=800.0)],
                 fixed=[Fixed(box=((-1, -1, -1), (0, 1, 1)))], loads=Loads(gravity=(0.0, 0.0, -gravity)),
                 solver=Solver(**solver), probes=[Probe("tip", (SIZE[0], SIZE[1] / 2, SIZE[2] / 2))])


class _TipRecorder:
    """A writer that keeps the vertical displacement of one node at every frame."""

    def __init__(self, node: int):
        self.node, self.t, self.z = node, [], []

    def write_frame(self, step, t, points, displacement, fields, **extra):
        self.t.append(t)
        self.z.append(float(displacement[self.node, 2]))

    def close(self):
        pass


def _period(t, z) -> float | None:
    """Mean time between upward crossings of the signal's mean (None: fewer than two crossings)."""
    t, z = np.asarray(t), np.asarray(z) - np.mean(z)
    up = np.nonzero((z[:-1] < 0) & (z[1:] >= 0))[0]
    if up.size < 2:
        return None
    crossings = t[up] - z[up] * (t[up + 1] - t[up]) / (z[up + 1] - z[up])
    return float(np.mean(np.diff(crossings)))


def _run(cells, u0, E0, tip_node, label, kind, dt, steps, extra, every=1) -> dict:
    model = Model.from_scene(_scene(cells, 0.0, every, kind=kind, dt=dt, steps=steps, rayleigh=(0.0, 0.0), **extra))
    recorder = _TipRecorder(tip_node)
    start = time.perf_counter()
    summary = Simulation(model, u0=u0, writer=recorder).run()
    wall = time.perf_counter() - start
    W = np.array([np.nan if w is None else w for w in summary.per_step["elastic"]])
    total = (W + np.array(summary.per_step["kinetic"])) / E0
    known = total[np.isfinite(total)]
    return {"label": label, "kind": kind, "dt": dt, "steps": steps, "time": dt * steps, **extra,
            "final_energy_ratio": float(total[-1]), "loss": float(1.0 - total[-1]),
            "max_deviation": float(np.abs(known - 1.0).max()),
            "newton_iterations": summary.iterations["newton"], "wall_s": wall, "status": summary.status,
            "_tip": (recorder.t, recorder.z)}


# Order of accuracy: a large release (6 x 1 x 1 hexahedra, bent by 30 m/s^2, tip 0.84 m), 0.4 s without
# load or damping; the end state (u and T v) of each scheme at n steps against generalized-alpha at N_REF
ORDER_CELLS, ORDER_GRAVITY, ORDER_TIME = (6, 1, 1), 30.0, 0.4
ORDER_STEPS, QUICK_ORDER_STEPS = (160, 320, 640, 1280), (20, 40)
ORDER_REF, QUICK_ORDER_REF = 5120, 160
ORDER_RUNS = (("generalized_alpha rho_inf=1", "generalized_alpha", {"rho_inf": 1.0}),
              ("generalized_alpha rho_inf=0.5", "generalized_alpha", {"rho_inf": 0.5}),
              ("backward_euler", "backward_euler", {}),
              ("implicit_euler", "implicit_euler", {}))


def _end_state(u0, kind, n, extra) -> np.ndarray:
    sim = Simulation(_scene(ORDER_CELLS, 0.0, kind=kind, steps=n, dt=ORDER_TIME / n, rayleigh=(0.0, 0.0),
                            newton_tolerance=1e-12, **extra), u0=u0)
    sim.run()
    return np.concatenate([sim.displacement.ravel(), ORDER_TIME * sim.velocity.ravel()])


def run_order_study(quick: bool = False, progress=print) -> dict:
    """Errors at the end of the large release for halved steps, and their ratios (4: second order)."""
    bent = Simulation(_scene(ORDER_CELLS, ORDER_GRAVITY))
    bent.run()
    u0 = bent.displacement
    n_ref = QUICK_ORDER_REF if quick else ORDER_REF
    ref = _end_state(u0, "generalized_alpha", n_ref, {"rho_inf": 1.0})
    rows = []
    for label, kind, extra in ORDER_RUNS:
        steps = QUICK_ORDER_STEPS if quick else ORDER_STEPS
        errors = [float(np.linalg.norm(_end_state(u0, kind, n, extra) - ref) / np.linalg.norm(ref)) for n in steps]
        ratios = [a / b for a, b in zip(errors, errors[1:])]
        # observed order: least-squares slope of log(error) against log(dt)
        order = float(np.polyfit(np.log(ORDER_TIME / np.array(steps)), np.log(errors), 1)[0])
        rows.append({"label": label, "kind": kind, **extra, "errors": errors, "ratios": ratios,
                     "observed_order": order})
        if progress:
            progress(f"order {label:30s} relative error of (u, T v) at {ORDER_TIME} s for {steps} steps: "
                     + ", ".join(f"{e:.3g}" for e in errors) + "; ratios " + ", ".join(f"{r:.2f}" for r in ratios)
                     + f"; observed order {order:.2f}")
    return {"cells": ORDER_CELLS, "bend_gravity": ORDER_GRAVITY, "tip_deflection": float(-u0[:, 2].min()),
            "time": ORDER_TIME, "steps": QUICK_ORDER_STEPS if quick else ORDER_STEPS, "reference_steps": n_ref,
            "law": LAW, "results": rows}


def run_integrator_bench(quick: bool = False, json_path=None, progress=print) -> dict:
    cells = QUICK_CELLS if quick else CELLS
    steps = QUICK_STEPS if quick else STEPS
    bent = Simulation(_scene(cells, BEND_GRAVITY))
    bent.run()
    u0 = bent.displacement
    probe = _scene(cells, 0.0)
    model = Model.from_scene(probe)
    tip_node = int(np.argmin(np.linalg.norm(model.mesh.points - np.array(probe.probes[0].point), axis=1)))
    E0 = float(assemble(model, u0.ravel())[0])
    results = []
    for dt in DTS:
        for label, kind, extra in RUNS:
            results.append(_run(cells, u0, E0, tip_node, label, kind, dt, steps, extra))
    # the explicit scheme at half its stable step, over the time of the largest-dt runs
    explicit_model = Model.from_scene(_scene(cells, 0.0, kind="explicit"))
    stable = stable_time_step(Context(explicit_model))
    dt_explicit = 0.5 * stable
    n_explicit = int(np.ceil(DTS[0] * steps / dt_explicit))
    results.append(_run(cells, u0, E0, tip_node, "explicit (half the stable step)", "explicit", dt_explicit,
                        n_explicit, {}, every=10))
    # the first bending period, from the conserving scheme at the smallest dt (resolved best)
    reference = next(r for r in results if r["kind"] == "generalized_alpha" and r.get("rho_inf") == 1.0
                     and r["dt"] == DTS[-1])
    period = _period(*reference["_tip"])
    longest = next(r for r in results if r["kind"] == "generalized_alpha" and r.get("rho_inf") == 1.0
                   and r["dt"] == DTS[0])
    period_long = _period(*longest["_tip"])
    period = period if period is not None else period_long
    for r in results:
        r.pop("_tip")
        r["periods"] = r["time"] / period if period else None
        r["steps_per_period"] = period / r["dt"] if period else None
        ratio = max(r["final_energy_ratio"], 0.0)
        r["loss_per_period"] = (1.0 - ratio ** (1.0 / r["periods"])) if period else None
    report = {"machine": machine_info(), "quick": quick,
              "case": {"body": "cantilever", "size": SIZE, "cells": cells, "element": "hexahedron", "law": LAW,
                       "E": 1e6, "nu": 0.3, "density": 800.0, "bend_gravity": BEND_GRAVITY,
                       "tip_deflection": float(-u0[tip_node, 2]), "initial_energy": E0,
                       "first_period": period, "stable_dt_explicit": stable},
              "results": results}
    if progress:
        progress(f"{report['case']['body']}: {LAW}, {cells} hexahedra, released from a tip deflection of "
                 f"{report['case']['tip_deflection']:.3f} m, energy {E0:.4g} J, first period "
                 + (f"{period:.4f} s" if period else "not measured (run too short)") + ", rayleigh = [0, 0]")
        for r in results:
            periods = "period unknown" if r["periods"] is None else f"{r['periods']:.2f} periods"
            per = "" if r["loss_per_period"] is None else f" ({100 * r['loss_per_period']:7.3f} % per period)"
            progress(f"{r['label']:32s} dt {r['dt']:.3g} s x {r['steps']:5d} ({periods}): "
                     f"energy lost {100 * r['loss']:7.3f} %{per}, "
                     f"max deviation {100 * r['max_deviation']:7.3f} %, Newton {r['newton_iterations']:5d}, "
                     f"{r['wall_s']:.1f} s, {r['status']}")
    report["order"] = run_order_study(quick, progress)
    if json_path:
        write_json_atomic(json_path, report)
    return report


def cmd_integrators(args) -> int:
    run_integrator_bench(quick=args.quick, json_path=args.json)
    return 0


def add_integrators_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("integrators", help="energy lost per period by each dynamic integrator "
                                    "(released neo-Hookean cantilever, no damping)")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="a coarse body and 100 steps (CI smoke test)")
    p.set_defaults(run=cmd_integrators)
