"""`tensormass report stability`: the stiff and extreme cases of the brief, each with a checked expectation.

    rows = run_stability("out", quick=True)     # writes out/stability.csv and out/report.md

Every case runs on a tiny mesh with few steps and ends in one of five outcomes, classified by
the runtime's own health monitor (runtime/physics/health.py), never by a separate judgement:

    stable               the run finished and the monitor trusts it (status "ok": finite, bounded
                         energy and displacement, no inverted element)
    recovered            the run finished (status "ok" or "warnings": e.g. elements inverted on
                         the way, none at the end) and the body returned close to its rest shape
    invalid (detected)   the run finished, but the monitor rejects its final state (inverted
                         elements): exit code 3 on the command line
    diverged (detected)  the runtime stopped the run (monitor: blow-up; or a failed step)
    refused (reason)     the scene, mesh or initial state was rejected before stepping

A case is ``ok`` when its outcome is one of those its expectation allows (and any extra
check, e.g. Hooke's ghost forces under a rigid rotation, holds). Nothing written is NaN.
"""
from __future__ import annotations

import csv
import io
import math
import re
import time
from pathlib import Path

import numpy as np

from ...runtime.base.errors import TensormassError
from ...runtime.base.files import write_text_atomic
from ...runtime.scene.types import Material
from ...runtime.scene.scene import Scene
from .springs_stability import case_spring_compression, case_spring_extremes
from .stability_runs import (COLUMNS, BAR, DIVERGED, GRAVITY, INVALID, RECOVERED, STABLE, Run, any_detected, clean,
                             md, min_det_F, num, outcome_in, refused, scene_dict, short, stable_dt)
from ...runtime.mesh.bars import generate_bar
from ..batch import map_tasks
from .accuracy import workers_of, add_workers_options

__all__ = ["run_stability", "add_stability_command", "COLUMNS"]


def case_stiffness(quick):
    """1. E sweep with linearly implicit Euler at dt = 1/60 and 0.1: stable, bounded."""
    Es = (1e3, 1e6, 1e10) if quick else (1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10)
    dts = (1.0 / 60, 0.1)
    steps = 6 if quick else 12
    rows = []
    for E in Es:
        for dt in dts:
            bound = GRAVITY * (dt * steps) ** 2 + 10.0 * max(BAR)
            # rho g L / E > 0.5: the bar cannot carry its own weight; StVK collapses (inverts) under it
            soft = 1000.0 * GRAVITY * BAR[0] / E > 0.5
            if soft:
                expected, allowed = ("too soft to carry its weight: invalid or diverged (detected), or stable "
                                     "without any inverted element", outcome_in(STABLE, INVALID, DIVERGED))
            else:
                expected, allowed = (f"stable: all finite, max|u| <= {bound:.3g} (free fall over the run + "
                                     "10 x size)", outcome_in(STABLE))
            run = Run(f"stiffness E={E:.0e}", "stvk", "implicit_euler", dt, expected, allowed)

            def judge(sim, summary, bound=bound, run=run):
                ok = run.max_u <= bound
                return (STABLE if ok else DIVERGED,
                        f"max|u| = {run.max_u:.3g} m (bound {bound:.3g}); tip z = {summary.probes['tip'][2]:.4g} m")
            rows.append(run.execute(scene_dict("stvk", "implicit_euler", dt, steps, E=E), judge=judge))
    return rows


def case_poisson(quick):
    """2. nu -> 0.5 with Hooke, static: stable (tip deflection shows locking); nu = 0.5 refused."""
    nus = (0.3, 0.49, 0.4999, 0.5) if quick else (0.3, 0.45, 0.49, 0.499, 0.4999, 0.5)
    rows = []
    for nu in nus:
        if nu >= 0.5:
            run = Run(f"poisson nu={nu}", "hooke", "static", None, "refused (scene validation: nu >= 0.5)",
                       refused)
        else:
            run = Run(f"poisson nu={nu}", "hooke", "static", None, "stable (tip deflection reported: locking)",
                       outcome_in(STABLE))

        def judge(sim, summary):
            tip = summary.probes["tip"]
            return STABLE, f"tip deflection z = {tip[2]:.5g} m (smaller as nu -> 0.5: volumetric locking)"
        rows.append(run.execute(scene_dict("hooke", "static", 1.0, 1, E=1e6, nu=nu,
                                            cells=(4, 1, 1) if quick else (6, 2, 2)), judge=judge))
    return rows


