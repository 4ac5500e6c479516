"""Global assembly: one CSR pattern built once, element results scattered with numba.

    asm = Assembler(model)
    f_int, K_data = asm.forces_and_stiffness(u)      # K = asm.matrix(K_data)
    W, f_int, K = assemble(model, u)                  # the same, for one-off use

Per part the pattern stores where every element matrix entry (e, r, s) lands in
the CSR data array (and, per node pair, where its block starts in its rows), so a
step runs the kernel and one scatter loop per block of elements, into buffers kept
between calls.  Segments of blocks sharing no node form colours; colours run in a
fixed order and the segments of one colour on runtime.base.parallel's threads, so the
result does not depend on the thread count.
"""
from __future__ import annotations

import sys
import time
from contextlib import nullcontext

import numpy as np
from threadpoolctl import ThreadpoolController, threadpool_limits
import scipy.sparse as sp
from numba import njit

from ..base import parallel as _parallel
from ..kernels.fused import block_positions
from .pattern import SparsePattern  # noqa: F401  (re-exported)
from ..base.errors import ElementError, InvertedElementError, TensormassError

__all__ = ["Assembler", "assemble", "project_psd", "scatter_matrix", "scatter_vector", "SparsePattern"]


# --------------------------------------------------------------------------- numba loops


@njit(cache=True)
def scatter_matrix(data, Ke, pos, scale):
    """data[pos[e]] += scale Ke[e], element after element (the serial reference of the scatters)."""
    for e in range(Ke.shape[0]):
        for r in range(Ke.shape[1]):
            for s in range(Ke.shape[2]):
                data[pos[e, r, s]] += scale * Ke[e, r, s]


@njit(cache=True)
def scatter_vector(out, fe, dofs):
    """out[dofs[e]] += fe[e], element after element."""
    for e in range(fe.shape[0]):
        for r in range(fe.shape[1]):
            out[dofs[e, r]] += fe[e, r]


# --------------------------------------------------------------------------- PSD projection


# Screening tolerance: an element whose symmetrised Hessian plus PSD_TOLERANCE x its largest
# diagonal entry has a Cholesky factor is left as it is (its smallest eigenvalue is >= about
# -PSD_TOLERANCE x that entry: round-off of the exactly singular rigid-translation modes);
# only the others go through eigh.  Eigenvalues above -PSD_TOLERANCE x scale are the only ones
# the batched-eigh reference clamps that this keeps: a change below round-off of K.
PSD_TOLERANCE = 1e-10


@njit(cache=True, nogil=True)
def _symmetrise_screen(K, tol, bad):
    """In place K[e] = (K[e] + K[e]^T) / 2; bad[e] = no Cholesky factor of K[e] + tol max|diag| I."""
    m = K.shape[1]
    L = np.empty((m, m))
    for e in range(K.shape[0]):
        scale = 0.0
        for i in range(m):
            for j in range(i + 1, m):
                v = 0.5 * (K[e, i, j] + K[e, j, i])
                K[e, i, j] = v
                K[e, j, i] = v
            a = abs(K[e, i, i])
            if a > scale:
                scale = a
        shift = tol * scale
        ok = True
        for j in range(m):
            d = K[e, j, j] + shift
            for k in range(j):
                d -= L[j, k] * L[j, k]
            if not d > 0.0:               # NaN too
                ok = False
                break
            ljj = np.sqrt(d)
            L[j, j] = ljj
            for i in range(j + 1, m):
                v = K[e, i, j]
                for k in range(j):
                    v -= L[i, k] * L[j, k]
                L[i, j] = v / ljj
        bad[e] = not ok


_blas_controller = None


def _one_blas_thread():
    """threadpool_limits(1) through one cached controller (a fresh threadpool_limits inspects
    every loaded library: 0.4 ms, paid per block of elements)."""
    global _blas_controller
    if _blas_controller is None:
        _blas_controller = ThreadpoolController()
    return _blas_controller.limit(limits=1, user_api="blas")


