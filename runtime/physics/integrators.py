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

from ..base.integrator_kinds import KINDS
from ..base.errors import InvertedElementError, TensormassError
from .health import safe_norm
from . import saddle
from .newton import Context, IncrementalPotential, Potential, newton

__all__ = ["make_integrator", "integrator_class", "outputs_for", "Static", "ImplicitEuler", "BackwardEuler", "Explicit",
           "GeneralizedAlpha", "StepBudget", "stable_time_step"]

# Dynamic steps that fail (NaN, inversion, no convergence) are retried with dt/2 this many times.
_MAX_DT_HALVINGS = 3
# explicit runs: a nodal rotation past this (radians, about 160 turns) is a run away, not a motion
MAX_ROTATION = 1e3


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
    outputs = KINDS["static"].outputs       # runtime.base.integrator_kinds

    def __init__(self, ctx):
        super().__init__(ctx)
        if self.model.n_user_fixed == 0:
            raise TensormassError("static: no node is fixed, so the body can move as a rigid body and has "
                                  "no equilibrium; add a fixed box (or use a dynamic solver)")

    def step(self, k: int) -> dict:
        ctx, lam = self.ctx, k / self.n_steps
        before = ctx.newton_iterations
        if ctx.history is not None:        # viscous materials: each load step lasts solver.dt
            ctx.history.prepare(self.model.solver.dt)
        potential = Potential(ctx.asm, self.external_force(lam), lam)
        ctx.u = solve_step(ctx, potential, ctx.u, self.prescribed(lam), f"static: load step {k}/{self.n_steps}",
                           (k - 1) / self.n_steps, lam, 1.0)
        if ctx.history is not None:
            ctx.history.commit(ctx.u)
            ctx.t = k * self.model.solver.dt
            return {"time": ctx.t, "newton": ctx.newton_iterations - before}
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
        history, pressures = self.ctx.history, self.ctx.pressures
        p0 = None if pressures is None else pressures.get()     # a failed step puts them back
        try:
            if history is not None:        # viscous materials: the step's g and H (runtime.physics.viscous)
                history.prepare(h)
            u1, v1 = self.single(u, v, t, h)
            if not (np.all(np.isfinite(u1)) and np.all(np.isfinite(v1))):
                raise TensormassError("the step produced NaN/Inf")
            self.ctx.check_not_inverted(u1)
            if history is not None:
                history.commit(u1)
            return u1, v1
        except TensormassError as exc:
            if pressures is not None:
                pressures.set(p0)
            if depth >= _MAX_DT_HALVINGS:
                raise TensormassError(f"{self.kind}: step {k} failed even with dt = {h:.3g} "
                                      f"({self.dt:.3g} halved {depth} times): {exc}") from None
            u, v = self._advance(u, v, t, h / 2, depth + 1, k)
            return self._advance(u, v, t + h / 2, h / 2, depth + 1, k)