def case_explicit(quick):
    """3. symplectic Euler at 0.5x, 1x, 2x the estimated stable step."""
    law = "hooke"
    base = scene_dict(law, "explicit", 1e-3, 1, E=1e6)
    crit = stable_dt(base)
    steps = 150 if quick else 400
    rows = []
    for factor, expected, allowed in ((0.5, "stable", outcome_in(STABLE)),
                                      (1.0, "stable or diverged (detected): at the limit, just reported",
                                       outcome_in(STABLE, DIVERGED)),
                                      (2.0, "diverged (detected)", outcome_in(DIVERGED))):
        dt = factor * crit
        run = Run(f"explicit {factor:g}x stable dt", law, "explicit", dt, expected, allowed)
        run.extra.append(f"estimated stable dt {crit:.4g} s, {steps} steps")
        data = scene_dict(law, "explicit", dt, steps, E=1e6)
        rows.append(run.execute(data))
    return rows


def _rest_points(size, cells, element="hexahedron"):
    return generate_bar(size, cells, element).points


def _recovery_judge(run, initial, tol=0.05):
    def judge(sim, summary):
        final = float(np.abs(sim.ctx.u).max())
        rel = final / initial if initial > 0 else 0.0
        if rel < tol:
            return RECOVERED, f"final max|u| = {final:.3g} = {100 * rel:.3g} % of the initial {initial:.3g}"
        return STABLE, f"not recovered: final max|u| = {final:.3g} = {100 * rel:.3g} % of the initial {initial:.3g}"
    return judge


CUBE = (1.0, 1.0, 1.0)


def case_squash(quick):
    """4. a cube squashed to 10 % of its height (bottom clamped), released with backward Euler."""
    laws_ = ("stable_neohookean", "neohookean") if quick else ("stable_neohookean", "neohookean",
                                                                "mooney_rivlin", "stvk")
    cells = (2, 2, 2)
    X = _rest_points(CUBE, cells)
    u0 = np.zeros_like(X)
    u0[:, 2] = -0.9 * X[:, 2]            # z -> 0.1 z: 10 % of the height
    dt, steps = 0.05, 40
    rows = []
    for law in laws_:
        if law == "stable_neohookean":
            expected, allowed = "recovered (max|u| < 5 % of initial)", outcome_in(RECOVERED)
        elif law == "stvk":
            expected, allowed = "anything, but detected (no silent non-finite values)", any_detected
        else:
            expected, allowed = "stable/recovered, or refused/diverged (detected) if it inverts", any_detected
        run = Run("squash 10% and release", law, "backward_euler", dt, expected, allowed)
        data = scene_dict(law, "backward_euler", dt, steps, E=1e5, nu=0.3, size=CUBE, cells=cells,
                           gravity=False, fixed="bottom", rayleigh=(2.0, 0.0))
        initial = float(np.abs(u0).max())
        rows.append(run.execute(data, u0=u0, refuse_inverted_start=True, judge=_recovery_judge(run, initial)))
    return rows


