"""Load generated kernels and give them one friendly, checked API.

    k = load_kernel("tetra", "stvk", "gauss1", backend="numba")
    D = k.constants(X, E=1e6, nu=0.3)      # per-element constants, once
    f, K = k.forces_and_stiffness(D, u)    # every step
    S = k.stress(D, u)                     # per point v, W, F, P (output fields, runtime.physics.fields)
    k.forces_and_stiffness_scatter(D, U, cells, pos, f_global, data)   # fused: straight into CSR values

A kernel comes from the committed catalogue (tensormass.generated); a
combination that is not there (a new law file, another rule) is generated on
first use into the user cache and loaded from there.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
from numba import njit

from ... import backends, generated, laws
from ..base.cache import cache_dir, writable_cache_dir
from ..base.errors import DegenerateElementError, InvertedElementError, KernelNotFoundError, TensormassError

BACKENDS = backends.BACKENDS


class Kernel:
    """One element x law x quadrature kernel: constants once, then energy, forces, stiffness.

    Every attribute comes from the metadata the generated file exports (backends.METADATA_KEYS),
    the layout of the per-element constants D included: nothing here re-derives it."""

    def __init__(self, module, backend: str):
        self.module = module
        self.backend = backend
        meta = module.METADATA
        self.metadata = meta
        self.name = meta["name"]
        self.element = meta["element"]
        self.law = meta["law"]
        self.quadrature = meta["quadrature"]
        self.dim = int(meta["dim"])
        self.n_nodes = int(meta["n_nodes"])
        self.n_points = int(meta["n_points"])
        self.n_constants = int(meta["n_constants"])
        self.parameters = tuple(meta["parameters"])
        self.ops = dict(meta["ops"])
        self.n_dofs = int(meta["n_dofs"])
        self.dofs_per_node = int(meta["dofs_per_node"])
        # Layout of D: per point q, D[q * point_stride + v_offset] = weight x det J and the shape
        # gradients G[i][b] (b < dim) at q * point_stride + G_offset + i * dim + b; then the material.
        self.point_stride = int(meta["point_stride"])
        self.point_fields = dict(meta["point_fields"])
        self.v_offset = self.point_fields.get("v")
        self.G_offset = self.point_fields.get("G")
        self.material_offset = int(meta["material_offset"])
        # "recompute" kernels (a generator option) keep rest coordinates in D instead of G.
        self.recompute = bool(meta["recompute"])
        # W homogeneous quadratic in grad u (Hooke): K is constant and f = -K u, so the assembly
        # builds K once and takes the forces and energy from it.
        self.quadratic_energy = bool(meta["quadratic_energy"])
        # What stress() writes per element and point: {"size", "offsets": {v, W, F, P(, P33)}}
        # (generator.kernel_body.stress_record, exported by every generated file).
        self.stress_record = {"size": int(meta["stress_record"]["size"]),
                              "offsets": dict(meta["stress_record"]["offsets"])}

    def point_volumes(self, D) -> np.ndarray:
        """(n_elem, n_points) integration weights x det J, read from the constants."""
        self._need_points()
        stop = self.n_points * self.point_stride
        return np.asarray(D)[:, self.v_offset:stop:self.point_stride]

    def point_gradients(self, D) -> np.ndarray:
        """(n_elem, n_points, n_nodes, dim) shape gradients G at the points, read from the constants."""
        self._need_points()
        D = np.asarray(D)
        n, s = len(D), self.point_stride
        block = D[:, :self.n_points * s].reshape(n, self.n_points, s)
        G = block[:, :, self.G_offset:self.G_offset + self.n_nodes * self.dim]
        return G.reshape(n, self.n_points, self.n_nodes, self.dim)

    def _need_points(self):
        if self.recompute:
            raise TensormassError(f"{self}: needs precomputed shape gradients (constants='precompute')")

    def __repr__(self):
        return f"<Kernel {self.element}/{self.law}/{self.quadrature} ({self.backend})>"

    # -- inputs -----------------------------------------------------------------------------
    def _coords(self, X) -> np.ndarray:
        X = np.ascontiguousarray(X, dtype=np.float64)
        if X.ndim == 2:
            X = X[None]
        if X.shape[1:] != (self.n_nodes, self.dim):
            raise TensormassError(f"{self.element}: rest coordinates must have shape (n_elem, {self.n_nodes}, {self.dim}), got {X.shape}")
        if not np.all(np.isfinite(X)):
            raise TensormassError(f"{self.element}: rest coordinates contain NaN or Inf")
        return X

    def _params(self, n: int, E, nu, native) -> np.ndarray:
        law = laws.kernel_law(self.law)
        values = law.native_parameters(E=E, nu=nu, **native)
        missing = [d for d in law.directions if any(f"{d}_{c}" not in values for c in "xyz")]
        if missing:
            raise TensormassError(f"law {self.law!r} needs its fibre direction {missing[0]!r}: give "
                                  f"{', '.join(f'{missing[0]}_{c}' for c in 'xyz')} (a scene: [[material]] fibres)")
        table = np.empty((n, len(self.parameters)))
        for k, p in enumerate(self.parameters):
            try:
                table[:, k] = np.broadcast_to(values[p], (n,))
            except ValueError:
                raise TensormassError(f"parameter {p} must be a scalar or have one value per element ({n})") from None
        return table

    def _displacements(self, D, u):
        """D and u as C-contiguous float64 arrays of the right shapes (views when they already are)."""
        D = np.ascontiguousarray(D, dtype=np.float64)
        if D.ndim != 2 or D.shape[1] != self.n_constants:
            raise TensormassError(f"{self}: constants must have shape (n_elem, {self.n_constants}), got {D.shape}")
        u = np.ascontiguousarray(u, dtype=np.float64)
        per_node = self.n_dofs // self.n_nodes
        if u.size != D.shape[0] * self.n_dofs:
            raise TensormassError(f"{self}: displacements must have shape ({D.shape[0]}, {self.n_nodes}, {per_node}), "
                                  f"got {u.shape}")
        u = u.reshape(D.shape[0], self.n_nodes, per_node)
        self._finite(u)
        return D, u

    @staticmethod
    def _finite(u):
        """A clear error when u holds NaN or Inf (never a silent NaN result).

        One pairwise sum over u (no temporary array): it is finite whenever every entry is (a NaN
        or Inf always propagates); only when it is not (a NaN, or an overflow) is u searched
        element by element.  It is one memory pass over u: ~0.15 ms per 50 000 tetra, 2-4 % of a
        forces_and_stiffness call, ~10 % of a forces-only call (measured, apps/bench.py)."""
        with np.errstate(over="ignore", invalid="ignore"):
            total = np.add.reduce(u, axis=None)
        if np.isfinite(total):
            return
        bad_u = ~np.isfinite(u.reshape(len(u), -1)).all(axis=1)
        if bad_u.any():
            bad = np.flatnonzero(bad_u)
            raise TensormassError(f"displacements contain NaN or Inf in element(s) {', '.join(map(str, bad[:10]))}")

    def _buffer(self, array, shape, name: str, dtype=np.float64) -> np.ndarray:
        """An out= buffer: exactly `shape`, dtype, C-contiguous and writeable; else a clear error."""
        if array is None:
            return np.zeros(shape, dtype=dtype) if dtype != np.float64 else np.empty(shape)
        if not isinstance(array, np.ndarray) or array.shape != shape or array.dtype != dtype \
                or not array.flags.c_contiguous or not array.flags.writeable:
            got = (f"{array.dtype} array of shape {array.shape}"
                   + ("" if array.flags.c_contiguous else ", not C-contiguous")
                   + ("" if array.flags.writeable else ", read-only")) if isinstance(array, np.ndarray) \
                else type(array).__name__
            raise TensormassError(f"{self}: {name} must be a writeable C-contiguous {np.dtype(dtype).name} array "
                                  f"of shape {shape}, got {got}")
        return array

    def _flags(self, flags, n):
        return self._buffer(flags, (n,), "flags=", np.int32)

    def _check(self, flags, what: str):
        if not flags.any():
            return
        bad = np.flatnonzero(flags)
        raise InvertedElementError(f"{what}: det F <= 0 (inverted element) where law {self.law!r} is undefined", bad)

    @staticmethod
    def _pair(out, what):
        if out is None:
            return None, None
        if not isinstance(out, (tuple, list)) or len(out) != 2:
            raise TensormassError(f"{what}: out= must be a pair (f, K) of buffers")
        return out

    # -- kernels ----------------------------------------------------------------------------
    def constants(self, X, E=None, nu=None, **native) -> np.ndarray:
        """Per-element constants D from rest coordinates and E, nu (or native parameters, e.g. mu=, lam=)."""
        X = self._coords(X)
        params = self._params(len(X), E, nu, native)
        D = np.empty((len(X), self.n_constants))
        flags = np.zeros(len(X), dtype=np.int32)
        self.module.constants(X, params, D, flags)
        if np.any(flags == 1):
            raise DegenerateElementError(f"{self.element}: det J <= 0 in the rest configuration (inverted or degenerate)",
                                         np.flatnonzero(flags == 1))
        if np.any(flags == 2):
            why = (f"law {self.law!r} is a lattice of springs: the cells must be cubes (edges or angles differ by "
                   "more than about 0.1 %)" if self.G_offset is None and self.point_fields else
                   "quadrature 'exact' needs straight-edged elements (curved edges found)")
            raise DegenerateElementError(f"{self.element}: {why}", np.flatnonzero(flags == 2))
        return D

    # The four evaluations take optional output buffers (out=, flags=): with them a call
    # allocates nothing (the runtime's assembly and the benchmark's "public API with out=" row);
    # without them fresh arrays are returned as before.  Buffers are checked (shape, float64,
    # C-contiguous, writeable), never copied: the result is written into them and returned.
    def energy(self, D, u, out=None, flags=None) -> np.ndarray:
        D, u = self._displacements(D, u)
        n = len(D)
        out, flags = self._buffer(out, (n,), "energy out="), self._flags(flags, n)
        self.module.energy(D, u, out, flags)
        self._check(flags, "energy")
        return out

    def forces(self, D, u, out=None, flags=None) -> np.ndarray:
        D, u = self._displacements(D, u)
        n = len(D)
        f, flags = self._buffer(out, (n, self.n_dofs), "forces out="), self._flags(flags, n)
        self.module.forces(D, u, f, flags)
        self._check(flags, "forces")
        return f

    def stiffness(self, D, u, out=None, flags=None) -> np.ndarray:
        D, u = self._displacements(D, u)
        n = len(D)
        K, flags = self._buffer(out, (n, self.n_dofs, self.n_dofs), "stiffness out="), self._flags(flags, n)
        self.module.stiffness(D, u, K, flags)
        self._check(flags, "stiffness")
        return K

    def forces_and_stiffness(self, D, u, out=None, flags=None):
        D, u = self._displacements(D, u)
        n = len(D)
        f, K = self._pair(out, "forces_and_stiffness")
        f = self._buffer(f, (n, self.n_dofs), "forces_and_stiffness out[0] (f)")
        K = self._buffer(K, (n, self.n_dofs, self.n_dofs), "forces_and_stiffness out[1] (K)")
        flags = self._flags(flags, n)
        self.module.forces_and_stiffness(D, u, f, K, flags)
        self._check(flags, "forces_and_stiffness")
        return f, K

    def stress(self, D, u, out=None, flags=None) -> np.ndarray:
        """(n_elem, n_points, stress_record["size"]) records: per element and integration point the
        rest volume v = w det J, the energy density W, F and P = dW/dF (dim x dim, row-major) and,
        in 2D (plane strain), P33; offsets in self.stress_record. runtime.physics.fields derives the
        output fields from them."""
        D, u = self._displacements(D, u)
        n = len(D)
        S = self._buffer(out, (n, self.n_points, self.stress_record["size"]), "stress out=")
        flags = self._flags(flags, n)
        self.module.stress(D, u, S, flags)
        self._check(flags, "stress")
        return S

    def forces_and_stiffness_scatter(self, D, U, cells, pos, f, data, flags=None, check: bool = True) -> None:
        """Fused evaluation and scatter: f += the element forces, data += the element stiffness
        (CSR values), element after element, with no per-element output arrays.

        D (n_elem, n_constants); U (n_points, dofs_per_node) global displacements (or flat),
        read through cells (n_elem, n_nodes) int64 node ids; pos (n_elem, n_dofs, n_nodes) int32
        from runtime.kernels.fused.block_positions (CSR index of row dof r, first dof of node j);
        f (U.size,) and data (nnz,) float64, contiguous, added to in place. flags: optional
        (n_elem,) int32 work array. check=False skips the index range checks of cells and pos
        (a caller that checked them once). Bit-identical to forces_and_stiffness followed by
        runtime.assembly.assembly's serial scatter."""
        n_elem = len(D)
        D = np.ascontiguousarray(D, dtype=np.float64)
        if D.ndim != 2 or D.shape[1] != self.n_constants:
            raise TensormassError(f"{self}: constants must have shape (n_elem, {self.n_constants}), got {D.shape}")
        U = np.ascontiguousarray(U, dtype=np.float64)
        if U.size % self.dofs_per_node:
            raise TensormassError(f"{self}: U must have shape (n_points, {self.dofs_per_node}), got {U.shape}")
        U = U.reshape(-1, self.dofs_per_node)
        if not np.all(np.isfinite(U)):
            raise TensormassError("displacements contain NaN or Inf at node(s) "
                                  + ", ".join(map(str, np.flatnonzero(~np.isfinite(U).all(axis=1))[:10])))
        cells = self._index_array(cells, np.int64, (n_elem, self.n_nodes), "cells")
        pos = self._index_array(pos, np.int32, (n_elem, self.n_dofs, self.n_nodes), "pos")
        for name, out, size in (("f", f, U.size), ("data", data, None)):
            if not (isinstance(out, np.ndarray) and out.dtype == np.float64 and out.ndim == 1
                    and out.flags.c_contiguous and out.flags.writeable):
                raise TensormassError(f"{self}: {name} must be a writable contiguous 1D float64 array")
            if size is not None and out.size != size:
                raise TensormassError(f"{self}: f must have {size} entries (U.size), got {out.size}")
        if check and n_elem:
            if cells.min() < 0 or cells.max() >= len(U):
                raise TensormassError(f"{self}: cells hold node ids outside 0..{len(U) - 1}")
            if pos.min() < 0 or pos.max() > data.size - self.dofs_per_node:
                raise TensormassError(f"{self}: pos holds CSR indices outside the {data.size} values of data")
        if flags is None:
            flags = np.zeros(n_elem, dtype=np.int32)
        elif not (isinstance(flags, np.ndarray) and flags.dtype == np.int32 and flags.shape == (n_elem,)
                  and flags.flags.c_contiguous and flags.flags.writeable):
            raise TensormassError(f"{self}: flags must be a writable contiguous int32 array of shape ({n_elem},)")
        self.module.forces_and_stiffness_scatter(D, U, cells, pos, f, data, flags)
        self._check(flags, "forces_and_stiffness_scatter")

    def _index_array(self, a, dtype, shape, name):
        a = np.asarray(a)
        if a.shape != shape or not np.issubdtype(a.dtype, np.integer):
            raise TensormassError(f"{self}: {name} must be an integer array of shape {shape}, got {a.dtype} {a.shape}")
        if a.dtype != dtype and a.size and (a.max() > np.iinfo(dtype).max or a.min() < np.iinfo(dtype).min):
            raise TensormassError(f"{self}: {name} holds values that do not fit {np.dtype(dtype).name}")
        return np.ascontiguousarray(a, dtype=dtype)

    def min_det_F(self, D, u, cells=None) -> np.ndarray:
        """Smallest det F over the integration points of each element (any law).

        u: element displacements (n_elem, n_nodes, dim); or, with cells (n_elem, n_nodes) node
        ids, the global (n_points, dim) displacements, read through cells without gathering
        them (the runtime's per-step checks: a gather costs 3x the loop itself)."""
        if self.recompute:
            raise TensormassError(f"{self}: min_det_F() needs precomputed shape gradients (constants='precompute')")
        if self.G_offset is None:
            return self._record_det_F(D, u, cells)
        if cells is None:
            D, u = self._displacements(D, u)
            n = len(D)
            U = u.reshape(n * self.n_nodes, self.dim)
            cells = np.arange(n * self.n_nodes).reshape(n, self.n_nodes)
        else:
            D = np.ascontiguousarray(D, dtype=np.float64)
            U = np.ascontiguousarray(u, dtype=np.float64).reshape(-1, self.dim)
            if cells.shape != (len(D), self.n_nodes):
                raise TensormassError(f"{self}: cells must have shape ({len(D)}, {self.n_nodes}), got {cells.shape}")
        out = np.empty(len(D))
        (_min_det_3d if self.dim == 3 else _min_det_2d)(D, cells, U, self.n_points, self.point_stride,
                                                        self.G_offset, out)
        return out

    def _record_det_F(self, D, u, cells) -> np.ndarray:
        """det F of the stress record's F: a discrete kernel's (springs, lattice cubes: no shape
        gradients) homogenised deformation gradient, the least-squares fit of its nodes (V / V0 of a cube)."""
        if cells is not None:
            u = np.asarray(u, dtype=np.float64).reshape(-1, self.dofs_per_node)[cells]
        S = self.stress(D, u)
        at = self.stress_record["offsets"]["F"]
        F = S[:, :, at:at + self.dim * self.dim].reshape(len(S), self.n_points, self.dim, self.dim)
        return np.linalg.det(F).min(axis=1)

    def inverted(self, D, u, cells=None) -> np.ndarray:
        """Boolean mask of elements whose det F <= 0 at some integration point (any law)."""
        return ~(self.min_det_F(D, u, cells) > 0.0)


