"""Run health: is the state after a step a result we stand behind?

    monitor = HealthMonitor(ctx)                 # after the context is set up (again after refinement)
    check = monitor.check(ctx, step, energies)   # after every step, before its frame is written
    check.stop                                   # None, or why the run must stop now (diverged)
    check.flag                                   # None, or the warning the step's frame carries
    status, message = monitor.verdict(ctx)       # at the end: "ok" | "warnings" | "invalid"

What is watched, and why each is cheap (a few vector passes per step; the
elastic energy is already evaluated for the energy history):

- non-finite values in u, v or the energies: stop;
- the energy balance H = W + K - f_ext . u (elastic + kinetic - work of the
  constant external loads).  With constant loads and fixed or linearly moving
  boundaries no integrator here may create energy: H can only grow by what the
  moving boundaries put in.  The run stops when H grows by more than
  `max_energy_growth` x the scene's energy scale E_ref, the largest of: the
  loads moved over one body size (|f_ext|_1 L), the elastic energy of the
  prescribed displacements applied to the fixed nodes alone (an upper bound of
  the energy a static solve can store: the equilibrium minimises the potential
  over fields that include this one), the kinetic energy of the boundary
  motion, and the initial energy;
- the largest displacement relative to the body size, after removing the mean
  motion (a falling or rigidly moving body is fine): stop beyond
  `max_displacement` body sizes;
- min det F over the integration points of every element, for every law.
  Laws undefined there (neo-Hookean, Mooney-Rivlin) already refuse inverted
  states; for the others an inverted element is a warning (frames flagged) and,
  if still inverted at the end, makes the result "invalid" (on_inversion = "stop":
  stop at once).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numba import njit

from ... import laws
from ..base.errors import InvertedElementError, TensormassError

__all__ = ["HealthMonitor", "Check", "min_det_F", "safe_norm", "MAX_ENERGY_SCALE"]

# Loads or prescribed displacements whose energy scale exceeds this (J) are refused before the
# first step: Newton forms products like f.u ~ |f|^2 / k that overflow doubles long before
# 1e308, and nothing physical comes near (a 1e6 N load over 1 km is 1e9 J).
MAX_ENERGY_SCALE = 1e100

# How many warnings are kept in full (the rest are counted): a run never grows without bound.
MAX_WARNINGS = 50


def safe_norm(x: np.ndarray) -> float:
    """Euclidean norm without overflow: |x| = m |x / m| with m = max |x_i| (inf only if x has inf/NaN)."""
    if x.size == 0:
        return 0.0
    m = float(np.max(np.abs(x)))
    if not np.isfinite(m):
        return np.inf if not np.isnan(m) else np.nan
    if m == 0.0:
        return 0.0
    return m * float(np.linalg.norm(x / m))


@njit(cache=True)
def _spread(U):
    """Largest distance of a node's displacement from the mean displacement (one pass each)."""
    n, dim = U.shape
    mean = np.zeros(dim)
    for i in range(n):
        for a in range(dim):
            mean[a] += U[i, a]
    mean /= max(n, 1)
    worst = 0.0
    for i in range(n):
        d = 0.0
        for a in range(dim):
            d += (U[i, a] - mean[a]) ** 2
        if d > worst:
            worst = d
    return np.sqrt(worst)


def part_min_det_F(model, part, u: np.ndarray) -> np.ndarray | None:
    """min det F per active element of a part; None for kernels without stored shape gradients."""
    if getattr(part.kernel, "recompute", False) or not hasattr(part.kernel, "min_det_F"):
        return None                        # (a hand-written kernel may have no inversion check)
    return part.kernel.min_det_F(part.D_active, model.part_nodal(part, u), cells=part.cells_active)


def min_det_F(model, u: np.ndarray) -> tuple:
    """(smallest det F over every checked element, global ids of inverted cells whose law allows it)."""
    low, inverted = np.inf, []
    for part in model.parts:
        if not part.n_active:
            continue
        d = part_min_det_F(model, part, u)
        if d is None or not d.size:
            continue
        low = min(low, float(d.min()))
        bad = ~(d > 0.0)
        if bad.any() and not laws.get(part.law).requires_positive_J:
            inverted.append(part.cell_ids_active[bad])
    cells = np.sort(np.concatenate(inverted)) if inverted else np.zeros(0, dtype=np.int64)
    return low, cells


@dataclass
class Check:
    """What one step's health check found."""
    stop: str | None = None            # why the run must stop now (None: go on)
    flag: str | None = None            # warning carried by this step's frame (None: clean)