class StepBudget:
    """The budgeted implicit Euler step's rule for keeping K, and an estimate of what keeping it cost.

    A kept K serves until it is `every` steps old, or until the step error estimated from the forces
    passes `tolerance` (ImplicitEuler._drift): both read the state, never a clock.

    The cost: while K0 (assembled at the state u_r) is kept, step j is off the exact step from the same
    state by e_j = A0^-1 h^2 (K_j - K0) v1_j in velocity (the two step equations subtracted).  Taking
    K_j - K0 as growing with the distance from u_r, K_j - K0 = s_j (K_R - K0) with s_j = |u_j - u_r| /
    |u_R - u_r| (u_R: where the next refresh assembles K_R), and each velocity error as moving the
    positions for tau_j = max(h, 1 / omega_j) (a quarter period of the motion, omega_j from Rayleigh's
    quotient of the displacement, before the exact forces turn it back), the positions are off by about
        z = sum_j tau_j e_j = A0^-1 h^2 (K_R - K0) w,   w = sum_j s_j tau_j v1_j,
    computed at that refresh from its K_R, or after the run's last step from K there (two products
    and one solve with the kept factor).  `error` is the largest |z|_inf over the largest |u|_inf so
    far: the interval that cost most.  The intervals are not
    summed: the forces are exact, so each interval's error is pulled back towards the exact path.
    A model, not a bound: docs/guide/interactive.md compares it with measured errors.
    """

    def __init__(self, every: int, tolerance: float):
        self.every, self.tolerance = every, tolerance
        self.age = 0                        # steps the kept K has served
        self.refreshes = 0                  # K assembled and factorised for the steps
        self.checks = 0                     # intervals estimated
        self.error = 0.0
        self.speed = 0.0                    # the largest |v1|_inf so far (the refresh rule's scale)
        self.amplitude = 0.0                # the largest |u|_inf so far
        self._origin = None                 # u_r
        self._weighted = None               # sum_j |u_j - u_r| tau_j v1_j
        self._omega = None                  # the motion's frequency in this interval

    def keeps(self, estimate: float) -> bool:
        """Whether the kept K serves this step too (its age and the estimate allow it)."""
        if self.age >= self.every or estimate > self.tolerance:
            return False
        self.age += 1
        return True

    def interval(self, u) -> np.ndarray | None:
        """w of the interval a refresh at u ends, or None (nothing kept since the last refresh)."""
        distance = float(np.linalg.norm(u - self._origin)) if self._origin is not None else 0.0
        if self._weighted is None or distance <= 0:
            return None
        return self._weighted / distance

    def estimated(self, z) -> None:
        """z: the position error estimated for the interval that ends now."""
        if self.amplitude > 0:
            self.checks += 1
            self.error = max(self.error, float(np.abs(z).max()) / self.amplitude)

    def refreshed(self, u) -> None:
        """A refresh at u."""
        self.age = 1
        self.refreshes += 1
        self._origin, self._weighted, self._omega = u.copy(), None, None

    def observe(self, u, u1, v1, h, frequency) -> None:
        """After a step from u to u1 with velocity v1; frequency(): the motion's (rad/s, or 0), asked once
        per interval (it changes as slowly as K)."""
        distance = float(np.linalg.norm(u - self._origin))
        if distance > 0:
            if self._omega is None:
                self._omega = frequency()
            omega = self._omega
            # a velocity error moves the positions for about a quarter period, 1 / omega, before the
            # (exact) forces turn it back; at least for the step itself
            x = distance * max(h, 1.0 / omega if omega > 0 else 0.0) * v1
            self._weighted = x if self._weighted is None else self._weighted + x
        self.speed = max(self.speed, float(np.abs(v1).max()))
        self.amplitude = max(self.amplitude, float(np.abs(u1).max()))

    def summary(self) -> dict:
        return {"stiffness_every": self.every,
                "stiffness_tolerance": self.tolerance if np.isfinite(self.tolerance) else None,
                "refreshes": self.refreshes, "checks": self.checks, "error_estimate": self.error}


