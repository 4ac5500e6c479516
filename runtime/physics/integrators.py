"""Time integrators and the static solver, all on one shared Context (state, assembly, solvers).

    ctx = Context(model)
    integ = make_integrator(ctx)          # by model.solver.kind
    for k in range(1, integ.n_steps + 1):
        info = integ.step(k)              # advances ctx.u, ctx.v, ctx.t

Conventions: u, v are global node-major vectors; f_int = -dW/du comes from the
kernels, K = d2W/du2 = -df_int/du.  Fixed dofs follow the model's prescribed
displacement: ramped with the load factor (static) or linearly over the whole
run (dynamic), so their velocity is constant; clamped dofs stay at zero.  Amplitude tables,
rigid motions and time-varying loads come from runtime.physics.motion through prescribed(s),
external_force(s) and boundary_velocity(u, t, h) (s: the run fraction, t / duration).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from ... import laws
from ..assembly.assembly import Assembler
from ..base.errors import InvertedElementError, TensormassError
from .health import safe_norm
from ..solve.amg import rigid_body_modes
from ..solve.solvers import ConstrainedSystem, LinearSolver

__all__ = ["Context", "make_integrator", "integrator_class", "outputs_for", "Static", "ImplicitEuler", "BackwardEuler", "Explicit",
           "newton", "stable_time_step"]

# Line search: Armijo constant, halvings, and the relative round-off allowance on energies.
_ARMIJO = 1e-4
_MAX_HALVINGS = 30
_ROUNDOFF = 1e-12
# Energy changes below this (relative) may be round-off: then the residual decides.
_NOISE = 1e-6
# Residual floor: after a full Newton step, a residual below _FLOOR x machine epsilon x |K| h (the
# forces a strain of one would cause, h the size of the cells at each node) is round-off, not an
# unconverged state: near incompressibility lambda (J - 1) loses the digits of J ~ 1 at any load.
_FLOOR = 1.0
# Watchdog (Chamberlain et al. 1982): full Newton steps that raise the energy are taken this many
# times in a row; if the energy has not then fallen below the last certified point (Armijo on that
# point's full step), Newton returns there and backtracks along that point's direction.
_WATCHDOG = 3
# Dynamic steps that fail (NaN, inversion, no convergence) are retried with dt/2 this many times.
_MAX_DT_HALVINGS = 3


class Context:
    """What every integrator shares: the model, its assembler, Dirichlet elimination, the state."""

    def __init__(self, model, assembler: Assembler | None = None):
        self.model = model
        s = model.solver
        self.asm = assembler if assembler is not None else Assembler(model)
        # multigrid's near-nullspace, only where a solver may use multigrid
        modes = (rigid_body_modes(model.mesh.points, np.arange(model.n_dofs), model.dofs_per_node)
                 if s.linear in ("auto", "amg") else None)
        self.hanging = getattr(model, "hanging", None)
        self.system = ConstrainedSystem(self.asm.pattern, model.free_dofs, model.fixed_dofs, modes, self.hanging)
        self.linear = LinearSolver(s.linear, s.cg_tolerance, s.cg_max_iterations)
        if getattr(model, "pressure", None) is not None and not model.pressure.symmetric:
            # follower pressure on an open surface: non-symmetric Newton matrices (runtime/assembly/pressure.py)
            self.linear = LinearSolver("lu", s.cg_tolerance, s.cg_max_iterations)
        # PSD projection of element Hessians (non-Hooke parts): True always, False never,
        # None "on demand": Newton solvers switch it on when a direction fails to descend
        self.project = None if s.project_psd is None else bool(s.project_psd)
        self.u = np.zeros(model.n_dofs)
        self.v = np.zeros(model.n_dofs)
        self.t = 0.0
        self.newton_iterations = 0
        self.linear_iterations = 0
        # (u, r): the residual of the discrete equation of motion the last step solved, whose rows on
        # the fixed dofs are the reaction forces at the state u (runtime.physics.reactions); None: not known
        self.residual = None
        self._cell_size = None

    def cell_size(self) -> np.ndarray:
        """Per dof, the largest cell (bounding-box diagonal) at its node: lengths for the residual floor."""
        if self._cell_size is None:
            model = self.model
            pts, dpn = np.asarray(model.mesh.points, dtype=float), model.dofs_per_node
            h = np.zeros(model.n_dofs // dpn)
            for p in model.parts:
                cells = np.asarray(p.cells)
                if cells.size:
                    x = pts[cells]
                    diag = np.linalg.norm(x.max(axis=1) - x.min(axis=1), axis=-1)
                    np.maximum.at(h, cells, diag[:, None])
            h = np.repeat(h, dpn)
            dim = pts.shape[1]
            if dpn > dim:                   # rotations: dimensionless, a perturbation of one radian
                h.reshape(-1, dpn)[:, dim:] = 1.0
            self._cell_size = h
        return self._cell_size

    def roundoff_floor(self, data) -> float:
        """The residual round-off leaves after a solve with the Newton matrix `data` (see _FLOOR)."""
        K = self.asm.pattern.matrix(np.abs(data))
        free = self.model.free_dofs
        return _FLOOR * np.finfo(float).eps * safe_norm((K @ self.cell_size())[free])

    def solve(self, data, b, x_c=None, x0=None):
        """Eliminate the fixed dofs (values x_c) and solve; counts linear iterations."""
        x, its = self.system.solve(self.linear, data, b, x_c, x0)
        self.linear_iterations += its
        return x

    def reduce(self, g: np.ndarray) -> np.ndarray:
        """A gradient or residual onto the constrained dofs (hanging nodes: P^T g; else g itself)."""
        return g if self.hanging is None else self.hanging.reduce(g)

    def add_diagonal(self, data, diag):
        out = data.copy()
        out[self.asm.pattern.diagonal] += diag
        return out

    def check_not_inverted(self, u):
        """Raise InvertedElementError if u inverts an element of a law undefined there."""
        for p in self.model.parts:
            if laws.get(p.law).requires_positive_J and p.n_active and hasattr(p.kernel, "inverted"):
                bad = p.kernel.inverted(p.D_active, u, cells=p.cells_active)
                if bad.any():
                    raise InvertedElementError(f"law {p.law!r}: det F <= 0", p.cell_ids_active[bad])


# --------------------------------------------------------------------------- Newton


class _Potential:
    """Total potential Pi(u) = W(u) - f_ext.u (+ optional quadratic inertia/damping terms)."""

    def __init__(self, asm, f_ext, factor=1.0):
        self.asm, self.f_ext = asm, f_ext
        self.free = asm.model.free_dofs
        # follower pressure (runtime/assembly/pressure.py) x the load factor: no potential on open surfaces, so
        # its energy is the work along the Newton path (exact on each straight step: see accept)
        self.pressure, self.factor = getattr(asm.model, "pressure", None), float(factor)
        self._anchor = None                         # (u, pressure energy there)

    def _pressure_energy(self, u):
        if self.pressure is None:
            return 0.0
        if self._anchor is None:
            self._anchor = (u.copy(), 0.0)
        u0, e0 = self._anchor
        return e0 - self.factor * self.pressure.work(u0, u)

    def accept(self, u, energy=None):
        """Newton moved to u: later energies are measured along the path from here."""
        if self.pressure is not None:
            self._anchor = (u.copy(), self._pressure_energy(u) if energy is None else energy)

    def extra(self, u):
        """(value, gradient, magnitude) of quadratic terms; none for statics."""
        return 0.0, 0.0, 0.0

    def value(self, u):
        """(Pi, magnitude for round-off); +inf where an element inverts for a law undefined there."""
        try:
            W = self.asm.energy(u)
        except InvertedElementError:
            return np.inf, 0.0
        work = float(self.f_ext @ u)
        q, _, qmag = self.extra(u)
        P = self._pressure_energy(u)
        return W - work + q + P, abs(W) + abs(work) + qmag + abs(P)

    def gradient(self, u):
        _, dq, _ = self.extra(u)
        g = dq - self.asm.forces(u) - self.f_ext
        g = g if self.pressure is None else g - self.factor * self.pressure.forces(u)
        # hanging nodes (runtime.physics.hanging): the gradient of the constrained problem, P^T g
        hanging = getattr(self.asm.model, "hanging", None)
        return g if hanging is None else hanging.reduce(g)

    def force_scale(self, u):
        """Forces that set the convergence tolerance: the external load (plus inertia, below)."""
        return safe_norm(self.f_ext[self.free])

    def hessian(self, u, project):
        data = self.asm.stiffness(u, project)
        if self.pressure is not None:       # full on open surfaces (LU, see Context), else its symmetric part
            self.pressure.add_stiffness(data, self.asm.pattern, u, self.factor)
        return data


class _IncrementalPotential(_Potential):
    """Backward Euler: Pi + 1/(2h^2)|x - x_pred|_M^2 + 1/(2h)|x - x_n|_D^2, D = alpha M + beta K_n."""

    def __init__(self, asm, f_ext, mass, h, u_n, v_n, alpha, K_n):
        super().__init__(asm, f_ext)
        self.mass, self.h, self.u_n = mass, h, u_n
        self.u_pred = u_n + h * v_n
        self.alpha, self.K_n = alpha, K_n              # K_n: CSR (beta already folded in) or None

    def _damping(self, x):
        out = self.alpha * (self.mass @ x)
        return out if self.K_n is None else out + self.K_n @ x

    def extra(self, u):
        a, b = u - self.u_pred, u - self.u_n
        Ma, Db = self.mass @ a, self._damping(b)
        q = 0.5 * (a @ Ma) / self.h**2 + 0.5 * (b @ Db) / self.h
        return q, Ma / self.h**2 + Db / self.h, abs(q)

    def force_scale(self, u):
        # a body moving without load still needs a force scale: its inertia forces
        _, dq, _ = self.extra(u)
        return max(super().force_scale(u), safe_norm(dq[self.free]))

    def hessian(self, u, project):
        data = super().hessian(u, project)
        self.mass.add_to(data, self.asm.pattern, 1.0 / self.h**2 + self.alpha / self.h)
        if self.K_n is not None:
            data += self.K_n.data / self.h
        return data


class _MixedPressure:
    """The pressure and volume of the locking-free formulations carried as Newton unknowns.

    Mean dilatation and nodal pressure are the three-field (u, p, J) problem with p and J condensed
    per group: J_g = Theta_g(u) / V_g and p_g = U'(J_g).  Newton on u alone evaluates the pressure
    U'(J_g(u)) after each step, so a step whose volume change is right to first order carries
    U'' x its second-order error (lambda times it) into the next matrix; near incompressibility
    the steps are then cut to 1e-3 or less.  The three-field Newton (FElupe's plain Newton on
    P2/P0 does this) linearises the constraint instead: after a step d the group's volume is its
    prediction Jbar = J + b_g . d / V_g and its pressure p = U'(J) + U''(J)(Jbar - J).  Here the
    matrix takes those (p U' of the measure's Hessian, U''(Jbar) / V b b^T) while the residual,
    the energy and the convergence test stay those of the condensed problem: at convergence
    Jbar = J and p = U'(J), the matrix is the exact Hessian, and the answer is the same.
    """

    def __init__(self, asm, u):
        from ..assembly import volumetric
        self.asm, self.scatter_cells, self.scatter_patches = asm, volumetric._scatter_cells, volumetric._scatter_patches
        self.state = [self._consistent(c, self._theta(c, u)[0]) for c in asm.couplings]
        self.last = None                # per coupling (J, b_g . d per unit step needs fe) of the last matrix

    def _U(self, u):
        m = self.asm.model
        return u.reshape(m.n_points, m.dofs_per_node)

    def _theta(self, c, u, stiffness=False):
        ue = np.ascontiguousarray(self._U(u)[c.cells])
        J = (c.S @ c.kernel.energy(c.D, ue)) / c.V
        if not stiffness:
            return J, None, None
        fe, Ke = c.kernel.forces_and_stiffness(c.D, ue)
        return J, fe, Ke

    @staticmethod
    def _derivatives(c, J):
        with np.errstate(all="ignore"):
            _, dU, d2U = (np.broadcast_to(np.asarray(x, dtype=float), J.shape) for x in c.function(J, **c.params))
        return dU, d2U

    def _consistent(self, c, J):
        return J.copy(), self._derivatives(c, J)[0].copy()

    def copy(self):
        return [(J.copy(), p.copy()) for J, p in self.state]

    def restore(self, state):
        self.state = [(J.copy(), p.copy()) for J, p in state]

    def correct(self, u, data) -> None:
        """Turn the condensed Hessian in data (at u) into the three-field one (see the class)."""
        self.last = []
        for c, (Jbar, p) in zip(self.asm.couplings, self.state):
            J, fe, Ke = self._theta(c, u, stiffness=True)
            dU, d2U = self._derivatives(c, J)
            _, d2Ubar = self._derivatives(c, Jbar)
            self.last.append((J, fe, dU, d2U))
            dp = c.ST @ (p - dU)
            dc = (d2Ubar - d2U) / c.V
            if c.formulation == "mean_dilatation":
                self.scatter_cells(data, Ke, fe, dp, dc, c.positions)
            else:
                self.scatter_cells(data, Ke, fe, dp, np.zeros(len(dp)), c.positions)
                b = c.B @ fe.ravel()
                for (members, slots), pos in zip(c._patch_index, c.patch_positions):
                    self.scatter_patches(data, b, slots, members, dc, pos)

    def advance(self, d, a) -> None:
        """The step a d from the point of the last matrix: each group's predicted volume and pressure."""
        U = self._U(d)
        state = []
        for c, (J, fe, dU, d2U) in zip(self.asm.couplings, self.last):
            bd = -np.einsum("ei,ei->e", fe, np.ascontiguousarray(U[c.cells]).reshape(len(c.cells), -1))
            Jbar = J + a * (c.S @ bd) / c.V
            state.append((Jbar, dU + d2U * (Jbar - J)))
        self.state, self.last = state, None

    def reset(self, u) -> None:
        """Back to the condensed problem's own pressure at u (after a projected or restored step)."""
        self.state = [self._consistent(c, self._theta(c, u)[0]) for c in self.asm.couplings]
        self.last = None