class HealthMonitor:
    """Per-step checks against the thresholds of model.solver (see the module docstring)."""

    def __init__(self, ctx, dynamic: bool, duration: float | None = None):
        model, s = ctx.model, ctx.model.solver
        self.model = model
        self.enabled = bool(getattr(s, "health_monitor", True))
        self.max_energy_growth = float(getattr(s, "max_energy_growth", 100.0))
        self.max_displacement = float(getattr(s, "max_displacement", 10.0))
        self.on_inversion = getattr(s, "on_inversion", "warn")
        self.dynamic = dynamic
        self.warnings: list = []
        self.dropped_warnings = 0
        self.first_warning = None
        self.time = 0.0
        self.steps_checked = 0
        self.min_det = np.inf
        self.max_rel_u = 0.0
        self.max_growth = 0.0
        self.inverted_now = np.zeros(0, dtype=np.int64)
        self.last_min_det = np.inf
        self.H0 = None
        self.energy_scale = self._energy_scale(ctx, duration) if self.enabled else None
        if self.enabled:                   # compile / load the numba loops now: setup, not the first step
            min_det_F(model, np.zeros(model.n_dofs))
            _spread(np.zeros((1, model.dim)))

    # -- reference energy -------------------------------------------------------------------------
    def _energy_scale(self, ctx, duration) -> float:
        model = self.model
        with np.errstate(over="ignore", invalid="ignore"):
            mo = getattr(model, "motion", None)              # amplitudes, rigid motions: their peaks
            f_peak = model.f_ext if mo is None else mo.peak_forces()
            if getattr(model, "pressure", None) is not None:  # pressure at rest
                f_peak = np.abs(f_peak) + np.abs(model.pressure.forces(np.zeros(model.n_dofs)))
            load = float(np.sum(np.linalg.norm(model.nodal(f_peak), axis=1))) * model.size
            boundary = self._boundary_energy(ctx)
            motion = 0.0
            if self.dynamic and duration:
                v_b = model.prescribed / duration if mo is None or not mo.moving else mo.peak_velocity()
                motion = 0.5 * float(np.sum(model.mass[model.fixed_dofs] * v_b ** 2))
        for what, value in (("the loads (total load x body size)", load),
                            ("the prescribed displacements (their elastic energy)", boundary),
                            ("the prescribed boundary motion (its kinetic energy)", motion)):
            if not value <= MAX_ENERGY_SCALE:
                raise TensormassError(f"the energy scale of {what} is {value:.3g} J, beyond what double precision "
                                      f"can simulate (limit {MAX_ENERGY_SCALE:.0e} J): check the units and "
                                      "magnitudes of [loads] and [[fixed]] displacement")
        return max(load, boundary, motion)

    def _boundary_energy(self, ctx) -> float:
        """Elastic energy of the prescribed displacements on the fixed nodes alone (every other node at rest)."""
        model = self.model
        motion = getattr(model, "motion", None)
        peak = model.prescribed if motion is None else motion.peak_displacement()
        if not np.any(peak):
            return 0.0
        u = np.zeros(model.n_dofs)
        u[model.fixed_dofs] = peak
        saved = ctx.asm.time
        values, inverted = [], 0
        for scale in (1.0, 1e-3):          # the small one: the linearised energy, defined for every law
            try:
                with np.errstate(over="ignore", invalid="ignore"):
                    W = ctx.asm.energy(scale * u) / scale ** 2
            except InvertedElementError:
                inverted += 1              # a law undefined there even at 1e-3: no estimate from it
                continue
            if np.isfinite(W):
                values.append(W)
        ctx.asm.time = saved
        if not values:                     # overflow (inf), or inverted both times (no estimate)
            return 0.0 if inverted == 2 else np.inf
        # A law that stiffens exponentially (hgo's fibres) gives an astronomic energy at the strain of
        # the boundary cells alone; the linearised energy is then the scale (in range unless the
        # displacements themselves are out of scale).
        within = [W for W in values if W <= MAX_ENERGY_SCALE]
        return max(within) if within else max(values)

    # -- per step ---------------------------------------------------------------------------------
    def start(self, ctx, energies: dict) -> Check:
        """The initial state: the energy balance is measured from here; an inverted u0 is a warning."""
        self.H0 = self._balance(energies)
        if not self.enabled:               # the user's choice, said in the summary: nothing vouches for the result
            self.warn(0, ctx.t, "unchecked", "health monitor off (solver.health_monitor = false): "
                                             "the result was not checked")
        if not self.enabled:
            return Check()
        if self.H0 is not None and np.isfinite(self.H0):
            self.energy_scale = max(self.energy_scale, abs(self.H0))
        return self._check_inversion(ctx, 0) if self.on_inversion == "warn" else Check()

    @staticmethod
    def _balance(energies: dict):
        W, K = energies.get("elastic"), energies.get("kinetic")
        if W is None:
            return None
        return W + (K or 0.0) - energies.get("external_work", 0.0)

    def check(self, ctx, step: int, energies: dict) -> Check:
        if not self.enabled:
            return Check()
        start = time.perf_counter()
        try:
            return self._check(ctx, step, energies)
        finally:
            self.time += time.perf_counter() - start
            self.steps_checked += 1

    def _check(self, ctx, step, energies) -> Check:
        model = self.model
        values = [v for v in energies.values() if v is not None]
        if not (np.all(np.isfinite(ctx.u)) and np.all(np.isfinite(ctx.v)) and np.all(np.isfinite(values))):
            return Check(stop=f"step {step}: the state or its energy is not finite (NaN/Inf): the solution diverged")
        rel = float(_spread(np.ascontiguousarray(model.split_dofs(ctx.u)[0]))) / model.size
        self.max_rel_u = max(self.max_rel_u, rel)
        if rel > self.max_displacement:
            return Check(stop=f"step {step}: a node moved {rel:.3g} body sizes ({rel * model.size:.3g} m) relative to "
                              f"the body's mean motion, beyond solver.max_displacement = {self.max_displacement:g}: "
                              "the solution diverged or the load is far outside what this model represents")
        stop = self._check_energy(step, energies)
        if stop:
            return Check(stop=stop)
        return self._check_inversion(ctx, step)

    def _check_energy(self, step, energies):
        H = self._balance(energies)
        if H is None or self.H0 is None or not self.energy_scale:
            return None
        growth = (H - self.H0) / self.energy_scale
        self.max_growth = max(self.max_growth, growth)
        if growth > self.max_energy_growth:
            return (f"step {step}: the energy balance (elastic + kinetic - external work) grew by {H - self.H0:.3g} J, "
                    f"{growth:.3g} x the scene's energy scale {self.energy_scale:.3g} J (solver.max_energy_growth = "
                    f"{self.max_energy_growth:g}) without external work to supply it: the time integration blew up")
        return None

    def _check_inversion(self, ctx, step) -> Check:
        low, cells = min_det_F(self.model, ctx.u)
        self.last_min_det = low
        self.min_det = min(self.min_det, low)
        was = self.inverted_now.size
        self.inverted_now = cells
        if cells.size:
            text = (f"{cells.size} inverted element(s) (det F <= 0, min det F = {low:.3g}), first {int(cells[0])}: "
                    "the law is evaluated outside its physical range")
            if self.on_inversion == "stop":
                return Check(stop=f"step {step}: {text} (solver.on_inversion = 'stop')")
            if not was:
                self.warn(step, ctx.t, "inverted", text)
            return Check(flag=f"step {step}: {text}")
        if was:
            self.warn(step, ctx.t, "recovered", "no inverted element any more")
        if self.first_warning is not None:
            return Check(flag=f"after warnings from step {self.first_warning['step']}: {self.first_warning['message']}")
        return Check()

    def warn(self, step, t, kind, message) -> None:
        event = {"step": int(step), "time": float(t), "kind": kind, "message": message}
        if self.first_warning is None:
            self.first_warning = event
        if len(self.warnings) < MAX_WARNINGS:
            self.warnings.append(event)
        else:
            self.dropped_warnings += 1

    # -- end ------------------------------------------------------------------------------------------
    def verdict(self) -> tuple:
        """(status, message) of a run that reached its last step: ok, warnings or invalid."""
        if self.enabled and self.inverted_now.size:
            return "invalid", (f"the final state has {self.inverted_now.size} inverted element(s) "
                               f"(min det F = {self.last_min_det:.3g}, first {int(self.inverted_now[0])}): "
                               "not a physical result; use smaller load or time steps, a finer mesh, or a law "
                               "made for large compression (stable_neohookean)")
        if self.warnings:
            return "warnings", None
        return "ok", None

    def summary(self) -> dict:
        def num(x):
            return float(x) if x is not None and np.isfinite(x) else None
        return {
            "monitor": self.enabled,
            "steps_checked": self.steps_checked,
            "min_det_F": num(self.min_det),
            "min_det_F_final": num(self.last_min_det),
            "inverted_final": int(self.inverted_now.size),
            "max_relative_displacement": num(self.max_rel_u),
            "energy_scale": num(self.energy_scale),
            "max_energy_growth": num(self.max_growth),
            "warnings_dropped": self.dropped_warnings,
            "limits": {"max_energy_growth": self.max_energy_growth, "max_displacement": self.max_displacement,
                       "on_inversion": self.on_inversion},
            "time": self.time,
        }
