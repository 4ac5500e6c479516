"""Newton on displacements and pressures together: the mixed u-p formulation's saddle-point solve.

A model with formulation "mixed" (runtime.assembly.mixed) has pressure unknowns p beside the free
displacements.  The equations are the stationarity of the Lagrangian in both,

    g(u, p) = dL/du = 0  (the equation of motion on the free dofs),   r(u, p) = dL/dp = 0  (the volume constraint),

and each Newton step solves the symmetric indefinite system

    [ K_ff   B_f^T ] [ d_f ]     [ g_f + K_fc d_c ]
    [ B_f    -C    ] [ dp  ] = - [ r   + B_c d_c  ]          d_c: the fixed dofs' remaining move

with PARDISO's symmetric indefinite LDL^T (Bunch-Kaufman pivoting handles the zero block at nu = 0.5;
the mkl wheel, a default dependency on x86-64), else and for the non-symmetric stiffness of a
follower pressure on an open surface with SuperLU's LU; each solve is refined twice against the
matrix.  L has a saddle
point, not a minimum, so the energy cannot rank trial steps: the line search halves the step until
the scaled residual norm |g_f|^2 / f^2 + sum_g (r_g / V_g)^2 decreases (Newton's direction always
descends it), or, while boundaries move, until the state is finite.  Converged: |g_f| <= newton_tolerance
x the force scale (or its round-off after a full step) and every group's relative volume residual
|r_g| / V_g <= newton_tolerance (V_g = integral of N_a at rest).

The pressures live in the couplings (MixedCoupling.pressure).  A solve that fails puts back the
pressures it started from, so a refused step or a cut time step leaves no trace.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..base.errors import InvertedElementError, TensormassError
from ..base.parallel import worker_threads
from ..solve import pardiso
from ..solve.solvers import PARDISO_PARALLEL_DOFS
from .health import safe_norm

__all__ = ["Pressures", "newton_saddle", "linearised_step"]

_MAX_HALVINGS = 30
_REFINEMENTS = 2                # iterative refinement steps of each saddle solve
_ACCURATE = 1e-10               # relative residual a PARDISO solve must reach, else SuperLU solves
_LOOSE = 1e-8                   # ... and SuperLU's, else the matrix is taken as singular
# a relative volume residual below this is round-off (sums of v_q theta_q over the cells)
_VOLUME_ROUNDOFF = 1e3 * np.finfo(float).eps


class Pressures:
    """The pressure unknowns of every mixed coupling of a model, as one vector."""

    def __init__(self, model, couplings):
        self.model = model
        self.couplings = [c for c in couplings if c.formulation == "mixed"]
        sizes = [c.n_groups for c in self.couplings]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.n = int(self.offsets[-1])
        self.V = np.concatenate([c.V for c in self.couplings]) if self.couplings else np.zeros(0)
        self.C = sp.block_diag([c.C for c in self.couplings], format="csr")

    def get(self) -> np.ndarray:
        return np.concatenate([c.pressure for c in self.couplings]) if self.couplings else np.zeros(0)

    def set(self, p: np.ndarray) -> None:
        for c, a, b in zip(self.couplings, self.offsets[:-1], self.offsets[1:]):
            c.pressure = np.array(p[a:b], dtype=float)

    def _U(self, u):
        m = self.model
        return u.reshape(m.n_points, m.dofs_per_node)

    def residual(self, u) -> np.ndarray:
        """dL/dp at u and the current pressures."""
        U = self._U(u)
        return np.concatenate([c.constraint(U) for c in self.couplings])

    def constraint_matrix(self, u) -> sp.csr_matrix:
        U = self._U(u)
        return sp.vstack([c.constraint_matrix(U, self.model.n_dofs) for c in self.couplings], format="csr")

    def volume_change(self, u) -> float:
        """max over the couplings of |their volume / their rest volume - 1| (the MINI stabilisation on
        tetra moves volume between pressure groups but keeps their sum: its rows sum to zero)."""
        U = self._U(u)
        return max((abs(float(np.dot(c.volume_ratio(U), c.V) / c.V.sum()) - 1.0) for c in self.couplings), default=0.0)

    def summary(self, u) -> dict:
        """For the run summary: the pairs, the pressure unknowns' range, the volume kept."""
        p = self.get()
        finite = bool(np.all(np.isfinite(u)))
        return {"pairs": sorted({c.pair for c in self.couplings}), "unknowns": self.n,
                "pressure_min": float(p.min()) if p.size else 0.0, "pressure_max": float(p.max()) if p.size else 0.0,
                "volume_change": self.volume_change(u) if finite else None,
                "group_volume_error": self.volume_error(u) if finite else None}

    def volume_error(self, u) -> float:
        """max over the pressure groups of |integral N_a theta dV / integral N_a dV - 1|."""
        U = self._U(u)
        return max((float(np.abs(c.volume_ratio(U) - 1.0).max(initial=0.0)) for c in self.couplings), default=0.0)


