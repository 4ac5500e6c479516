"""Global assembly: one CSR pattern built once, element results scattered with numba.

    asm = Assembler(model)
    f_int, K_data = asm.forces_and_stiffness(u)      # K = asm.matrix(K_data)
    W, f_int, K = assemble(model, u)                  # the same, for one-off use

Per part the pattern stores where every element matrix entry (e, r, s) lands in
the CSR data array, so a step only runs the kernel and one scatter loop.  With
more than one numba thread the scatter runs colour by colour in parallel:
elements of one colour share no node, so they never write the same entry.
"""
from __future__ import annotations

import time

import numba
import numpy as np
from threadpoolctl import threadpool_limits
import scipy.sparse as sp
from numba import njit, prange

from .. import laws
from .errors import ElementError, TensormassError

__all__ = ["Assembler", "assemble", "colour_elements", "project_psd", "SparsePattern"]


# --------------------------------------------------------------------------- numba loops


@njit(cache=True)
def _scatter_matrix(data, Ke, pos, scale):
    for e in range(Ke.shape[0]):
        for r in range(Ke.shape[1]):
            for s in range(Ke.shape[2]):
                data[pos[e, r, s]] += scale * Ke[e, r, s]


@njit(cache=True, parallel=True)
def _scatter_matrix_coloured(data, Ke, pos, scale, order, starts):
    for c in range(starts.shape[0] - 1):
        # no two elements of colour c share a node, hence no shared CSR entry
        for i in prange(starts[c], starts[c + 1]):
            e = order[i]
            for r in range(Ke.shape[1]):
                for s in range(Ke.shape[2]):
                    data[pos[e, r, s]] += scale * Ke[e, r, s]


@njit(cache=True)
def _scatter_vector(out, fe, dofs):
    for e in range(fe.shape[0]):
        for r in range(fe.shape[1]):
            out[dofs[e, r]] += fe[e, r]


@njit(cache=True)
def _greedy_colours(cells, node_start, node_elems):
    """Smallest colour not used by any already coloured element sharing a node."""
    n = cells.shape[0]
    colour = np.full(n, -1, dtype=np.int64)
    banned = np.full(n + 1, -1, dtype=np.int64)      # banned[c] == e: colour c is taken near e
    for e in range(n):
        for a in range(cells.shape[1]):
            node = cells[e, a]
            for j in range(node_start[node], node_start[node + 1]):
                other = colour[node_elems[j]]
                if other >= 0:
                    banned[other] = e
        c = 0
        while banned[c] == e:
            c += 1
        colour[e] = c
    return colour


def colour_elements(cells: np.ndarray):
    """Greedy colouring of elements so that no two of one colour share a node.

    Returns (colour per element, order: element ids grouped by colour, starts:
    offsets of each colour in order).
    """
    cells = np.ascontiguousarray(cells, dtype=np.int64)
    n_nodes = int(cells.max()) + 1 if cells.size else 0
    flat = cells.ravel()
    node_elems = np.argsort(flat, kind="stable") // cells.shape[1]
    node_start = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=n_nodes))]).astype(np.int64)
    colour = _greedy_colours(cells, node_start, node_elems.astype(np.int64))
    order = np.argsort(colour, kind="stable").astype(np.int64)
    starts = np.concatenate([[0], np.cumsum(np.bincount(colour))]).astype(np.int64)
    return colour, order, starts


# --------------------------------------------------------------------------- PSD projection


