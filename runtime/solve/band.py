"""Banded Cholesky: a bandwidth-reducing ordering, a float32 LAPACK factor refined to float64 accuracy.

The solver of bars and slabs (runtime.solve.solvers picks it by its cost model): on a body
numbered slice by slice the band is narrow and LAPACK's blocked band Cholesky (spbtrf,
one BLAS thread) beats every general sparse factorisation.  The factor is kept and
preconditions CG on the next matrix of the pattern (runtime.solve.solvers.LinearSolver).
"""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.linalg import lapack
from threadpoolctl import ThreadpoolController

from .cg import REFINE_MAX, refine, reuse_iterations
from .choices import BAND_MAX_ENTRIES

__all__ = ["BandPlan", "BandFactor", "band_solve", "band_costs", "reuse_cap", "band_ordering",
           "one_blas_thread", "BAND_MAX_ENTRIES"]

# Cost model of the band path: modelled seconds on the benchmark machine (2-core EPYC,
# 32 MiB L3, one BLAS thread, float32 factor).  It replaces the measured seconds the reuse
# cap used to come from: those made the decision, and so the bits of the result, depend on
# the machine load (two identical runs started together differed at 1e-13, issue #10).
#  - spbtrf does n kd^2 flops at a rate that grows with the band (its blocked level-3
#    updates need a wide one): 20 Gflop/s at kd 173, 37 at kd 335, 57 at kd 1145, about
#    _FACTOR_FLOPS kd / (kd + _FACTOR_BLOCK_KD);
#  - one refinement iteration (two band triangular solves, 4 n kd flops, one sparse
#    product, 2 nnz, a few vector operations) is memory-bound: 7-10 Gflop/s while the
#    factor fits in the cache, 5.4-6.3 once it streams from memory, plus ~25 us of calls.
# Model / best measured (idle), factor and one reuse iteration, on `bench steps` and test
# step matrices: 1k tetrahedra 0.40 / 0.39 ms, 59 / 62 us; 10k tetrahedra 15 / 17 ms,
# 0.85 / 0.77 ms; 2k hexahedra 22 / 22 ms, 1.15 / 1.21 ms; 6k hexahedra 133 / 132 ms,
# 8.2 / 7.6 ms; 20k hexahedra 1.44 / 1.39-1.55 s, 53 / 55-57 ms.  float64 factors: twice
# the bytes and half the flop rate.
_FACTOR_FLOPS = 80e9
_FACTOR_BLOCK_KD = 400.0
_SOLVE_FLOPS_CACHED = 9.5e9
_SOLVE_FLOPS_MEMORY = 5.8e9
_CACHE_BYTES = 32 * 2**20
_ITERATION_OVERHEAD_S = 25e-6

_threads = None


def one_blas_thread():
    """Context: LAPACK band routines on one thread (with two OpenBLAS threads on shared cores
    spbtrf/dpbtrf ran 5-10x slower)."""
    global _threads
    if _threads is None:
        _threads = ThreadpoolController()
    return _threads.limit(limits=1, user_api="blas")


def band_costs(n: int, kd: int, nnz: int, itemsize: int = 4) -> tuple[float, float]:
    """(factorisation, one refinement iteration) of the band path in modelled seconds (see
    the cost model above): a function of the pattern and precision alone, never a timing."""
    n, kd, nnz = float(n), float(kd), float(nnz)
    slower = itemsize / 4.0                             # float64: twice the bytes, half the rate
    factor = slower * n * kd * (kd + _FACTOR_BLOCK_KD) / _FACTOR_FLOPS    # n kd^2 flops at the rate above
    cached = itemsize * n * (kd + 1.0) <= _CACHE_BYTES
    rate = _SOLVE_FLOPS_CACHED if cached else _SOLVE_FLOPS_MEMORY
    iteration = slower * (2.0 * nnz + 4.0 * n * kd) / rate + _ITERATION_OVERHEAD_S
    return factor, iteration


def reuse_cap(n: int, kd: int, nnz: int, itemsize: int = 4) -> int:
    """Most CG iterations a kept band factor gets before refactoring (cg.reuse_iterations of the
    modelled costs): a function of the pattern alone (n unknowns, half-bandwidth kd, nnz stored
    entries, the factor's precision), so the same matrices get the same decisions on any load."""
    return reuse_iterations(*band_costs(n, kd, nnz, itemsize))


class BandPlan:
    """A bandwidth-reducing ordering of one sparsity pattern (runtime.solve.solvers keeps one per pattern)."""

    def __init__(self, A):
        self.indptr, self.indices = A.indptr, A.indices
        self.n = A.shape[0]
        self.perm, self.iperm, self.kd = band_ordering(A)
        self.work = float(self.n) * float(self.kd) ** 2
        self.entries = (self.kd + 1) * self.n
        self.nnz = int(A.nnz)


class BandFactor:
    """A banded Cholesky factor of one matrix (for its pattern's plan); calling it applies A^-1."""

    def __init__(self, plan, c, dtype):
        self.plan, self.c, self.dtype = plan, c, dtype
        self.trs = lapack.spbtrs if dtype is np.float32 else lapack.dpbtrs
        self.name = "band32" if dtype is np.float32 else "band64"
        # CG iterations it may precondition on a later matrix of the pattern (LinearSolver._band)
        self.reuse_cap = reuse_cap(plan.n, plan.kd, plan.nnz, np.dtype(dtype).itemsize)

    def __call__(self, r):
        perm = self.plan.perm
        y, _ = self.trs(self.c, r[perm].astype(self.dtype), lower=1, overwrite_b=1)
        z = np.empty(self.plan.n)
        z[perm] = y
        return z


