"""`tensormass report accuracy --benchmark dynamics`: error against time per step of dynamic runs.

The organ of `bench organ` (neo-Hookean, E 5 kPa, nu 0.45, clamped underneath) starts at rest and
falls under gravity and a 400 Pa traction on its top patch, for DURATION seconds.  Each setting runs
the same scene through the public API (Scene, Simulation.run); what it is measured by:

  step_ms_mean, step_ms_p95   wall time per step after the first, health checks and energies included
                              (between two on_step calls), mean and 95th percentile: a
                              refactorisation the mean hides shows in the percentile;
  error_reference             the top pole's displacement against the reference run, the largest
                              difference over time over the reference's largest displacement;
  error_exact_step            the same against the exact step of the same integrator and dt: what
                              the linear settings cost, apart from the time step's own error;
  error_energy                elastic + kinetic energy against the reference's, the largest
                              difference over time over the reference's largest.

The reference is implicit Euler at dt / 4 with every step exact and its factor refined to 1e-12.  It
measures the time-discretisation error of the implicit Euler rows; it is first order and damped itself,
so the explicit and generalized-alpha rows differ from it by its own error too (their error_reference
is an upper bound of theirs against the true motion, not a fair ranking of integrators).

Meshes: full, the tetra organ (h = 6 mm) and the tetra10 organ (h = 8 mm) of `bench organ`, made by
gmsh into the user cache; quick (and without gmsh), the small tetra organ committed beside this module
(organ_quick.msh: the same shape at scale 1, h = 9 mm, 821 tetrahedra).
"""
from __future__ import annotations

import functools
import math
import time
from pathlib import Path

import numpy as np

from ...runtime.base.errors import TensormassError
from ...runtime.scene.scene import Scene
from .common import result_row

__all__ = ["dynamics", "plot", "SETTINGS", "DYNAMICS_COLUMNS", "trajectory_error"]

QUICK_MESH = Path(__file__).resolve().with_name("organ_quick.msh")
DT = 0.01
DURATION, QUICK_DURATION = 1.0, 0.2
REFERENCE_REFINEMENT = 4                 # the reference's dt is DT / this
# the extra columns of results.csv on dynamics rows (accuracy.py appends them when present)
DYNAMICS_COLUMNS = ["setting", "dt", "step_ms_mean", "step_ms_p95", "error_exact_step", "error_energy",
                    "stiffness_refreshes", "error_estimate"]

# (label, [solver] keys, dt over DT, the exact row it is compared with for error_exact_step)
SETTINGS = (
    ("exact", {}, 1.0, None),
    ("interactive", {"mode": "interactive"}, 1.0, "exact"),
    ("K kept 10 steps", {"stiffness_every": 10, "stiffness_tolerance": math.inf, "factor_tolerance": 1e-4}, 1.0, "exact"),
    ("K kept the whole run", {"stiffness_every": 10 ** 8, "stiffness_tolerance": math.inf, "factor_tolerance": 1e-4},
     1.0, "exact"),
    ("20 CG-IC iterations (the thesis)", {"linear": "cg", "cg_max_iterations": 20}, 1.0, "exact"),
    ("CG-IC to 1e-3", {"linear": "cg", "cg_tolerance": 1e-3}, 1.0, "exact"),
    ("exact, dt / 2", {}, 0.5, None),
    ("interactive, dt / 2", {"mode": "interactive"}, 0.5, "exact, dt / 2"),
    ("generalized-alpha", {"kind": "generalized_alpha"}, 1.0, None),
    ("explicit at 0.9 x its stable step", {"kind": "explicit"}, None, None),
)
QUICK_SETTINGS = ("exact", "interactive", "K kept 10 steps", "20 CG-IC iterations (the thesis)")
# left out on the tetra10 organ (34 434 dofs), where each would take minutes: generalized-alpha takes 3 to 15
# Newton iterations per step on the organs, each with a new factor (docs/limitations.md)
TETRA_ONLY = ("exact, dt / 2", "interactive, dt / 2", "generalized-alpha")


def _meshes(quick, progress) -> list:
    """[(label, element, quadrature, mesh file)]: the organ meshes this run uses."""
    quick_mesh = ("tetra organ x1 h9 mm", "tetra", "gauss1", QUICK_MESH)
    if quick:
        return [quick_mesh]
    from .. import bench_organ
    try:
        bench_organ.require_gmsh()
    except bench_organ.GmshMissing as why:
        progress(f"dynamics: {why}; the small committed organ instead")
        return [quick_mesh]
    out = []
    for element, size in (("tetra", 0.006), ("tetra10", 0.008)):
        case = bench_organ.Case(f"dynamics_{element}", "organ", element, "implicit_euler", 1, size=size)
        path, _ = bench_organ.organ_mesh(case)
        out.append((f"{element} organ x{case.scale:g} h{1e3 * size:g} mm", element,
                    "gauss2" if element == "tetra10" else "gauss1", path))
    return out