def case_scramble(quick):
    """5. vertices scrambled by ~ one element size (bottom clamped), released with backward Euler."""
    laws_ = ("stable_neohookean", "neohookean") if quick else ("stable_neohookean", "neohookean",
                                                                "mooney_rivlin", "hooke", "stvk")
    cells = (2, 2, 2)
    X = _rest_points(CUBE, cells)
    rng = np.random.default_rng(1234)
    h = 1.0 / 2
    u0 = rng.uniform(-h, h, size=X.shape)
    u0[X[:, 2] <= 1e-12] = 0.0           # clamped nodes stay at rest
    dt, steps = 0.05, 40
    rows = []
    for law in laws_:
        if law == "stable_neohookean":
            expected, allowed = "recovered (max|u| < 5 % of initial)", outcome_in(RECOVERED)
        elif law in ("neohookean", "mooney_rivlin"):
            expected, allowed = "refused (inverted elements ...) or detected", any_detected
        else:
            expected, allowed = "anything, but detected (no silent non-finite values)", any_detected
        run = Run("scramble and release", law, "backward_euler", dt, expected, allowed)
        data = scene_dict(law, "backward_euler", dt, steps, E=1e5, nu=0.3, size=CUBE, cells=cells,
                           gravity=False, fixed="bottom", rayleigh=(2.0, 0.0))
        initial = float(np.abs(u0).max())
        rows.append(run.execute(data, u0=u0, refuse_inverted_start=True, judge=_recovery_judge(run, initial)))
        if law == "neohookean":
            # the same without the report's up-front check: what the runtime itself does
            run = Run("scramble and release (runtime alone)", law, "backward_euler", dt,
                       "diverged (detected) or refused: the runtime stops with a clear message",
                       lambda o: o == DIVERGED or refused(o))
            rows.append(run.execute(data, u0=u0, judge=_recovery_judge(run, initial)))
    return rows


def case_inverted_rest(quick):
    """6. a rest mesh with one element's nodes swapped: refused, naming the element."""
    element = 1
    row = {c: "" for c in COLUMNS}
    row.update(case="inverted rest element", law="stvk", integrator="static", expected=
               f"refused (...) naming element {element}")
    # deferred: model (scipy.sparse, pyamg), 0.35 s skipped by `tensormass report --help` (0.7 s)
    from ...runtime.model.model import Model
    start = time.perf_counter()
    mesh = generate_bar(BAR, (3, 1, 1), "hexahedron")
    cells = mesh.blocks[0].cells
    cells[element] = cells[element][[4, 5, 6, 7, 0, 1, 2, 3]]     # top <-> bottom: mirrored, det J < 0
    messages = []
    outcome = STABLE
    for check in (True, False):      # the mesh check, then the kernel's own det J test
        try:
            Model(mesh, [Material(law="stvk", E=1e6, nu=0.3)], check=check)
            messages.append(f"check={check}: accepted")
        except TensormassError as exc:
            messages.append(f"{'mesh check' if check else 'kernel constants'}: {exc}")
            if outcome == STABLE:
                outcome = f"refused ({short(exc)})"
    named = outcome.startswith("refused (") and all(
        re.search(rf"\b{element}\b", m) for m in messages)
    row.update(outcome=outcome, ok=bool(named), wall_time=round(time.perf_counter() - start, 4),
               message=clean("; ".join(messages)))
    return [row]


def case_sliver(quick):
    """7. very thin elements: stable or refused with a clear message."""
    rows = []
    for law in ("stvk",) if quick else ("stvk", "stable_neohookean"):
        run = Run("sliver elements 1 x 1 x 1e-4", law, "implicit_euler", 0.01,
                   "stable or refused (clear message)", lambda o: o == STABLE or refused(o))
        data = scene_dict(law, "implicit_euler", 0.01, 5, E=1e6, size=(1.0, 1.0, 1e-4), cells=(2, 2, 1))
        rows.append(run.execute(data))
    return rows