# min det F from the stored constants: per point q, the shape gradients G_qi start at
# D[e, q*stride + g_offset], node-major (the kernel's metadata); F = I + sum_i u_i (x) G_qi.  numba loops, not numpy:
# implicit steps check every element after every step (laws undefined at det F <= 0, the health
# monitor), and the einsum version allocated an (n, dim, dim) F per point.
@njit(cache=True)
def _min_det_3d(D, cells, U, n_points, stride, g_offset, out):
    for e in range(D.shape[0]):
        low = np.inf
        for q in range(n_points):
            b = q * stride + g_offset
            f00 = 1.0; f01 = 0.0; f02 = 0.0                       # noqa: E702
            f10 = 0.0; f11 = 1.0; f12 = 0.0                       # noqa: E702
            f20 = 0.0; f21 = 0.0; f22 = 1.0                       # noqa: E702
            for i in range(cells.shape[1]):
                n = cells[e, i]
                gx, gy, gz = D[e, b + 3 * i], D[e, b + 3 * i + 1], D[e, b + 3 * i + 2]
                ux, uy, uz = U[n, 0], U[n, 1], U[n, 2]
                f00 += ux * gx; f01 += ux * gy; f02 += ux * gz    # noqa: E702
                f10 += uy * gx; f11 += uy * gy; f12 += uy * gz    # noqa: E702
                f20 += uz * gx; f21 += uz * gy; f22 += uz * gz    # noqa: E702
            det = (f00 * (f11 * f22 - f12 * f21) - f01 * (f10 * f22 - f12 * f20)
                   + f02 * (f10 * f21 - f11 * f20))
            if not det >= low:             # NaN too: a non-finite state is never "not inverted"
                low = det
        out[e] = low


