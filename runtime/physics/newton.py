"""Newton's method on an energy, and the Context every solver shares (state, assembly, Dirichlet
elimination, linear solvers).

    ctx = Context(model)
    u, iterations = newton(ctx, Potential(ctx.asm, f_ext), ctx.u, target, "static: step 1")

Potential is W(u) - f_ext.u (IncrementalPotential adds backward Euler's inertia and damping terms);
newton minimises it over the free dofs with a line search on the energy, a watchdog that lets plain
full steps through, a round-off floor for the convergence test and, for the locking-free
formulations, the three-field pressure in the Newton matrix (MixedPressure).
"""
from __future__ import annotations

import numpy as np

from ... import laws
from ..assembly import volumetric
from ..assembly.assembly import Assembler
from ..base.errors import InvertedElementError, TensormassError
from .viscous import ViscousHistory
from .saddle import Pressures, newton_saddle
from ..solve.amg import rigid_body_modes
from ..solve.solvers import ConstrainedSystem, LinearSolver
from .health import safe_norm

__all__ = ["Context", "Potential", "IncrementalPotential", "newton", "line_search"]

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
        self.linear = LinearSolver(s.linear, s.cg_tolerance, s.cg_max_iterations,
                                   factor_tol=getattr(s, "factor_tolerance", 1e-10))
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
        # viscous parts (laws/viscous.py): their Prony state, prepared before and committed after each step
        self.history = ViscousHistory(model, self.asm) if any(p.branches is not None for p in model.parts) else None
        # formulation "mixed": the pressure unknowns, solved with the displacements (runtime.physics.saddle)
        mixed = [c for c in getattr(model, "couplings", []) if c.formulation == "mixed"]
        self.pressures = Pressures(model, mixed) if mixed else None
        # a viewer's spring on a material point (runtime.physics.grab), set and dropped between steps
        self.grab = None
        self._cell_size = None

    def warm_up_solver(self) -> None:
        """The linear solver's numba loops for this system, loaded before the first step (runs that
        solve with a stiffness only: an explicit run never calls it; a mixed one solves saddle systems)."""
        if self.pressures is None:
            self.linear.warm_up(self.system.structure())

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

    def roundoff_floor(self, data, extra=None) -> float:
        """The residual round-off leaves after a solve with the Newton matrix `data` (see _FLOOR); extra:
        a matrix added beside it (contact: a stiff barrier's forces carry round-off of their own)."""
        K = self.asm.pattern.matrix(np.abs(data))
        if extra is not None:
            K = K + abs(extra)
        free = self.model.free_dofs
        return _FLOOR * np.finfo(float).eps * safe_norm((K @ self.cell_size())[free])

    def solve(self, data, b, x_c=None, x0=None, extra=None):
        """Eliminate the fixed dofs (values x_c) and solve; counts linear iterations.
        extra: a sparse matrix added to the pattern's (contact's Hessian: runtime.contact)."""
        x, its = self.system.solve(self.linear, data, b, x_c, x0, extra)
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
                bad = p.kernel.inverted(p.D_active, self.model.part_nodal(p, u), cells=p.cells_active)
                if bad.any():
                    raise InvertedElementError(f"law {p.law!r}: det F <= 0", p.cell_ids_active[bad])


# --------------------------------------------------------------------------- Newton


class Potential:
    """Total potential Pi(u) = W(u) - f_ext.u (+ optional quadratic inertia/damping terms)."""

    def __init__(self, asm, f_ext, factor=1.0):
        self.asm, self.f_ext = asm, f_ext
        self.free = asm.model.free_dofs
        # follower pressure (runtime/assembly/pressure.py) x the load factor: no potential on open surfaces, so
        # its energy is the work along the Newton path (exact on each straight step: see accept)
        self.pressure, self.factor = getattr(asm.model, "pressure", None), float(factor)
        self._anchor = None                         # (u, pressure energy there)
        # runtime.contact (IPC or penalty): its energy, gradient and Hessian join the potential's
        self.contact = getattr(asm.model, "contact", None)

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
        C = 0.0 if self.contact is None else self.contact.energy(u)
        return W - work + q + P + C, abs(W) + abs(work) + qmag + abs(P) + abs(C)

    def gradient(self, u, contact=True):
        _, dq, _ = self.extra(u)
        g = dq - self.asm.forces(u) - self.f_ext
        g = g if self.pressure is None else g - self.factor * self.pressure.forces(u)
        if contact and self.contact is not None:
            g = g + self.contact.gradient(u)
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

    def contact_matrix(self, u, project):
        """The contact's Hessian (PSD-projected when project) as a sparse matrix beside the pattern's
        data, or None."""
        return None if self.contact is None else self.contact.hessian(u, project)

    def max_step(self, u, d) -> float:
        """The largest step along d the contact allows (CCD: no intersection on the way); 1 without."""
        return 1.0 if self.contact is None else self.contact.max_step(u, d)

    # Obstacles moving within a solve (runtime.contact.ipc): a prescribed motion like the fixed dofs'
    # one, taken by Newton's steps as far as CCD allows (the line search tries them, accept_step keeps).
    def moving_obstacles(self) -> bool:
        return self.contact is not None and self.contact.pose_moving()

    def obstacle_load(self, u):
        """The first-order change of the gradient that the obstacles' remaining move causes, or None."""
        return None if self.contact is None else self.contact.pose_load(u)

    def try_step(self, a: float) -> None:
        if self.contact is not None:
            self.contact.try_pose(a)

    def accept_step(self, a: float) -> None:
        if self.contact is not None:
            self.contact.accept_pose(a)