def case_rotation(quick):
    """8. a rigid 90 deg rotation as the state: Hooke gives ghost forces, finite-strain laws do not."""
    # deferred: model and assembly (scipy.sparse, pyamg), 0.43 s skipped by `tensormass report --help` (0.7 s)
    from ...runtime.assembly.assembly import Assembler
    from ...runtime.model.model import Model
    laws_ = ("hooke", "stvk", "stable_neohookean") if quick else (
        "hooke", "stvk", "neohookean", "stable_neohookean", "mooney_rivlin")
    rows = []
    for law in laws_:
        expected = ("stable; ghost force / weight > 1e-3" if law == "hooke"
                    else "stable; ghost force / weight < 1e-8")
        row = {c: "" for c in COLUMNS}
        row.update(case="rigid rotation 90 deg", law=law, integrator="static (forces at the state)",
                   expected=expected)
        start = time.perf_counter()
        try:
            data = scene_dict(law, "backward_euler", 1.0, 1, E=1e6, fixed=None)   # static needs a fixed box
            model = Model.from_scene(Scene.from_dict(data))
            asm = Assembler(model)
            X = model.mesh.points
            c = X.mean(axis=0)
            R = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])   # 90 deg about y
            u = ((X - c) @ R.T + c - X).ravel()
            f = asm.forces(u)
            W = asm.energy(u)
            weight = float(model.mass.reshape(-1, 3)[:, 0].sum()) * GRAVITY
            ghost = float(np.linalg.norm(f))
            ratio = ghost / weight
            ok = ratio > 1e-3 if law == "hooke" else ratio < 1e-8
            row.update(outcome=STABLE if np.isfinite(ratio) else DIVERGED, ok=bool(ok and np.isfinite(ratio)),
                       max_energy=num(W), max_abs_u=num(np.abs(u).max()), min_det_F=num(min_det_F(model, u)),
                       message=clean(f"ghost force |f| = {ghost:.3g} N, weight {weight:.3g} N, ratio {ratio:.3g}; "
                                      f"elastic energy {W:.3g} J"))
        except TensormassError as exc:
            row.update(outcome=f"refused ({short(exc)})", ok=False, message=clean(exc))
        row["wall_time"] = round(time.perf_counter() - start, 4)
        rows.append(row)
    return rows


def case_large_dt(quick):
    """9. linearly implicit Euler with dt = 1 s and 10 s on a stiff beam: stable (dissipative)."""
    rows = []
    for dt in (1.0, 10.0):
        steps = 3
        bound = 10.0 * max(BAR)
        run = Run("large dt stiff beam E=1e9", "stvk", "implicit_euler", dt,
                   f"stable: bounded (max|u| <= {bound:.3g})", outcome_in(STABLE))

        def judge(sim, summary, run=run, bound=bound):
            tip = summary.probes["tip"][2]
            return (STABLE if run.max_u <= bound else DIVERGED,
                    f"max|u| = {run.max_u:.3g} m, tip z = {tip:.4g} m (static sag of a clamped beam)")
        rows.append(run.execute(scene_dict("stvk", "implicit_euler", dt, steps, E=1e9), judge=judge))
    return rows


CASES = (case_stiffness, case_poisson, case_explicit, case_squash, case_scramble, case_inverted_rest,
         case_sliver, case_rotation, case_large_dt)


CASES = CASES + (case_spring_compression, case_spring_extremes)


# ============================================================================== output


def _fmt(value) -> str:
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.6g}"
    return clean(value)


def _csv_text(rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS)
    for r in rows:
        w.writerow([_fmt(r.get(c, "")) for c in COLUMNS])
    return buf.getvalue()