@njit(cache=True)
def _min_det_2d(D, cells, U, n_points, stride, g_offset, out):
    for e in range(D.shape[0]):
        low = np.inf
        for q in range(n_points):
            b = q * stride + g_offset
            f00 = 1.0; f01 = 0.0; f10 = 0.0; f11 = 1.0          # noqa: E702
            for i in range(cells.shape[1]):
                n = cells[e, i]
                gx, gy = D[e, b + 2 * i], D[e, b + 2 * i + 1]
                f00 += U[n, 0] * gx; f01 += U[n, 0] * gy          # noqa: E702
                f10 += U[n, 1] * gx; f11 += U[n, 1] * gy          # noqa: E702
            det = f00 * f11 - f01 * f10
            if not det >= low:
                low = det
        out[e] = low


def backend_of(name: str):
    """The registered backend called name (TensormassError naming the known ones otherwise)."""
    try:
        return backends.get(name)
    except backends.BackendError as error:
        raise TensormassError(str(error)) from None


@lru_cache(maxsize=None)
def load_kernel(element: str, law: str, quadrature: str, backend: str | None = None) -> Kernel:
    """The kernel for (element, law, quadrature): committed, cached, or generated now.  backend:
    "c" or "numba"; None: a scene's default, C where a compiler is found (it compiles a kernel in
    about a second; numba takes 6 to 40 s per function at its first call)."""
    if backend is None:
        backend = backends.default_backend()
    target = backend_of(backend)
    name = f"{element}_{law}_{quadrature}"
    return _load(target, kernel_source(element, law, quadrature, backend), name)