def newton(ctx: Context, potential: _Potential, u: np.ndarray, target_c: np.ndarray, where: str):
    """Minimise the potential over the free dofs with u[fixed] -> target_c; returns (u, iterations).

    Directions: the exact Hessian (the three-field one with locking-free formulations, see
    _MixedPressure), PSD-projected while it does not give descent (ctx.project None) and back to
    exact after a projected full step that cuts the residual tenfold.  Steps: Armijo backtracking on the
    energy, with a watchdog that, while every step so far was a full one, takes up to _WATCHDOG
    full steps raising the energy (plain Newton, as most FE codes take) before returning to the
    last certified point and backtracking from there.  Convergence: the residual
    on the free dofs below newton_tolerance x the force scale, or below the round-off floor
    (Context.roundoff_floor) after a full step."""
    model, s = ctx.model, ctx.model.solver
    fixed, free = model.fixed_dofs, model.free_dofs
    project = ctx.project is True
    fallback = ctx.project is None        # may switch projection on (and off again) for this solve
    u = u.copy()
    g = potential.gradient(u)
    Pi, mag = potential.value(u)
    force_scale = max(potential.force_scale(u), 1e-30)
    mixed = _MixedPressure(ctx.asm, u) if getattr(ctx.asm, "couplings", None) else None
    # the watchdog needs one energy along the whole path: not with a follower pressure (path work)
    watchdog = potential.pressure is None
    anchor = None                         # the last certified point while relaxed steps run
    floor, full = 0.0, False
    res = np.inf
    for it in range(1, s.newton_max_iterations + 1):
        du_c = target_c - u[fixed]
        moving = bool(np.any(du_c))
        # reactions (gradient on fixed dofs) set the force scale when there is no load
        scale = max(force_scale, safe_norm(g[fixed]))
        res = safe_norm(g[free])
        if not (np.isfinite(res) and np.isfinite(scale)):
            # inf <= tol * inf would pass the test below: a load or state beyond float range is no solution
            raise TensormassError(f"{where}: the residual or the load is not finite (|residual| = {res:.3g}, "
                                  f"|load| = {scale:.3g}): loads or displacements beyond floating-point range")
        if not moving and (res <= s.newton_tolerance * scale or (full and res <= floor)):
            ctx.residual = (u, g)              # reactions at u (runtime.physics.reactions), no extra assembly
            return u, it - 1
        if anchor is not None and anchor["count"] >= _WATCHDOG:
            # the relaxed steps did not pay: back to the certified point, backtrack along its direction
            u, g, Pi, mag, d, slope = (anchor[k] for k in ("u", "g", "Pi", "mag", "d", "slope"))
            if mixed is not None:
                mixed.restore(anchor["mixed"])
                mixed.last = anchor["last"]
            watchdog, anchor = False, None
            found = _line_search(potential, u, d, g, Pi, mag, slope, False)
            if found is None:
                raise TensormassError(f"{where}: line search failed (residual {res:.3e}); the load step is too "
                                      "large or elements invert: use more steps")
            u, a, Pi, mag, g_new = found[:5]
            if mixed is not None:
                mixed.advance(d, a) if mixed.last is not None else mixed.reset(u)
            potential.accept(u)
            g = potential.gradient(u) if g_new is None else g_new
            full = False
            continue
        try:
            data = potential.hessian(u, project)
            if mixed is not None and not project:
                mixed.correct(u, data)
            d = ctx.solve(data, -g, du_c)
        except TensormassError:
            if fallback and not project:            # e.g. CG on an indefinite matrix
                project = True
                continue
            raise
        floor = ctx.roundoff_floor(data)
        ctx.newton_iterations += 1
        slope = float(g @ d)
        if not moving and slope >= 0.0:
            if fallback and not project:            # indefinite Hessian: retry with PSD projection
                project = True
                if mixed is not None:
                    mixed.reset(u)
                continue
            raise TensormassError(f"{where}: Newton direction is not a descent direction even with "
                                  f"PSD projection (residual {res:.3e}); a singular stiffness? "
                                  "check that every rigid-body motion is fixed")
        # relaxed steps only while this solve has been plain Newton: once a step was cut, the energy decides
        relax = watchdog and not moving and (anchor is None or anchor["count"] < _WATCHDOG)
        found = _line_search(potential, u, d, g, Pi, mag, slope, moving, relax)
        if found is None:
            if fallback and not project:
                project = True
                if mixed is not None:
                    mixed.reset(u)
                continue
            raise TensormassError(f"{where}: line search failed (residual {res:.3e}); the load step is too "
                                  "large or elements invert: use more steps")
        u_new, a, Pi_new, mag_new, g_new, relaxed = found
        if relaxed and anchor is None:
            anchor = {"u": u, "g": g, "Pi": Pi, "mag": mag, "d": d, "slope": slope, "count": 0,
                      "mixed": None if mixed is None else mixed.copy(),
                      "last": None if mixed is None else mixed.last}
        if mixed is not None and not project:
            mixed.advance(d, a)
        potential.accept(u_new)
        tiny = np.abs(a * d).max() <= 1e-13 * max(np.abs(u_new).max(), 1e-9 * model.size)
        u, Pi, mag = u_new, Pi_new, mag_new
        g = potential.gradient(u) if g_new is None else g_new
        full = a == 1.0
        watchdog = watchdog and full
        if anchor is not None:
            anchor["count"] += 1
            if Pi <= anchor["Pi"] + _ARMIJO * anchor["slope"] + _ROUNDOFF * max(mag, anchor["mag"]):
                anchor = None                       # the energy fell below the certified point: go on
        if fallback and project and full and ctx.project is None and safe_norm(g[free]) <= 0.1 * res:
            project = False                         # in the basin: back to the exact Hessian
            if mixed is not None:
                mixed.reset(u)
        if tiny and not np.any(target_c - u[fixed]):
            ctx.residual = (u, g)
            return u, it
    res = safe_norm(g[free])
    raise TensormassError(f"{where}: Newton did not converge in {s.newton_max_iterations} iterations "
                          f"(residual {res:.3e}, tolerance {s.newton_tolerance * scale:.3e}, round-off floor "
                          f"{floor:.3e}); use more steps or a larger newton_max_iterations")