def _report_text(rows, quick, total) -> str:
    n_ok = sum(bool(r["ok"]) for r in rows)
    lines = ["# Stability report", "",
             f"{'Quick' if quick else 'Full'} suite: {len(rows)} cases, {n_ok} met their expectation, "
             f"{len(rows) - n_ok} did not; {total:.1f} s in all.", "",
             "Outcomes (by the runtime's health monitor): `stable`, `recovered`, `invalid (detected)`, "
             "`diverged (detected)`, `refused (reason)`; the spring lattices' compression case also "
             "`buckled (detected by the report)` (its mirror symmetry lost).", "",
             "| case | law | integrator | dt | outcome | ok | max energy | max abs u | min det F | newton | linear | wall s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        cells = [r["case"], r["law"], r["integrator"], _fmt(r["dt"]), r["outcome"], "yes" if r["ok"] else "NO",
                 _fmt(r["max_energy"]), _fmt(r["max_abs_u"]), _fmt(r["min_det_F"]),
                 _fmt(r["newton_iterations"]), _fmt(r["linear_iterations"]), _fmt(r["wall_time"])]
        lines.append("| " + " | ".join(md(c) for c in cells) + " |")
    lines += ["", "## Expectations", ""]
    for r in rows:
        met = "met" if r["ok"] else "NOT met"
        dt = f", dt {_fmt(r['dt'])}" if r["dt"] != "" else ""
        lines.append(f"- **{clean(r['case'])}** ({r['law']}, {r['integrator']}{dt}): expects {clean(r['expected'])}; "
                     f"got `{clean(r['outcome'])}`: {met}. {clean(r['message'])}")
    return "\n".join(lines) + "\n"


def _run_case(index, quick) -> tuple:
    """CASES[index] as a task (apps/batch.map_tasks): (its rows, seconds); a bug in a case is a row."""
    case = CASES[index]
    t0 = time.perf_counter()
    try:
        got = case(quick)
    except Exception as exc:      # a bug in a case must not lose the others' results
        row = {c: "" for c in COLUMNS}
        row.update(case=case.__name__, outcome=f"refused (report error: {short(exc)})",
                   expected="the case runs", ok=False, message=clean(f"{type(exc).__name__}: {exc}"))
        got = [row]
    return got, time.perf_counter() - t0


def run_stability(out_dir, quick=False, progress=print, workers: int = 1, scheduler: str | None = None) -> list:
    """Run every case, write stability.csv and report.md into out_dir; the rows (dicts) are returned.

    workers / scheduler: the cases run as independent tasks through apps/batch.map_tasks (in this
    process with workers 1, else on dask); rows in CASES order, the same outcomes; only wall_time
    (and the times in report.md) are measurements."""
    out = Path(out_dir)
    start = time.perf_counter()
    rows = []

    def show(i, outcome):
        got, seconds = outcome[1]
        if progress is not None:
            summary = ", ".join(f"{r['law']}: {r['outcome']}{'' if r['ok'] else ' (NOT ok)'}" for r in got)
            progress(f"{CASES[i].__name__[5:]:>14s} {seconds:6.1f} s  {short(summary, 200)}")
    outcomes = map_tasks(_run_case, [(i, quick) for i in range(len(CASES))], workers=workers, scheduler=scheduler,
                         label="case", capture=False, progress=workers > 1 or scheduler is not None, on_result=show)
    for _, (got, _) in outcomes:
        rows.extend(got)
    total = time.perf_counter() - start
    write_text_atomic(out / "stability.csv", _csv_text(rows))
    write_text_atomic(out / "report.md", _report_text(rows, quick, total))
    if progress is not None:
        n_ok = sum(bool(r["ok"]) for r in rows)
        progress(f"{n_ok}/{len(rows)} cases met their expectation in {total:.1f} s; wrote {out / 'stability.csv'} "
                 f"and {out / 'report.md'}")
    return rows


def _cmd_stability(args) -> int:
    workers, scheduler = workers_of(args), getattr(args, "scheduler", None)
    extra = {"workers": workers, "scheduler": scheduler} if workers > 1 or scheduler is not None else {}
    rows = run_stability(args.out, quick=args.quick, **extra)
    return 0 if rows and all(r["ok"] for r in rows) else 1


def add_stability_command(subparsers) -> None:
    p = subparsers.add_parser("stability", help="stiff and extreme cases: stable, recovered, diverged or refused")
    p.add_argument("--quick", action="store_true", help="fewer values and steps (< 1 minute)")
    p.add_argument("--out", required=True, help="output folder for stability.csv and report.md")
    add_workers_options(p)
    p.set_defaults(run=_cmd_stability)