def project_psd(K: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Element Hessians with negative eigenvalues clamped to zero, symmetrised.

    A numba Cholesky attempt per element (with a shift of PSD_TOLERANCE x its largest diagonal
    entry) finds the elements that are PSD; only the others get an eigendecomposition, and
    those with a negative eigenvalue are rebuilt from it (the batched-eigh-over-everything
    rule of before, on far fewer elements: 2 880 tetra of soft_block_squeezed went from 72 ms
    to a few).  out: where to write (may be K itself); default a new array."""
    K = np.asarray(K, dtype=np.float64)
    if out is None:
        out = np.array(K, order="C")
    elif out is not K:
        np.copyto(out, K)
    # Many tiny eigenproblems: BLAS threads only add overhead (measured 3.1 s vs 0.04 s
    # for 288 30x30 matrices on 2 cores), so run them single-threaded.
    with _one_blas_thread():
        return _project_into(out)


def _project_into(out: np.ndarray) -> np.ndarray:
    """project_psd in place; the caller limits BLAS to one thread (the Assembler does so once
    around a whole pass: the limit is process-wide, so worker threads must not toggle it)."""
    bad = np.empty(len(out), dtype=np.bool_)
    _symmetrise_screen(out, PSD_TOLERANCE, bad)
    suspect = np.flatnonzero(bad)
    if suspect.size:
        w, V = np.linalg.eigh(out[suspect])
        neg = np.flatnonzero(w[:, 0] < 0.0)
        if neg.size:
            Vb, wb = V[neg], np.maximum(w[neg], 0.0)
            out[suspect[neg]] = np.einsum("eij,ej,ekj->eik", Vb, wb, Vb, optimize=True)
    return out


def _project_psd_reference(K: np.ndarray) -> np.ndarray:
    """The batched eigh over every element (what project_psd did before; tests compare with it)."""
    K = 0.5 * (K + np.swapaxes(K, 1, 2))
    with threadpool_limits(limits=1, user_api="blas"):
        w, V = np.linalg.eigh(K)
    bad = np.flatnonzero(w[:, 0] < 0.0)
    if bad.size:
        wb = np.maximum(w[bad], 0.0)
        K[bad] = np.einsum("eij,ej,ekj->eik", V[bad], wb, V[bad], optimize=True)
    return K


# --------------------------------------------------------------------------- element blocks

# Evaluation and scatter run block by block: a block of consecutive elements is gathered,
# evaluated into small per-thread buffers and scattered while its element matrices are still
# in cache (instead of a whole-part K that streams through memory twice).  Blocks hold about
# BLOCK_BYTES of per-element data (element matrix, forces, displacements, constants, scatter
# positions), at least MIN_BLOCK elements (each block costs a few Python calls).  A fixed
# rule from sizes, never from timings.  Measured (one thread, 2 shared cores, forces+stiffness
# into CSR, best of 4): 384 000 neo-Hookean tetra, numba: whole-part buffers 170 ms, blocks of
# 1 MB 190 ms, 4 MB 169 ms (the old fresh-array path 230 ms); C 245 / 291 / 252 ms (old 382);
# 20 000 neo-Hookean hexahedra (gauss2), numba: whole 84.4 ms, 1 MB 83.9, 4 MB 82.6 (old 91.5).
# Blocks of 4 MB run as fast as whole-part buffers and need no (n, nd, nd) buffer per part
# (442 MB for the tetra cube).
BLOCK_BYTES = 4 << 20
MIN_BLOCK = 64
MAX_BLOCK = 4096
SEGMENTS = 16
# Threads share a part's blocks when it has this many matrix entries or more (a colour's
# barrier costs tens of microseconds).
PARALLEL_MIN_ENTRIES = 200_000


def block_size(n_dofs: int, n_nodes: int, dofs_per_node: int, n_constants: int, pos_bytes: int = 4) -> int:
    """Elements per block for elements with n_dofs dofs: BLOCK_BYTES / bytes per element."""
    per = 8 * (n_dofs * n_dofs + 2 * n_dofs + n_constants) + pos_bytes * n_dofs * n_dofs + 8 * n_dofs
    return int(min(MAX_BLOCK, max(MIN_BLOCK, BLOCK_BYTES // per)))


@njit(cache=True)
def _block_colours(cells, block):
    """Greedy colours of the blocks of `block` consecutive elements: no two blocks of one colour
    share a node, so they write disjoint entries of f and K (and may run at once)."""
    n, k = cells.shape
    n_blocks = (n + block - 1) // block
    n_nodes = 0
    for e in range(n):
        for a in range(k):
            if cells[e, a] + 1 > n_nodes:
                n_nodes = cells[e, a] + 1
    start = np.zeros(n_nodes + 1, dtype=np.int64)
    for e in range(n):
        for a in range(k):
            start[cells[e, a] + 1] += 1
    for i in range(n_nodes):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    node_blocks = np.empty(n * k, dtype=np.int64)
    for e in range(n):
        for a in range(k):
            node = cells[e, a]
            node_blocks[fill[node]] = e // block
            fill[node] += 1
    colour = np.full(n_blocks, -1, dtype=np.int64)
    banned = np.full(n_blocks + 1, -1, dtype=np.int64)
    for b in range(n_blocks):
        for e in range(b * block, min(n, (b + 1) * block)):
            for a in range(k):
                node = cells[e, a]
                for j in range(start[node], start[node + 1]):
                    c = colour[node_blocks[j]]
                    if c >= 0:
                        banned[c] = b
        c = 0
        while banned[c] == b:
            c += 1
        colour[b] = c
    return colour


@njit(cache=True, nogil=True)
def _gather(U, cells, start, stop, ue):
    """ue[e - start] = U[cells[e]] for e in [start, stop) (the first ue.shape[2] dofs of each node: a
    solid's cells beside shells use their nodes' displacement only)."""
    for e in range(start, stop):
        for a in range(cells.shape[1]):
            node = cells[e, a]
            for d in range(ue.shape[2]):
                ue[e - start, a, d] = U[node, d]


@njit(cache=True, nogil=True)
def _scatter_block_f(f, fe, dofs, start, m):
    for e in range(m):
        for r in range(fe.shape[1]):
            f[dofs[start + e, r]] += fe[e, r]


@njit(cache=True, nogil=True)
def _scatter_block_K(data, Ke, pos, start, m):
    for e in range(m):
        for r in range(Ke.shape[1]):
            for c in range(Ke.shape[2]):
                data[pos[start + e, r, c]] += Ke[e, r, c]


@njit(cache=True, nogil=True)
def _scatter_block_K_nodes(data, Ke, blocks, dpn, start, m):
    """data += Ke through the node-blocked map of runtime.kernels.fused.block_positions: row r of element
    e holds node b's dpn columns at blocks[e, r, b] .. + dpn - 1 (node-major dofs)."""
    for e in range(m):
        for r in range(Ke.shape[1]):
            for b in range(blocks.shape[2]):
                base = blocks[start + e, r, b]
                for j in range(dpn):
                    data[base + j] += Ke[e, r, b * dpn + j]


def _node_blocks(pos, dpn, blocks=None):
    """The node-blocked map: the pattern's `blocks` when given (node-major dofs), else
    block_positions(pos, dpn) (pos: the per-entry map or a callable building it); None when the
    dofs are not node-major (full positions then)."""
    if blocks is not None:
        return blocks
    try:
        return block_positions(pos() if callable(pos) else pos, dpn)
    except TensormassError:
        return None


# The fused generated path (forces_and_stiffness_scatter: evaluate and add into f and the CSR
# values, no element buffers) against element buffers + the scatter above, full Newton
# assembly, one thread (`tensormass bench assembly`, 206 763 dofs): 384k tetra 110 / 152 ms
# (numba), 68 / 110 ms (C); 48k tetra10 170 / 192, 92 / 129; 64k hexahedra 337 / 388,
# 123 / 154.  Fused wins for every measured type on both backends, so every generated kernel
# with the function takes it, unless its element type is listed here (a fixed table, never a
# choice from timings at run time).  Stiffness-only calls (Newton's Hessian) take it too, with
# the forces added into a scratch vector: the forces cost a fraction of the stiffness.
BUFFERED_ELEMENTS: frozenset = frozenset()


def _fused(kernel):
    """The kernel's generated fused function, or None (hand-written kernels, older files, BUFFERED_ELEMENTS)."""
    module = getattr(kernel, "module", None)
    if module is None or kernel.element in BUFFERED_ELEMENTS:
        return None
    return getattr(module, "forces_and_stiffness_scatter", None)


def _releases_gil(kernel) -> bool:
    """C kernels (cffi) release the GIL; numba kernels only when compiled with nogil=True."""
    if kernel.backend != "numba":
        return True
    fn = getattr(kernel.module, "forces_and_stiffness", None)
    return bool(getattr(fn, "targetoptions", {}).get("nogil", False))


class _Plan:
    """One part's blocks, their colours, per-thread element buffers and its flags/energy arrays."""

    def __init__(self, part, pos, dofs_per_node: int, parallel, blocks=None, index_dtype=None, colours=None):
        """pos: the per-entry map of the active cells, or a callable building it (only needed when
        there is no node-blocked map); blocks: their node-blocked map from the pattern (node-major
        dofs) or None; index_dtype: the per-entry map's index type when pos is a callable; colours:
        (segment, order, starts) of a plan of the same cells before a cut, reused when the segments
        are the same (a cut gives a new node only to cells that shared its parent, so segments that
        shared no node still share none)."""
        k = part.kernel
        self.part, self.pos = part, pos
        index_bytes = np.dtype(index_dtype).itemsize if callable(pos) else pos.dtype.itemsize
        self.n = part.n_active
        self.cells = np.ascontiguousarray(part.cells_active, dtype=np.int64)
        self.dofs = np.ascontiguousarray(part.dofs_active, dtype=np.int64)
        self.D = np.ascontiguousarray(part.D_active, dtype=np.float64)
        # dofs of a node the kernel reads: the model's, or a solid's 3 of the 6 a node beside shells carries
        self.nd, self.k, self.dpn = k.n_dofs, k.n_nodes, k.n_dofs // k.n_nodes
        # A hand-written kernel (runtime.kernels.custom_kernels) has no generated module to write into
        # buffers: it is called through its own methods, on the whole part at once.
        self.generic = getattr(k, "module", None) is None
        self.block = max(1, min(self.n, block_size(self.nd, self.k, dofs_per_node, self.D.shape[1], index_bytes)))
        if self.generic:
            self.block = max(1, self.n)
        n_blocks = (self.n + self.block - 1) // self.block
        # Segments: SEGMENTS runs of consecutive blocks, coloured so that segments of one colour
        # share no node.  Segments go in colour order, blocks inside a segment in element order
        # (locality), and only segments of one colour run at once: every entry of f and K gets
        # its contributions in the same order whatever the thread count.
        self.segment = self.block * max(1, -(-n_blocks // SEGMENTS))
        n_segments = -(-self.n // self.segment) if self.n else 0
        if colours is not None and colours[0] == self.segment and len(colours[1]) == n_segments:
            self.order, self.starts = colours[1], colours[2]
        else:
            colour = _block_colours(self.cells, self.segment) if self.n else np.zeros(0, dtype=np.int64)
            self.order = np.argsort(colour, kind="stable")
            self.starts = np.concatenate([[0], np.cumsum(np.bincount(colour, minlength=int(colour.max(initial=-1)) + 1))])
        self.n_blocks = n_blocks
        self.n_segments = n_segments
        entries = self.n * self.nd * self.nd
        if parallel is None:
            parallel = entries >= PARALLEL_MIN_ENTRIES
        self.parallel = bool(parallel) and not self.generic and _releases_gil(k)
        self.flags = np.zeros(self.n, dtype=np.int32)
        self.energy = np.zeros(self.n)
        # one node-blocked map serves the buffered scatter and the fused kernels
        self.blocks = _node_blocks(pos, self.dpn, blocks) if self.n else None
        if callable(self.pos):
            self.pos = self.pos() if self.blocks is None else None
        # the generated fused functions read and write the global arrays with the kernel's own stride
        self.fused = _fused(k) if self.blocks is not None and self.dpn == dofs_per_node else None
        self._scratch_f = None
        self._buffers = []

    def scratch_f(self, size: int) -> np.ndarray:
        """A force vector the stiffness-only fused calls add into (and nobody reads)."""
        if self._scratch_f is None or self._scratch_f.size != size:
            self._scratch_f = np.zeros(size)
        return self._scratch_f

    def buffers(self, shares: int):
        while len(self._buffers) < shares:
            b = self.block
            self._buffers.append((np.empty((b, self.k, self.dpn)), np.empty((b, self.nd)), np.empty((b, self.nd, self.nd))))
        return self._buffers

    def shares(self) -> int:
        return max(1, min(_parallel.worker_threads(), self.n_segments)) if self.parallel else 1


class Assembler:
    """Energy, internal forces and stiffness of a Model, assembled into global arrays.

    f_int = -dW/du (what the kernels return); K = d2W/du2.  `project` selects
    parts whose element Hessians are projected to PSD (a set of part indices,
    True for all non-Hooke parts, or False).  Times spent are accumulated in
    `self.time` (kernel calls and scatter).

    Nothing is allocated per call on the hot path: element buffers live per part and thread
    (runtime.assembly.assembly._Plan), and the returned f / CSR data arrays come from a small pool: an
    array is reused only once nobody else holds it (its reference count), so a caller that
    keeps a result (or a matrix built on it) never sees it overwritten.
    Evaluation runs in blocks of elements, blocks in a fixed colour order whatever the
    thread count (runtime.base.parallel): results are bit-identical for 1 and more threads.
    """

    def __init__(self, model, parallel: bool | None = None, colours=None, grow_from=None):
        """colours: Assembler.colours() of this model before a cut (runtime.change.cutting), to reuse;
        grow_from: that model's pattern, to grow by the cut's new nodes (SparsePattern.grown)."""
        self.model = model
        self._colours_from = colours
        couplings = getattr(model, "couplings", [])
        # nodal-pressure couplings join the nodes around a node: their patches widen the pattern
        extra = [t for c in couplings for t in c.patch_tables]
        tables = [p.dofs for p in model.parts] + extra
        grown = SparsePattern.grown(grow_from, tables, model.n_dofs) if grow_from is not None and not extra else None
        self.pattern = grown if grown is not None else SparsePattern(tables, model.n_dofs, model.dofs_per_node)
        n_parts = len(model.parts)
        # couplings get per-entry maps of their cells and patches only (node-major dofs: expanded
        # from the node-blocked maps, not the whole parts')
        at = n_parts
        for c in couplings:
            c.positions = self.pattern.table_positions(c.part_index, c.rows)
            c.patch_positions = [self.pattern.table_positions(at + j) for j in range(len(c.patch_tables))]
            at += len(c.patch_tables)
        self.pattern.keep(n_parts)
        self.couplings = couplings
        self._parallel_option = parallel
        # Parts of a law quadratic in grad u (Hooke) have a constant K and f_int = -K u:
        # their K is assembled once (again after a law switch) instead of at every call.
        # (Not for solvers that load no stiffness kernel: explicit scenes never build one.)
        needs_K = "stiffness" in getattr(model, "outputs", ("stiffness",))
        self.constant = [needs_K and getattr(p.kernel, "quadratic_energy", False) for p in model.parts]
        self.time = 0.0
        self._pools = {"f": [], "K": []}
        self.refresh()

    def refresh(self) -> None:
        """Re-read which cells each part models (after a law switch); the pattern stays."""
        parts = self.model.parts
        dpn = self.model.dofs_per_node
        self._positions = None
        pattern = self.pattern
        self.plans = []
        for i, (p, blocks) in enumerate(zip(parts, pattern.blocks)):
            # node-major dofs: the node-blocked map straight from the pattern; the per-entry map
            # is built only for a plan that has none
            if blocks is not None and p.index is not None:
                blocks = np.ascontiguousarray(blocks[p.index])
            reuse = self._colours_from[i] if self._colours_from is not None else None
            self.plans.append(_Plan(p, lambda i=i: self._part_positions(i), dpn, self._parallel_option,
                                    blocks, pattern.index_dtype, reuse))
        self._colours_from = None                # a law switch later: colour afresh
        self.parallel = [plan.parallel for plan in self.plans]
        self._constant_K = None

    def _part_positions(self, i: int) -> np.ndarray:
        p = self.model.parts[i]
        return self.pattern.table_positions(i, p.index)

    @property
    def positions(self) -> list:
        """Per part, the per-entry map (n_active, nd, nd) of its active cells, built on first use."""
        if self._positions is None:
            self._positions = [self._part_positions(i) for i in range(len(self.model.parts))]
        return self._positions

    def colours(self) -> list:
        """(segment, order, starts) of every part's plan: what a model cut from this one may reuse."""
        return [(plan.segment, plan.order, plan.starts) for plan in self.plans]

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
                    self._evaluate(i, "stiffness", zero, None, data, False)
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

    def _take(self, name: str, size: int) -> np.ndarray:
        """An output array from the pool that nobody outside holds; a new one otherwise."""
        pool = self._pools[name]
        for j in range(len(pool)):
            # references: the pool list, and getrefcount's argument
            if pool[j].size == size and sys.getrefcount(pool[j]) == 2:
                return pool[j]
        array = np.empty(size)
        if len(pool) < 3:
            pool.append(array)
        return array

    def _start(self, u, want_f: bool, want_K: bool):
        """Output arrays holding the constant-K parts' share, and u checked for NaN/Inf."""
        u = np.ascontiguousarray(u, dtype=np.float64).reshape(-1)
        if u.size != self.model.n_dofs:
            raise TensormassError(f"u must have {self.model.n_dofs} entries, got {u.size}")
        with np.errstate(over="ignore", invalid="ignore"):
            total = np.add.reduce(u)
        if not np.isfinite(total):
            self._non_finite(u)
        K = self.constant_stiffness() if (want_f or want_K) else None
        f = data = None
        if want_f:
            f = self._take("f", self.model.n_dofs)
            if K is None:
                f.fill(0.0)
            else:
                np.negative(self._constant_K[1] @ u, out=f)
        if want_K:
            data = self._take("K", self.pattern.nnz)
            if K is None:
                data.fill(0.0)
            else:
                np.copyto(data, K)
        return u, f, data

    def _non_finite(self, u):
        bad = ~np.isfinite(u)
        if not bad.any():
            return                         # the sum overflowed; every entry is finite
        node_bad = bad.reshape(self.model.n_points, -1).any(axis=1)
        cells = [p.cell_ids_active[node_bad[p.cells_active].any(axis=1)] for p in self.model.parts if p.n_active]
        cells = np.unique(np.concatenate(cells)) if cells else np.zeros(0, dtype=int)
        dofs = np.flatnonzero(bad)
        raise TensormassError(f"displacements contain NaN or Inf at {dofs.size} dof(s) (first {', '.join(map(str, dofs[:5]))})"
                              + (f", in cell(s) {', '.join(map(str, cells[:10]))}" if cells.size else ""))

    def _evaluate(self, i: int, what: str, u, f, data, project: bool) -> None:
        """Run part i's kernel block by block (what: energy | forces | stiffness |
        forces_and_stiffness) and add its element results to f / data / plan.energy."""
        plan = self.plans[i]
        if not plan.n:
            return
        U = u.reshape(self.model.n_points, self.model.dofs_per_node)
        D, cells, dofs, pos, flags, B = plan.D, plan.cells, plan.dofs, plan.pos, plan.flags, plan.block
        blocks, dpn = plan.blocks, plan.dpn
        if plan.fused is not None and not project and what in ("forces_and_stiffness", "stiffness"):
            self._evaluate_fused(plan, what, U, f, data)
            return
        call = getattr(plan.part.kernel if plan.generic else plan.part.kernel.module, what)
        shares = plan.shares()
        buffers = plan.buffers(shares)

        def run(segment, bufs):
            first = segment * plan.segment
            for s in range(first, min(plan.n, first + plan.segment), B):
                block(s, min(plan.n, s + B), bufs)

        def block(s, t, bufs):
            m = t - s
            ue, fe, Ke = bufs[0][:m], bufs[1][:m], bufs[2][:m]
            _gather(U, cells, s, t, ue)
            if plan.generic:
                result = _global_ids(plan.part, lambda: call(D[s:t], ue))
                if what == "energy":
                    plan.energy[s:t] = result
                    return
                fe, Ke = (result, None) if what == "forces" else (None, result) if what == "stiffness" else result
                fe = None if fe is None else np.ascontiguousarray(fe, dtype=np.float64)
                Ke = None if Ke is None else np.ascontiguousarray(Ke, dtype=np.float64)
            elif what == "energy":
                call(D[s:t], ue, plan.energy[s:t], flags[s:t])
                return
            elif what == "forces":
                call(D[s:t], ue, fe, flags[s:t])
            elif what == "stiffness":
                call(D[s:t], ue, Ke, flags[s:t])
            else:
                call(D[s:t], ue, fe, Ke, flags[s:t])
            if project and flags[s:t].any():
                return              # no eigh of a NaN matrix; flagged elements are reported after the pass
            if f is not None and what != "stiffness":
                _scatter_block_f(f, fe, dofs, s, m)
            if data is not None and what != "forces":
                if project:
                    _project_into(Ke)
                if blocks is None:
                    _scatter_block_K(data, Ke, pos, s, m)
                else:
                    _scatter_block_K_nodes(data, Ke, blocks, dpn, s, m)

        with _one_blas_thread() if project else nullcontext():
            self._colours(plan, shares, buffers, run)
        if flags.any():
            part = plan.part
            bad = np.flatnonzero(flags)
            raise InvertedElementError(f"{what}: det F <= 0 (inverted element) where law {part.law!r} is undefined",
                                       part.cell_ids_active[bad])

    def _evaluate_fused(self, plan, what, U, f, data) -> None:
        """The generated fused path, segment by segment in the same colour order (and on the same
        threads) as the buffered path: f and data get each element's terms with no buffers."""
        pos, flags, D, cells, fn = plan.blocks, plan.flags, plan.D, plan.cells, plan.fused
        if what == "stiffness":
            f = plan.scratch_f(U.size)

        def run(segment, _bufs):
            s = segment * plan.segment
            t = min(plan.n, s + plan.segment)
            if t > s:
                fn(D[s:t], U, cells[s:t], pos[s:t], f, data, flags[s:t])

        self._colours(plan, plan.shares(), [None] * plan.shares(), run)
        if flags.any():
            part = plan.part
            bad = np.flatnonzero(flags)
            raise InvertedElementError(f"{what}: det F <= 0 (inverted element) where law {part.law!r} is undefined",
                                       part.cell_ids_active[bad])

    @staticmethod
    def _colours(plan, shares, buffers, run):
        """Segments colour by colour; those of one colour shared among the threads."""
        order, starts = plan.order, plan.starts
        for c in range(len(starts) - 1):
            segments = order[starts[c]:starts[c + 1]]
            n_sh = min(shares, len(segments))
            if n_sh <= 1:
                bufs = buffers[0]
                for g in segments:
                    run(g, bufs)
            else:
                _parallel.run_shares(lambda sh: [run(g, buffers[sh]) for g in segments[sh::n_sh]], n_sh)

    # -- public ---------------------------------------------------------------------------------
    def energy(self, u: np.ndarray) -> float:
        """Total strain energy W(u); InvertedElementError propagates (with global cell ids)."""
        start = time.perf_counter()
        try:
            u, _, _ = self._start(u, False, False)
            K = self.constant_stiffness()
            W = 0.0 if K is None else -0.5 * float(u @ self._constant_forces(u))
            for i, p in self._varying():
                self._evaluate(i, "energy", u, None, None, False)
                W += float(self.plans[i].energy.sum())
            return W + self._couple(u, None, None, False)
        finally:
            self.time += time.perf_counter() - start

    def forces(self, u: np.ndarray) -> np.ndarray:
        """f_int = -dW/du, global."""
        start = time.perf_counter()
        try:
            u, f, _ = self._start(u, True, False)
            for i, _p in self._varying():
                self._evaluate(i, "forces", u, f, None, False)
            self._couple(u, f, None, False)
            return f
        finally:
            self.time += time.perf_counter() - start

    def stiffness(self, u: np.ndarray, project=False) -> np.ndarray:
        """CSR data of K = d2W/du2 (optionally PSD-projected per element)."""
        start = time.perf_counter()
        try:
            u, _, data = self._start(u, False, True)
            for i, _p in self._varying():
                self._evaluate(i, "stiffness", u, None, data, self._projected(i, project))
            self._couple(u, None, data, project)
            return data
        finally:
            self.time += time.perf_counter() - start

    def forces_and_stiffness(self, u: np.ndarray, project=False):
        """(f_int, CSR data of K) in one kernel call per block."""
        start = time.perf_counter()
        try:
            u, f, data = self._start(u, True, True)
            for i, _p in self._varying():
                self._evaluate(i, "forces_and_stiffness", u, f, data, self._projected(i, project))
            self._couple(u, f, data, project)
            return f, data
        finally:
            self.time += time.perf_counter() - start

    def _couple(self, u, f, data, project) -> float:
        """The locking-free formulations' volumetric terms (runtime.assembly.volumetric); their energy."""
        if not self.couplings:
            return 0.0
        U = u.reshape(self.model.n_points, self.model.dofs_per_node)
        return sum(c.evaluate(U, f, data, bool(project)) for c in self.couplings)

    def element_forces(self, part, u: np.ndarray) -> np.ndarray:
        """(n_active, k * dim) element internal forces of one part (criteria such as R_S)."""
        return _global_ids(part, lambda: part.kernel.forces(part.D_active, self._u(part, u)))

    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        return self.pattern.matrix(data)

    def warm_up(self) -> None:
        """Compile the gather and scatter loops now (setup time), on one element of the first part."""
        if not self.model.parts:
            return
        p = self.model.parts[0]
        nd, k = p.dofs.shape[1], p.cells.shape[1]
        data, f = np.zeros(self.pattern.nnz), np.zeros(self.model.n_dofs)
        U = np.zeros((self.model.n_points, self.model.dofs_per_node))
        _gather(U, self.plans[0].cells[:1] if self.plans[0].n else np.zeros((1, k), dtype=np.int64), 0, 1,
                np.zeros((1, k, self.model.dofs_per_node)))
        dofs = np.ascontiguousarray(p.dofs[:1], dtype=np.int64)
        _scatter_block_f(f, np.zeros((1, nd)), dofs, 0, 1)
        _scatter_block_K(data, np.zeros((1, nd, nd)), np.zeros((1, nd, nd), dtype=self.pattern.index_dtype), 0, 1)
        plan = self.plans[0]
        if plan.blocks is not None:
            _scatter_block_K_nodes(data, np.zeros((1, nd, nd)), plan.blocks, plan.dpn, 0, 1)
        self.constant_stiffness()            # Hooke parts: their one assembly belongs to setup


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
