"""Generalized-alpha (Chung-Hulbert 1993): second-order implicit dynamics with controllable damping.

    [solver]
    kind = "generalized_alpha"
    rho_inf = 1.0        # spectral radius at infinite frequency: 1 = no numerical damping, < 1 damps high frequencies

The equation of motion is enforced at the intermediate times
t_{n+1-alpha_f} (elastic, damping and external forces) and t_{n+1-alpha_m}
(inertia), x_{n+1-alpha} = (1 - alpha) x_{n+1} + alpha x_n:

    M a_{n+1-alpha_m} + D v_{n+1-alpha_f} - f_int(u_{n+1-alpha_f}) - f_ext = 0

with Newmark's update u_{n+1} = u_n + h v_n + h^2 ((1/2 - beta) a_n + beta a_{n+1}),
v_{n+1} = v_n + h ((1 - gamma) a_n + gamma a_{n+1}) and, from rho_inf (0 <= rho_inf <= 1),

    alpha_m = (2 rho_inf - 1) / (rho_inf + 1),  alpha_f = rho_inf / (rho_inf + 1),
    gamma = 1/2 - alpha_m + alpha_f,            beta = (1 - alpha_m + alpha_f)^2 / 4.

Second order for every rho_inf; rho_inf = 1 (alpha_m = alpha_f = 1/2, gamma = 1/2,
beta = 1/4) is the trapezoidal rule / implicit midpoint rule: no numerical
damping, the energy of a linear undamped system is conserved exactly, and
for nonlinear laws the energy error per step is the midpoint rule's O(h^3)
(bounded oscillation, no systematic drift while the motion is resolved).

Unknown: y = u_{n+1-alpha_f}.  The residual above is the gradient in y of an
incremental potential, W(y) - f_ext . y + Q(y) with Q quadratic (inertia and
Rayleigh damping, D = alpha M + beta K(u_n) frozen over the step as in backward
Euler), so the step is a Newton solve with the shared line search, PSD fallback
and dt halving (runtime.integrators.newton and _Dynamic).  The state carries the
acceleration a_n, started from the equation of motion at t = 0 (M a_0 = f_ext +
f_int(u_0) - D v_0) so that the scheme keeps its second order.

Prescribed displacements: the fixed dofs of u_{n+1} take the prescribed values
(so y takes (1 - alpha_f) u_{n+1} + alpha_f u_n there); their velocity and
acceleration are backward differences of the prescribed path (exact for the
linear ramp of a run; no ringing at a kink of an amplitude table).
"""
from __future__ import annotations

import numpy as np

from .errors import InvertedElementError, TensormassError
from .health import safe_norm
from .integrators import _KINDS, _Dynamic, _Potential, newton

__all__ = ["GeneralizedAlpha", "alpha_parameters"]


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
        out = (self.c_m + self.c_d * self.alpha) * self.mass * x
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
        data = self.asm.stiffness(y, project)
        data[self.asm.pattern.diagonal] += (self.c_m + self.c_d * self.alpha) * self.mass
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
    def initial_acceleration(self, u, v):
        """a_0 from M a_0 = f_ext + f_int(u) - D v on the free dofs with mass (0 elsewhere)."""
        ctx, free = self.ctx, self.model.free_dofs
        r = ctx.asm.forces(u) + self.model.f_ext - self.alpha * self.mass * v
        if self.beta and np.any(v):
            r -= self.beta * (ctx.asm.matrix(ctx.asm.stiffness(u, ctx.project is True)) @ v)
        a = np.zeros_like(u)
        m = self.mass[free]
        a[free] = np.where(m > 0, r[free] / np.where(m > 0, m, 1.0), 0.0)
        return a

    def step(self, k: int) -> dict:
        ctx = self.ctx
        if self.a is None:
            self.a = self.initial_acceleration(ctx.u, ctx.v)
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
        a = known[1] if known is not None and known[0] is u else self.initial_acceleration(u, v)
        am, af, gamma, beta = self.alpha_m, self.alpha_f, self.gamma, self.newmark_beta
        mass = self.mass
        K_n = None
        if self.beta:
            K_n = ctx.asm.matrix(self.beta * ctx.asm.stiffness(u, ctx.project is True))

        def damp(x):
            out = self.alpha * mass * x
            return out if K_n is None else out + K_n @ x

        def kinematics(u1):
            a1 = (u1 - u - h * v) / (beta * h * h) - (0.5 / beta - 1.0) * a
            return a1, v + h * ((1.0 - gamma) * a + gamma * a1)

        # residual's quadratic part at y0 = u (u_{n+1} = u_n)
        a1, v1 = kinematics(u)
        g0 = mass * ((1.0 - am) * a1 + am * a) + damp((1.0 - af) * v1 + af * v)
        c_m = (1.0 - am) / ((1.0 - af) * beta * h * h)
        c_d = gamma / (beta * h)
        scale = max(safe_norm(g0[free]), safe_norm((mass * a)[free]))
        potential = _AlphaPotential(ctx.asm, model.f_ext, mass, c_m, c_d, self.alpha, K_n, u, g0, scale)
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
        a1, v1 = kinematics(u1)
        # boundary velocity and acceleration: backward differences of the prescribed path
        v1[fixed] = (target_u - u[fixed]) / h
        a1[fixed] = (v1[fixed] - v[fixed]) / h
        self._acc[id(u1)] = (u1, a1)
        return u1, v1


_KINDS[GeneralizedAlpha.kind] = GeneralizedAlpha