def scene_text(mesh_file, quadrature, solver: dict, dt: float, steps: int) -> str:
    """The organ under gravity and traction (bench organ's scene), with these [solver] keys."""
    from ..bench_organ import organ_text
    text = organ_text("dynamics", mesh_file, quadrature, {"kind": "implicit_euler", **solver, "dt": dt, "steps": steps})
    return text + f"""[[probe]]
name = "pole"
point = {list(_pole(mesh_file))}
"""


@functools.lru_cache(maxsize=8)
def _pole(mesh_file) -> tuple:
    """The organ's top pole (the highest mesh point, on the axis): where the probe reads (read once
    per mesh file: every setting's scene asks)."""
    import meshio
    z = float(np.asarray(meshio.read(mesh_file).points)[:, 2].max())
    return (0.0, 0.0, z)


def _run(text) -> dict:
    """One run: its summary, its trajectory (times, pole displacement, elastic + kinetic energy) and the
    wall time of each step after the first, from the end of one step's bookkeeping (health checks,
    energies, history) to the end of the next's: what a loop stepping the scene waits for."""
    from ...runtime.run.simulation import Simulation
    ends = []
    sim = Simulation(Scene.from_string(text), output=False, on_step=lambda _: ends.append(time.perf_counter()))
    summary, peak = sim.run(), float("nan")
    if summary.status not in ("ok", "warnings"):
        raise TensormassError(f"dynamics: a run ended {summary.status}: {summary.message}")
    ps = summary.per_step
    t = np.concatenate([[0.0], np.asarray(ps["time"], dtype=float)])
    pole = np.vstack([np.zeros(3), np.asarray(ps["probes"]["pole"], dtype=float)])
    energy = [(e or 0.0) + (k or 0.0) for e, k in zip(ps["elastic"], ps["kinetic"])]
    energy = np.concatenate([[0.0], np.asarray(energy, dtype=float)])
    known = np.array([True] + [e is not None for e in ps["elastic"]])
    wall = np.diff(ends) if len(ends) > 1 else np.asarray(ps["wall"], dtype=float)
    return {"summary": summary, "peak": peak, "t": t, "pole": pole, "energy": energy, "energy_known": known,
            "wall": wall, "sim": sim}


def trajectory_error(run: dict, reference: dict) -> tuple[float, float]:
    """(displacement error, energy error) of a run against a reference, both relative to the reference's
    largest value; the reference is interpolated linearly in time at the run's sample times."""
    t = run["t"]
    ref = np.column_stack([np.interp(t, reference["t"], reference["pole"][:, i]) for i in range(3)])
    scale = float(np.linalg.norm(reference["pole"], axis=1).max())
    du = float(np.linalg.norm(run["pole"] - ref, axis=1).max()) / scale if scale > 0 else float("nan")
    known = run["energy_known"]
    e_ref = np.interp(t[known], reference["t"], reference["energy"])
    e_scale = float(np.abs(reference["energy"]).max())
    de = float(np.abs(run["energy"][known] - e_ref).max()) / e_scale if e_scale > 0 else float("nan")
    return du, de


def _stable_dt(mesh_file, quadrature) -> float:
    """The explicit row's dt: 0.9 x the stable step the runtime estimates for the scene."""
    from ...runtime.run.simulation import Simulation
    # one step far below any stable step: the estimate is made before it (runtime.run.simulation)
    sim = Simulation(Scene.from_string(scene_text(mesh_file, quadrature, {"kind": "explicit"}, 1e-9, 1)), output=False)
    sim.run()
    if not (sim.stable_dt and math.isfinite(sim.stable_dt)):
        raise TensormassError("dynamics: no stable step estimate for the explicit row")
    return 0.9 * float(sim.stable_dt)