def _line_search(potential, u, d, g, Pi0, mag0, slope, moving, relax=False):
    """Backtracking: halve until Pi decreases enough (or, while boundaries move, is finite).

    Returns (u, a, Pi, magnitude, gradient or None, relaxed).  Near a solution the energy
    change drowns in round-off (I1 - 3 at small strain cancels ~1/strain^2 digits),
    so a full step whose energy change is tiny is also accepted when it halves
    the residual.  relax: a finite full step is taken even when the energy rises
    (relaxed = True; newton's watchdog decides whether it paid).
    """
    a = 1.0
    for _ in range(_MAX_HALVINGS):
        trial = u + a * d
        Pi, mag = potential.value(trial)
        if moving:
            ok = np.isfinite(Pi)
        else:
            ok = Pi <= Pi0 + _ARMIJO * a * slope + _ROUNDOFF * max(mag, mag0)
        if ok:
            return trial, a, Pi, mag, None, False
        if a == 1.0 and not moving and abs(Pi - Pi0) <= _NOISE * max(mag, mag0):
            g_trial = potential.gradient(trial)
            free = potential.free
            if safe_norm(g_trial[free]) <= 0.5 * safe_norm(g[free]):
                return trial, a, Pi, mag, g_trial, False
        if a == 1.0 and relax and np.isfinite(Pi):
            return trial, a, Pi, mag, None, True
        a *= 0.5
    return None


