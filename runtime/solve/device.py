"""The implicit step on an array device: a body's Newton system assembled, constrained and solved
where its arrays live. On a GPU the arrays are CuPy's and the kernel is the cuda backend's; on the host
they are numpy's and the kernel is the cuda backend's host shim (the same CUDA file compiled as C),
which is how a machine without a GPU checks the whole step.

    step = DeviceStep(module, xp, points, cells, params, fixed_nodes, node_mass, dt, body_force)
    step.advance()           # one linearised implicit Euler step
    step.u, step.v           # (n_points, dim) arrays of xp

The step: K and f at u by the fused kernel, launched once per colour of the element graph (elements
of one colour share no node, so their plain additions never collide, and the fixed colour order
makes every sum the same run after run); then

    (M + dt^2 K) dv = dt (f + f_ext - dt K v),   v += dv,   u += dt v,

with the fixed nodes' rows and columns replaced by the identity, solved by Jacobi-preconditioned CG.
Nothing crosses to the host during a step but the CG's residual norms and the element flags.
"""
from __future__ import annotations

import numpy as np

from ..assembly.colouring import colour_cells
from ..assembly.pattern import SparsePattern
from ..base.dofs import node_dofs
from ..base.errors import TensormassError
from ..kernels.fused import node_block_positions

__all__ = ["DeviceStep", "colour_ranges", "jacobi_pcg"]


def colour_ranges(cells) -> tuple[np.ndarray, np.ndarray]:
    """(order, offsets): the elements sorted by DSATUR colour (stable: by index within a colour) and
    the start of each colour's range in that order (n_colours + 1 entries)."""
    colours = colour_cells(cells)
    order = np.argsort(colours, kind="stable")
    offsets = np.concatenate([[0], np.cumsum(np.bincount(colours))])
    return order, offsets


def _csr(xp, data, indices, indptr, n):
    if xp is np:
        import scipy.sparse as sparse
    else:
        import cupyx.scipy.sparse as sparse
    return sparse.csr_matrix((data, indices, indptr), shape=(n, n), copy=False)


def jacobi_pcg(xp, A, b, diagonal, tolerance: float, max_iterations: int):
    """x with |A x - b| <= tolerance |b| by conjugate gradients preconditioned by the diagonal;
    returns (x, iterations). A: an xp CSR matrix (symmetric positive definite)."""
    x = xp.zeros_like(b)
    r = b.copy()
    target = tolerance * float(xp.linalg.norm(b))
    if target == 0.0:
        return x, 0
    inverse = 1.0 / diagonal
    z = inverse * r
    p = z.copy()
    rz = float(r @ z)
    for iteration in range(1, max_iterations + 1):
        Ap = A @ p
        alpha = rz / float(p @ Ap)
        x += alpha * p
        r -= alpha * Ap
        if float(xp.linalg.norm(r)) <= target:
            return x, iteration
        z = inverse * r
        rz, rz_old = float(r @ z), rz
        p = z + (rz / rz_old) * p
    raise TensormassError(f"the device CG did not reach a relative residual of {tolerance:g} in {max_iterations} iterations")


class DeviceStep:
    """One body (one kernel) stepped by linearised implicit Euler on an array device (see the module)."""

    def __init__(self, module, xp, points, cells, params, fixed_nodes, node_mass, dt: float, body_force,
                 tolerance: float = 1e-10, max_iterations: int = 5000):
        points = np.asarray(points, dtype=np.float64)
        n_points, dim = points.shape
        self.module, self.xp, self.dt = module, xp, float(dt)
        self.tolerance, self.max_iterations = tolerance, max_iterations
        order, self.offsets = colour_ranges(cells)
        cells = np.ascontiguousarray(np.asarray(cells)[order], dtype=np.int64)
        params = np.ascontiguousarray(np.asarray(params, dtype=np.float64)[order])
        self.n_dofs = n_points * dim
        pattern = SparsePattern([node_dofs(cells, dim)], self.n_dofs, dim)
        self.pattern = pattern
        pos = node_block_positions(pattern, dim)[0]
        n = len(cells)
        meta = module.METADATA
        D = xp.zeros((n, int(meta["n_constants"])))
        flags = xp.zeros(n, dtype=np.int32)
        module.constants(xp.asarray(np.ascontiguousarray(points[cells])), xp.asarray(params), D, flags)
        if bool((flags != 0).any()):
            raise TensormassError("degenerate or inverted element(s) at rest")
        fixed = np.zeros(self.n_dofs, dtype=bool)
        fixed[node_dofs(np.asarray(fixed_nodes).reshape(-1, 1), dim).ravel()] = True
        rows = np.repeat(np.arange(self.n_dofs), np.diff(pattern.indptr))
        constrained = fixed[rows] | fixed[pattern.indices]
        mass = np.repeat(np.asarray(node_mass, dtype=np.float64), dim)
        self.D, self.flags, self.cells, self.pos = D, flags, xp.asarray(cells), xp.asarray(pos)
        self.constrained = xp.asarray(np.flatnonzero(constrained))
        self.fixed_diagonal = xp.asarray(pattern.diagonal[fixed])
        self.diagonal = xp.asarray(pattern.diagonal)
        self.free = xp.asarray((~fixed).astype(np.float64))
        self.mass = xp.asarray(mass)
        self.f_ext = xp.asarray(mass * np.tile(np.asarray(body_force, dtype=np.float64), n_points))
        self.u, self.v = xp.zeros((n_points, dim)), xp.zeros((n_points, dim))
        self.f, self.data = xp.zeros(self.n_dofs), xp.zeros(pattern.nnz)
        self.system = xp.zeros(pattern.nnz)
        indptr, indices = xp.asarray(pattern.indptr), xp.asarray(pattern.indices)
        self.K = _csr(xp, self.data, indices, indptr, self.n_dofs)
        self.A = _csr(xp, self.system, indices, indptr, self.n_dofs)
        self.iterations = []

    def assemble(self) -> None:
        """f (the internal forces -dW/du) and K (the CSR values) at u: one launch per colour."""
        self.f.fill(0.0)
        self.data.fill(0.0)
        for a, b in zip(self.offsets[:-1], self.offsets[1:]):
            self.module.forces_and_stiffness_scatter(self.D[a:b], self.u, self.cells[a:b], self.pos[a:b],
                                                     self.f, self.data, self.flags[a:b])
        if bool((self.flags != 0).any()):
            raise TensormassError("an element inverted (det F <= 0) during the step: take a smaller dt")

    def advance(self) -> int:
        """One step; returns the CG iterations it took."""
        xp, dt = self.xp, self.dt
        self.assemble()
        v = self.v.reshape(-1)
        rhs = dt * (self.f + self.f_ext - dt * (self.K @ v))
        self.system[...] = (dt * dt) * self.data
        self.system[self.diagonal] += self.mass
        self.system[self.constrained] = 0.0
        self.system[self.fixed_diagonal] = 1.0
        rhs *= self.free
        dv, iterations = jacobi_pcg(xp, self.A, rhs, self.system[self.diagonal], self.tolerance, self.max_iterations)
        self.v += (dv * self.free).reshape(self.v.shape)
        self.u += dt * self.v
        self.iterations.append(iterations)
        return iterations
