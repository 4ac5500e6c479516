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

__all__ = ["Device", "DevicePCG", "DeviceSystem", "DeviceStep", "get_device", "host_device", "colour_ranges",
           "DEVICES"]

DEVICES = ("cpu", "cuda")


@dataclass(frozen=True)
class Device:
    """An array device: its array module (numpy's API) and how it loads a generated kernel
    (element, law, quadrature) as a module whose functions take its arrays."""
    name: str
    xp: object
    load: Callable
    pcg: Callable                     # () -> backends.cuda.loader.PCGFunctions

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


def _cache_call(function):
    from ..base.cache import cache_dir, writable_cache_dir
    from ... import backends
    try:
        return function(cache_dir(), writable_cache_dir)
    except backends.BackendError as error:
        raise TensormassError(str(error)) from None


def host_device() -> Device:
    """numpy arrays and the cuda backend's host shim: the device code path, checked on the host."""
    from ...backends.cuda import loader
    return Device("cuda (host shim)", np, _host_load, lambda: _cache_call(loader.load_pcg_host_shim))


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
    from ...backends.cuda import loader
    return Device("cuda", cp, _cuda_load, lambda: _cache_call(loader.load_pcg))


def colour_ranges(cells) -> tuple[np.ndarray, np.ndarray]:
    """(order, offsets): the elements sorted by DSATUR colour (stable: by index within a colour) and
    the start of each colour's range in that order (n_colours + 1 entries)."""
    colours = colour_cells(cells)
    order = np.argsort(colours, kind="stable")
    offsets = np.concatenate([[0], np.cumsum(np.bincount(colours))])
    return order, offsets


class DevicePCG:
    """Jacobi-preconditioned CG whose iterations run on the device (backends/cuda/solvers/pcg.cu): every
    check_every iterations are one CUDA graph launch on a GPU (captured at the first solve), and only
    r.r crosses to the host between them. On the host shim the same kernels run in a loop.

    pcg = DevicePCG(device, pattern.indptr, pattern.indices, n)
    x, iterations = pcg.solve(data, b, diagonal, tolerance, max_iterations, x0)   # |A x - b| <= tol |b|

    The residual is checked between blocks only: a solve takes a multiple of check_every iterations,
    up to check_every - 1 past max_iterations, and stops on the recurrence's residual (as scipy's CG).
    """

    def __init__(self, device: Device, indptr, indices, n: int, check_every: int = 8):
        from ...backends.cuda.loader import PCG_BLOCK_THREADS, PCG_ROW_LANES
        xp = device.xp
        self.device, self.xp, self.n, self.check_every = device, xp, int(n), int(check_every)
        self.kernels = device.pcg()
        if len(indices) >= 2**31:
            raise TensormassError("the device CG indexes the matrix with int32: more than 2^31 nonzeros")
        self.indptr = xp.asarray(np.asarray(indptr, dtype=np.int32))
        self.indices = xp.asarray(np.asarray(indices, dtype=np.int32))
        # launch shapes from the sizes alone: the same sums in the same order, run after run
        self.row_blocks = max(1, min(-(-self.n * PCG_ROW_LANES // PCG_BLOCK_THREADS), 65535))
        self.blocks = max(1, min(-(-self.n // PCG_BLOCK_THREADS), 1024))
        self.x, self.r, self.z, self.p, self.Ap, self.inverse = (xp.zeros(self.n) for _ in range(6))
        self.s = xp.zeros(4)
        self.partial = xp.zeros(2 * self.blocks)
        self._graph = None

    def _iteration(self, data) -> None:
        launch, n, b = self.kernels.launch, self.n, self.blocks
        launch("tm_spmv", self.row_blocks, n, self.indptr, self.indices, data, self.p, self.Ap)
        launch("tm_dot_partial", b, n, self.p, self.Ap, self.partial)
        launch("tm_dot_finish", 1, b, 1, self.partial, self.s, 1)
        launch("tm_update_xrz", b, n, self.s, self.p, self.Ap, self.inverse, self.x, self.r, self.z)
        launch("tm_dot2_partial", b, n, self.r, self.z, b, self.partial)
        launch("tm_dot_finish", 1, b, 2, self.partial, self.s, 2)
        launch("tm_update_p", b, n, self.s, self.z, self.p)
        launch("tm_shift", 1, self.s)

    def _iterations(self, data) -> None:
        """check_every iterations: a captured CUDA graph on a GPU (the arrays it reads keep their
        addresses: data is the caller's matrix buffer, updated in place between solves)."""
        if not self.kernels.on_device:
            for _ in range(self.check_every):
                self._iteration(data)
            return
        cp = self.xp
        key = data.data.ptr
        if self._graph is None or self._graph[0] != key:
            stream = cp.cuda.Stream(non_blocking=True)
            with stream:
                stream.begin_capture()
                for _ in range(self.check_every):
                    self._iteration(data)
                graph = stream.end_capture()
            self._graph = (key, graph, stream)
        _, graph, stream = self._graph
        # the graph's stream does not wait for the default stream, which wrote x, r, z, p and s
        cp.cuda.Stream.null.synchronize()
        graph.launch(stream=stream)
        stream.synchronize()

    def solve(self, data, b, diagonal, tolerance: float, max_iterations: int, x0=None):
        xp = self.xp
        norm_b = float(xp.linalg.norm(b))
        if norm_b == 0.0:
            return xp.zeros(self.n), 0
        target = (tolerance * norm_b) ** 2
        self.inverse[...] = 1.0 / diagonal
        if x0 is None:
            self.x.fill(0.0)
            self.r[...] = b
        else:
            self.x[...] = x0
            self.kernels.launch("tm_spmv", self.row_blocks, self.n, self.indptr, self.indices, data, self.x, self.Ap)
            self.r[...] = b - self.Ap
        self.z[...] = self.inverse * self.r
        self.p[...] = self.z
        self.s[0] = float(self.r @ self.z)
        rr = float(self.r @ self.r)
        iterations = 0
        while rr > target:
            if iterations >= max_iterations:
                raise TensormassError(f"the device CG did not reach a relative residual of {tolerance:g} in "
                                      f"{max_iterations} iterations (solver.cg_max_iterations)")
            self._iterations(data)
            iterations += self.check_every
            rr = float(self.s[3])
            if not np.isfinite(rr):
                raise TensormassError("the device CG broke down (the step's matrix is not positive definite)")
        return self.x.copy(), iterations


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
                 cg_max_iterations=1000, check_every: int = 8):
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
        self.pcg = DevicePCG(device, pattern.indptr, pattern.indices, self.n, check_every)
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
        dv, its = self.pcg.solve(self.system, b, diagonal, self.cg_tolerance, self.cg_max_iterations, x0=self._dv)
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
                 tolerance: float = 1e-10, max_iterations: int = 5000, check_every: int = 8):
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
        s, h = self._s, self.dt
        f_int, _ = s.assemble(self.u)
        Kv = s.K @ self.v
        rhs = h * (f_int + self.f_ext - h * Kv) * s.free
        s.system[...] = (h * h) * s.data + s.mass_data
        diagonal = s.system[s.diagonal] * s.free + (1.0 - s.free)
        s.system[s.constrained] = 0.0
        s.system[s.fixed_diagonal] = 1.0
        dv, its = s.pcg.solve(s.system, rhs, diagonal, s.cg_tolerance, s.cg_max_iterations)
        self.v += dv
        self.u += h * self.v
        self.iterations.append(its)
        return its