# --------------------------------------------------------------------------- integrators


class _Integrator:
    kind = ""
    # The kernel outputs this integrator calls (the model loads and compiles exactly these); energy
    # serves the line search, the health monitor's energy balance and reports.
    outputs: tuple = ()

    def __init__(self, ctx: Context):
        self.ctx, self.model = ctx, ctx.model
        self.n_steps = int(ctx.model.solver.steps)
        if self.n_steps < 1:
            raise TensormassError(f"solver.steps must be >= 1, got {self.n_steps}")

    def prescribed(self, fraction: float) -> np.ndarray:
        """Values of the fixed dofs at run fraction s (the ramp, amplitudes, rigid motions: runtime.physics.motion)."""
        return self.model.motion.displacement(fraction)

    def external_force(self, fraction: float) -> np.ndarray:
        """External loads at run fraction s (static default: s f_ext; dynamic default: f_ext; amplitudes).
        Follower pressures with amplitudes take their values at s here too (before forces(u) is asked)."""
        pressure, motion = getattr(self.model, "pressure", None), self.model.motion
        if pressure is not None and getattr(pressure, "amplitude_names", None):
            pressure.set_factors({n: motion.factor(n, fraction, load=True) for n in pressure.amplitude_names})
        return motion.forces(fraction)


class Static(_Integrator):
    """Load stepping with Newton + line search on Pi(u) = W(u) - lambda f_ext.u."""
    kind = "static"
    outputs = ("energy", "forces", "stiffness")

    def __init__(self, ctx):
        super().__init__(ctx)
        if self.model.n_user_fixed == 0:
            raise TensormassError("static: no node is fixed, so the body can move as a rigid body and has "
                                  "no equilibrium; add a fixed box (or use a dynamic solver)")

    def step(self, k: int) -> dict:
        ctx, lam = self.ctx, k / self.n_steps
        before = ctx.newton_iterations
        potential = _Potential(ctx.asm, self.external_force(lam), lam)
        ctx.u, _ = newton(ctx, potential, ctx.u, self.prescribed(lam),
                          f"static: load step {k}/{self.n_steps}")
        ctx.t = lam
        return {"time": lam, "newton": ctx.newton_iterations - before}