class IncrementalPotential(Potential):
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


class MixedPressure:
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


def newton(ctx: Context, potential: Potential, u: np.ndarray, target_c: np.ndarray, where: str):
    """Minimise the potential over the free dofs with u[fixed] -> target_c; returns (u, iterations).

    Directions: the exact Hessian (the three-field one with locking-free formulations, see
    MixedPressure), PSD-projected while it does not give descent (ctx.project None) and back to
    exact after a projected full step that cuts the residual tenfold.  Steps: Armijo backtracking on the
    energy, with a watchdog that, while every step so far was a full one, takes up to _WATCHDOG
    full steps raising the energy (plain Newton, as most FE codes take) before returning to the
    last certified point and backtracking from there.  Convergence: the residual
    on the free dofs below newton_tolerance x the force scale, or below the round-off floor
    (Context.roundoff_floor) after a full step."""
    if getattr(ctx, "pressures", None) is not None:
        return newton_saddle(ctx, potential, u, target_c, where)
    model, s = ctx.model, ctx.model.solver
    fixed, free = model.fixed_dofs, model.free_dofs
    project = ctx.project is True
    fallback = ctx.project is None        # may switch projection on (and off again) for this solve
    u = u.copy()
    g = potential.gradient(u)
    Pi, mag = potential.value(u)
    force_scale = max(potential.force_scale(u), 1e-30)
    mixed = MixedPressure(ctx.asm, u) if getattr(ctx.asm, "couplings", None) else None
    # the watchdog needs one energy along the whole path: not with a follower pressure (path work)
    watchdog = potential.pressure is None and potential.contact is None
    anchor = None                         # the last certified point while relaxed steps run
    floor, full = 0.0, False
    res = np.inf
    for it in range(1, s.newton_max_iterations + 1):
        du_c = target_c - u[fixed]
        moving = bool(np.any(du_c)) or potential.moving_obstacles()
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
            found = line_search(potential, u, d, g, Pi, mag, slope, False, a=potential.max_step(u, d))
            if found is None:
                raise TensormassError(f"{where}: line search failed (residual {res:.3e}); the load step is too "
                                      "large or elements invert: use more steps")
            u, a, Pi, mag, g_new = found[:5]
            potential.accept_step(a)
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
            extra = potential.contact_matrix(u, project)
            pushed = potential.obstacle_load(u)
            d = ctx.solve(data, -g if pushed is None else -g - pushed, du_c, extra=extra)
        except TensormassError:
            if fallback and not project:            # e.g. CG on an indefinite matrix
                project = True
                continue
            raise
        floor = ctx.roundoff_floor(data, extra)
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
        found = line_search(potential, u, d, g, Pi, mag, slope, moving, relax, a=potential.max_step(u, d))
        if found is None:
            if fallback and not project:
                project = True
                if mixed is not None:
                    mixed.reset(u)
                continue
            raise TensormassError(f"{where}: line search failed (residual {res:.3e}); the load step is too "
                                  "large or elements invert: use more steps")
        u_new, a, Pi_new, mag_new, g_new, relaxed = found
        potential.accept_step(a)
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
        if fallback and project and ctx.project is None and (
                (full and safe_norm(g[free]) <= 0.1 * res) or potential.contact is not None):
            # in the basin: back to the exact Hessian.  With contact at once: projected barrier pairs
            # (edge-edge, point-edge curvature clamped) leave Newton converging only linearly
            project = False
            if mixed is not None:
                mixed.reset(u)
        if tiny and not np.any(target_c - u[fixed]) and not potential.moving_obstacles():
            ctx.residual = (u, g)
            return u, it
    res = safe_norm(g[free])
    raise TensormassError(f"{where}: Newton did not converge in {s.newton_max_iterations} iterations "
                          f"(residual {res:.3e}, tolerance {s.newton_tolerance * scale:.3e}, round-off floor "
                          f"{floor:.3e}); use more steps or a larger newton_max_iterations")


def line_search(potential, u, d, g, Pi0, mag0, slope, moving, relax=False, a=1.0):
    """Backtracking: halve until Pi decreases enough (or, while boundaries move, is finite).
    a: the first step tried (contact: the largest step CCD allows, below 1 when a pair would cross).

    Returns (u, a, Pi, magnitude, gradient or None, relaxed).  Near a solution the energy
    change drowns in round-off (I1 - 3 at small strain cancels ~1/strain^2 digits),
    so a full step whose energy change is tiny is also accepted when it halves
    the residual.  relax: a finite full step is taken even when the energy rises
    (relaxed = True; newton's watchdog decides whether it paid).
    """
    if not a > 0.0:
        return None
    for _ in range(_MAX_HALVINGS):
        trial = u + a * d
        potential.try_step(a)
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
    potential.try_step(0.0)
    return None
