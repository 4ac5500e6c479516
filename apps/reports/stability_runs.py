"""The harness of `tensormass report stability`: the outcomes a case can end in, the scene of a
tiny bar, and Run, which runs a scene and classifies its ending through the runtime's own
health monitor (runtime/physics/health.py).  The cases: stability.py and springs_stability.py."""
from __future__ import annotations

import math
import re
import time

import numpy as np

from ... import laws
from ...runtime.physics import health
from ...runtime.base.errors import TensormassError
from ...runtime.scene.scene import Scene

COLUMNS = ("case", "law", "integrator", "dt", "outcome", "expected", "ok", "max_energy", "max_abs_u",
           "min_det_F", "newton_iterations", "linear_iterations", "wall_time", "message")

STABLE, RECOVERED, DIVERGED = "stable", "recovered", "diverged (detected)"
INVALID = "invalid (detected)"
GRAVITY = 9.81
BAR = (1.0, 0.2, 0.2)


# ============================================================================== helpers


def scene_dict(law="stvk", kind="implicit_euler", dt=1.0 / 60, steps=5, E=1e6, nu=0.3, size=BAR,
                cells=(4, 1, 1), element="hexahedron", gravity=True, fixed="left", rayleigh=(0.0, 0.0),
                quadrature="gauss2", density=1000.0, newton_max_iterations=25):
    """A validated-scene dict: a bar clamped at x = 0 (fixed="left"), at z = 0 ("bottom"), or free."""
    big = 10.0 * max(size)
    data = {
        "name": "stability",
        "mesh": {"generate": "bar", "size": list(size), "cells": list(cells), "element": element},
        "material": [{"law": law, "quadrature": quadrature, "E": float(E), "nu": float(nu),
                      "density": float(density)}],
        "loads": {"gravity": [0.0, 0.0, -GRAVITY if gravity else 0.0]},
        "solver": {"kind": kind, "dt": float(dt), "steps": int(steps), "rayleigh": list(rayleigh),
                   "newton_max_iterations": int(newton_max_iterations)},
        "probe": [{"name": "tip", "point": [float(size[0]), size[1] / 2, size[2] / 2]}],
    }
    eps = 1e-9 * max(size)
    if fixed == "left":
        data["fixed"] = [{"box": [[-big, -big, -big], [eps, big, big]]}]
    elif fixed == "bottom":
        data["fixed"] = [{"box": [[-big, -big, -big], [big, big, eps]]}]
    return data


def min_det_F(model, u) -> float:
    """Smallest det F over every integration point of every element: the health monitor's measure."""
    return health.min_det_F(model, np.asarray(u, dtype=float))[0]


def short(exc_or_text, limit=110) -> str:
    text = str(exc_or_text).strip().splitlines()[0] if str(exc_or_text).strip() else type(exc_or_text).__name__
    return text if len(text) <= limit else text[:limit - 3] + "..."


def clean(text) -> str:
    """Messages go into CSV/markdown cells: one line, no literal NaN token."""
    text = " ".join(str(text).split())
    return re.sub(r"\bnan\b", "non-finite", text, flags=re.IGNORECASE)


def md(text) -> str:
    """A markdown table cell: clean, with pipes escaped."""
    return clean(text).replace("|", "\\|")


def num(x):
    """A finite float or "" (never NaN/inf in the output)."""
    if x is None or isinstance(x, bool):
        return ""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return ""
    return x if math.isfinite(x) else ""


