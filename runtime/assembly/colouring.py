"""Element-graph colouring for colour-parallel assembly and matrix-free products (thesis ch. 6).

    indptr, indices = element_graph(cells)      # elements sharing a node are neighbours
    colours = colour_cells(cells)               # DSATUR (Brelaz); method="greedy": first-fit
    check_colouring(cells, colours)             # ValueError if one colour has two elements on a node
    K = ColouredOperator(cells, 3, Ke, colours) # y = K x without assembling K
    y = K.matvec(x); K.as_linear_operator()

Why colour: elements of one colour share no node, so their contributions go to disjoint entries of
a global vector (or matrix) and may be added by several threads at once without locks or atomics.
Fewer colours means fewer synchronisation points and larger parallel loops, which is why DSATUR is
used: 10 colours on an icosphere and 7 on a structured plate (first-fit in index order: 10-11 and 8,
apps.bench_colouring); on Delaunay tetrahedra both reach the lower bound, the most elements on one node.

DSATUR runs in O((V + E) log V): a binary max-heap with lazy updates (an element is pushed again
each time its saturation grows; stale entries are skipped when popped) and, per element, a bitset
of the colours its coloured neighbours use (saturation = number of set bits, the element's colour =
lowest clear bit).  Everything is deterministic: ties go to the larger degree, then the smaller index.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

__all__ = ["element_graph", "dsatur", "greedy", "colour_cells", "colour_classes", "check_colouring",
           "ColouredOperator", "METHODS"]


def _cells(cells) -> np.ndarray:
    cells = np.asarray(cells)
    if cells.ndim != 2:
        raise ValueError(f"cells must be a 2-D (elements, nodes per element) array, got shape {cells.shape}")
    if cells.size and (not np.issubdtype(cells.dtype, np.integer) or cells.min() < 0):
        raise ValueError("cells must hold non-negative integer node indices")
    return cells.astype(np.int64, copy=False)


def _incidence(cells: np.ndarray, n_nodes: int | None = None) -> sp.csr_matrix:
    """C[e, node] = 1 where element e has the node (a node repeated in a cell counts once)."""
    m, k = cells.shape
    n = int(cells.max(initial=-1)) + 1 if n_nodes is None else int(n_nodes)
    rows = np.repeat(np.arange(m, dtype=np.int64), k)
    C = sp.csr_matrix((np.ones(m * k, dtype=np.int32), (rows, cells.ravel())), shape=(m, n))
    C.data[:] = 1
    return C


def element_graph(cells):
    """CSR adjacency (indptr, indices; int64, columns sorted) of the elements sharing at least one node.

    Built as A = C C^T without its diagonal (C: the element-node incidence), so it costs two sparse
    products and no Python loop; no self loops; the same cells always give the same arrays.
    """
    cells = _cells(cells)
    m = cells.shape[0]
    if m == 0 or cells.shape[1] == 0:
        return np.zeros(m + 1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    C = _incidence(cells)
    A = (C @ C.T).tocoo()
    keep = A.row != A.col
    A = sp.csr_matrix((np.ones(int(keep.sum()), dtype=np.int8), (A.row[keep], A.col[keep])), shape=(m, m))
    A.sum_duplicates()
    A.sort_indices()
    return A.indptr.astype(np.int64), A.indices.astype(np.int64)


# ----------------------------------------------------------------------------------------- heap
# A binary max-heap on (key, -index): arrays `key`, `item` and its size, shared by the functions below.

@njit(cache=True, inline="always")
def _above(key, item, i, j):
    """Entry i goes before entry j: larger key, ties by smaller index (the DSATUR tie rule)."""
    return key[i] > key[j] or (key[i] == key[j] and item[i] < item[j])


@njit(cache=True)
def _swap(key, item, i, j):
    key[i], key[j] = key[j], key[i]
    item[i], item[j] = item[j], item[i]


@njit(cache=True)
def _push(key, item, size, k, v):
    key[size] = k
    item[size] = v
    i = size
    while i > 0:
        p = (i - 1) // 2
        if not _above(key, item, i, p):
            break
        _swap(key, item, i, p)
        i = p
    return size + 1


@njit(cache=True)
def _pop(key, item, size):
    """Remove the top entry (its key and item are returned by the caller reading index 0 first)."""
    size -= 1
    key[0] = key[size]
    item[0] = item[size]
    i = 0
    while True:
        left = 2 * i + 1
        if left >= size:
            break
        best = left
        if left + 1 < size and _above(key, item, left + 1, left):
            best = left + 1
        if not _above(key, item, best, i):
            break
        _swap(key, item, i, best)
        i = best
    return size


# --------------------------------------------------------------------------------------- colourings

@njit(cache=True)
def _lowest_clear(bits, v):
    """The lowest colour not set in row v of the bitset (the smallest colour no neighbour uses)."""
    for w in range(bits.shape[1]):
        word = bits[v, w]
        if word != np.uint64(0xFFFFFFFFFFFFFFFF):
            b = 0
            while (word >> np.uint64(b)) & np.uint64(1):
                b += 1
            return w * 64 + b
    return bits.shape[1] * 64


@njit(cache=True)
def _dsatur(indptr, indices):
    n = indptr.shape[0] - 1
    colour = np.full(n, -1, dtype=np.int32)
    if n == 0:
        return colour
    degree = indptr[1:] - indptr[:-1]
    scale = np.int64(degree.max()) + 1          # key = saturation * scale + degree: saturation first
    sat = np.zeros(n, dtype=np.int64)
    bits = np.zeros((n, 1), dtype=np.uint64)     # widened (doubling) when the colours outgrow it
    cap = n + indices.shape[0]                   # one push per element + at most one per edge end
    key = np.empty(cap, dtype=np.int64)
    item = np.empty(cap, dtype=np.int64)
    size = 0
    for v in range(n):
        size = _push(key, item, size, degree[v], v)
    done = 0
    while done < n:
        k = key[0]
        v = item[0]
        size = _pop(key, item, size)
        if colour[v] >= 0 or k != sat[v] * scale + degree[v]:
            continue                             # coloured already, or a stale (lower) saturation
        c = _lowest_clear(bits, v)
        colour[v] = c
        done += 1
        w, b = c // 64, np.uint64(c % 64)
        if w >= bits.shape[1]:
            wider = np.zeros((n, 2 * bits.shape[1]), dtype=np.uint64)
            wider[:, :bits.shape[1]] = bits
            bits = wider
        mask = np.uint64(1) << b
        for j in range(indptr[v], indptr[v + 1]):
            u = indices[j]
            if colour[u] < 0 and not (bits[u, w] & mask):
                bits[u, w] |= mask
                sat[u] += 1
                size = _push(key, item, size, sat[u] * scale + degree[u], u)
    return colour


def _graph(indptr, indices):
    indptr = np.ascontiguousarray(indptr, dtype=np.int64)
    indices = np.ascontiguousarray(indices, dtype=np.int64)
    if indptr.ndim != 1 or indptr.size < 1 or indptr[0] != 0 or indptr[-1] != indices.size:
        raise ValueError("(indptr, indices) is not a CSR adjacency: indptr[0] must be 0 and indptr[-1] "
                         "the number of indices")
    if indices.size and (indices.min() < 0 or indices.max() >= indptr.size - 1):
        raise ValueError("adjacency indices out of range")
    return indptr, indices


def dsatur(indptr, indices) -> np.ndarray:
    """DSATUR colouring (Brelaz 1979) of a symmetric CSR graph without self loops: int32 colours.

    Repeatedly colours the uncoloured vertex with the most distinct neighbour colours (saturation),
    ties by larger degree then smaller index, with the smallest colour its neighbours do not use.
    Uses at most max degree + 1 colours; usually fewer than first-fit on meshes.
    """
    return _dsatur(*_graph(indptr, indices))


@njit(cache=True)
def _greedy(indptr, indices):
    n = indptr.shape[0] - 1
    colour = np.full(n, -1, dtype=np.int32)
    if n == 0:
        return colour
    banned = np.full(int((indptr[1:] - indptr[:-1]).max()) + 2, -1, dtype=np.int64)
    for v in range(n):
        for j in range(indptr[v], indptr[v + 1]):
            c = colour[indices[j]]
            if c >= 0:
                banned[c] = v
        c = 0
        while banned[c] == v:
            c += 1
        colour[v] = c
    return colour


def greedy(indptr, indices) -> np.ndarray:
    """First-fit colouring in index order (the baseline DSATUR is compared with): int32 colours."""
    return _greedy(*_graph(indptr, indices))


METHODS = {"dsatur": dsatur, "greedy": greedy}


def colour_cells(cells, method: str = "dsatur") -> np.ndarray:
    """Colours (int32, one per element) such that elements of one colour share no node."""
    if method not in METHODS:
        raise ValueError(f"unknown colouring method {method!r}; choose from {sorted(METHODS)}")
    return METHODS[method](*element_graph(cells))


def colour_classes(colours) -> list:
    """The elements of each colour 0 .. max (int64 arrays, ascending), from one stable sort."""
    colours = np.asarray(colours)
    if colours.size == 0:
        return []
    order = np.argsort(colours, kind="stable")
    counts = np.bincount(colours, minlength=int(colours.max()) + 1)
    return np.split(order.astype(np.int64), np.cumsum(counts)[:-1])


def check_colouring(cells, colours) -> None:
    """Raise ValueError if two elements of one colour share a node (or the colours do not fit the cells)."""
    cells = _cells(cells)
    colours = np.asarray(colours)
    if colours.shape != (cells.shape[0],):
        raise ValueError(f"{colours.shape} colours for {cells.shape[0]} elements")
    if colours.size == 0:
        return
    if colours.min() < 0:
        raise ValueError("an element has no colour (negative value)")
    # one (colour, node) slot per distinct (element, node) pair: a slot seen twice is a clash
    k = cells.shape[1]
    n = int(cells.max(initial=-1)) + 1
    pairs = np.stack([np.repeat(np.arange(cells.shape[0]), k), cells.ravel()], axis=1)
    pairs = np.unique(pairs, axis=0)                         # a node repeated inside one cell once
    slot = colours[pairs[:, 0]].astype(np.int64) * n + pairs[:, 1]
    order = np.argsort(slot, kind="stable")
    same = np.flatnonzero(slot[order][1:] == slot[order][:-1])
    if same.size:
        i, j = order[same[0]], order[same[0] + 1]
        c, node = divmod(int(slot[i]), n)
        raise ValueError(f"elements {int(pairs[i, 0])} and {int(pairs[j, 0])} both have colour {c} "
                         f"and share node {node}")


# ------------------------------------------------------------------------------------- matvec

@njit(cache=True, parallel=True)
def _coloured_matvec(Ke, dofs, starts, x, y, transpose):
    """y += sum_e P_e Ke x_e (Ke^T with `transpose`), colour after colour, the elements of one
    colour (rows starts[c]:starts[c+1] of Ke and dofs, stored in colour order) in parallel.

    Within a colour no two elements share a node, so each entry of y is written by one thread
    only; the element product is plain loops in a fixed order (no BLAS, whose sums may depend on
    threads), so y is the same bit for bit whatever the thread count.
    """
    n_e = dofs.shape[1]
    for c in range(starts.shape[0] - 1):
        for e in prange(starts[c], starts[c + 1]):
            if transpose:
                for a in range(n_e):
                    s = 0.0
                    for b in range(n_e):
                        s += Ke[e, b, a] * x[dofs[e, b]]
                    y[dofs[e, a]] += s
            else:
                for a in range(n_e):
                    s = 0.0
                    for b in range(n_e):
                        s += Ke[e, a, b] * x[dofs[e, b]]
                    y[dofs[e, a]] += s


class ColouredOperator:
    """Matrix-free y = K x with K = sum_e P_e^T Ke P_e (per-element dense blocks, node-major dofs).

    Colours run in ascending order; the elements of one colour run on numba's threads (the count
    set by runtime.base.parallel / numba.set_num_threads).  Why the result is deterministic: an entry
    y[i] belongs to one node, and within a colour at most one element has that node, so during a
    colour y[i] receives at most one addition, from one thread; across colours the additions come
    in the fixed colour order, and within an element the sums run in a fixed loop order.  So every
    y[i] is the same sequence of floating-point additions whatever the thread count or schedule.
    """

    def __init__(self, cells, dofs_per_node: int, element_matrices, colours, n_nodes: int | None = None):
        cells = _cells(cells)
        m, k = cells.shape
        d = int(dofs_per_node)
        if d < 1:
            raise ValueError(f"dofs_per_node must be >= 1, got {dofs_per_node}")
        Ke = np.ascontiguousarray(element_matrices, dtype=np.float64)
        if Ke.shape != (m, k * d, k * d):
            raise ValueError(f"element_matrices: expected shape {(m, k * d, k * d)}, got {Ke.shape}")
        check_colouring(cells, colours)
        self.n_nodes = int(cells.max(initial=-1)) + 1 if n_nodes is None else int(n_nodes)
        if self.n_nodes <= int(cells.max(initial=-1)):
            raise ValueError(f"n_nodes={self.n_nodes} but the cells use node {int(cells.max())}")
        self.cells, self.dofs_per_node = cells, d
        self.colours = np.asarray(colours, dtype=np.int32)
        # Element blocks and dof rows copied into colour order: each colour is then one contiguous
        # run that the matvec streams through (in element order the colour classes jump across
        # memory, about 4 times slower on 50k tetrahedra).  `order[i]`: the element in row i.
        self.order = np.argsort(self.colours, kind="stable").astype(np.int64)
        self.Ke = np.ascontiguousarray(Ke[self.order])
        self.dofs = np.ascontiguousarray((cells[self.order, :, None] * d + np.arange(d)).reshape(m, k * d))
        counts = np.bincount(self.colours, minlength=1) if m else np.zeros(0, dtype=np.int64)
        self.starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.n = self.n_nodes * d
        self.shape = (self.n, self.n)

    @property
    def n_colours(self) -> int:
        return len(self.starts) - 1

    def _apply(self, x, transpose: bool) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1)
        if x.shape[0] != self.n:
            raise ValueError(f"x has {x.shape[0]} entries, the operator {self.n}")
        y = np.zeros(self.n)
        if len(self.dofs):
            _coloured_matvec(self.Ke, self.dofs, self.starts, x, y, transpose)
        return y

    def matvec(self, x) -> np.ndarray:
        """y = K x (a new array)."""
        return self._apply(x, False)

    def rmatvec(self, x) -> np.ndarray:
        """y = K^T x (the element blocks transposed)."""
        return self._apply(x, True)

    def as_linear_operator(self):
        """A scipy.sparse.linalg.LinearOperator (for cg, gmres, eigsh, ...)."""
        from scipy.sparse.linalg import LinearOperator
        return LinearOperator(self.shape, matvec=self.matvec, rmatvec=self.rmatvec, dtype=np.float64)

    def to_csr(self) -> sp.csr_matrix:
        """The assembled matrix (duplicates summed): a reference for tests and benchmarks."""
        m, n_e = self.dofs.shape
        rows = np.repeat(self.dofs, n_e, axis=1).ravel()
        cols = np.tile(self.dofs, (1, n_e)).ravel()
        return sp.csr_matrix((self.Ke.ravel(), (rows, cols)), shape=self.shape)
