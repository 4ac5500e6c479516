"""A grab: a spring from a material point of the body to a target point, as a mouse pulls in a viewer.

    grab = Grab.at(asm, u, point, target, stiffness)     # point: where the body is now (deformed)
    f = grab.forces(u)          # the spring's force on every dof (zero off the grabbed cell's nodes)
    H = grab.hessian()          # d(-f)/du, constant: k (w w^T) (x) I on the grabbed nodes
    grab.force(u)               # (dim,) the force on the body [N]; grab.target = new_target to drag

The material point is x_p(u) = sum_i w_i (X_i + u_i) over the nodes of the cell that holds the
point picked on the deformed body (its shape functions there: runtime.mesh.probes.locate_point),
and the spring's energy is k/2 |x_p(u) - target|^2. Its force on node i is w_i k (target - x_p)
and its Hessian k w_i w_j I does not depend on u, so an implicit step takes it exactly. The target
moves between steps, never within one. The integrators add both (runtime.physics.integrators:
implicit_euler and explicit); a fixed dof keeps its prescribed value (the solver eliminates it).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..base.errors import TensormassError
from ..mesh.container import Mesh
from ..mesh.probes import ProbeError, locate_point

__all__ = ["Grab", "GrabError", "default_stiffness", "GRAB_KINDS"]

# The solver kinds that take a grab's spring (runtime.physics.integrators): the implicit step, whose
# matrix takes its Hessian, and the explicit one, whose forces take its force.
GRAB_KINDS = ("implicit_euler", "explicit")


class GrabError(TensormassError):
    """A grab that cannot be made (a point off the body, a bad stiffness or target)."""


class Grab:
    """A spring of stiffness k [N/m] from the material point sum_i w_i x_i to `target`."""

    def __init__(self, model, nodes, weights, target, stiffness: float):
        self.model = model
        self.nodes = np.asarray(nodes, dtype=np.int64)
        self.weights = np.asarray(weights, dtype=float)
        self.stiffness = _positive(stiffness)
        self.target = target
        self.work = 0.0                  # the spring's work on the body so far [J] (add_work)
        self.cell_size = 0.0             # the grabbed cell's size [m] (Grab.at), for a viewer's drag steps
        dim, per_node = model.dim, model.dofs_per_node
        # the dofs of x_p: node-major, the first dim components of each node (runtime.base.dofs)
        self._dofs = (self.nodes[:, None] * per_node + np.arange(dim)[None, :])
        self._hessian = None

    @classmethod
    def at(cls, asm, u, point, target=None, stiffness: float | None = None):
        """The grab of the body point nearest `point` in the deformed state u (a point on the body,
        within runtime.mesh.probes' tolerance), for the model of the assembler asm; target None: the
        point itself (no pull yet); stiffness None: default_stiffness."""
        model = asm.model
        U = model.nodal(u)[:, :model.dim]
        deformed = Mesh(model.mesh.points + U, model.mesh.blocks)
        try:
            probe = locate_point(deformed, point, name="grab")
        except ProbeError as exc:
            raise GrabError(str(exc).replace("probe 'grab'", "grab")) from None
        p = np.asarray(point, dtype=float).reshape(-1)
        k = default_stiffness(asm, probe.nodes) if stiffness is None else stiffness
        grab = cls(model, probe.nodes, probe.weights, p if target is None else target, k)
        corners = deformed.points[probe.nodes]
        grab.cell_size = float(np.linalg.norm(np.ptp(corners, axis=0)))
        return grab

    @property
    def target(self) -> np.ndarray:
        return self._target

    @target.setter
    def target(self, value) -> None:
        t = np.asarray(value, dtype=float).reshape(-1)
        if t.size != self.model.dim or not np.all(np.isfinite(t)):
            raise GrabError(f"grab target must be {self.model.dim} finite numbers, got {list(np.ravel(value))}")
        self._target = t.copy()

    def position(self, u) -> np.ndarray:
        """x_p(u): where the grabbed material point is [m]."""
        X = self.model.mesh.points[self.nodes]
        return self.weights @ (X + np.asarray(u)[self._dofs])

    def force(self, u) -> np.ndarray:
        """(dim,) the spring's force on the body, k (target - x_p(u)) [N]."""
        return self.stiffness * (self._target - self.position(u))

    def forces(self, u) -> np.ndarray:
        """The force on every dof: w_i k (target - x_p) on the grabbed nodes, 0 elsewhere."""
        f = np.zeros(self.model.n_dofs)
        np.add.at(f, self._dofs, self.weights[:, None] * self.force(u)[None, :])
        return f

    def energy(self, u) -> float:
        d = self.position(u) - self._target
        return 0.5 * self.stiffness * float(d @ d)

    def hessian(self) -> sp.csr_matrix:
        """k w_i w_j on each pair of grabbed nodes, per component (n_dofs x n_dofs, PSD)."""
        if self._hessian is None:
            rows = np.repeat(self._dofs[:, None, :], len(self.nodes), axis=1)       # (i, j, c): dof of i
            cols = np.repeat(self._dofs[None, :, :], len(self.nodes), axis=0)       # (i, j, c): dof of j
            vals = self.stiffness * np.outer(self.weights, self.weights)[:, :, None] * np.ones(self.model.dim)
            n = self.model.n_dofs
            self._hessian = sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(n, n))
        return self._hessian

    def add_work(self, u0, u1) -> None:
        """The spring's work on the body over a step from u0 to u1, the target held (trapezoid rule on
        f . dx_p: exact for the spring's linear force along a straight path)."""
        dx = self.position(u1) - self.position(u0)
        self.work += 0.5 * float((self.force(u0) + self.force(u1)) @ dx)


# The default spring: this share of the body's own stiffness where it is grabbed (default_stiffness).
# The grabbed point then follows a slow drag to about 80 % on the soft organ (examples/organ/live.toml)
# while the spring stays softer than the elements around it, which a concentrated pull would invert.
STIFFNESS_SHARE = 0.3


def default_stiffness(asm, nodes) -> float:
    """STIFFNESS_SHARE of the mean diagonal of the rest stiffness on the grabbed nodes' translations."""
    model = asm.model
    diagonal = getattr(asm, "_rest_diagonal", None)
    if diagonal is None:                 # once per assembler; not counted as the run's assembly time
        saved = asm.time
        K = asm.matrix(asm.stiffness(np.zeros(model.n_dofs)).copy())
        asm.time = saved
        diagonal = asm._rest_diagonal = np.asarray(K.diagonal())
    dofs = (np.asarray(nodes)[:, None] * model.dofs_per_node + np.arange(model.dim)[None, :]).ravel()
    k = STIFFNESS_SHARE * float(np.mean(np.abs(diagonal[dofs])))
    if not (k > 0 and np.isfinite(k)):
        raise GrabError("grab: the body has no stiffness at this point; give the grab a stiffness")
    return k


def _positive(stiffness) -> float:
    k = float(stiffness)
    if not (k > 0 and np.isfinite(k)):
        raise GrabError(f"grab stiffness must be a finite number > 0 [N/m], got {stiffness!r}")
    return k