def _band_factor(A, plan, dtype):
    """Factor A in band storage in the given precision (call on one BLAS thread); None if not SPD."""
    ab = np.empty((plan.kd + 1, plan.n), dtype=dtype, order="F")
    _fill_band(A.indptr, A.indices, A.data, plan.iperm, ab)
    factor = lapack.spbtrf if dtype is np.float32 else lapack.dpbtrf
    c, info = factor(ab, lower=1, overwrite_ab=1)
    if info != 0:
        return None                             # not positive definite (in this precision)
    return BandFactor(plan, c, dtype)


def band_solve(A, b, plan):
    """Banded Cholesky in float32 then float64, refined by factor-preconditioned CG.

    Returns (x, factor), or None when A is not positive definite (the caller
    falls back to LU).
    """
    for dtype in (np.float32, np.float64):
        factor = _band_factor(A, plan, dtype)
        if factor is None:
            continue
        out = refine(A, b, factor, exact=dtype is np.float64, max_iterations=REFINE_MAX)
        if out is not None:
            return out[0], factor
    return None


@njit(cache=True)
def _fill_band(indptr, indices, data, iperm, ab):
    """Lower band storage of the permuted matrix: ab[pi - pj, pj] = a_ij for pi >= pj."""
    ab[:, :] = 0.0
    for i in range(indptr.size - 1):
        pi = iperm[i]
        for k in range(indptr[i], indptr[i + 1]):
            pj = iperm[indices[k]]
            if pi >= pj:
                ab[pi - pj, pj] += data[k]


# --------------------------------------------------------------------------- band ordering


@njit(cache=True)
def _bfs_levels(indptr, indices, start):
    n = indptr.size - 1
    level = np.full(n, -1, np.int64)
    queue = np.empty(n, np.int64)
    queue[0] = start
    level[start] = 0
    head, tail = 0, 1
    while head < tail:
        v = queue[head]
        head += 1
        for k in range(indptr[v], indptr[v + 1]):
            w = indices[k]
            if level[w] < 0:
                level[w] = level[v] + 1
                queue[tail] = w
                tail += 1
    return level


@njit(cache=True)
def _cuthill_mckee(indptr, indices, sources):
    """Cuthill-McKee from a set of start vertices (in the given order); other components appended."""
    n = indptr.size - 1
    degree = np.empty(n, np.int64)
    for i in range(n):
        degree[i] = indptr[i + 1] - indptr[i]
    seen = np.zeros(n, np.bool_)
    order = np.empty(n, np.int64)
    new = np.empty(n, np.int64)
    head, tail, nxt = 0, 0, 0
    for s in sources:
        if not seen[s]:
            seen[s] = True
            order[tail] = s
            tail += 1
    while True:
        while head < tail:
            v = order[head]
            head += 1
            m = 0
            for k in range(indptr[v], indptr[v + 1]):
                w = indices[k]
                if not seen[w]:
                    seen[w] = True
                    new[m] = w
                    m += 1
            for a in range(1, m):                  # by degree, then index (insertion sort)
                x = new[a]
                c = a - 1
                while c >= 0 and (degree[new[c]] > degree[x] or (degree[new[c]] == degree[x] and new[c] > x)):
                    new[c + 1] = new[c]
                    c -= 1
                new[c + 1] = x
            for a in range(m):
                order[tail] = new[a]
                tail += 1
        if tail == n:
            break
        while seen[nxt]:
            nxt += 1
        seen[nxt] = True
        order[tail] = nxt
        tail += 1
    return order


@njit(cache=True)
def _bandwidth(indptr, indices, iperm):
    kd = 0
    for i in range(indptr.size - 1):
        for k in range(indptr[i], indptr[i + 1]):
            d = iperm[i] - iperm[indices[k]]
            if d > kd:
                kd = d
    return kd


def band_ordering(A):
    """(perm, iperm, kd): a small-bandwidth ordering of A's (symmetric) pattern.

    Candidates: the given order, and Cuthill-McKee started from the whole last
    level of a breadth-first search from a minimum-degree vertex (and again from
    the far end of that): on a bar this numbers the unknowns slice by slice.
    The smallest bandwidth wins.  (scipy's reverse_cuthill_mckee starts from one
    vertex and gave kd 653 / 332 / 3083 on the three `bench steps` matrices where
    this gives 275 / 278 / 1145: 2.4-7x the band work.)
    """
    indptr, indices = A.indptr, A.indices
    n = A.shape[0]
    candidates = [np.arange(n, dtype=np.int64)]
    if n > 1:
        start = int(np.argmin(np.diff(indptr)))
        for _ in range(2):
            level = _bfs_levels(indptr, indices, start)
            far = np.flatnonzero(level == level.max()).astype(np.int64)
            order = _cuthill_mckee(indptr, indices, far)
            candidates.append(order)
            start = int(order[-1])
    best = None
    for perm in candidates:
        iperm = np.empty(n, dtype=np.int64)
        iperm[perm] = np.arange(n)
        kd = _bandwidth(indptr, indices, iperm)
        if best is None or kd < best[2]:
            best = (perm, iperm, int(kd))
    return best