def _merit(g_free, r, f_scale, V) -> float:
    return (safe_norm(g_free) / f_scale) ** 2 + safe_norm(r / V) ** 2


def newton_saddle(ctx, potential, u, target_c, where: str):
    """Solve g = 0, r = 0 over the free dofs and the pressures with u[fixed] -> target_c;
    returns (u, iterations).  See the module docstring."""
    model, s = ctx.model, ctx.model.solver
    P = ctx.pressures
    fixed, free = model.fixed_dofs, model.free_dofs
    if potential.contact is not None or ctx.hanging is not None:
        raise TensormassError(f"{where}: formulation 'mixed' cannot be combined with contact or hanging nodes")
    p_start = P.get()
    try:
        return _iterate(ctx, potential, u.copy(), target_c, where, P, fixed, free, s)
    except BaseException:
        P.set(p_start)
        raise


def _iterate(ctx, potential, u, target_c, where, P, fixed, free, s):
    force_scale = max(potential.force_scale(u), 1e-30)
    V = P.V
    g, r = potential.gradient(u), P.residual(u)
    full, floor = False, 0.0
    for it in range(1, s.newton_max_iterations + 1):
        du_c = target_c - u[fixed]
        moving = bool(np.any(du_c))
        f_scale = max(force_scale, safe_norm(g[fixed]))
        res_u, res_p = safe_norm(g[free]), float(np.abs(r / V).max(initial=0.0))
        if not (np.isfinite(res_u) and np.isfinite(res_p)):
            raise TensormassError(f"{where}: the residual is not finite (|residual| = {res_u:.3g}, volume "
                                  f"residual {res_p:.3g}): elements inverted or loads beyond range")
        volume_ok = res_p <= max(s.newton_tolerance, _VOLUME_ROUNDOFF)
        if not moving and volume_ok and (res_u <= s.newton_tolerance * f_scale or (full and res_u <= floor)):
            ctx.residual = (u, g)
            return u, it - 1
        data = potential.hessian(u, False)
        d, dp = _solve(ctx, data, P.constraint_matrix(u), P.C, g, r, du_c, fixed, free)
        floor = ctx.roundoff_floor(data)
        ctx.newton_iterations += 1
        m0 = _merit(g[free], r, f_scale, V)
        p0, a = P.get(), 1.0
        for _ in range(_MAX_HALVINGS):
            trial = u + a * d
            P.set(p0 + a * dp)
            try:
                ctx.check_not_inverted(trial)
                g_t, r_t = potential.gradient(trial), P.residual(trial)
                m = _merit(g_t[free], r_t, f_scale, V)
            except InvertedElementError:
                m = np.inf
            if np.isfinite(m) and (moving or m < m0 or (a == 1.0 and m <= (1.0 + 1e-6) * m0)):
                break
            a *= 0.5
        else:
            P.set(p0)
            raise TensormassError(f"{where}: line search failed (residual {res_u:.3e}, volume residual "
                                  f"{res_p:.3e}); the load step is too large or elements invert: use more steps")
        u, g, r, full = trial, g_t, r_t, a == 1.0
    raise TensormassError(f"{where}: Newton did not converge in {s.newton_max_iterations} iterations (residual "
                          f"{safe_norm(g[free]):.3e}, largest relative volume residual {np.abs(r / V).max():.3e}); "
                          "use more steps or a larger newton_max_iterations")


def linearised_step(ctx, A_data, b, dv_c, u, v, h):
    """The linearly implicit Euler step (runtime.physics.integrators.ImplicitEuler) with pressures:

        (M + h^2 K) dv + h B^T dp = b = h (f - h K v),     h B dv - C dp = -(r + h B v)

    (the volume constraint at u + h (v + dv) to first order), solved for dp = h pi in the symmetric
    form [[A, h^2 B^T], [h^2 B, -h^2 C]].  Sets the pressures to p + dp; returns (dv, B^T dp)."""
    P = ctx.pressures
    model = ctx.model
    fixed, free = model.fixed_dofs, model.free_dofs
    B, r = P.constraint_matrix(u), P.residual(u)
    rhs_p = -h * (r + h * (B @ v)) - h * h * (B[:, fixed] @ dv_c)
    A = ctx.asm.pattern.matrix(A_data)
    Af = A[free]
    Bf = B[:, free]
    rhs = np.concatenate([b[free] - Af[:, fixed] @ dv_c, rhs_p])
    M = sp.bmat([[Af[:, free], h * h * Bf.T], [h * h * Bf, -h * h * P.C]], format="csr")
    pressure = model.pressure
    x = _timed_solve(ctx, M, rhs, len(free), pressure is None or pressure.symmetric)
    dv = np.zeros(model.n_dofs)
    dv[free], dv[fixed] = x[:len(free)], dv_c
    dp = h * x[len(free):]
    P.set(P.get() + dp)
    return dv, B.T @ dp


