"""Linear solvers for the free dofs: banded Cholesky, CHOLMOD, SuperLU and preconditioned CG.

    solver = LinearSolver("auto", tol=1e-8, max_iterations=1000)
    x, iterations = solver.solve(A, b)          # iterations: CG steps, 1 for a direct solve
    solver.last                                 # what solved it: "band32", "band64", "cholmod", "lu", "cg-ic", ...

Methods: "direct" (the fastest direct solver for the matrix: banded Cholesky,
CHOLMOD when scikit-sparse imports, SuperLU), "cg" (preconditioned conjugate
gradients), "auto" (direct or cg by the estimated cost, see `choose`), and the
individual direct solvers "band", "cholmod", "lu".

The banded Cholesky orders the unknowns for a small bandwidth (Cuthill-McKee
from the far end of a level structure, cached per sparsity pattern), factors
in single precision with LAPACK (spbtrf, one BLAS thread) and iterates to
double-precision accuracy with CG preconditioned by that factor; a factor that
fails (indefinite or too ill-conditioned for float32) is redone in double
precision, and a matrix that is not positive definite goes to SuperLU's LU.
Every direct path therefore returns the solution of an indefinite system too.
The band factor is kept: the next matrix of the same pattern is first solved
by CG preconditioned with it (see LinearSolver, reuse).

Every decision (which solver, reuse or refactor, how many iterations) comes from
the matrix's size, pattern and values, never from measured times: the same
sequence of systems gives the same bits on an idle or a loaded machine (issue
#10).  Times are only reported (`LinearSolver.time`).

Dirichlet conditions are applied by elimination before calling these (see
`ConstrainedSystem`): K_ff x_f = r_f - K_fc x_c.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit
from scipy.linalg import lapack
from threadpoolctl import ThreadpoolController

from .errors import TensormassError

__all__ = ["LinearSolver", "ConstrainedSystem", "DIRECT_LIMIT", "METHODS", "PRECONDITIONERS",
           "has_cholmod", "has_pyamg", "warm_up"]

METHODS = ("auto", "direct", "cg", "band", "cholmod", "lu")
PRECONDITIONERS = ("ic", "jacobi", "amg")

# --------------------------------------------------------------------------- thresholds
#
# Measured on the 2-core AMD EPYC (AVX-512) this project benchmarks on, shared with
# other jobs, best of 3-5, on the matrices `tensormass bench steps` builds (one fresh
# solve each, no factor reuse):
#
#   system (free dofs, nnz, bandwidth kd)             band32   SuperLU   CG-Jacobi       CG-IC(0)
#   3072-hex neo-Hookean K (11 664, 0.80 M, 275)        32 ms    294 ms   114 ms/210 it   132 ms/112 it
#   10k-tet StVK implicit Euler (6 552, 0.26 M, 278)    14 ms    114 ms    41 ms/220 it    30 ms/73 it
#   20k-hex StVK implicit Euler (64 980, 4.8 M, 1145)  1.4 s      16 s    0.76 s/217 it   0.58 s/69 it
#
# (band32: float32 LAPACK factor + CG refinement to 1e-10 relative residual, one BLAS
# thread: with two OpenBLAS threads on the shared cores spbtrf/dpbtrf ran 5-10x slower;
# cholespy 2.1 (CHOLMOD, simplicial) took 480 ms / 170 ms / 32 s, slower than SuperLU.)
# The band solve costs about n kd^2 x 1.7-3.7e-11 s, CG-IC(0) about nnz x 1.2-1.7e-7 s:
# "auto" takes the band Cholesky while n kd^2 <= AUTO_BAND_WORK_PER_NNZ x nnz (3072
# hexes: 1.1e3 x nnz, 10k tets: 2.0e3 x nnz -> band; 20k hexes: 17.5e3 x nnz -> CG),
# and always below AUTO_DIRECT_BELOW unknowns.
AUTO_BAND_WORK_PER_NNZ = 6_000.0
AUTO_DIRECT_BELOW = 3_000
# "direct" prefers CHOLMOD (scikit-sparse, when installed; fill-reducing orderings beat a
# band on compact 3D bodies) once the band factor would cost more than this (~0.1 s).
DIRECT_BAND_WORK_CHOLMOD = 5e9
# The band factor is refused (SuperLU instead) beyond this many float64 band entries (2 GiB).
BAND_MAX_ENTRIES = 2**28
# Relative residual the band Cholesky refines to, and its refinement budget.
DIRECT_TOL = 1e-10
_REFINE_MAX = 30
# A kept band factor preconditions CG on the next matrix of the same pattern (the next
# implicit step or Newton iteration) for at most _REUSE_MAX iterations, and at most half
# of a new factorisation's modelled cost (below), before it is refactored.
_REUSE_MAX = 20
_REUSE_MIN = 3
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
# Above this many unknowns "auto" never factorises (a band plan alone would cost too much).
DIRECT_LIMIT = 200_000
# IC(0) breaks down on some SPD matrices: retry with these diagonal shifts, then use Jacobi.
_IC_SHIFTS = (0.0, 1e-3, 1e-2, 1e-1)

try:                                    # optional accelerators (pip install tensormass[fast])
    from sksparse import cholmod as _cholmod
except ImportError:                     # pragma: no cover - depends on the environment
    _cholmod = None
try:
    import pyamg as _pyamg
except ImportError:                     # pragma: no cover
    _pyamg = None

_threads = None


def _one_blas_thread():
    """Context: LAPACK band routines on one thread (see the thresholds above)."""
    global _threads
    if _threads is None:
        _threads = ThreadpoolController()
    return _threads.limit(limits=1, user_api="blas")


def has_cholmod() -> bool:
    return _cholmod is not None


def has_pyamg() -> bool:
    return _pyamg is not None


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
    """Most CG iterations a kept band factor gets before refactoring: as many as cost half a
    new factorisation by the cost model, within [_REUSE_MIN, _REUSE_MAX].

    A function of the pattern alone (n unknowns, half-bandwidth kd, nnz stored entries,
    the factor's precision), so the same matrices get the same decisions on any load.
    """
    factor, iteration = band_costs(n, kd, nnz, itemsize)
    return int(min(_REUSE_MAX, max(_REUSE_MIN, 0.5 * factor / iteration)))


class _BandPlan:
    """A bandwidth-reducing ordering of one sparsity pattern."""

    def __init__(self, A):
        self.indptr, self.indices = A.indptr, A.indices
        self.n = A.shape[0]
        self.perm, self.iperm, self.kd = band_ordering(A)
        self.work = float(self.n) * float(self.kd) ** 2
        self.entries = (self.kd + 1) * self.n
        self.nnz = int(A.nnz)

    def matches(self, A) -> bool:
        if A.shape[0] != self.n:
            return False
        if A.indices is self.indices and A.indptr is self.indptr:
            return True
        return (A.indices.size == self.indices.size and np.array_equal(A.indptr, self.indptr)
                and np.array_equal(A.indices, self.indices))


class LinearSolver:
    """Solve A x = b for a sparse symmetric A; see the module docstring for the methods.

    preconditioner for CG: "ic" (default: incomplete Cholesky IC(0), with a
    diagonal shift if it breaks down, Jacobi if it still does), "jacobi" or
    "amg" (smoothed aggregation, only when pyamg imports; IC otherwise).  A CG
    run that hits the iteration cap returns its last iterate (an inexact Newton
    step, like the thesis' fixed 20 iterations); `self.converged` says whether
    it met tol.

    reuse: the band Cholesky keeps its factor; the next system with the same
    pattern is first solved by CG preconditioned with it (to the same 1e-10
    relative residual), which takes a few iterations while the matrix changes
    little (consecutive implicit steps, late Newton iterations); otherwise it is
    refactored.  `last` then ends in "-reuse".  The iteration cap comes from the
    pattern's cost model (`reuse_cap`), never from timings.

    time: seconds spent in solve, reported only (no decision reads it).
    """

    def __init__(self, method: str = "auto", tol: float = 1e-8, max_iterations: int = 1000,
                 preconditioner: str = "ic", reuse: bool = True):
        if method not in METHODS:
            raise TensormassError(f"unknown linear solver {method!r}; use {', '.join(METHODS)}")
        if preconditioner not in PRECONDITIONERS:
            raise TensormassError(f"unknown preconditioner {preconditioner!r}; use {', '.join(PRECONDITIONERS)}")
        self.method, self.tol, self.max_iterations = method, float(tol), int(max_iterations)
        self.preconditioner = preconditioner
        self.converged = True
        self.time = 0.0                          # statistics only: never an input to a decision
        self.last = None
        self.reuse = bool(reuse)
        self._plan = None
        self._factor = None                      # last band factor (reuse)
        self._skip_reuse = 0                     # calls left that refactor without trying reuse
        self._reuse_backoff = 0

    # -- choice -------------------------------------------------------------------------------
    def plan(self, A) -> _BandPlan:
        """The band ordering of A's pattern (computed once per pattern)."""
        if self._plan is None or not self._plan.matches(A):
            self._plan = _BandPlan(A)
            self._factor = None
        return self._plan

    def choose(self, A) -> str:
        """The solver "solve" uses for A: "band", "cholmod", "lu" or "cg"."""
        method, n = self.method, A.shape[0]
        if method in ("band", "cholmod", "lu", "cg"):
            if method == "cholmod" and _cholmod is None:
                return "lu"
            return method
        if method == "auto" and n > AUTO_DIRECT_BELOW:
            if n > DIRECT_LIMIT:
                return "cg"
            plan = self.plan(A)
            if plan.work > AUTO_BAND_WORK_PER_NNZ * A.nnz or plan.entries > BAND_MAX_ENTRIES:
                return "cg"
            return "band"
        plan = self.plan(A)
        if _cholmod is not None and plan.work > DIRECT_BAND_WORK_CHOLMOD:
            return "cholmod"
        return "band" if plan.entries <= BAND_MAX_ENTRIES else "lu"

    def kind_for(self, A) -> str:
        """"direct" or "cg" (A: the matrix, or only its size for the fixed methods)."""
        if isinstance(A, (int, np.integer)):
            if self.method == "auto":
                return "direct" if A <= AUTO_DIRECT_BELOW else "cg"
            return "cg" if self.method == "cg" else "direct"
        return "cg" if self.choose(A) == "cg" else "direct"

    # -- solve --------------------------------------------------------------------------------
    def solve(self, A, b: np.ndarray, x0: np.ndarray | None = None):
        """(x, iterations); raises TensormassError on a singular system or NaN/Inf."""
        start = time.perf_counter()
        try:
            b = np.asarray(b, dtype=float)
            if not np.all(np.isfinite(b)):
                raise TensormassError("linear solve: right-hand side contains NaN/Inf")
            if b.size == 0 or not np.any(b):
                self.last = "zero"
                return np.zeros_like(b), 0
            A = sp.csr_matrix(A) if not sp.isspmatrix_csr(A) else A
            if A.shape != (b.size, b.size):
                raise TensormassError(f"linear solve: matrix {A.shape} does not match {b.size} unknowns")
            if not np.all(np.isfinite(A.data)):
                raise TensormassError("linear solve: the system matrix contains NaN/Inf "
                                      "(inverted elements? a diverging step?)")
            kind = self.choose(A)
            if kind == "cg":
                x, its, self.converged = self._cg(A, b, x0)
            else:
                x, its = self._direct(A, b, kind), 1
                self.converged = True
            if not np.all(np.isfinite(x)):
                raise TensormassError("linear solve produced NaN/Inf: the system matrix is singular or "
                                      "badly conditioned (is every rigid motion fixed? inverted elements?)")
            return x, its
        finally:
            self.time += time.perf_counter() - start

    def _direct(self, A, b, kind):
        if kind == "band":
            with _one_blas_thread():
                x = self._band(A, b)
            if x is not None:
                return x
        elif kind == "cholmod" and _cholmod is not None:
            try:
                x = _cholmod.cholesky(A.tocsc())(b)
                if np.all(np.isfinite(x)):
                    self.last = "cholmod"
                    return x
            except Exception:                       # not positive definite (or CHOLMOD failed): LU
                pass
        self._factor = None
        self.last = "lu"
        return _lu(A, b)

    def _band(self, A, b):
        """Band Cholesky; with reuse, the previous factor of this pattern preconditions CG first."""
        plan = self.plan(A)
        old = self._factor
        if self.reuse and old is not None and old.plan is plan:
            if self._skip_reuse > 0:
                self._skip_reuse -= 1
            else:
                # worth it while cheaper than half a new factorisation (modelled, not timed)
                out = _refine(A, b, old, exact=False, max_iterations=old.reuse_cap)
                if out is not None:
                    self._reuse_backoff = 0
                    self.last = old.name + "-reuse"
                    return out[0]
                # the matrix moved on (large Newton steps): refactor the next 1, 2, 4, ... times directly
                self._skip_reuse = self._reuse_backoff = min(2 * self._reuse_backoff + 1, 63)
        self._factor = None
        out = _band_solve(A, b, plan)
        if out is None:
            return None
        x, factor = out
        if self.reuse:
            self._factor = factor
        self.last = factor.name
        return x

    def _cg(self, A, b, x0):
        d = A.diagonal()
        if np.any(d <= 0):
            raise TensormassError("cg needs a positive diagonal; the system matrix is not positive definite "
                                  "(use linear = 'direct' or enable project_psd)")
        if self.preconditioner == "amg" and _pyamg is not None:
            self.last = "cg-amg"
            return _scipy_cg(A, b, x0, self.tol, self.max_iterations, _amg(A))
        x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
        factor = None
        if self.preconditioner != "jacobi":
            if not A.has_canonical_format:
                A = A.copy()
                A.sum_duplicates()
            factor = ic0(A)
        self.last = "cg-ic" if factor is not None else "cg-jacobi"
        if factor is None:
            factor = jacobi_factor(d, _unsigned(A.indices).dtype)
        its, status = _pcg(A.indptr, _unsigned(A.indices), A.data, b, *factor, x, self.tol, self.max_iterations)
        if status < 0:
            raise TensormassError("linear solve (cg) broke down: the system matrix is not positive definite "
                                  "(use linear = 'direct' or enable project_psd)")
        return x, its, status == 0


# --------------------------------------------------------------------------- direct solvers


def _lu(A, b):
    """SuperLU; symmetric mode first (minimum degree on A^T + A beats COLAMD by far)."""
    try:
        lu = spla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A",
                       options=dict(SymmetricMode=True), diag_pivot_thresh=0.0)
        x = lu.solve(b)
        if np.all(np.isfinite(x)):
            return x
        lu = spla.splu(A.tocsc(), permc_spec="COLAMD")      # retry with partial pivoting
        return lu.solve(b)
    except RuntimeError as exc:                   # "Factor is exactly singular"
        raise TensormassError(f"linear solve failed ({exc}): the system matrix is singular; "
                              "is every rigid-body motion constrained?") from None


class _BandFactor:
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
    return _BandFactor(plan, c, dtype)


def _band_solve(A, b, plan):
    """Banded Cholesky in float32 then float64, refined by factor-preconditioned CG.

    Returns (x, factor), or None when A is not positive definite (the caller
    falls back to LU).
    """
    for dtype in (np.float32, np.float64):
        factor = _band_factor(A, plan, dtype)
        if factor is None:
            continue
        out = _refine(A, b, factor, exact=dtype is np.float64, max_iterations=_REFINE_MAX)
        if out is not None:
            return out[0], factor
    return None


def _refine(A, b, M, exact, max_iterations):
    """CG on A x = b preconditioned by M ~ A^-1, from x = M b, to DIRECT_TOL.

    exact (M is a float64 factor of A): the first iterate is already a direct
    solve; refinement only polishes it and stops when the residual stops
    dropping.  Returns (x, iterations), or None when the iteration does not
    converge in max_iterations (or breaks down).
    """
    bnorm = np.linalg.norm(b)
    x = M(b)
    r = b - A @ x
    res = np.linalg.norm(r)
    if not np.isfinite(res):
        return None
    best, best_res = x, res
    z = M(r)
    p = z.copy()
    rz = r @ z
    its = 0
    while res > DIRECT_TOL * bnorm and its < max_iterations:
        its += 1
        q = A @ p
        pq = p @ q
        if not pq > 0.0:
            break
        alpha = rz / pq
        x = x + alpha * p
        r -= alpha * q
        res = np.linalg.norm(r)
        if res < best_res:
            best, best_res = x, res
        elif exact:
            break                                    # round-off level reached
        if res <= DIRECT_TOL * bnorm:
            break
        z = M(r)
        rz_new = r @ z
        p = z + (rz_new / rz) * p
        rz = rz_new
    if best_res > DIRECT_TOL * bnorm:               # the recursive residual may drift: check
        true_res = np.linalg.norm(b - A @ best)
        if not (true_res <= DIRECT_TOL * bnorm or (exact and true_res <= 1e-6 * bnorm)):
            return None
    return best, its


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


# --------------------------------------------------------------------------- conjugate gradients


@njit(cache=True)
def _csr_matvec(indptr, indices, data, x, out):
    """out = A x.  indices unsigned (no negative-index wraparound code) and four partial
    sums per row (no single dependency chain): as fast as scipy's, twice the naive loop."""
    for i in range(out.size):
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        a3 = 0.0
        k = indptr[i]
        end = indptr[i + 1]
        while k + 3 < end:
            a0 += data[k] * x[indices[k]]
            a1 += data[k + 1] * x[indices[k + 1]]
            a2 += data[k + 2] * x[indices[k + 2]]
            a3 += data[k + 3] * x[indices[k + 3]]
            k += 4
        while k < end:
            a0 += data[k] * x[indices[k]]
            k += 1
        out[i] = (a0 + a1) + (a2 + a3)


def _unsigned(indices):
    """The same index array viewed as unsigned (indices are never negative)."""
    return indices.view(np.uint32 if indices.dtype.itemsize == 4 else np.uint64)


@njit(cache=True)
def _ic0_factor(indptr, indices, data, shift):
    """IC(0) on the lower triangle of a symmetric CSR with sorted indices.

    Returns (Lp, Li, Lv, inv_diag, ok): the strictly lower part of L in CSR and
    1 / diag(L); ok is False when a pivot is not positive or a diagonal entry is
    missing.  The diagonal of A is scaled by (1 + shift).
    """
    n = indptr.size - 1
    Lp = np.zeros(n + 1, np.int64)
    for i in range(n):
        c = 0
        for k in range(indptr[i], indptr[i + 1]):
            if indices[k] < i:
                c += 1
        Lp[i + 1] = Lp[i] + c
    Li = np.empty(Lp[n], indices.dtype)
    Lv = np.empty(Lp[n])
    inv_diag = np.empty(n)
    w = np.zeros(n)
    mark = np.full(n, -1, np.int64)
    for i in range(n):
        p = Lp[i]
        diag = 0.0
        has_diag = False
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            if j < i:
                Li[p] = j
                w[j] = data[k]
                mark[j] = i
                p += 1
            elif j == i:
                diag = data[k] * (1.0 + shift)
                has_diag = True
        if not has_diag:
            return Lp, Li, Lv, inv_diag, False
        for p in range(Lp[i], Lp[i + 1]):       # l_ik = (a_ik - sum_j<k l_ij l_kj) / l_kk, k ascending
            k = Li[p]
            s = w[k]
            for q in range(Lp[k], Lp[k + 1]):
                j = Li[q]
                if mark[j] == i:
                    s -= w[j] * Lv[q]
            s *= inv_diag[k]
            w[k] = s
            Lv[p] = s
            diag -= s * s
        if not diag > 0.0:
            return Lp, Li, Lv, inv_diag, False
        inv_diag[i] = 1.0 / np.sqrt(diag)
    return Lp, Li, Lv, inv_diag, True


def jacobi_factor(diagonal, index_dtype=np.uint32):
    """Jacobi as an IC factor with no off-diagonal entries: L = diag(A)^(1/2), so one CG loop serves both."""
    n = diagonal.size
    return np.zeros(n + 1, np.int64), np.empty(0, index_dtype), np.empty(0), 1.0 / np.sqrt(diagonal)


def ic0(A):
    """IC(0) factor (Lp, Li, Lv, inv_diag) of a canonical CSR A, shifting the diagonal on breakdown; None if all fail."""
    for shift in _IC_SHIFTS:
        Lp, Li, Lv, inv_diag, ok = _ic0_factor(A.indptr, _unsigned(A.indices), A.data, shift)
        if ok:
            return Lp, Li, Lv, inv_diag
    return None


@njit(cache=True)
def _ic_apply(Lp, Li, Lv, inv_diag, r, z):
    """z = (L L^T)^-1 r."""
    n = r.size
    for i in range(n):
        a0 = 0.0
        a1 = 0.0
        p = Lp[i]
        end = Lp[i + 1]
        while p + 1 < end:
            a0 += Lv[p] * z[Li[p]]
            a1 += Lv[p + 1] * z[Li[p + 1]]
            p += 2
        if p < end:
            a0 += Lv[p] * z[Li[p]]
        z[i] = (r[i] - (a0 + a1)) * inv_diag[i]
    for i in range(n - 1, -1, -1):
        zi = z[i] * inv_diag[i]
        z[i] = zi
        for p in range(Lp[i], Lp[i + 1]):
            z[Li[p]] -= Lv[p] * zi


@njit(cache=True)
def _pcg(indptr, indices, data, b, Lp, Li, Lv, inv_diag, x, tol, max_iterations):
    """CG preconditioned by (L L^T)^-1 (IC(0), or Jacobi: see jacobi_factor) in place on x;
    (iterations, status 0 ok / 1 cap / -1 breakdown).

    Written out in numba rather than scipy's cg: small BLAS calls on tiny vectors cost
    more than the matvec when OpenBLAS threads share busy cores.
    """
    n = b.size
    r, z, p, q = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    _csr_matvec(indptr, indices, data, x, q)
    bnorm = 0.0
    for i in range(n):
        r[i] = b[i] - q[i]
        bnorm += b[i] * b[i]
    stop = tol * np.sqrt(bnorm)
    _ic_apply(Lp, Li, Lv, inv_diag, r, z)
    rz = 0.0
    rnorm = 0.0
    for i in range(n):
        p[i] = z[i]
        rz += r[i] * z[i]
        rnorm += r[i] * r[i]
    for it in range(max_iterations + 1):
        if np.sqrt(rnorm) <= stop:
            return it, 0
        if it == max_iterations:
            return it, 1
        _csr_matvec(indptr, indices, data, p, q)
        pq = 0.0
        for i in range(n):
            pq += p[i] * q[i]
        if not pq > 0.0:
            return it, -1
        alpha = rz / pq
        rnorm = 0.0
        for i in range(n):
            x[i] += alpha * p[i]
            r[i] -= alpha * q[i]
            rnorm += r[i] * r[i]
        _ic_apply(Lp, Li, Lv, inv_diag, r, z)
        rz_new = 0.0
        for i in range(n):
            rz_new += r[i] * z[i]
        beta = rz_new / rz
        rz = rz_new
        for i in range(n):
            p[i] = z[i] + beta * p[i]
    return max_iterations, 1


def _scipy_cg(A, b, x0, tol, max_iterations, M):
    count = [0]

    def callback(_):
        count[0] += 1

    x, info = spla.cg(A, b, x0=x0, rtol=tol, maxiter=max_iterations, M=M, callback=callback)
    if info < 0:
        raise TensormassError("linear solve (cg) broke down: the system matrix is not positive definite")
    return x, count[0], info == 0


def _amg(A):
    return _pyamg.smoothed_aggregation_solver(A.tocsr()).aspreconditioner()


_warm = set()


def warm_up(index_dtype=np.int32, pointer_dtype=np.int32) -> None:
    """Load (or compile) the numba loops of every solver path for these index types, once per
    process: setup time, like the kernels' and the scatter loops' warm-up, not the first solve."""
    key = (np.dtype(index_dtype).str, np.dtype(pointer_dtype).str)
    if key in _warm:
        return
    A = sp.csr_matrix((np.array([2.0, -1.0, -1.0, 2.0]), np.array([0, 1, 0, 1], dtype=index_dtype),
                       np.array([0, 2, 4], dtype=pointer_dtype)), shape=(2, 2))
    b = np.array([1.0, 0.5])
    for method, preconditioner in (("band", "ic"), ("cg", "ic"), ("cg", "jacobi")):
        LinearSolver(method, preconditioner=preconditioner, reuse=False).solve(A, b)
    _warm.add(key)


class ConstrainedSystem:
    """Dirichlet conditions by elimination on a fixed global CSR pattern.

    The free/free and free/fixed blocks are gathered from the global data with
    index maps computed once: A_ff x_f = b_f - A_fc x_c.
    """

    def __init__(self, pattern, free: np.ndarray, fixed: np.ndarray):
        self.pattern, self.free, self.fixed = pattern, free, fixed
        self.ff = pattern.submatrix_map(free, free)
        self.fc = pattern.submatrix_map(free, fixed) if fixed.size else None
        if free.size:
            _, indices, indptr, _ = self.ff
            warm_up(indices.dtype, indptr.dtype)

    @staticmethod
    def _block(data, block):
        entries, indices, indptr, shape = block
        return sp.csr_matrix((data[entries], indices, indptr), shape=shape)

    def solve(self, solver: LinearSolver, data: np.ndarray, b: np.ndarray, x_c=None, x0=None):
        """Full x with x[fixed] = x_c (zero if None) and A x = b on the free rows; (x, iterations)."""
        x = np.zeros(self.pattern.n_dofs)
        rhs = b[self.free]
        if x_c is not None and self.fc is not None and np.any(x_c):
            x[self.fixed] = x_c
            rhs = rhs - self._block(data, self.fc) @ x_c
        guess = None if x0 is None else x0[self.free]
        x[self.free], its = solver.solve(self._block(data, self.ff), rhs, guess)
        return x, its