class _Dynamic(_Integrator):
    """Fixed-dt time stepping; a failed step is retried as two half steps (a few times)."""

    def __init__(self, ctx):
        super().__init__(ctx)
        s = self.model.solver
        self.dt = float(s.dt)
        if not (self.dt > 0 and np.isfinite(self.dt)):
            raise TensormassError(f"solver.dt must be > 0, got {s.dt}")
        self.alpha, self.beta = (float(x) for x in s.rayleigh)
        self.duration = self.dt * self.n_steps
        self.mass = self.model.mass_matrix        # runtime.assembly.mass.MassMatrix: M @ x, M.add_to(...)

    def boundary_velocity(self, u=None, t=None, h=None):
        """Velocity of the fixed dofs over the step from t to t + h (u: the state at t).

        The linear ramp's constant velocity; with rigid motions or amplitudes the finite
        difference that lands the fixed dofs on the motion at t + h (runtime.physics.motion).
        """
        motion = self.model.motion
        if motion.moving and u is None:
            raise TensormassError(f"{self.kind}: moving boundaries need boundary_velocity(u, t, h)")
        s1 = None if t is None else (t + h) / self.duration
        return motion.boundary_velocity(u, s1, h)

    def step(self, k: int) -> dict:
        ctx = self.ctx
        before = ctx.newton_iterations
        ctx.u, ctx.v = self._advance(ctx.u, ctx.v, ctx.t, self.dt, 0, k)
        ctx.t = k * self.dt
        return {"time": ctx.t, "newton": ctx.newton_iterations - before}

    def _advance(self, u, v, t, h, depth, k):
        try:
            u1, v1 = self.single(u, v, t, h)
            if not (np.all(np.isfinite(u1)) and np.all(np.isfinite(v1))):
                raise TensormassError("the step produced NaN/Inf")
            self.ctx.check_not_inverted(u1)
            return u1, v1
        except TensormassError as exc:
            if depth >= _MAX_DT_HALVINGS:
                raise TensormassError(f"{self.kind}: step {k} failed even with dt = {h:.3g} "
                                      f"({self.dt:.3g} halved {depth} times): {exc}") from None
            u, v = self._advance(u, v, t, h / 2, depth + 1, k)
            return self._advance(u, v, t + h / 2, h / 2, depth + 1, k)


class ImplicitEuler(_Dynamic):
    """Baraff-Witkin linearly implicit Euler, one linearisation per step:

    (M + h D + h^2 K) dv = h (f(x, v) - h K v),  f = f_int + f_ext - D v,  D = alpha M + beta K.
    """
    kind = "implicit_euler"
    outputs = ("energy", "forces", "stiffness")

    def __init__(self, ctx):
        super().__init__(ctx)
        self._last_dv = None

    def single(self, u, v, t, h):
        ctx = self.ctx
        f_int, K = ctx.asm.forces_and_stiffness(u, ctx.project is True)
        Kv = ctx.asm.matrix(K) @ v
        f = f_int + self.external_force((t + h) / self.duration) - self.alpha * (self.mass @ v) - self.beta * Kv
        A = self.mass.added((h * self.beta + h * h) * K, ctx.asm.pattern, 1.0 + h * self.alpha)
        if self.model.pressure is not None:
            f += self.model.pressure.forces(u)
            self.model.pressure.add_stiffness(A, ctx.asm.pattern, u, h * h)
        dv_c = self.boundary_velocity(u, t, h) - v[self.model.fixed_dofs]
        # CG starts from the previous step's dv: consecutive steps change v alike
        dv = ctx.solve(A, h * (f - h * Kv), dv_c, x0=self._last_dv)
        self._last_dv = dv if h == self.dt else None
        ctx.newton_iterations += 1
        v1 = v + dv
        u1 = u + h * v1
        # the step's equation, A dv / h - (f - h K v) = 0, on every dof: its fixed rows are the reactions
        ctx.residual = (u1, ctx.reduce(ctx.asm.matrix(A) @ dv / h - (f - h * Kv)))
        return u1, v1