class ImplicitEuler(_Dynamic):
    """Baraff-Witkin linearly implicit Euler, one linearisation per step:

    (M + h D + h^2 K) dv = h (f(x, v) - h K v),  f = f_int + f_ext - D v,  D = alpha M + beta K.

    The budgeted step (solver.stiffness_every = N > 1) keeps K, and so the step's matrix and its factor,
    for up to N steps (StepBudget's rule); the steps between take the forces at their own state with
    the kept matrix, which the linear solver solves with its kept factor.
    """
    kind = "implicit_euler"
    outputs = KINDS["implicit_euler"].outputs       # runtime.base.integrator_kinds

    def __init__(self, ctx):
        super().__init__(ctx)
        self._last_dv = None
        s = self.model.solver
        every = int(getattr(s, "stiffness_every", 1))
        self.budget = StepBudget(every, float(getattr(s, "stiffness_tolerance", np.inf))) if every > 1 else None
        self._kept = None                   # (h, K, A, A's diagonal on the free dofs) of the last assembly
        self._previous = None               # (forces, h) of the last step (budgeted step)

    def step(self, k: int) -> dict:
        info = super().step(k)
        kept = self._kept
        if k == self.n_steps and kept is not None and self.budget.age > 1:
            # the run's last interval: its estimate from K at the final state, with the kept factor (no
            # new factor: the steps are done)
            K = self.ctx.asm.stiffness(self.ctx.u, self.ctx.project is True)
            self._estimate(self.ctx.u, K, (kept[1], kept[2]), kept[0])
        return info

    def single(self, u, v, t, h):
        ctx = self.ctx
        f_int, K, A, stale, Kv = self._linearisation(u, v, h)
        if Kv is None:
            Kv = ctx.asm.matrix(K) @ v
        f = f_int + self.external_force((t + h) / self.duration) - self.alpha * (self.mass @ v) - self.beta * Kv
        if self.model.pressure is not None:
            f += self.model.pressure.forces(u)
        contact, extra = self.model.contact, None
        if contact is not None:             # penalty contact, linearised like the elastic forces
            f, extra = self._contact_terms(contact, u, t, h, f)
        if ctx.grab is not None:            # a viewer's grab (runtime.physics.grab): its constant Hessian
            f = f + ctx.grab.forces(u)
            extra = h * h * ctx.grab.hessian() if extra is None else extra + h * h * ctx.grab.hessian()
        dv_c = self.boundary_velocity(u, t, h) - v[self.model.fixed_dofs]
        if stale is not None:               # a refresh (budgeted step): what the interval it ends cost
            self._refresh(u, K, stale, h)
        pressure_forces = 0.0
        if ctx.pressures is not None:       # formulation "mixed": the pressures' increment with dv
            dv, pressure_forces = saddle.linearised_step(ctx, A, h * (f - h * Kv), dv_c, u, v, h)
        else:
            # CG starts from the previous step's dv: consecutive steps change v alike
            dv = ctx.solve(A, h * (f - h * Kv), dv_c, x0=self._last_dv, extra=extra)
        self._last_dv = dv if h == self.dt else None
        ctx.newton_iterations += 1
        residual = ctx.asm.matrix(A) @ dv / h - (f - h * Kv) + pressure_forces
        if extra is not None:
            residual = residual + extra @ dv / h
        v1 = v + dv
        u1 = u + h * v1
        if self.budget is not None:
            self.budget.observe(u, u1, v1, h, lambda: self._frequency(u1, K))
        # the step's equation, A dv / h - (f - h K v) = 0, on every dof: its fixed rows are the reactions
        ctx.residual = (u1, ctx.reduce(residual))
        return u1, v1

    def _frequency(self, u, K) -> float:
        """The frequency of the body's lowest motion, sqrt(u.Ku / u.Mu) (Rayleigh's quotient of the
        displacement, which the slow modes dominate), 0 at rest."""
        free = self.model.free_dofs
        uu = float(u[free] @ (self.mass @ u)[free])
        uk = float(u[free] @ (self.ctx.asm.matrix(K) @ u)[free])
        return float(np.sqrt(uk / uu)) if uu > 0 and uk > 0 else 0.0

    def _refresh(self, u, K, stale, h) -> None:
        """A refresh of the budgeted step: the estimate of the interval it ends (with the kept factor),
        then the fresh matrix gets a factor of its own."""
        self._estimate(u, K, stale, h)
        self.budget.refreshed(u)
        self.ctx.linear.drop_factor()

    def _estimate(self, u, K, stale, h) -> None:
        """The kept interval's position error z = A0^-1 h^2 (K - K0) w (StepBudget) at the state u where
        K was assembled, solved with the kept factor of A0."""
        ctx, budget = self.ctx, self.budget
        w = budget.interval(u) if stale[0] is not None else None
        if w is not None:
            r = h * h * (ctx.asm.matrix(K) @ w - ctx.asm.matrix(stale[0]) @ w)
            budget.estimated(ctx.solve(stale[1], r, np.zeros(self.model.fixed_dofs.size)))

    def _drift(self, f_int, Kv, h) -> float:
        """The velocity error keeping K makes on this step, estimated from the last step's motion:
        d = f(u) - f(u_prev) + K_kept (u - u_prev) is the stiffness K_kept misses along the motion
        (u - u_prev = h v), and h d over the kept matrix's diagonal the velocity it moves; over the
        largest speed so far.  Free: the forces and K_kept v are the step's own."""
        previous, budget = self._previous, self.budget
        if previous is None or previous[1] != h or budget.speed <= 0:
            return 0.0
        free = self.model.free_dofs
        d = f_int - previous[0] + h * Kv
        return h * float(np.abs(d[free] / self._kept[3]).max()) / budget.speed

    def _linearisation(self, u, v, h):
        """(f_int, K, A, stale, Kv): the forces at u, the stiffness and the step's matrix A = M' + (h beta + h^2) K
        (+ pressure's); stale: on a refresh of the budgeted step, the kept (K, A) it replaces ((None, None)
        when they were for another dt or there were none), else None; Kv: K v when it was needed already."""
        ctx, kept, budget = self.ctx, self._kept, self.budget
        if kept is not None and kept[0] == h:
            f_int = ctx.asm.forces(u)
            Kv = ctx.asm.matrix(kept[1]) @ v
            keep = budget.keeps(self._drift(f_int, Kv, h))
            self._previous = (f_int, h)
            if keep:
                return f_int, kept[1], kept[2], None, Kv
            K = ctx.asm.stiffness(u, ctx.project is True)
        else:
            f_int, K = ctx.asm.forces_and_stiffness(u, ctx.project is True)
        # the product is a new array: M is added to it in place
        A = self.mass.add_to((h * self.beta + h * h) * K, ctx.asm.pattern, 1.0 + h * self.alpha)
        if self.model.pressure is not None:
            self.model.pressure.add_stiffness(A, ctx.asm.pattern, u, h * h)
        if budget is None:
            return f_int, K, A, None, None
        self._previous = (f_int, h)             # what the next step's drift compares its forces with
        K = K.copy()                        # the assembler's output array goes back to its pool
        K.flags.writeable = A.flags.writeable = False       # kept: the solver may keep what it built of A
        self._kept = (h, K, A, ctx.asm.matrix(A).diagonal()[self.model.free_dofs])
        same = kept is not None and kept[0] == h
        return f_int, K, A, (kept[1], kept[2]) if same else (None, None), None

    def _contact_terms(self, contact, u, t, h, f):
        """Penalty contact's forces and h^2 x its Hessian at u, the obstacles at the step's end
        (implicit Euler takes penalty contact only: runtime.contact.base.METHODS_OF)."""
        contact.begin_step(u, t / self.duration, (t + h) / self.duration, h)
        contact.set_pose((t + h) / self.duration)
        H = contact.hessian(u, True)
        return f - contact.gradient(u), None if H is None else h * h * H