def dynamics(quick, progress, sweep=None) -> dict:
    """The benchmark (see the module docstring); sweep (tests): {"settings": labels, "duration": s}."""
    sweep = sweep or {}
    duration = float(sweep.get("duration", QUICK_DURATION if quick else DURATION))
    wanted = sweep.get("settings", QUICK_SETTINGS if quick else [s[0] for s in SETTINGS])
    rows, notes, table = [], [], []
    for label, element, quadrature, mesh in _meshes(quick, progress):
        settings = [s for s in SETTINGS if s[0] in wanted and (element == "tetra" or s[0] not in TETRA_ONLY)]
        left = [s[0] for s in SETTINGS if s[0] in wanted and s not in settings]
        if left:
            notes.append(f"- {label}: {', '.join(left)} left out (minutes each at this size)")
        progress(f"dynamics: {label}: the reference (implicit Euler, dt = {1e3 * DT / REFERENCE_REFINEMENT:g} ms)")
        # every setting's kernels and caches are loaded by the reference first: no compile time in a row
        ref_dt = DT / REFERENCE_REFINEMENT
        reference = _run(scene_text(mesh, quadrature, {"factor_tolerance": 1e-12}, ref_dt,
                                    _steps(duration, ref_dt)))
        done = {}
        for name, solver, factor, exact in settings:
            dt = _stable_dt(mesh, quadrature) if factor is None else DT * factor
            progress(f"dynamics: {label}: {name} (dt = {1e3 * dt:.3g} ms)")
            run = done[name] = _run(scene_text(mesh, quadrature, solver, dt, _steps(duration, dt)))
            err, energy = trajectory_error(run, reference)
            solver_err = trajectory_error(run, done[exact])[0] if exact in done else float("nan")
            rows.append(_row(label, element, quadrature, name, dt, run, err, energy, solver_err))
        table += _table(label, rows[-len(settings):])
    notes += ["", "Dynamics (time per step after the first, health checks and energies included; speed-up: "
                  "wall time per simulated second against the exact step at dt = 10 ms; errors of the top pole's "
                  "trajectory, the largest difference over time over the reference's largest displacement; the "
                  "energy error on the steps whose energy was evaluated, every 10th for the budgeted step):",
              ""] + table
    return {"rows": rows,
            "reference": {"subject": f"the organ's top pole over {duration:g} s of falling under gravity and traction",
                          "numerical": f"implicit Euler at dt = {1e3 * DT / REFERENCE_REFINEMENT:g} ms, every step "
                                       "exact (factor refined to 1e-12)",
                          "analytic": "none"},
            "compile_s": {}, "notes": notes}


def _steps(duration, dt) -> int:
    return max(1, int(round(duration / dt)))


def _row(label, element, quadrature, name, dt, run, err, energy, solver_err) -> dict:
    summary = run["summary"]
    row = result_row(element, "neohookean", quadrature, (0,), summary, run["peak"],
                     float(np.linalg.norm(run["pole"], axis=1).max()), benchmark="dynamics", case=name)
    budget = summary.iterations.get("budget") or {}
    row.update(cells=label, error_reference=err, setting=name, dt=dt,
               step_ms_mean=1e3 * float(run["wall"].mean()), step_ms_p95=1e3 * float(np.percentile(run["wall"], 95)),
               error_exact_step=solver_err, error_energy=energy,
               stiffness_refreshes=budget.get("refreshes", ""), error_estimate=budget.get("error_estimate", ""))
    return row


def _table(label, rows) -> list:
    exact = next((r for r in rows if r["setting"] == "exact"), None)
    base = exact["step_ms_mean"] / exact["dt"] if exact else float("nan")        # ms per simulated second
    out = [f"{label}:", "", "| setting | dt (ms) | ms per step (mean / p95) | speed-up over exact | error vs reference | "
           "error vs exact step | its estimate | energy error | K refreshes |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['setting']} | {1e3 * r['dt']:.3g} | {r['step_ms_mean']:.1f} / {r['step_ms_p95']:.1f} | "
                   f"{base / (r['step_ms_mean'] / r['dt']):.2f}x | {_pct(r['error_reference'])} | {_pct(r['error_exact_step'])} | "
                   f"{_pct(r['error_estimate'])} | {_pct(r['error_energy'])} | {r['stiffness_refreshes']} |")
    return out + [""]


def _pct(x) -> str:
    return "-" if not isinstance(x, float) or math.isnan(x) else f"{100 * x:.3g} %"


def plot(rows) -> bytes:
    """dynamics.png: per organ, each setting's error against the exact step (left) and against the
    reference (right) over its wall time per simulated second, the points named."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    meshes = list(dict.fromkeys(r["cells"] for r in rows))
    fig = Figure(figsize=(13, 4.8 * len(meshes)))
    FigureCanvasAgg(fig)
    for m, mesh in enumerate(meshes):
        sub = [r for r in rows if r["cells"] == mesh]
        for c, (key, what) in enumerate((("error_exact_step", "error against the exact step at the same dt"),
                                         ("error_reference", "error against the reference (dt / 4)"))):
            ax = fig.add_subplot(len(meshes), 2, 2 * m + c + 1)
            for r in sub:
                x, y = r["step_ms_mean"] / r["dt"] / 1e3, r[key]
                if isinstance(y, float) and math.isfinite(y) and y > 0:
                    ax.scatter([x], [y], s=30)
                    ax.annotate(r["setting"], (x, y), fontsize=7, xytext=(4, 3), textcoords="offset points")
            exact = next((r for r in sub if r["setting"] == "exact"), None)
            if exact is not None:          # the time of the exact step at dt = DT, for scale
                ax.axvline(exact["step_ms_mean"] / exact["dt"] / 1e3, color="grey", ls="--", lw=1, label="exact step")
                ax.legend(fontsize=7, loc="lower right")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("wall time per simulated second [s]")
            ax.set_ylabel(what)
            ax.set_title(mesh, fontsize=10)
            ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    import io
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return buf.getvalue()
