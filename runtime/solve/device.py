"""Newton systems on an array device: assembled, constrained and solved where their arrays live.

On a GPU the arrays are CuPy's and the kernels the cuda backend's; on the host they are numpy's and the
kernels the cuda backend's host shim (the same CUDA file compiled as C), which is how a machine without
a GPU checks every line here but the array library.

    device = get_device("cuda")                      # CuPy + the cuda backend (or a clear error)
    system = DeviceSystem(device, pattern, parts, mass, fixed_dofs)
    f, data = system.assemble(u)                     # device arrays: -dW/du and the CSR values of K
    dv, residual = system.implicit_euler(u, v, f_ext, dv_fixed, h, alpha, beta)
    step = DeviceStep(device, points, cells, kernel, params, fixed_nodes, node_mass, dt, body_force)

Assembly: each part's elements are sorted by DSATUR colour of its element graph and its fused kernel is
launched once per colour: elements of one colour share no node, so their plain additions never collide,
and the fixed colour order makes every sum the same, run after run (no atomics).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..assembly.colouring import colour_cells
from ..base.errors import InvertedElementError, TensormassError

__all__ = ["Device", "DeviceSystem", "DeviceStep", "get_device", "host_device", "colour_ranges", "jacobi_pcg",
           "DEVICES"]

DEVICES = ("cpu", "cuda")


@dataclass(frozen=True)
class Device:
    """An array device: its array module (numpy's API) and how it loads a generated kernel
    (element, law, quadrature) as a module whose functions take its arrays."""
    name: str
    xp: object
    load: Callable

    def csr(self, data, indices, indptr, n: int):
        """A CSR matrix on this device sharing data (updated in place by the assembly)."""
        if self.xp is np:
            import scipy.sparse as sparse
        else:
            import cupyx.scipy.sparse as sparse
        return sparse.csr_matrix((data, indices, indptr), shape=(n, n), copy=False)

    def synchronize(self) -> None:
        if self.xp is not np:
            self.xp.cuda.get_current_stream().synchronize()


def _cuda_load(element, law, quadrature):
    from ... import backends
    from ..base.cache import cache_dir, writable_cache_dir
    from ..kernels.kernels import kernel_source
    try:
        return backends.get("cuda").load(kernel_source(element, law, quadrature, "cuda"), cache_dir(),
                                         writable=writable_cache_dir)
    except backends.BackendError as error:
        raise TensormassError(str(error)) from None


def _host_load(element, law, quadrature):
    from ...backends.cuda import loader
    from ... import backends
    from ..base.cache import cache_dir, writable_cache_dir
    from ..kernels.kernels import kernel_source
    try:
        return loader.load_host_shim(kernel_source(element, law, quadrature, "cuda"), cache_dir(), writable_cache_dir)
    except backends.BackendError as error:
        raise TensormassError(str(error)) from None


def host_device() -> Device:
    """numpy arrays and the cuda backend's host shim: the device code path, checked on the host."""
    return Device("cuda (host shim)", np, _host_load)


def get_device(name: str) -> Device:
    """The device called name: "cuda" is CuPy with a CUDA device (TensormassError saying what is missing)."""
    if name != "cuda":
        raise TensormassError(f"solver.device: unknown device {name!r}; known: {', '.join(DEVICES)}")
    from ...backends import BackendError
    from ...backends.cuda.loader import cupy
    try:
        cp = cupy(instead="leave solver.device out (the step then runs on the CPU)")
    except BackendError as error:
        raise TensormassError(f"solver.device = \"cuda\": {error}") from None
    return Device("cuda", cp, _cuda_load)


def colour_ranges(cells) -> tuple[np.ndarray, np.ndarray]:
    """(order, offsets): the elements sorted by DSATUR colour (stable: by index within a colour) and
    the start of each colour's range in that order (n_colours + 1 entries)."""
    colours = colour_cells(cells)
    order = np.argsort(colours, kind="stable")
    offsets = np.concatenate([[0], np.cumsum(np.bincount(colours))])
    return order, offsets


def jacobi_pcg(xp, A, b, diagonal, tolerance: float, max_iterations: int, x0=None, check_every: int = 1):
    """x with |A x - b| <= tolerance |b| by conjugate gradients preconditioned by the diagonal;
    returns (x, iterations). A: a CSR matrix of xp (symmetric positive definite). The residual norm
    crosses to the host every check_every iterations only (a GPU waits for nothing in between)."""
    x = xp.zeros_like(b) if x0 is None else x0.copy()
    r = b - A @ x if x0 is not None else b.copy()
    target = tolerance * float(xp.linalg.norm(b))
    if target == 0.0:
        return xp.zeros_like(b), 0
    if float(xp.linalg.norm(r)) <= target:
        return x, 0
    inverse = 1.0 / diagonal
    z = inverse * r
    p = z.copy()
    rz = r @ z
    for iteration in range(1, max_iterations + 1):
        Ap = A @ p
        alpha = rz / (p @ Ap)
        x += alpha * p
        r -= alpha * Ap
        if iteration % check_every == 0 and float(xp.linalg.norm(r)) <= target:
            return x, iteration
        z = inverse * r
        rz, rz_old = r @ z, rz
        p = z + (rz / rz_old) * p
    if float(xp.linalg.norm(r)) <= target:
        return x, max_iterations
    raise TensormassError(f"the device CG did not reach a relative residual of {tolerance:g} in {max_iterations} "
                          "iterations (solver.cg_max_iterations)")


class _DevicePart:
    """One part on the device: its elements sorted by colour, their constants, cells and CSR map."""

    def __init__(self, device, module, D, cells, blocks, cell_ids):
        order, self.offsets = colour_ranges(cells)
        xp = device.xp
        self.module = module
        self.D = xp.asarray(np.ascontiguousarray(D[order], dtype=np.float64))
        self.cells = xp.asarray(np.ascontiguousarray(cells[order], dtype=np.int64))
        self.pos = xp.asarray(np.ascontiguousarray(blocks[order], dtype=np.int32))
        self.flags = xp.zeros(len(order), dtype=np.int32)
        self.cell_ids = np.asarray(cell_ids)[order]
        self.n_colours = len(self.offsets) - 1

    def add(self, u, f, data) -> None:
        for a, b in zip(self.offsets[:-1], self.offsets[1:]):
            self.module.forces_and_stiffness_scatter(self.D[a:b], u, self.cells[a:b], self.pos[a:b], f, data,
                                                     self.flags[a:b])

    def inverted(self) -> np.ndarray:
        bad = self.flags != 0
        if not bool(bad.any()):
            return np.zeros(0, dtype=np.int64)
        return self.cell_ids[np.flatnonzero(np.asarray(bad.get() if hasattr(bad, "get") else bad))]


class DeviceSystem:
    """The global f and K of several parts on a device, and the implicit Euler step's linear system.

    parts: (module, D, cells, blocks, cell_ids) per part, host arrays: module a kernel loaded by
    device.load, D its constants, cells (n, k) node ids, blocks (n, nd, k) the node-blocked CSR map
    (runtime.kernels.fused); mass: the mass matrix's values on the pattern (host); fixed_dofs: dofs
    whose rows and columns the step replaces by the identity."""

    def __init__(self, device: Device, pattern, parts, mass_data, fixed_dofs, cg_tolerance=1e-8,
                 cg_max_iterations=1000, check_every: int = 1):
        xp = device.xp
        self.device, self.xp = device, xp
        self.n = pattern.n_dofs
        self.cg_tolerance, self.cg_max_iterations, self.check_every = cg_tolerance, cg_max_iterations, check_every
        self.parts = [_DevicePart(device, *part) for part in parts]
        fixed = np.zeros(self.n, dtype=bool)
        fixed[np.asarray(fixed_dofs, dtype=np.int64)] = True
        rows = np.repeat(np.arange(self.n), np.diff(pattern.indptr))
        self.constrained = xp.asarray(np.flatnonzero(fixed[rows] | fixed[pattern.indices]))
        self.fixed = xp.asarray(np.flatnonzero(fixed))
        self.fixed_diagonal = xp.asarray(pattern.diagonal[fixed])
        self.diagonal = xp.asarray(pattern.diagonal)
        self.free = xp.asarray((~fixed).astype(np.float64))
        indptr, indices = xp.asarray(pattern.indptr), xp.asarray(pattern.indices)
        self.f, self.data = xp.zeros(self.n), xp.zeros(pattern.nnz)
        self.system = xp.zeros(pattern.nnz)
        self.mass_data = xp.asarray(np.asarray(mass_data, dtype=np.float64))
        self.K = device.csr(self.data, indices, indptr, self.n)
        self.A = device.csr(self.system, indices, indptr, self.n)
        self.M = device.csr(self.mass_data, indices, indptr, self.n)
        self._dv = None
        self.iterations = 0

    def assemble(self, u):
        """f = -dW/du and the CSR values of K at u (a device array, node-major), on the device."""
        self.f.fill(0.0)
        self.data.fill(0.0)
        for part in self.parts:
            part.add(u, self.f, self.data)
        for part in self.parts:
            bad = part.inverted()
            if bad.size:
                raise InvertedElementError("det F <= 0 (inverted element) during the device assembly", bad)
        return self.f, self.data

    def implicit_euler(self, u, v, f_ext, dv_fixed, h: float, alpha: float = 0.0, beta: float = 0.0):
        """(dv, residual) of one linearised implicit Euler step from host vectors (the integrator's
        ImplicitEuler.single): (M' + (h beta + h^2) K) dv = h (f - h K v), f = f_int + f_ext - alpha M v
        - beta K v, M' = (1 + h alpha) M, the fixed dofs' dv given; residual = A dv / h - (f - h K v) on
        every dof (its fixed rows are the reactions). Returns host arrays."""
        xp = self.xp
        ud, vd = xp.asarray(u), xp.asarray(v)
        f_int, _ = self.assemble(ud)
        Kv = self.K @ vd
        f = f_int + xp.asarray(f_ext) - alpha * (self.M @ vd) - beta * Kv
        rhs = h * (f - h * Kv)
        self.system[...] = (h * beta + h * h) * self.data + (1.0 + h * alpha) * self.mass_data
        lift = xp.zeros(self.n)
        lift[self.fixed] = xp.asarray(dv_fixed)
        full_A_lift = self.A @ lift                    # the fixed dofs' dv moved to the right-hand side
        diagonal_before = self.system[self.diagonal]
        b = (rhs - full_A_lift) * self.free
        self.system[self.constrained] = 0.0
        self.system[self.fixed_diagonal] = 1.0
        diagonal = diagonal_before * self.free + (1.0 - self.free)
        dv, its = jacobi_pcg(xp, self.A, b, diagonal, self.cg_tolerance, self.cg_max_iterations,
                             x0=self._dv if self._dv is not None and self._dv.shape == b.shape else None,
                             check_every=self.check_every)
        self.iterations += its
        self._dv = dv.copy()
        dv += lift
        # the step's residual with the unconstrained matrix, rebuilt from its parts (A was overwritten)
        A_dv = (h * beta + h * h) * (self.K @ dv) + (1.0 + h * alpha) * (self.M @ dv)
        residual = A_dv / h - (f - h * Kv)
        return _host(dv), _host(residual), its


def _host(a) -> np.ndarray:
    return a if isinstance(a, np.ndarray) else a.get()


class DeviceStep:
    """One body of one kernel stepped by linearised implicit Euler with every array on a device:
    lumped masses, clamped nodes and a body force (the benchmark's and the device check's step; a
    scene runs the integrator runtime.physics.device_euler)."""

    def __init__(self, device: Device, points, cells, kernel, params, fixed_nodes, node_mass, dt: float, body_force,
                 tolerance: float = 1e-10, max_iterations: int = 5000, check_every: int = 1):
        from ..assembly.pattern import SparsePattern
        from ..base.dofs import node_dofs
        from ..kernels.fused import node_block_positions
        points = np.asarray(points, dtype=np.float64)
        n_points, dim = points.shape
        cells = np.ascontiguousarray(cells, dtype=np.int64)
        xp = device.xp
        self.device, self.xp, self.dt = device, xp, float(dt)
        module = device.load(kernel.element, kernel.law, kernel.quadrature)
        n = len(cells)
        D = np.zeros((n, kernel.n_constants))
        flags = np.zeros(n, dtype=np.int32)
        kernel.module.constants(np.ascontiguousarray(points[cells]), np.ascontiguousarray(params, dtype=np.float64),
                                D, flags)
        if flags.any():
            raise TensormassError("degenerate or inverted element(s) at rest")
        pattern = SparsePattern([node_dofs(cells, dim)], n_points * dim, dim)
        mass = np.repeat(np.asarray(node_mass, dtype=np.float64), dim)
        mass_data = np.zeros(pattern.nnz)
        mass_data[pattern.diagonal] = mass
        fixed = node_dofs(np.asarray(fixed_nodes).reshape(-1, 1), dim).ravel()
        blocks = node_block_positions(pattern, dim)[0]
        self.system = DeviceSystem(device, pattern, [(module, D, cells, blocks, np.arange(n))], mass_data, fixed,
                                   tolerance, max_iterations, check_every)
        self.pattern, self.n_dofs = pattern, pattern.n_dofs
        s = self.system
        self.f_ext = xp.asarray(mass * np.tile(np.asarray(body_force, dtype=np.float64), n_points))
        self.u, self.v = xp.zeros(self.n_dofs), xp.zeros(self.n_dofs)
        self.iterations = []
        self._s = s

    def advance(self) -> int:
        """One step, every array staying on the device; returns the CG iterations it took."""
        s, xp, h = self._s, self.xp, self.dt
        f_int, _ = s.assemble(self.u)
        Kv = s.K @ self.v
        rhs = h * (f_int + self.f_ext - h * Kv) * s.free
        s.system[...] = (h * h) * s.data + s.mass_data
        diagonal = s.system[s.diagonal] * s.free + (1.0 - s.free)
        s.system[s.constrained] = 0.0
        s.system[s.fixed_diagonal] = 1.0
        dv, its = jacobi_pcg(xp, s.A, rhs, diagonal, s.cg_tolerance, s.cg_max_iterations, check_every=s.check_every)
        self.v += dv
        self.u += h * self.v
        self.iterations.append(its)
        return its