class BackwardEuler(_Dynamic):
    """Fully implicit Euler: Newton on the incremental potential (see IncrementalPotential)."""
    kind = "backward_euler"
    outputs = KINDS["backward_euler"].outputs       # runtime.base.integrator_kinds

    def single(self, u, v, t, h):
        ctx = self.ctx
        K_n = None
        if self.beta:
            K_n = ctx.asm.matrix(self.beta * ctx.asm.stiffness(u, ctx.project is True))
        potential = IncrementalPotential(ctx.asm, self.external_force((t + h) / self.duration), self.mass, h, u, v,
                                          self.alpha, K_n)
        target = self.prescribed((t + h) / self.duration)
        u1 = solve_step(ctx, potential, u, target, f"backward_euler: time {t + h:.6g}", t / self.duration,
                        (t + h) / self.duration, h)
        return u1, (u1 - u) / h


class Explicit(_Dynamic):
    """Symplectic Euler: v += h M^-1 f(x, v); x += h v.  Stops when it detects instability."""
    kind = "explicit"
    outputs = KINDS["explicit"].outputs       # runtime.base.integrator_kinds

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
        contact = self.model.contact
        if contact is not None:             # penalty contact (runtime.contact.penalty) at the step's start
            contact.begin_step(u, t / self.duration, (t + h) / self.duration, h)
            contact.set_pose(t / self.duration)
            f -= contact.gradient(u)
        if ctx.grab is not None:            # a viewer's grab (runtime.physics.grab)
            f += ctx.grab.forces(u)
        if self.beta:
            f -= self.beta * stiffness_times(ctx.asm, u, v, f_int, self.model.size)
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
        """Unstable: NaN/Inf, a translation > 1e3 x size or a rotation > 1e3 rad (shells), or |v|
        growing > 1.5x for 20 steps running."""
        finite = np.all(np.isfinite(u)) and np.all(np.isfinite(v))
        speed = float(np.linalg.norm(v)) if finite else np.inf
        self._growth = self._growth + 1 if speed > 1.5 * self._speed and speed > 0 else 0
        self._speed = speed
        dim, dpn = self.model.dim, self.model.dofs_per_node
        nodal = u.reshape(-1, dpn) if finite else None
        moved = 0.0 if nodal is None else float(np.abs(nodal[:, :dim]).max())
        turned = 0.0 if nodal is None or dpn == dim else float(np.abs(nodal[:, dim:]).max())
        if finite and moved <= 1e3 * self.model.size and turned <= MAX_ROTATION and self._growth < 20:
            return
        self._runaway = None
        if finite and turned > MAX_ROTATION and moved <= 1e3 * self.model.size:
            # not a too-large dt: the translations are bounded while a rotation runs away (an explicit
            # co-rotational shell under impacts, docs/limitations.md), at any dt tried
            self._runaway = (f"the nodal rotations reached {turned:.3g} rad while no node moved more than "
                             f"{moved:.3g} m; explicit shells' rotations run away under impacts at any dt; "
                             "use implicit_euler or backward_euler")
        raise TensormassError(f"explicit integration unstable at step {k}: {self.instability_hint()}")

    def instability_hint(self) -> str:
        """Why an explicit run diverges: a rotation that ran away (_check), else dt against the stable
        step estimated at rest."""
        if getattr(self, "_runaway", None):
            return self._runaway
        crit = self.stable_dt
        if crit is not None and self.dt > crit:
            why = (f"dt = {self.dt:.3g} s exceeds the estimated stable step {crit:.3g} s (2 / omega_max at rest, "
                   "summary stable_dt)")
        elif crit is not None:
            why = (f"dt = {self.dt:.3g} s is below the estimated stable step {crit:.3g} s at rest, "
                   "but the deformed body is stiffer")
        else:
            why = f"dt = {self.dt:.3g} is probably above the stable step"
        return f"{why}; reduce dt or use implicit_euler / backward_euler"