class Run:
    """One simulation case: builds, runs, tracks max |u|, min det F, energies; classifies the outcome."""

    def __init__(self, case, law, integrator, dt, expected, allowed):
        self.row = {c: "" for c in COLUMNS}
        self.row.update(case=case, law=law, integrator=integrator, dt=num(dt), expected=expected)
        self.allowed = allowed            # callable(outcome) -> bool
        self.sim = None
        self.max_u = 0.0
        self.min_det = math.inf
        self.extra = []                   # extra message parts
        self.start = time.perf_counter()

    def _track(self, k=None, n=None):
        u = self.sim.ctx.u
        if np.all(np.isfinite(u)):
            self.max_u = max(self.max_u, float(np.abs(u).max()) if u.size else 0.0)

    def execute(self, scene_data, u0=None, v0=None, refuse_inverted_start=False, judge=None):
        """judge(sim, summary) -> (outcome, message) for a finished run (default: stable if bounded)."""
        from ...runtime.run.simulation import Simulation    # deferred: 0.50 s skipped by `tensormass report --help` (0.7 s)
        try:
            scene = Scene.from_dict(scene_data)
            self.sim = sim = Simulation(scene, progress=self._track, u0=u0, v0=v0, output=False)
            if u0 is not None:
                self.min_det = min_det_F(sim.model, sim._u0)
                self.max_u = float(np.abs(u0).max())
                if refuse_inverted_start:
                    self._refuse_inverted(sim, sim._u0)
        except TensormassError as exc:
            return self._finish(f"refused ({short(exc)})", str(exc))
        try:
            summary = sim.run()
        except TensormassError as exc:
            if sim.ctx is not None:
                self.row["newton_iterations"] = sim.ctx.newton_iterations
                self.row["linear_iterations"] = sim.ctx.linear_iterations
            stopped = getattr(exc, "summary", None)
            if stopped is not None:
                self._health(stopped)
            outcome = INVALID if getattr(exc, "status", None) == "invalid" else DIVERGED
            return self._finish(outcome, f"{type(exc).__name__}: {exc}")
        self._health(summary)
        self.row["newton_iterations"] = summary.iterations["newton"]
        self.row["linear_iterations"] = summary.iterations["linear"]
        energies = [e for e in summary.per_step.get("elastic", []) if e is not None]
        u = sim.ctx.u
        if not (np.all(np.isfinite(u)) and all(math.isfinite(e) for e in energies)):
            # the runtime should never get here; the report says so instead of writing NaN
            return self._finish(DIVERGED, "non-finite state NOT caught by the runtime (found by the report)",
                                force_fail=True)
        if energies:
            self.row["max_energy"] = num(max(energies))
        warned = f"monitor warnings: {summary.warnings[0]['message']}" if summary.warnings else ""
        if warned:
            self.extra.append(warned)
        if judge is None:
            return self._finish(STABLE if not warned else RECOVERED, "finished; the health monitor trusts it")
        outcome, message = judge(sim, summary)
        if outcome == STABLE and warned:       # "stable" is only what the monitor found clean throughout
            outcome = RECOVERED
        return self._finish(outcome, message)

    def _health(self, summary):
        """min det F as the health monitor saw it (every step, every law), not recomputed here."""
        low = (summary.health or {}).get("min_det_F")
        if low is not None:
            self.min_det = min(self.min_det, low)

    def _refuse_inverted(self, sim, u):
        for p in sim.model.parts:
            if laws.get(p.law).requires_positive_J:
                bad = p.kernel.inverted(p.D_active, sim.model.element_displacements(p, u))
                if bad.any():
                    ids = ", ".join(str(int(i)) for i in p.cell_ids[bad][:8])
                    more = f" and {int(bad.sum()) - 8} more" if bad.sum() > 8 else ""
                    raise TensormassError(f"inverted elements in the initial state (det F <= 0, law {p.law!r} "
                                          f"is undefined there): element(s) {ids}{more}")

    def _finish(self, outcome, message, force_fail=False):
        r = self.row
        r["outcome"] = outcome
        r["max_abs_u"] = num(self.max_u)
        r["min_det_F"] = num(self.min_det)
        r["wall_time"] = round(time.perf_counter() - self.start, 4)
        parts = [message] + self.extra
        if self.min_det <= 0:
            parts.append(f"some element inverted (min det F = {self.min_det:.3g}, initial state included)")
        r["message"] = clean("; ".join(p for p in parts if p))
        r["ok"] = bool(self.allowed(outcome)) and not force_fail
        return r


def any_detected(outcome) -> bool:
    return outcome in (STABLE, RECOVERED, DIVERGED, INVALID) or outcome.startswith("refused (")


def outcome_in(*names):
    return lambda outcome: outcome in names


def refused(outcome) -> bool:
    return outcome.startswith("refused (")


# ============================================================================== cases



def stable_dt(scene_data) -> float:
    # deferred: model and integrators (scipy.sparse, pyamg), 0.50 s skipped by `tensormass report --help` (0.7 s)
    from ...runtime.physics.newton import Context
    from ...runtime.physics.integrators import stable_time_step
    from ...runtime.model.model import Model
    return float(stable_time_step(Context(Model.from_scene(Scene.from_dict(scene_data)))))
