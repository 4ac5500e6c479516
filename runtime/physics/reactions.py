"""Reaction forces: what each [[fixed]] entry's support exerts on the body.

    reactions = Reactions(model)                 # one group per [[fixed]] entry
    reactions.evaluate(r, u)                     # {name: {"force", "moment", "point"}}
    reactions.field(r)                           # (n_points, dim) nodal forces, 0 off the supports
    r = residual(ctx, integrator)                # the full residual vector at the current state

Definition.  Every integrator solves a discrete equation of motion on the free dofs,

    M a + D v - f_int(u) - f_ext - f_p(u) = 0          (statics: a = v = 0, loads x the load factor)

(M the mass matrix, D = alpha M + beta K the Rayleigh damping, f_int = -dW/du the internal
forces, f_ext gravity, nodal forces and tractions, f_p the follower pressure).  On a constrained
dof the same expression is not zero: it is the force r the support must exert on the body so
that the dof follows its prescribed value,

    r = M a + D v - f_int(u) - f_ext - f_p(u)          on the constrained dofs.

So in static equilibrium sum(r) + sum(f_ext + f_p) = 0 (sum(f_int) = 0: internal forces do not
move the centre of mass), and in dynamics sum(r) + sum(f_ext + f_p) = sum(M a + D v), the rate of
change of the momentum plus the mass-proportional damping force.  Each integrator evaluates
this expression the way its own step does, and leaves it in `ctx.residual` (no extra assembly):

    static             Newton's residual (the gradient of the potential) at the converged u_k
    backward_euler     the same at u_k: a = (v_k - v_{k-1}) / h, D with K at the step's start
    generalized_alpha  Newton's residual at t_{k+1-alpha_f}: a, v, u at the scheme's
                       intermediate times, where the scheme enforces the equation
    implicit_euler     the linearised step's equation: f_int(u_{k-1}) - K (u_k - u_{k-1}) for f_int
    explicit           the step's own equation M (v_k - v_{k-1}) / h = f(u_{k-1}, v_{k-1}) + r:
                       the support's force over the step (its impulse / h)

Before the first step, after an [[adapt]] refinement and wherever the state was set from
outside, one internal-force assembly evaluates the expression at the current state with
a = 0 (the acceleration is not known outside a step; the velocity is used for D v).

Per [[fixed]] entry (name: its `name`, default ``fixed[i]``): the force is the sum of r over
the dofs the entry constrains (the displacement components, 2 or 3; dofs beyond the
displacement, e.g. rotations, are left out); a dof constrained by several entries counts for
the first of them (in scene order).  The moment is about the point p (``moment_about``; default
the centroid of the entry's nodes at rest, as given in "point"):

    moment = sum over the entry's nodes of (x - p) x r_node,    x = X + u the current position.

In 2D the moment is the scalar z component (a 1-entry list in histories).  Units: N and N m
(2D: per unit thickness, N/m and N m/m).  With this moment, the axial moment about a rotating
support's axis is dPi/dtheta, the derivative of the equilibrium potential energy with respect
to the rotation angle (radians): what tests/runtime/physics/test_reactions.py checks.
"""
from __future__ import annotations

import numpy as np

from ..base import integrator_kinds
from ..base.errors import TensormassError
from ..mesh.regions import box_contains, selection_nodes
from .integrators import stiffness_times as _integrator_stiffness_times

__all__ = ["Reactions", "residual", "reaction_field", "entry_name"]


def entry_name(entry, i: int) -> str:
    """The name of the i-th [[fixed]] entry: its `name`, default ``fixed[i]``."""
    name = getattr(entry, "name", None)
    return f"fixed[{i}]" if name is None else str(name)


class _Group:
    """One [[fixed]] entry: the dofs it owns (first entry wins), their nodes and components, the point."""

    def __init__(self, name, dofs, dofs_per_node, n_comp, point):
        self.name, self.dofs, self.point = name, dofs, point
        self.nodes, self.comps = dofs // dofs_per_node, dofs % dofs_per_node
        # per distinct node: which displacement components the entry owns (for evaluate)
        self.unique, where = np.unique(self.nodes, return_inverse=True)
        self.mask = np.zeros((self.unique.size, n_comp))
        self.mask[where, self.comps] = 1.0