def stiffness_times(asm, u, x, f_int, size):
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
# and dt halving (runtime.physics.newton.newton and _Dynamic).  The state carries the
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


class _AlphaPotential(Potential):
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
    outputs = KINDS["generalized_alpha"].outputs       # runtime.base.integrator_kinds

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
        if model.contact is not None:       # penalty contact at t (runtime.contact.base.METHODS_OF)
            model.contact.set_pose(t / self.duration)
            r -= model.contact.gradient(u)
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
        if model.contact is not None:       # penalty contact at y (runtime.contact.base.METHODS_OF)
            model.contact.begin_step(u, t / self.duration, (t + h) / self.duration, h)
            model.contact.set_pose((t + h * (1.0 - af)) / self.duration)
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


def solve_step(ctx, potential, u, target, where, s0, s1, h):
    """newton() for one step from run fraction s0 to s1, with the scene's contact (runtime.contact).

    IPC: the obstacles move from their pose at s0 to that at s1 within Newton, as prescribed dofs do
    (each step as far as CCD allows); friction's lagging iterations each re-solve with the normal
    forces and tangent bases of the state before."""
    contact = ctx.model.contact
    if contact is None:
        return newton(ctx, potential, u, target, where)[0]
    contact.begin_step(u, s0, s1, h)
    if contact.method != "ipc":
        contact.set_pose(s1)
        return newton(ctx, potential, u, target, where)[0]
    contact.start_stiffness(potential, u)
    for _ in range(contact.spec.friction_iterations if contact.spec.mu > 0 else 1):
        contact.lag_friction(u)
        u = newton(ctx, potential, u, target, where)[0]
    contact.end_step(u)
    return u


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
    """The integrator of the model's solver.kind (solver.device: runtime.physics.device_euler.make_integrator)."""
    return integrator_class(ctx.model.solver.kind)(ctx)

