"""The global CSR pattern and the maps from element entries to its nonzeros, built fast.

    pattern = SparsePattern(dof_tables, n_dofs, dofs_per_node)   # or SparsePattern.rebuild(...)
    pattern.indptr, pattern.indices, pattern.nnz, pattern.diagonal
    pattern.blocks[i]      # (n, nd, k) node-blocked map of table i (runtime.kernels.fused.block_positions)
    pattern.positions[i]   # (n, nd, nd) per-entry map, built from blocks[i] on first use

Why: the runtime changes mesh topology during a run (cutting duplicates nodes, renumbers
cells) and must rebuild the pattern then.  With node-major dofs (dof = node dpn + i, the
runtime's layout) the pattern is one dense dpn x dpn block per coupled node pair, so it is
built from the node tables by one numba pass over the node -> cell incidences with a marker
array (no sort of all node-pair keys), and the node-blocked map of every element comes out of
the same pass.  The full per-entry map (7.2 M ints for 50 400 tetra) is only built for callers
that ask for it (consistent mass, volumetric couplings, dof-based tests).
Measured with apps/bench_pattern.py (best of 5, 2 shared cores, old = the sort-based build,
runtime.assembly.pattern.ReferencePattern, in the same run):
    50 400 tetra (29 520 dofs, 1.22 M nonzeros): SparsePattern 100 -> 11.5 ms, rebuild 10.4 ms,
        Assembler(model) 151 -> 16.7 ms, Context(model) 155 -> 25 ms
    6 720 tetra10 (2.47 M nonzeros): SparsePattern 94 -> 12 ms, Assembler 126 -> 13 ms
    8 400 hexahedra (2.15 M nonzeros): SparsePattern 77 -> 9 ms, Assembler 104 -> 10 ms
Most of what is left is writing the node-blocked map (2.4 M int32 for the tetra) and the
CSR indices; the per-entry map would be 4 times more.

Tables whose dofs are not node-major go through every dof pair (one sort, `_by_dofs`).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

__all__ = ["SparsePattern", "node_tables"]

INDEX_LIMIT = 2**31 - 1       # int32 indices (the generated C code reads int)


# --------------------------------------------------------------------------- numba passes


@njit(cache=True)
def _incidences(flat, estart, n_nodes):
    """(ptr, inc, elem_of): the entries of `flat` (all cells' nodes) grouped by node, in order."""
    n_elem = estart.size - 1
    elem_of = np.empty(flat.size, dtype=np.int64)
    for g in range(n_elem):
        for p in range(estart[g], estart[g + 1]):
            elem_of[p] = g
    ptr = np.zeros(n_nodes + 1, dtype=np.int64)
    for p in range(flat.size):
        ptr[flat[p] + 1] += 1
    for m in range(n_nodes):
        ptr[m + 1] += ptr[m]
    fill = ptr[:-1].copy()
    inc = np.empty(flat.size, dtype=np.int64)
    for p in range(flat.size):
        m = flat[p]
        inc[fill[m]] = p
        fill[m] += 1
    return ptr, inc, elem_of


# Shell sort's gaps (Ciura's sequence, extended by x2.25): the last, 1, is an insertion sort.
_GAPS = np.array([1, 4, 10, 23, 57, 132, 301, 701, 1577, 3548, 7983, 17961, 40412, 90927], dtype=np.int64)


@njit(cache=True)
def _sort_small(a, lo, hi):
    """Sort a[lo:hi] in place: rows hold tens to hundreds of nodes, where Shell sort is as fast as
    np.sort, whose numba implementation takes about 15 s to compile on a first run."""
    n = hi - lo
    for k in range(_GAPS.size - 1, -1, -1):
        gap = _GAPS[k]
        if gap >= n:
            continue
        for i in range(lo + gap, hi):
            v = a[i]
            j = i
            while j - gap >= lo and a[j - gap] > v:
                a[j] = a[j - gap]
                j -= gap
            a[j] = v


@njit(cache=True)
def _node_pattern(flat, estart, bstart, n_nodes, dpn, blocks):
    """Node-level CSR (every diagonal, columns sorted) and the node-blocked map, in one pass.

    Row m: m and every node of every cell holding m, deduplicated with a marker.  Then, for every
    (cell g, its slot a) holding m and every dof row r = a dpn + i: blocks[bstart[g] + r k + b] =
    first CSR index of node b's dpn columns in row (m, i) = dpn^2 node_indptr[m] + i dpn deg(m)
    + dpn (rank of node b in row m)."""
    ptr, inc, elem_of = _incidences(flat, estart, n_nodes)
    bound = n_nodes
    for q in range(inc.size):
        g = elem_of[inc[q]]
        bound += estart[g + 1] - estart[g]
    cols = np.empty(bound, dtype=np.int64)
    node_indptr = np.zeros(n_nodes + 1, dtype=np.int64)
    mark = np.full(n_nodes, -1, dtype=np.int64)
    rank = np.zeros(n_nodes, dtype=np.int64)
    k_max = 0
    for g in range(estart.size - 1):
        k_max = max(k_max, estart[g + 1] - estart[g])
    offset = np.empty(k_max, dtype=np.int64)
    at = 0
    for m in range(n_nodes):
        lo = at
        mark[m] = m
        cols[at] = m
        at += 1
        for q in range(ptr[m], ptr[m + 1]):
            g = elem_of[inc[q]]
            for s in range(estart[g], estart[g + 1]):
                c = flat[s]
                if mark[c] != m:
                    mark[c] = m
                    cols[at] = c
                    at += 1
        _sort_small(cols, lo, at)
        node_indptr[m + 1] = at
        deg = at - lo
        for j in range(deg):
            rank[cols[lo + j]] = j
        base = dpn * dpn * lo
        step = dpn * deg
        for q in range(ptr[m], ptr[m + 1]):
            p = inc[q]
            g = elem_of[p]
            e0 = estart[g]
            k = estart[g + 1] - e0
            for b in range(k):
                offset[b] = base + dpn * rank[flat[e0 + b]]
            o = bstart[g] + (p - e0) * dpn * k
            for i in range(dpn):
                shift = i * step
                for b in range(k):
                    blocks[o + b] = offset[b] + shift
                o += k
    return node_indptr, cols[:at].copy()


@njit(cache=True)
def _dof_pattern(node_indptr, node_cols, dpn, indptr, indices, diagonal):
    """The dof-level CSR of node-major dofs: row (m, i) holds columns c dpn + j for every node c of
    node row m; diagonal[(m, i)] = its entry (m dpn + i, m dpn + i).  Serial: it writes each entry once
    (memory-bound), and parallel=True cost 3 to 4 s more of numba compilation on a first run."""
    n_nodes = node_indptr.size - 1
    for m in range(n_nodes):
        lo = node_indptr[m]
        deg = node_indptr[m + 1] - lo
        rel = 0
        for j in range(deg):
            if node_cols[lo + j] == m:
                rel = j
        base = dpn * dpn * lo
        for i in range(dpn):
            start = base + i * dpn * deg
            indptr[m * dpn + i] = start
            for j in range(deg):
                c = node_cols[lo + j] * dpn
                for d in range(dpn):
                    indices[start + j * dpn + d] = c + d
            diagonal[m * dpn + i] = start + dpn * rel + i
    indptr[n_nodes * dpn] = dpn * dpn * node_indptr[n_nodes]


@njit(cache=True)
def _submatrix(indptr, indices, rows_keep, cols_keep, n_dofs, out_indptr):
    """Entries of the block (rows_keep, cols_keep) in CSR order: count per row, prefix sums, fill;
    serial for the reason _dof_pattern is."""
    cmap = np.full(n_dofs, -1, dtype=np.int64)
    for j in range(cols_keep.size):
        cmap[cols_keep[j]] = j
    n = rows_keep.size
    counts = np.zeros(n, dtype=np.int64)
    for i in range(n):
        row = rows_keep[i]
        c = 0
        for p in range(indptr[row], indptr[row + 1]):
            if cmap[indices[p]] >= 0:
                c += 1
        counts[i] = c
    out_indptr[0] = 0
    for i in range(n):
        out_indptr[i + 1] = out_indptr[i] + counts[i]
    count = out_indptr[n]
    entries = np.empty(count, dtype=np.int64)
    out_indices = np.empty(count, dtype=indices.dtype)
    for i in range(n):
        row = rows_keep[i]
        at = out_indptr[i]
        for p in range(indptr[row], indptr[row + 1]):
            c = cmap[indices[p]]
            if c >= 0:
                entries[at] = p
                out_indices[at] = c
                at += 1
    return entries, out_indices


@njit(cache=True)
def _grow_nodes(old_ptr, old_cols, n_nodes, add_rows, add_cols):
    """The node CSR of old_ptr/old_cols (n_old rows) with the sorted, unique (row, col) pairs added:
    every added column of an old row is a new node (ids >= n_old), so it goes after the old ones."""
    n_old = old_ptr.size - 1
    count = np.zeros(n_nodes + 1, dtype=np.int64)
    for m in range(n_old):
        count[m + 1] = old_ptr[m + 1] - old_ptr[m]
    for q in range(add_rows.size):
        count[add_rows[q] + 1] += 1
    ptr = np.zeros(n_nodes + 1, dtype=np.int64)
    for m in range(n_nodes):
        ptr[m + 1] = ptr[m] + count[m + 1]
    cols = np.empty(ptr[n_nodes], dtype=np.int64)
    fill = ptr[:-1].copy()
    for m in range(n_old):
        for p in range(old_ptr[m], old_ptr[m + 1]):
            cols[fill[m]] = old_cols[p]
            fill[m] += 1
    for q in range(add_rows.size):
        m = add_rows[q]
        cols[fill[m]] = add_cols[q]
        fill[m] += 1
    return ptr, cols


@njit(cache=True, parallel=True)
def _blocks_from_rows(flat, estart, bstart, node_indptr, node_cols, dpn, blocks):
    """The node-blocked map of every cell from a node CSR with sorted rows (binary search of each
    node in its neighbours' rows); cells write their own entries, in parallel."""
    for g in prange(estart.size - 1):
        e0 = estart[g]
        k = estart[g + 1] - e0
        o = bstart[g]
        for a in range(k):
            m = flat[e0 + a]
            lo = node_indptr[m]
            deg = node_indptr[m + 1] - lo
            base = dpn * dpn * lo
            for b in range(k):
                c = flat[e0 + b]
                left, right = lo, lo + deg
                while left < right:
                    mid = (left + right) // 2
                    if node_cols[mid] < c:
                        left = mid + 1
                    else:
                        right = mid
                at = base + dpn * (left - lo)
                for i in range(dpn):
                    blocks[o + (a * dpn + i) * k + b] = at + i * dpn * deg


# --------------------------------------------------------------------------- the pattern


class SparsePattern:
    """CSR structure of the global matrix and, per dof table, the scatter maps.

    blocks[i] (node-major dofs, else None): the node-blocked map of runtime.kernels.fused.block_positions;
    positions[i]: the per-entry map (n, nd, nd), built from blocks[i] when first asked for.
    Tables given as one object (a switchable group's parts) share their maps."""

    def __init__(self, dof_tables, n_dofs: int, dofs_per_node: int | None = None, node_tables=None):
        self.n_dofs = n_dofs
        self.dofs_per_node = dofs_per_node
        # parts of one switchable group share their dof table: build its maps once
        first = {}
        for i, d in enumerate(dof_tables):
            first.setdefault(id(d), i)
        owner = [first[id(d)] for d in dof_tables]
        unique = sorted(set(owner))
        slot = {o: j for j, o in enumerate(unique)}
        self._owner = [slot[o] for o in owner]
        tables = [dof_tables[i] for i in unique]
        nodes = None
        if node_tables is not None:
            nodes = [node_tables[i] for i in unique]
        else:
            nodes = _node_tables(tables, n_dofs, dofs_per_node)
        self._rows_cache = None
        self.node_indptr = self.node_cols = None
        if nodes is None:
            self._blocks, self._positions = [None] * len(tables), self._by_dofs(tables, n_dofs)
        else:
            self._blocks, self._positions = self._by_nodes(nodes, n_dofs // dofs_per_node, dofs_per_node)

    @classmethod
    def grown(cls, old: "SparsePattern", dof_tables, n_dofs: int) -> "SparsePattern":
        """The pattern of dof_tables after a cut (runtime.change.cutting): old's, with the couplings of the
        new nodes (ids from old's node count on) added at the ends of the rows.  Old couplings a cut
        ends stay as explicit zeros (a superset pattern: every matrix is the same, the solvers see a
        few more stored entries); no global sort, no incidence pass.  None when old is not node-major
        or the tables are shared between parts (switchable groups): build afresh then."""
        dpn = old.dofs_per_node
        if old.node_indptr is None or not dpn or len({id(d) for d in dof_tables}) != len(dof_tables):
            return None
        nodes = _node_tables(list(dof_tables), n_dofs, dpn)
        if nodes is None:
            return None
        n_old, n_nodes = old.node_indptr.size - 1, n_dofs // dpn
        pairs = []
        for c in nodes:
            c = c[(c >= n_old).any(axis=1)]          # the cells holding a new node
            if len(c):
                k = c.shape[1]
                a, b = np.repeat(c, k, axis=1).ravel(), np.tile(c, (1, k)).ravel()
                keep = (a >= n_old) | (b >= n_old)
                pairs.append(np.stack([a[keep], b[keep]], axis=1))
        new_nodes = np.arange(n_old, n_nodes, dtype=np.int64)
        pairs.append(np.stack([new_nodes, new_nodes], axis=1))   # every diagonal
        pairs = np.vstack(pairs)
        key = np.unique(pairs[:, 0] * np.int64(n_nodes) + pairs[:, 1])   # sorted by row, then column
        pairs = np.stack([key // n_nodes, key % n_nodes], axis=1)
        self = cls.__new__(cls)
        self.n_dofs, self.dofs_per_node = n_dofs, dpn
        self._owner = list(range(len(nodes)))
        self._rows_cache = None
        node_indptr, node_cols = _grow_nodes(old.node_indptr, old.node_cols, n_nodes, pairs[:, 0], pairs[:, 1])
        self.node_indptr, self.node_cols = node_indptr, node_cols
        nnz = int(dpn * dpn * node_indptr[-1])
        itype = np.int32 if nnz < INDEX_LIMIT else np.int64
        self.index_dtype, self.nnz = itype, nnz
        self.indptr = np.empty(n_nodes * dpn + 1, dtype=itype)
        self.indices = np.empty(nnz, dtype=itype)
        self.diagonal = np.empty(n_nodes * dpn, dtype=np.int64)
        _dof_pattern(node_indptr, node_cols, dpn, self.indptr, self.indices, self.diagonal)
        self._blocks = []
        for c in nodes:
            c = np.ascontiguousarray(c, dtype=np.int64)
            n, k = c.shape
            estart = np.arange(n + 1, dtype=np.int64) * k
            bstart = np.arange(n + 1, dtype=np.int64) * (dpn * k * k)
            flat = np.empty(n * dpn * k * k, dtype=itype)
            _blocks_from_rows(c.ravel(), estart, bstart, node_indptr, node_cols, dpn, flat)
            self._blocks.append(flat.reshape(n, dpn * k, k))
        self._positions = [None] * len(nodes)
        return self

    @classmethod
    def warm_up_growth(cls) -> None:
        """Load the compiled functions `grown` uses (numba's cache) on a toy: a run with [[cut]]
        events calls this at setup, so that its first cut does not pay for it."""
        def dofs(cells):                        # node-major dofs of one tetrahedron, 3 per node
            return np.repeat(np.array([cells]) * 3, 3, axis=1) + np.tile(np.arange(3), 4)
        cls.grown(cls([dofs([0, 1, 2, 3])], 12, 3), [dofs([0, 1, 2, 4])], 15)

    @classmethod
    def rebuild(cls, node_tables, n_nodes: int, dofs_per_node: int) -> "SparsePattern":
        """The pattern of new node tables ((n, k) int arrays, node-major dofs), e.g. after a cut
        duplicated nodes and renumbered cells: no dof tables are built nor checked.
        Measured 10.4 ms for 50 400 tetra (29 520 dofs, 1.22 M nonzeros; apps/bench_pattern.py)."""
        node_tables = [np.asarray(c) for c in node_tables]
        return cls(node_tables, n_nodes * dofs_per_node, dofs_per_node, node_tables=node_tables)

    # -- maps, per table ------------------------------------------------------------------------
    @property
    def blocks(self) -> list:
        """Per table, the node-blocked map (n, nd, k) int32 (None: dofs not node-major, or too
        many nonzeros for int32: the fused kernels read int)."""
        return [_int32_or_none(self._blocks[j]) for j in self._owner]

    @property
    def positions(self) -> list:
        """Per table, the per-entry map (n, nd, nd) (int32 when the matrix allows), cached."""
        for j in set(self._owner):
            if self._positions[j] is None:
                self._positions[j] = self._expand(self._blocks[j])
        return [self._positions[j] for j in self._owner]

    @positions.setter
    def positions(self, value) -> None:
        """Replace the per-table maps (kept for callers that trimmed the list)."""
        value = list(value)
        self._owner = list(range(len(value)))
        self._positions = value
        self._blocks = [None] * len(value)

    def keep(self, n_tables: int) -> None:
        """Forget the maps of the tables after the first n_tables (the Assembler keeps its parts')."""
        self._owner = self._owner[:n_tables]

    def table_positions(self, i: int, rows=None) -> np.ndarray:
        """positions[i][rows] without building the whole per-entry map when it is not cached."""
        j = self._owner[i]
        if self._positions[j] is not None:
            pos = self._positions[j]
            return pos if rows is None else pos[rows]
        b = self._blocks[j]
        return self._expand(b if rows is None else b[rows])

    def _expand(self, blocks):
        """positions[e, r, b dpn + j] = blocks[e, r, b] + j."""
        d = self.dofs_per_node
        n, nd, k = blocks.shape
        pos = blocks.astype(self.index_dtype)[..., None] + np.arange(d, dtype=self.index_dtype)
        return pos.reshape(n, nd, k * d)

    @property
    def _rows(self) -> np.ndarray:
        """The row of every stored entry (int64), on first use."""
        if self._rows_cache is None:
            self._rows_cache = np.repeat(np.arange(self.n_dofs, dtype=np.int64), np.diff(self.indptr))
        return self._rows_cache

    @_rows.setter
    def _rows(self, value) -> None:
        self._rows_cache = value

    # -- builders -------------------------------------------------------------------------------
    def _by_dofs(self, dof_tables, n_dofs):
        """The pattern from every (row dof, column dof) pair of every element: one sort of n nd^2 keys."""
        keys = [self._keys(d, n_dofs) for d in dof_tables]
        diag = np.arange(n_dofs, dtype=np.int64) * (n_dofs + 1)   # keep every diagonal entry
        uniq, inverse = np.unique(np.concatenate(keys + [diag]), return_inverse=True)
        rows, cols = np.divmod(uniq, n_dofs)
        itype = np.int32 if uniq.size < INDEX_LIMIT else np.int64
        self.index_dtype = itype
        self.indices = cols.astype(itype)
        self.indptr = np.searchsorted(rows, np.arange(n_dofs + 1)).astype(itype)
        self.nnz = uniq.size
        positions, start = [], 0
        for d, k in zip(dof_tables, keys):
            nd = d.shape[1]
            # int32 where the matrix allows it: the scatter reads these at every assembly
            positions.append(inverse[start:start + k.size].reshape(len(d), nd, nd).astype(itype))
            start += k.size
        self.diagonal = inverse[start:].astype(np.int64)
        self._rows = rows
        return positions

    def _by_nodes(self, node_tables, n_nodes, dpn):
        """Node-major dofs: the pattern and every table's node-blocked map from one numba pass over
        the node -> cell incidences (O(incidences x k)); returns (blocks, positions: not built yet)."""
        tables = [np.ascontiguousarray(c, dtype=np.int64) for c in node_tables]
        sizes = [c.shape[1] for c in tables]
        flat = np.concatenate([c.ravel() for c in tables]) if tables else np.zeros(0, dtype=np.int64)
        per_elem = np.concatenate([np.full(len(c), k, dtype=np.int64) for c, k in zip(tables, sizes)]
                                  + [np.zeros(0, dtype=np.int64)])
        estart = np.zeros(per_elem.size + 1, dtype=np.int64)
        np.cumsum(per_elem, out=estart[1:])
        bstart = np.zeros(per_elem.size + 1, dtype=np.int64)
        np.cumsum(dpn * per_elem * per_elem, out=bstart[1:])
        # int32 maps unless an upper bound of the nonzeros says they might not fit
        bound = dpn * dpn * (n_nodes + int((per_elem * per_elem).sum()))
        btype = np.int32 if bound <= INDEX_LIMIT else np.int64
        flat_blocks = np.empty(int(bstart[-1]), dtype=btype)
        node_indptr, node_cols = _node_pattern(flat, estart, bstart, n_nodes, dpn, flat_blocks)
        nnz = int(dpn * dpn * node_indptr[-1])
        itype = np.int32 if nnz < INDEX_LIMIT else np.int64
        self.index_dtype = itype
        self.nnz = nnz
        self.node_indptr, self.node_cols = node_indptr, node_cols
        self.indptr = np.empty(n_nodes * dpn + 1, dtype=itype)
        self.indices = np.empty(nnz, dtype=itype)
        self.diagonal = np.empty(n_nodes * dpn, dtype=np.int64)
        _dof_pattern(node_indptr, node_cols, dpn, self.indptr, self.indices, self.diagonal)
        if btype is np.int64 and nnz - 1 <= INDEX_LIMIT:
            flat_blocks = flat_blocks.astype(np.int32)
        out, at = [], 0
        for c, k in zip(tables, sizes):
            size = len(c) * dpn * k * k
            out.append(flat_blocks[at:at + size].reshape(len(c), dpn * k, k))
            at += size
        return out, [None] * len(out)

    @staticmethod
    def _keys(dofs, n_dofs):
        return (dofs[:, :, None] * n_dofs + dofs[:, None, :]).ravel().astype(np.int64)

    # -- use ------------------------------------------------------------------------------------
    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n_dofs, self.n_dofs))

    def submatrix_map(self, rows_keep: np.ndarray, cols_keep: np.ndarray):
        """Structure of the block (rows_keep, cols_keep), both sorted dof lists.

        Returns (entries, indices, indptr, shape): the block's data is data[entries]."""
        rows_keep = np.asarray(rows_keep)
        cols_keep = np.asarray(cols_keep)
        if not (_strictly_increasing(rows_keep) and _strictly_increasing(cols_keep)):
            return _reference_submatrix_map(self, rows_keep, cols_keep)
        out_indptr = np.empty(rows_keep.size + 1, dtype=self.indptr.dtype)
        entries, out_indices = _submatrix(self.indptr, self.indices, rows_keep.astype(np.int64, copy=False),
                                          cols_keep.astype(np.int64, copy=False), self.n_dofs, out_indptr)
        shape = (rows_keep.size, cols_keep.size)
        return entries, out_indices, out_indptr, shape


def _int32_or_none(b):
    return b if b is not None and b.dtype == np.int32 else None


def _strictly_increasing(a) -> bool:
    return a.ndim == 1 and (a.size < 2 or bool(np.all(a[1:] > a[:-1])))


def _node_tables(dof_tables, n_dofs, dpn):
    """Per dof table, its (n, k) node table when the dofs are node-major (dof = node dpn + i, the
    runtime's layout: runtime.base.dofs); None when any table is not (then the pattern goes by dofs)."""
    if not dpn or dpn < 1 or n_dofs % dpn:
        return None
    out = []
    for d in dof_tables:
        d = np.asarray(d, dtype=np.int64)
        if d.ndim != 2 or d.shape[1] % dpn:
            return None
        nodes = np.empty((len(d), d.shape[1] // dpn), dtype=np.int64)
        if not _nodes_of(np.ascontiguousarray(d), dpn, nodes):
            return None
        out.append(nodes)
    return out


@njit(cache=True)
def _nodes_of(dofs, dpn, nodes):
    """nodes[e, a] = dofs[e, a dpn] // dpn; False unless dofs[e, a dpn + i] = nodes[e, a] dpn + i."""
    for e in range(dofs.shape[0]):
        for a in range(nodes.shape[1]):
            m = dofs[e, a * dpn] // dpn
            nodes[e, a] = m
            for i in range(dpn):
                if dofs[e, a * dpn + i] != m * dpn + i:
                    return False
    return True


node_tables = _node_tables


# --------------------------------------------------------------------------- references (tests)


def _reference_by_nodes(node_tables, n_nodes, dpn) -> dict:
    """The sort-based node-pair build this module replaced (np.unique of every node-pair key and
    the full per-entry maps): the tests' reference for indptr, indices, diagonal, _rows, positions."""
    keys = [(c[:, :, None] * n_nodes + c[:, None, :]).ravel() for c in node_tables]
    diag = np.arange(n_nodes, dtype=np.int64) * (n_nodes + 1)
    uniq, inverse = np.unique(np.concatenate(keys + [diag]), return_inverse=True)
    node_rows, node_cols = np.divmod(uniq, n_nodes)
    node_indptr = np.searchsorted(node_rows, np.arange(n_nodes + 1))
    comp = np.arange(dpn)
    row_len = np.repeat(dpn * np.diff(node_indptr), dpn)               # per dof row
    indptr = np.concatenate([[0], np.cumsum(row_len)])
    nnz = int(indptr[-1])
    itype = np.int32 if nnz < 2**31 - 1 else np.int64
    expanded = (node_cols[:, None] * dpn + comp).ravel()
    start = np.repeat(np.repeat(node_indptr[:-1] * dpn, dpn), row_len)
    within = np.arange(nnz) - np.repeat(indptr[:-1], row_len)
    out = {"indices": expanded[start + within].astype(itype), "indptr": indptr.astype(itype), "nnz": nnz,
           "_rows": np.repeat(np.arange(n_nodes * dpn, dtype=np.int64), row_len),
           "node_indptr": node_indptr, "node_cols": node_cols}
    positions, at = [], 0
    for c, k in zip(node_tables, keys):
        n, kn = c.shape
        rel = (dpn * (inverse[at:at + k.size].reshape(n, kn, kn) - node_indptr[c][:, :, None])).astype(itype)
        at += k.size
        base = indptr[c[:, :, None] * dpn + comp].astype(itype)
        pos = base[:, :, :, None, None] + rel[:, :, None, :, None] + comp.astype(itype)
        positions.append(pos.reshape(n, kn * dpn, kn * dpn))
    m = np.arange(n_nodes)
    rel_diag = inverse[at:] - node_indptr[m]
    out["diagonal"] = (indptr[m[:, None] * dpn + comp] + dpn * rel_diag[:, None] + comp).ravel().astype(np.int64)
    out["positions"] = positions
    return out


def _reference_submatrix_map(pattern, rows_keep, cols_keep):
    """The numpy O(nnz) submatrix map (any row/column order); the tests' reference."""
    rmap = np.full(pattern.n_dofs, -1, dtype=np.int64)
    rmap[rows_keep] = np.arange(rows_keep.size)
    cmap = np.full(pattern.n_dofs, -1, dtype=np.int64)
    cmap[cols_keep] = np.arange(cols_keep.size)
    r, c = rmap[pattern._rows], cmap[pattern.indices]
    entries = np.flatnonzero((r >= 0) & (c >= 0))
    indptr = np.concatenate([[0], np.cumsum(np.bincount(r[entries], minlength=rows_keep.size))])
    shape = (rows_keep.size, cols_keep.size)
    return entries, c[entries].astype(pattern.indices.dtype), indptr.astype(pattern.indptr.dtype), shape


class ReferencePattern(SparsePattern):
    """The pattern as it was built before runtime.assembly.pattern (node pairs sorted, every per-entry map
    built at once, the Assembler deriving the node-blocked maps from them, numpy submatrix maps):
    the tests and apps/bench_pattern.py compare with it."""

    def _by_nodes(self, node_tables, n_nodes, dpn):
        ref = _reference_by_nodes(node_tables, n_nodes, dpn)
        self.indices, self.indptr, self.nnz, self.diagonal = ref["indices"], ref["indptr"], ref["nnz"], ref["diagonal"]
        self._rows = ref["_rows"]
        self.index_dtype = self.indices.dtype.type
        return [None] * len(node_tables), ref["positions"]

    def submatrix_map(self, rows_keep, cols_keep):
        return _reference_submatrix_map(self, rows_keep, cols_keep)