def prepare_kernels(triples, backend: str) -> None:
    """Get several (element, law, quadrature) kernels ready before they are loaded one by one: the
    C backend compiles the missing libraries at once, one compiler per core (a scene's first run)."""
    target = backend_of(backend)
    sources = [kernel_source(*triple, backend) for triple in sorted(set(triples))]
    try:
        target.prepare(sources, cache_dir(), writable=writable_cache_dir)
    except backends.BackendError as error:
        raise TensormassError(str(error)) from None


def kernel_source(element: str, law: str, quadrature: str, backend: str) -> Path:
    """The generated file of a catalogue entry: the committed one, else one in the user cache,
    generated now when missing or made by other templates (a stale one is regenerated)."""
    target = backend_of(backend)
    name = f"{element}_{law}_{quadrature}"
    committed = Path(generated.__file__).resolve().parent / backend / target.file_name(name)
    if committed.exists():
        return committed
    # deferred: the catalogue and the generator load sympy and jinja2 (0.80 s); a run whose kernels
    # are all committed never needs them.
    from ...generator.catalogue import Entry, entries
    from ...generator.pipeline import generate_all
    entries([element], [law], [quadrature])      # validates the names with clear messages
    folder = kernel_folder(law)
    cached = folder / backend / target.file_name(name)
    if not (cached.exists() and _fresh(cached, target)):
        writable_cache_dir(cached.parent, f"generating kernel {name} (not in the committed catalogue)")
        generate_all([Entry(element, law, quadrature)], [backend], folder, progress=None)
    if not cached.exists():
        raise KernelNotFoundError(f"could not generate kernel {name} ({backend})")
    return cached