class BackwardEuler(_Dynamic):
    """Fully implicit Euler: Newton on the incremental potential (see _IncrementalPotential)."""
    kind = "backward_euler"
    outputs = ("energy", "forces", "stiffness")

    def single(self, u, v, t, h):
        ctx = self.ctx
        K_n = None
        if self.beta:
            K_n = ctx.asm.matrix(self.beta * ctx.asm.stiffness(u, ctx.project is True))
        potential = _IncrementalPotential(ctx.asm, self.external_force((t + h) / self.duration), self.mass, h, u, v,
                                          self.alpha, K_n)
        target = self.prescribed((t + h) / self.duration)
        u1, _ = newton(ctx, potential, u, target, f"backward_euler: time {t + h:.6g}")
        return u1, (u1 - u) / h


class Explicit(_Dynamic):
    """Symplectic Euler: v += h M^-1 f(x, v); x += h v.  Stops when it detects instability."""
    kind = "explicit"
    outputs = ("forces", "energy")            # energy every few steps only (health monitor, reports)

    def __init__(self, ctx):
        super().__init__(ctx)
        if self.mass.kind != "lumped":
            raise TensormassError("explicit integration needs the lumped mass (solver.mass = 'lumped'): it "
                                  "inverts the diagonal; use implicit_euler or backward_euler with 'consistent'")
        self.mass = self.model.mass               # the lumped masses per dof
        free = self.model.free_dofs
        if np.any(self.mass[free] <= 0):
            raise TensormassError("explicit integration needs a positive mass at every free node (density > 0)")
        self.inv_mass = np.where(self.mass > 0, 1.0 / np.maximum(self.mass, 1e-300), 0.0)
        self.stable_dt = None             # set by the Simulation (stable_time_step)
        self._growth = 0
        self._speed = 0.0

    def single(self, u, v, t, h):
        ctx, free, fixed = self.ctx, self.model.free_dofs, self.model.fixed_dofs
        f_int = ctx.asm.forces(u)
        f = f_int + self.external_force(t / self.duration) - self.alpha * self.mass * v
        if self.model.pressure is not None:
            f += self.model.pressure.forces(u)
        if self.beta:
            f -= self.beta * _stiffness_times(ctx.asm, u, v, f_int, self.model.size)
        v1 = v.copy()
        v1[free] += h * self.inv_mass[free] * f[free]
        v1[fixed] = self.boundary_velocity(u, t, h)
        u1 = u + h * v1
        # M (v1 - v) / h - f(u, v): zero on the free dofs, the reactions over the step on the fixed ones
        ctx.residual = (u1, self.mass * (v1 - v) / h - f)
        return u1, v1

    def step(self, k: int) -> dict:
        # no dt halving here: an explicit blow-up is a too-large dt, reported clearly
        ctx = self.ctx
        u1, v1 = self.single(ctx.u, ctx.v, ctx.t, self.dt)
        self._check(u1, v1, k)
        ctx.u, ctx.v, ctx.t = u1, v1, k * self.dt
        return {"time": ctx.t, "newton": 0}

    def _check(self, u, v, k):
        """Unstable: NaN/Inf, displacement > 1e3 x size, or |v| growing > 1.5x for 20 steps running."""
        finite = np.all(np.isfinite(u)) and np.all(np.isfinite(v))
        speed = float(np.linalg.norm(v)) if finite else np.inf
        self._growth = self._growth + 1 if speed > 1.5 * self._speed and speed > 0 else 0
        self._speed = speed
        huge = finite and np.abs(u).max() > 1e3 * self.model.size
        if finite and not huge and self._growth < 20:
            return
        raise TensormassError(f"explicit integration unstable at step {k}: {self.instability_hint()}")

    def instability_hint(self) -> str:
        """Why an explicit run diverges: dt against the stable step estimated at rest."""
        crit = self.stable_dt
        if crit is not None and self.dt > crit:
            why = f"dt = {self.dt:.3g} exceeds the estimated stable step {crit:.3g}"
        elif crit is not None:
            why = (f"dt = {self.dt:.3g} is below the estimated stable step {crit:.3g} at rest, "
                   "but the deformed body is stiffer")
        else:
            why = f"dt = {self.dt:.3g} is probably above the stable step"
        return f"{why}; reduce dt or use implicit_euler / backward_euler"


def _stiffness_times(asm, u, x, f_int, size):
    """K x by a forward difference of the forces (explicit runs load no stiffness kernel)."""
    norm = np.abs(x).max()
    if norm == 0:
        return np.zeros_like(x)
    eps = 1e-7 * size / norm
    return (f_int - asm.forces(u + eps * x)) / eps


def stable_time_step(ctx: Context) -> float:
    """2 / omega_max at rest, omega_max^2 = largest eigenvalue of M^-1 K on the free dofs.

    K x comes from central differences of the forces, so only the forces kernel is
    needed; the eigenvalue from Lanczos (eigsh) on M^-1/2 K M^-1/2.
    """
    model, asm = ctx.model, ctx.asm
    free = model.free_dofs
    m = model.mass[free]
    if free.size == 0 or np.any(m <= 0):
        return np.inf if free.size == 0 else 0.0
    scale = 1.0 / np.sqrt(m)
    zero = np.zeros(model.n_dofs)

    def matvec(x):
        y = zero.copy()
        y[free] = scale * np.ravel(x)
        eps = 1e-6 * model.size / max(np.abs(y).max(), 1e-300)
        Ky = (asm.forces(-eps * y) - asm.forces(eps * y)) / (2 * eps)
        return scale * Ky[free]

    n = free.size
    if n <= 60:
        A = np.column_stack([matvec(e) for e in np.eye(n)])
        lam = float(np.linalg.eigvalsh(0.5 * (A + A.T)).max())
    else:
        op = spla.LinearOperator((n, n), matvec=matvec, dtype=float)
        v0 = np.random.default_rng(0).standard_normal(n)
        lam = float(spla.eigsh(op, k=1, which="LA", tol=1e-4, v0=v0, ncv=min(n - 1, 30),
                               return_eigenvectors=False)[0])
    return 2.0 / np.sqrt(lam) if lam > 0 else np.inf