def _timed_solve(ctx, A, rhs, n_u, symmetric):
    """_factor_solve, counted and timed with the context's linear solves (statistics only)."""
    start = time.perf_counter()
    x, method = _factor_solve(A, rhs, n_u, symmetric, ctx.pressures)
    linear = ctx.linear
    linear.time += time.perf_counter() - start
    linear.counts[method] = linear.counts.get(method, 0) + 1
    ctx.linear_iterations += 1
    return x


def _factor_solve(A, rhs, n_u, symmetric=True, keeper=None):
    """x = A^-1 rhs for A = [[K, B^T], [B, -C]] with n_u displacement rows: PARDISO's symmetric
    indefinite LDL^T (Bunch-Kaufman pivoting) where the mkl wheel is installed and A is symmetric,
    else SuperLU; refined in float64 against A.  The pressures are scaled by s = max|K| / max|B|
    first, so that the two blocks' pivots are of one size (B is a volume, K a stiffness)."""
    singular = ("the mixed (u, p) system is singular ({}): a rigid-body motion left free, or pressure "
                "groups with no displacement to constrain")
    n = A.shape[0]
    top, coupling = abs(A[:n_u, :n_u]).max(), abs(A[n_u:, :n_u]).max()
    scale = np.ones(n)
    if top > 0 and coupling > 0:
        scale[n_u:] = top / coupling
    S = sp.diags(scale, format="csr")
    A = (S @ A @ S).tocsr()
    rhs = scale * rhs
    if symmetric and pardiso.available():
        upper = sp.triu(A, format="coo")
        # PARDISO needs every diagonal entry stored, zeros too (COO -> CSR keeps a summed zero)
        upper = sp.coo_matrix((np.concatenate([upper.data, np.zeros(n)]),
                               (np.concatenate([upper.row, np.arange(n)]), np.concatenate([upper.col, np.arange(n)]))),
                              shape=(n, n)).tocsr()
        upper.sort_indices()
        try:
            handle = _handle(keeper, upper)
            handle.factor(upper.data)
            x = _refined(handle.solve, A, rhs)
            if _accurate(A, x, rhs):
                return scale * x, "pardiso-saddle"
        except pardiso.PardisoError:
            pass                              # SuperLU below says whether the matrix is singular
    try:
        x = _refined(splu(A.tocsc()).solve, A, rhs)
    except RuntimeError as exc:               # SuperLU: "Factor is exactly singular"
        raise TensormassError(singular.format(exc)) from None
    if not (np.all(np.isfinite(x)) and _accurate(A, x, rhs, _LOOSE)):
        raise TensormassError("the mixed (u, p) system gave an inaccurate or non-finite step (a singular matrix)")
    return scale * x, "superlu-saddle"


def _handle(keeper, upper):
    """A PARDISO handle for this pattern: the one kept on `keeper` (Pressures) when the pattern is the
    last one's, so that its analysis (ordering, symbolic factor) serves every Newton step."""
    kept = getattr(keeper, "_pardiso", None)
    if kept is not None and np.array_equal(kept.indptr, upper.indptr) and np.array_equal(kept.indices, upper.indices):
        return kept
    n = upper.shape[0]
    # (PARDISO's weighted matching, iparm 13, was measured to break Q1-P0 at nu = 0.5: left off)
    handle = pardiso.Pardiso(n, upper.indptr, upper.indices, threads=worker_threads() if n >= PARDISO_PARALLEL_DOFS else 1)
    if keeper is not None:
        keeper._pardiso = handle
    return handle


def _refined(solve, A, rhs):
    x = solve(rhs)
    for _ in range(_REFINEMENTS):             # perturbed pivots (PARDISO) and round-off: refine against A
        x = x + solve(rhs - A @ x)
    return x


def _accurate(A, x, rhs, bound=None) -> bool:
    """Whether |A x - rhs| <= bound x (|A| |x| + |rhs|) in the max norm (PARDISO's perturbed pivots
    can leave a solution refinement does not repair: then SuperLU solves)."""
    bound = _ACCURATE if bound is None else bound
    if not np.all(np.isfinite(x)):
        return False
    size = float(abs(A).max()) * float(np.abs(x).max()) + float(np.abs(rhs).max())
    return float(np.abs(A @ x - rhs).max()) <= bound * max(size, 1e-300)


def _solve(ctx, data, B, C, g, r, du_c, fixed, free):
    """The step (d over all dofs, dp) of the saddle system (module docstring)."""
    K = ctx.asm.pattern.matrix(data)
    Kf = K[free]
    Bf, Bc = B[:, free], B[:, fixed]
    rhs = -np.concatenate([g[free] + Kf[:, fixed] @ du_c, r + Bc @ du_c])
    pressure = ctx.model.pressure
    x = _timed_solve(ctx, sp.bmat([[Kf[:, free], Bf.T], [Bf, -C]], format="csr"), rhs, len(free),
                     pressure is None or pressure.symmetric)
    d = np.zeros(ctx.model.n_dofs)
    d[free] = x[:len(free)]
    d[fixed] = du_c
    return d, x[len(free):]