def kernel_folder(law: str) -> Path:
    """Where kernels of `law` generated on demand live: the user cache; for a law file outside the
    package (laws.load_file, $TENSORMASS_LAWS) a folder of its own named by the file's content
    hash, so that an edited law file gets new kernels and never the old ones."""
    user = laws.user_law(law)
    if user is None:
        return cache_dir()
    return cache_dir() / "laws" / f"{law}-{user.digest}"


def _fresh(path: Path, target) -> bool:
    """A cached file made by the current templates of its backend (an older one is regenerated)."""
    try:
        meta = target.read_metadata(path)
    except backends.BackendError:
        return False
    return meta.get("templates") == target.templates_hash()[:16]


def _load(target, path: Path, name: str) -> Kernel:
    """Load through the backend; its errors become TensormassError with the same message."""
    try:
        module = target.load(path, cache_dir(), writable=writable_cache_dir)
    except backends.BackendError as error:
        raise TensormassError(str(error)) from None
    if module.METADATA["name"] != name:
        raise TensormassError(f"{path}: holds kernel {module.METADATA['name']!r}, expected {name!r}")
    return Kernel(module, target.name)


@lru_cache(maxsize=None)
def load_recompute_kernel(element: str, law: str, quadrature: str, backend: str = "numba") -> Kernel:
    """The generator's constants="recompute" variant (D holds rest coordinates, the geometry is
    recomputed every call), generated into the cache on first use. Used by the kernel benchmark
    to compare memory traffic against arithmetic; not part of the committed catalogue."""
    # deferred: benchmark-only; the generator loads sympy and jinja2 (0.93 s).
    from ...generator.ir import build_ir
    from ...generator.pipeline import write_atomic
    target = backend_of(backend)
    ir = build_ir(element, law, quadrature, constants="recompute")
    path = cache_dir() / "recompute" / backend / target.file_name(ir)
    text = target.render(ir)
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        writable_cache_dir(path.parent, f"the recompute variant of {ir.name}")
        write_atomic(path, text)
    return _load(target, path, ir.name)