# --------------------------------------------------------------------------- generalized-alpha
#
# Generalized-alpha (Chung-Hulbert 1993): second-order implicit dynamics with controllable damping.
#
#     [solver]
#     kind = "generalized_alpha"
#     rho_inf = 1.0        # spectral radius at infinite frequency: 1 = no numerical damping, < 1 damps high frequencies
#
# The equation of motion is enforced at the intermediate times
# t_{n+1-alpha_f} (elastic, damping and external forces) and t_{n+1-alpha_m}
# (inertia), x_{n+1-alpha} = (1 - alpha) x_{n+1} + alpha x_n:
#
#     M a_{n+1-alpha_m} + D v_{n+1-alpha_f} - f_int(u_{n+1-alpha_f}) - f_ext = 0
#
# with Newmark's update u_{n+1} = u_n + h v_n + h^2 ((1/2 - beta) a_n + beta a_{n+1}),
# v_{n+1} = v_n + h ((1 - gamma) a_n + gamma a_{n+1}) and, from rho_inf (0 <= rho_inf <= 1),
#
#     alpha_m = (2 rho_inf - 1) / (rho_inf + 1),  alpha_f = rho_inf / (rho_inf + 1),
#     gamma = 1/2 - alpha_m + alpha_f,            beta = (1 - alpha_m + alpha_f)^2 / 4.
#
# Second order for every rho_inf; rho_inf = 1 (alpha_m = alpha_f = 1/2, gamma = 1/2,
# beta = 1/4) is the trapezoidal rule / implicit midpoint rule: no numerical
# damping, the energy of a linear undamped system is conserved exactly, and
# for nonlinear laws the energy error per step is the midpoint rule's O(h^3)
# (bounded oscillation, no systematic drift while the motion is resolved).
#
# Unknown: y = u_{n+1-alpha_f}.  The residual above is the gradient in y of an
# incremental potential, W(y) - f_ext . y + Q(y) with Q quadratic (inertia and
# Rayleigh damping, D = alpha M + beta K(u_n) frozen over the step as in backward
# Euler), so the step is a Newton solve with the shared line search, PSD fallback
# and dt halving (runtime.physics.integrators.newton and _Dynamic).  The state carries the
# acceleration a_n, started from the equation of motion at t = 0 (M a_0 = f_ext +
# f_int(u_0) - D v_0) so that the scheme keeps its second order.
#
# Prescribed displacements: the fixed dofs of u_{n+1} take the prescribed values
# (so y takes (1 - alpha_f) u_{n+1} + alpha_f u_n there); their velocity and
# acceleration are backward differences of the prescribed path (exact for the
# linear ramp of a run; no ringing at a kink of an amplitude table).


def _sparse_solve(A, b):
    """A x = b for the consistent mass block (SPD, sparse)."""
    return spla.spsolve(A, b)


def alpha_parameters(rho_inf: float) -> tuple:
    """(alpha_m, alpha_f, gamma, beta) of Chung-Hulbert's generalized-alpha for spectral radius rho_inf."""
    rho = float(rho_inf)
    if not 0.0 <= rho <= 1.0:         # also refuses NaN
        raise TensormassError(f"solver.rho_inf must be in [0, 1] (1: no numerical damping, 0: the most "
                              f"high-frequency damping), got {rho_inf!r}")
    alpha_m = (2.0 * rho - 1.0) / (rho + 1.0)
    alpha_f = rho / (rho + 1.0)
    gamma = 0.5 - alpha_m + alpha_f
    beta = 0.25 * (1.0 - alpha_m + alpha_f) ** 2
    return alpha_m, alpha_f, gamma, beta


class _AlphaPotential(_Potential):
    """W(y) - f_ext . y + Q(y): Q(y) = 1/2 (y - y0)' H (y - y0) + g0 . (y - y0), H = c_m M + c_d D."""

    def __init__(self, asm, f_ext, mass, c_m, c_d, alpha, K_n, y0, g0, scale):
        super().__init__(asm, f_ext)
        self.mass, self.c_m, self.c_d, self.alpha, self.K_n = mass, c_m, c_d, alpha, K_n
        self.y0, self.g0, self.scale = y0, g0, scale

    def _H(self, x):
        out = (self.c_m + self.c_d * self.alpha) * (self.mass @ x)
        return out if self.K_n is None else out + self.c_d * (self.K_n @ x)

    def extra(self, y):
        d = y - self.y0
        Hd = self._H(d)
        q = 0.5 * float(d @ Hd) + float(self.g0 @ d)
        return q, Hd + self.g0, abs(0.5 * float(d @ Hd)) + abs(float(self.g0 @ d))

    def force_scale(self, y):
        # the load, the inertia forces and the momentum change of the step (a body moving without load)
        return max(super().force_scale(y), self.scale)

    def hessian(self, y, project):
        data = super().hessian(y, project)          # the stiffness (and a follower pressure's)
        self.mass.add_to(data, self.asm.pattern, self.c_m + self.c_d * self.alpha)
        if self.K_n is not None:
            data += self.c_d * self.K_n.data
        return data