def project_psd(K: np.ndarray) -> np.ndarray:
    """Element Hessians with negative eigenvalues clamped to zero (batched eigh).

    Only elements that have a negative eigenvalue are rebuilt, so a mostly
    convex state costs one batched eigenvalue computation.
    """
    K = 0.5 * (K + np.swapaxes(K, 1, 2))          # kernels are symmetric up to round-off
    # Many tiny eigenproblems: BLAS threads only add overhead (measured 3.1 s vs 0.04 s
    # for 288 30x30 matrices on 2 cores), so run them single-threaded.
    with threadpool_limits(limits=1, user_api="blas"):
        w, V = np.linalg.eigh(K)
    bad = np.flatnonzero(w[:, 0] < 0.0)
    if bad.size:
        wb = np.maximum(w[bad], 0.0)
        K[bad] = np.einsum("eij,ej,ekj->eik", V[bad], wb, V[bad], optimize=True)
    return K


# --------------------------------------------------------------------------- the pattern


class SparsePattern:
    """CSR structure of the global matrix and, per part, the scatter positions."""

    def __init__(self, dof_tables, n_dofs: int):
        self.n_dofs = n_dofs
        # parts of one switchable group share their dof table: sort its entries once
        first = {}
        for i, d in enumerate(dof_tables):
            first.setdefault(id(d), i)
        owner = [first[id(d)] for d in dof_tables]
        dof_tables = [dof_tables[i] for i in sorted(set(owner))]
        keys = [self._keys(d, n_dofs) for d in dof_tables]
        diag = np.arange(n_dofs, dtype=np.int64) * (n_dofs + 1)   # keep every diagonal entry
        uniq, inverse = np.unique(np.concatenate(keys + [diag]), return_inverse=True)
        rows, cols = np.divmod(uniq, n_dofs)
        itype = np.int32 if uniq.size < 2**31 - 1 else np.int64
        self.indices = cols.astype(itype)
        self.indptr = np.searchsorted(rows, np.arange(n_dofs + 1)).astype(itype)
        self.nnz = uniq.size
        self.positions, start = [], 0
        for d, k in zip(dof_tables, keys):
            nd = d.shape[1]
            self.positions.append(inverse[start:start + k.size].reshape(len(d), nd, nd).astype(np.int64))
            start += k.size
        slot = {o: j for j, o in enumerate(sorted(set(owner)))}
        self.positions = [self.positions[slot[o]] for o in owner]
        self.diagonal = inverse[start:].astype(np.int64)
        self._rows = rows

    @staticmethod
    def _keys(dofs, n_dofs):
        return (dofs[:, :, None] * n_dofs + dofs[:, None, :]).ravel().astype(np.int64)

    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n_dofs, self.n_dofs))

    def submatrix_map(self, rows_keep: np.ndarray, cols_keep: np.ndarray):
        """Structure of the block (rows_keep, cols_keep), both sorted dof lists.

        Returns (entries, indices, indptr, shape): the block's data is data[entries].
        """
        rmap = np.full(self.n_dofs, -1, dtype=np.int64)
        rmap[rows_keep] = np.arange(rows_keep.size)
        cmap = np.full(self.n_dofs, -1, dtype=np.int64)
        cmap[cols_keep] = np.arange(cols_keep.size)
        r, c = rmap[self._rows], cmap[self.indices]
        entries = np.flatnonzero((r >= 0) & (c >= 0))
        indptr = np.concatenate([[0], np.cumsum(np.bincount(r[entries], minlength=rows_keep.size))])
        shape = (rows_keep.size, cols_keep.size)
        return entries, c[entries].astype(self.indices.dtype), indptr.astype(self.indptr.dtype), shape


# --------------------------------------------------------------------------- the assembler