class Reactions:
    """The reaction groups of a model: one per [[fixed]] entry (model._specs holds the entries)."""

    def __init__(self, model):
        self.model = model
        fixed = list(model._specs[0])
        dpn, dim = model.dofs_per_node, model.dim
        self.dim = dim
        self.n_comp = min(dim, dpn)                        # the displacement components
        claimed = np.zeros(model.n_dofs, dtype=bool)
        names = [entry_name(f, i) for i, f in enumerate(fixed)]
        for i, name in enumerate(names):
            if names.index(name) != i:
                raise TensormassError(f"fixed[{i}].name: duplicate reaction name {name!r} (fixed[{names.index(name)}] "
                                      "has it too)")
        self.groups = []
        for i, f in enumerate(fixed):
            key = f"fixed[{i}]"
            if getattr(f, "region", None) is not None or f.box is None:
                nodes = selection_nodes(model.mesh, f, key, model.box_tol)
            else:
                nodes = np.flatnonzero(box_contains(f.box, model.mesh.points, model.box_tol))
            comps = range(dpn) if f.components is None else [int(c) for c in f.components]
            comps = [c for c in comps if c < self.n_comp]
            if comps:
                dofs = (nodes[:, None] * dpn + np.asarray(comps)[None, :]).ravel()
            else:
                dofs = np.zeros(0, dtype=np.int64)
            dofs = np.sort(dofs[~claimed[dofs]])
            claimed[dofs] = True
            point = self._point(f, nodes, key)
            self.groups.append(_Group(names[i], dofs, dpn, self.n_comp, point))

    def _point(self, entry, nodes, key) -> np.ndarray:
        about = getattr(entry, "moment_about", None)
        if about is None:
            return self.model.mesh.points[nodes].mean(axis=0) if nodes.size else np.zeros(self.dim)
        p = np.asarray(about, dtype=float).reshape(-1)
        if p.size != self.dim or not np.all(np.isfinite(p)):
            raise TensormassError(f"{key}.moment_about: expected {self.dim} finite coordinates (the mesh is "
                                  f"{self.dim}D), got {list(about)!r}")
        return p

    @property
    def names(self) -> list:
        return [g.name for g in self.groups]

    def evaluate(self, r: np.ndarray, u: np.ndarray) -> dict:
        """{name: {"force": (dim,), "moment": (3,) or float (2D), "point": (dim,)}} from the residual r."""
        model = self.model
        U, R = model.nodal(u), model.nodal(r)
        nc = self.n_comp
        out = {}
        for g in self.groups:
            nodal = np.zeros((g.unique.size, self.dim))
            nodal[:, :nc] = R[g.unique, :nc] * g.mask
            force = nodal.sum(axis=0)
            arm = model.mesh.points[g.unique] - g.point
            arm[:, :nc] += U[g.unique, :nc]
            if self.dim == 3:
                moment = np.cross(arm, nodal).sum(axis=0)
            else:
                moment = float((arm[:, 0] * nodal[:, 1] - arm[:, 1] * nodal[:, 0]).sum())
            out[g.name] = {"force": force, "moment": moment, "point": g.point.copy()}
        return out

    def field(self, r: np.ndarray) -> np.ndarray:
        """(n_points, dim): r on every constrained displacement dof, 0 elsewhere (point data `reaction`)."""
        model = self.model
        out = np.zeros((model.n_points, self.dim))
        fixed = model.fixed_dofs
        nodes, comps = fixed // model.dofs_per_node, fixed % model.dofs_per_node
        keep = comps < self.n_comp
        out[nodes[keep], comps[keep]] = r[fixed[keep]]
        return out


def residual(ctx, integrator) -> np.ndarray:
    """The residual vector whose fixed rows are the reactions at ctx.u (see the module doc).

    The one the last step left in ctx.residual when it belongs to ctx.u (by identity: the
    integrators set ctx.u to the array they evaluated it at); otherwise one assembly of the
    internal forces at the current state, with a = 0 (not counted as assembly time).
    """
    known = getattr(ctx, "residual", None)
    if known is not None and known[0] is ctx.u:
        return known[1]
    saved = ctx.asm.time
    try:
        return _evaluate(ctx, integrator)
    finally:
        ctx.asm.time = saved


def _evaluate(ctx, integrator) -> np.ndarray:
    """M a + D v - f_int - f_ext - f_p at the current state with a = 0."""
    model, u, v = ctx.model, ctx.u, ctx.v
    static = not integrator_kinds.get(model.solver.kind).dynamic
    duration = getattr(integrator, "duration", 1.0) or 1.0
    fraction = ctx.t if static else ctx.t / duration
    f = ctx.asm.forces(u) + integrator.external_force(fraction)
    pressure = getattr(model, "pressure", None)
    if pressure is not None:
        f = f + (fraction if static else 1.0) * pressure.forces(u)
    r = -f
    contact = getattr(model, "contact", None)
    if contact is not None:                 # the obstacles' push on fixed nodes is part of their reaction
        r = r + contact.gradient(u)
    if not static and np.any(v):
        alpha, beta = (float(x) for x in model.solver.rayleigh)
        if alpha:
            r = r + alpha * (model.mass_matrix @ v)
        if beta:
            r = r + beta * (ctx.asm.matrix(ctx.asm.stiffness(u)) @ v if "stiffness" in integrator.outputs
                            else stiffness_times(ctx, u, v))
    return r


def stiffness_times(ctx, u, v):
    return _integrator_stiffness_times(ctx.asm, u, v, ctx.asm.forces(u), ctx.model.size)


def reaction_field(sim) -> np.ndarray:
    """The nodal field `reaction` of a Simulation at its current state (for Simulation._write)."""
    return sim._reaction_groups().field(sim._reaction_residual())