class GeneralizedAlpha(_Dynamic):
    """Generalized-alpha (see the module docstring); rho_inf = 1: energy-conserving trapezoidal rule."""
    kind = "generalized_alpha"
    outputs = ("energy", "forces", "stiffness")

    def __init__(self, ctx):
        super().__init__(ctx)
        self.rho_inf = float(getattr(self.model.solver, "rho_inf", 1.0))
        self.alpha_m, self.alpha_f, self.gamma, self.newmark_beta = alpha_parameters(self.rho_inf)
        # accelerations of the states single() has produced this step, by the identity of their u
        # (the base class's dt halving passes states on as (u, v) only); kept alive with their u
        self._acc: dict = {}
        self.a = None                 # acceleration at (ctx.u, ctx.v); None: from the equation of motion

    # -- state ------------------------------------------------------------------------------------
    def initial_acceleration(self, u, v, t):
        """a_0 from M a_0 = f_ext(t) + f_int(u) - D v on the free dofs with mass (0 elsewhere)."""
        ctx, model, free = self.ctx, self.model, self.model.free_dofs
        r = ctx.asm.forces(u) + self.external_force(t / self.duration) - self.alpha * (self.mass @ v)
        if model.pressure is not None:
            r += model.pressure.forces(u)
        if self.beta and np.any(v):
            r -= self.beta * (ctx.asm.matrix(ctx.asm.stiffness(u, ctx.project is True)) @ v)
        a = np.zeros_like(u)
        if self.mass.kind == "lumped":
            m = self.mass.diagonal[free]
            a[free] = np.where(m > 0, r[free] / np.where(m > 0, m, 1.0), 0.0)
        else:           # consistent mass: M_ff a_f = r_f (prescribed dofs' acceleration taken as 0 here)
            M = self.mass.matrix()[free][:, free].tocsc()
            a[free] = _sparse_solve(M, r[free])
        return a

    def step(self, k: int) -> dict:
        ctx = self.ctx
        if self.a is None:
            self.a = self.initial_acceleration(ctx.u, ctx.v, ctx.t)
        self._acc = {id(ctx.u): (ctx.u, self.a)}
        try:
            info = super().step(k)
            self.a = self._acc[id(ctx.u)][1]
        finally:
            self._acc = {}
        return info

    # -- one step -----------------------------------------------------------------------------------
    def single(self, u, v, t, h):
        ctx, model = self.ctx, self.model
        fixed, free = model.fixed_dofs, model.free_dofs
        known = self._acc.get(id(u))
        a = known[1] if known is not None and known[0] is u else self.initial_acceleration(u, v, t)
        am, af, gamma, beta = self.alpha_m, self.alpha_f, self.gamma, self.newmark_beta
        mass = self.mass
        K_n = None
        if self.beta:
            K_n = ctx.asm.matrix(self.beta * ctx.asm.stiffness(u, ctx.project is True))

        def damp(x):
            out = self.alpha * (mass @ x)
            return out if K_n is None else out + K_n @ x

        def kinematics(u1):
            a1 = (u1 - u - h * v) / (beta * h * h) - (0.5 / beta - 1.0) * a
            return a1, v + h * ((1.0 - gamma) * a + gamma * a1)

        # residual's quadratic part at y0 = u (u_{n+1} = u_n)
        a1, v1 = kinematics(u)
        g0 = mass @ ((1.0 - am) * a1 + am * a) + damp((1.0 - af) * v1 + af * v)
        c_m = (1.0 - am) / ((1.0 - af) * beta * h * h)
        c_d = gamma / (beta * h)
        scale = max(safe_norm(g0[free]), safe_norm((mass @ a)[free]))
        # loads at t_{n+1-alpha_f} (amplitudes: runtime.physics.motion); a follower pressure at y itself
        # (t first: a pressure amplitude is left at t + h, the state y's time, by the second call)
        f_then = self.external_force(t / self.duration)
        f_alpha = (1.0 - af) * self.external_force((t + h) / self.duration) + af * f_then
        potential = _AlphaPotential(ctx.asm, f_alpha, mass, c_m, c_d, self.alpha, K_n, u, g0, scale)
        target_u = self.prescribed((t + h) / self.duration)
        target_y = (1.0 - af) * target_u + af * u[fixed]
        # Newton starts from the Taylor predictor (the step from u_n when that inverts an element)
        guess = u + h * v + 0.5 * h * h * a
        guess[fixed] = target_u
        y = (1.0 - af) * guess + af * u
        try:
            ctx.check_not_inverted(y)
        except InvertedElementError:
            y = u.copy()
        y[fixed] = target_y
        y, _ = newton(ctx, potential, y, target_y, f"{self.kind}: time {t + h:.6g}")
        u1 = (y - af * u) / (1.0 - af)
        u1[fixed] = target_u
        ctx.residual = (u1, ctx.residual[1])      # the equation solved at t_{n+1-alpha_f} (reactions)
        a1, v1 = kinematics(u1)
        # boundary velocity and acceleration: backward differences of the prescribed path
        v1[fixed] = (target_u - u[fixed]) / h
        a1[fixed] = (v1[fixed] - v[fixed]) / h
        self._acc[id(u1)] = (u1, a1)
        return u1, v1


_KINDS = {"static": Static, "implicit_euler": ImplicitEuler, "backward_euler": BackwardEuler,
          "explicit": Explicit, "generalized_alpha": GeneralizedAlpha}


def integrator_class(kind: str) -> type:
    """The integrator of a solver kind (a TensormassError naming the known kinds otherwise)."""
    try:
        return _KINDS[kind]
    except KeyError:
        raise TensormassError(f"unknown solver kind {kind!r}; known: {', '.join(_KINDS)}") from None


def outputs_for(kind: str) -> tuple:
    """The kernel outputs a solver kind needs: its integrator's declared `outputs`."""
    return integrator_class(kind).outputs


def make_integrator(ctx: Context):
    return integrator_class(ctx.model.solver.kind)(ctx)