class Assembler:
    """Energy, internal forces and stiffness of a Model, assembled into global arrays.

    f_int = -dW/du (what the kernels return); K = d2W/du2.  `project` selects
    parts whose element Hessians are projected to PSD (a set of part indices,
    True for all non-Hooke parts, or False).  Times spent are accumulated in
    `self.time` (kernel calls and scatter).
    """

    def __init__(self, model, parallel: bool | None = None):
        self.model = model
        self.pattern = SparsePattern([p.dofs for p in model.parts], model.n_dofs)
        self._parallel_option = parallel
        # Parts of a law quadratic in grad u (Hooke) have a constant K and f_int = -K u:
        # their K is assembled once (again after a law switch) instead of at every call.
        # (Not for solvers that load no stiffness kernel: explicit scenes never build one.)
        needs_K = "stiffness" in getattr(model, "outputs", ("stiffness",))
        self.constant = [needs_K and laws.is_quadratic(p.law) for p in model.parts]
        self.time = 0.0
        self.refresh()

    def refresh(self) -> None:
        """Re-read which cells each part models (after a law switch); the pattern stays."""
        parts = self.model.parts
        self.positions = [pos if p.index is None else pos[p.index]
                          for p, pos in zip(parts, self.pattern.positions)]
        # per part: scatter in parallel (coloured) or serially; see _use_parallel
        self.parallel = [p.index is None and _use_parallel(p, self._parallel_option) for p in parts]
        self.colours = [colour_elements(p.cells) if par else None for p, par in zip(parts, self.parallel)]
        self._constant_K = None

    # -- parts ----------------------------------------------------------------------------------
    def _u(self, part, u):
        return self.model.element_displacements(part, u)

    def _varying(self):
        """(index, part) of the parts whose kernels run at every call: active, not constant."""
        return [(i, p) for i, p in enumerate(self.model.parts) if p.n_active and not self.constant[i]]

    def constant_stiffness(self) -> np.ndarray | None:
        """CSR data of the constant-K parts (None when there are none), assembled on first use."""
        if not any(c and p.n_active for c, p in zip(self.constant, self.model.parts)):
            return None
        if self._constant_K is None:
            data = np.zeros(self.pattern.nnz)
            zero = np.zeros(self.model.n_dofs)
            for i, p in enumerate(self.model.parts):
                if self.constant[i] and p.n_active:
                    Ke = _global_ids(p, lambda p=p: p.kernel.stiffness(p.D_active, self._u(p, zero)))
                    self._scatter_K(data, Ke, i)
            self._constant_K = (data, self.pattern.matrix(data))
        return self._constant_K[0]

    def _constant_forces(self, u):
        """f_int of the constant-K parts: -K u."""
        return -(self._constant_K[1] @ u)

    def _projected(self, i: int, project) -> bool:
        if project is True:
            return self.model.parts[i].law != "hooke"     # Hooke's Hessian is already PSD
        if project in (False, None):
            return False
        return i in project

    def _scatter_K(self, data, Ke, i, scale=1.0):
        pos = self.positions[i]
        if self.parallel[i]:
            _, order, starts = self.colours[i]
            _scatter_matrix_coloured(data, Ke, pos, scale, order, starts)
        else:
            _scatter_matrix(data, Ke, pos, scale)

    # -- public ---------------------------------------------------------------------------------
    def energy(self, u: np.ndarray) -> float:
        """Total strain energy W(u); InvertedElementError propagates (with global cell ids)."""
        start = time.perf_counter()
        try:
            K = self.constant_stiffness()
            W = 0.0 if K is None else -0.5 * float(u @ self._constant_forces(u))
            return W + float(sum(_global_ids(p, lambda p=p: p.kernel.energy(p.D_active, self._u(p, u))).sum()
                                 for _, p in self._varying()))
        finally:
            self.time += time.perf_counter() - start

    def forces(self, u: np.ndarray) -> np.ndarray:
        """f_int = -dW/du, global."""
        start = time.perf_counter()
        K = self.constant_stiffness()
        f = np.zeros(self.model.n_dofs) if K is None else self._constant_forces(u)
        for _, p in self._varying():
            fe = _global_ids(p, lambda p=p: p.kernel.forces(p.D_active, self._u(p, u)))
            _scatter_vector(f, fe, p.dofs_active)
        self.time += time.perf_counter() - start
        return f

    def stiffness(self, u: np.ndarray, project=False) -> np.ndarray:
        """CSR data of K = d2W/du2 (optionally PSD-projected per element)."""
        start = time.perf_counter()
        K = self.constant_stiffness()
        data = np.zeros(self.pattern.nnz) if K is None else K.copy()
        for i, p in self._varying():
            Ke = _global_ids(p, lambda p=p: p.kernel.stiffness(p.D_active, self._u(p, u)))
            self._scatter_K(data, project_psd(Ke) if self._projected(i, project) else Ke, i)
        self.time += time.perf_counter() - start
        return data

    def forces_and_stiffness(self, u: np.ndarray, project=False):
        """(f_int, CSR data of K) in one kernel call per part."""
        start = time.perf_counter()
        K = self.constant_stiffness()
        if K is None:
            f, data = np.zeros(self.model.n_dofs), np.zeros(self.pattern.nnz)
        else:
            f, data = self._constant_forces(u), K.copy()
        for i, p in self._varying():
            fe, Ke = _global_ids(p, lambda p=p: p.kernel.forces_and_stiffness(p.D_active, self._u(p, u)))
            _scatter_vector(f, fe, p.dofs_active)
            self._scatter_K(data, project_psd(Ke) if self._projected(i, project) else Ke, i)
        self.time += time.perf_counter() - start
        return f, data

    def element_forces(self, part, u: np.ndarray) -> np.ndarray:
        """(n_active, k * dim) element internal forces of one part (criteria such as R_S)."""
        return _global_ids(part, lambda: part.kernel.forces(part.D_active, self._u(part, u)))

    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        return self.pattern.matrix(data)

    def warm_up(self) -> None:
        """Compile the scatter loops now (setup time), on one element of the first part."""
        if not self.model.parts:
            return
        p = self.model.parts[0]
        nd = p.dofs.shape[1]
        data, f = np.zeros(self.pattern.nnz), np.zeros(self.model.n_dofs)
        _scatter_vector(f, np.zeros((1, nd)), p.dofs[:1])
        _scatter_matrix(data, np.zeros((1, nd, nd)), self.pattern.positions[0][:1], 1.0)
        if any(self.parallel):
            one = np.zeros(1, dtype=np.int64)
            _scatter_matrix_coloured(data, np.zeros((1, nd, nd)), self.pattern.positions[0][:1], 1.0,
                                     one, np.array([0, 1], dtype=np.int64))
        self.constant_stiffness()            # Hooke parts: their one assembly belongs to setup


# A parallel region costs ~10 us on an idle machine but ~10 ms per colour when the
# cores are shared (OpenMP threads wait for each other), and the scatter is memory
# bound: go parallel only for parts with this many matrix entries or more.
PARALLEL_MIN_ENTRIES = 4_000_000


def _use_parallel(part, parallel) -> bool:
    """parallel=None: decide by thread count and part size; True/False forces it."""
    if parallel is not None:
        return bool(parallel)
    entries = part.dofs.shape[0] * part.dofs.shape[1] ** 2
    return numba.get_num_threads() > 1 and entries >= PARALLEL_MIN_ENTRIES


def _global_ids(part, call):
    """Run a kernel call; an ElementError gets the part's global cell ids."""
    try:
        return call()
    except ElementError as exc:
        message = str(exc).rsplit(": element(s)", 1)[0]
        raise type(exc)(message, part.cell_ids_active[exc.elements]) from None


def assemble(model, u: np.ndarray, project=False):
    """(W, f_int, K) at displacement u: energy, -dW/du and d2W/du2 (scipy CSR)."""
    asm = getattr(model, "_assembler", None)
    if asm is None:
        asm = model._assembler = Assembler(model)
    u = np.asarray(u, dtype=float).reshape(-1)
    if u.size != model.n_dofs:
        raise TensormassError(f"u must have {model.n_dofs} entries, got {u.size}")
    f, data = asm.forces_and_stiffness(u, project)
    return asm.energy(u), f, asm.matrix(data)
