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
           "has_cholmod", "has_pyamg"]

METHODS = ("auto", "direct", "cg", "band", "cholmod", "lu")
PRECONDITIONERS = ("ic", "jacobi", "amg")

# --------------------------------------------------------------------------- thresholds
#
# Measured on the 2-core AMD EPYC (AVX-512) this project benchmarks on, shared with
# other jobs, best of 3-5 (`tensormass bench steps` and the matrices it builds):
#
#   system (free dofs, nnz, bandwidth kd)      band32   band64   SuperLU   CG-Jacobi   CG-IC(0)
#   3072-hex neo-Hookean K (11 664, 0.80 M, 296)   ~27 ms   ~37 ms   300 ms   185 ms/210 it  190 ms/112 it
#   10k-tet StVK implicit Euler (6 552, 0.26 M, 278) ~14 ms  ~22 ms   118 ms    64 ms/220 it   42 ms/73 it
#   20k-hex StVK implicit Euler (64 980, 4.8 M, 1145) ~1.4 s  ~2.7 s    16 s     1.2 s/217 it   0.9 s/69 it
#
# (band32: float32 LAPACK factor + CG refinement to 1e-10; one BLAS thread: with two
# OpenBLAS threads on the shared cores spbtrf/dpbtrf ran 5-10x slower.)  The band
# factor costs about n kd^2 / 4e10 s and CG-IC(0) about 150 iterations' worth of
# matrix-vector products, 150 nnz x 1.1 ns; "auto" takes the band Cholesky when
# n kd^2 <= AUTO_BAND_WORK_PER_NNZ x nnz (3072 hexes: 0.9e9 <= 7e9, 10k tets:
# 0.5e9 <= 2.3e9, 20k hexes: 85e9 > 39e9 -> CG), always below AUTO_DIRECT_BELOW dofs.
AUTO_BAND_WORK_PER_NNZ = 8_000.0
AUTO_DIRECT_BELOW = 3_000
# "direct" prefers CHOLMOD (scikit-sparse, when installed; fill-reducing orderings beat a
# band on compact 3D bodies) once the band factor would cost more than this (~0.1 s).
DIRECT_BAND_WORK_CHOLMOD = 5e9
# The band factor is refused (SuperLU instead) beyond this many float64 band entries (2 GiB).
BAND_MAX_ENTRIES = 2**28
# Relative residual the band Cholesky refines to, and its refinement budget.
DIRECT_TOL = 1e-10
_REFINE_MAX = 30
# Kept for compatibility: above this many unknowns "auto" never factorises.
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


class _BandPlan:
    """A bandwidth-reducing ordering of one sparsity pattern."""

    def __init__(self, A):
        self.indptr, self.indices = A.indptr, A.indices
        self.n = A.shape[0]
        self.perm, self.iperm, self.kd = band_ordering(A)
        self.work = float(self.n) * float(self.kd) ** 2
        self.entries = (self.kd + 1) * self.n

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
    """

    def __init__(self, method: str = "auto", tol: float = 1e-8, max_iterations: int = 1000,
                 preconditioner: str = "ic"):
        if method not in METHODS:
            raise TensormassError(f"unknown linear solver {method!r}; use {', '.join(METHODS)}")
        if preconditioner not in PRECONDITIONERS:
            raise TensormassError(f"unknown preconditioner {preconditioner!r}; use {', '.join(PRECONDITIONERS)}")
        self.method, self.tol, self.max_iterations = method, float(tol), int(max_iterations)
        self.preconditioner = preconditioner
        self.converged = True
        self.time = 0.0
        self.last = None
        self._plan = None

    # -- choice -------------------------------------------------------------------------------
    def plan(self, A) -> _BandPlan:
        """The band ordering of A's pattern (computed once per pattern)."""
        if self._plan is None or not self._plan.matches(A):
            self._plan = _BandPlan(A)
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
            x = _band_solve(A, b, self.plan(A))
            if x is not None:
                self.last = x[1]
                return x[0]
        elif kind == "cholmod" and _cholmod is not None:
            try:
                x = _cholmod.cholesky(A.tocsc())(b)
                if np.all(np.isfinite(x)):
                    self.last = "cholmod"
                    return x
            except Exception:                       # not positive definite (or CHOLMOD failed): LU
                pass
        self.last = "lu"
        return _lu(A, b)

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
        if factor is not None:
            self.last = "cg-ic"
            its, status = _ic_pcg(A.indptr, A.indices, A.data, b, *factor, x, self.tol, self.max_iterations)
        else:
            self.last = "cg-jacobi"
            its, status = _jacobi_pcg(A.indptr, A.indices, A.data, b, 1.0 / d, x, self.tol, self.max_iterations)
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


def _band_solve(A, b, plan):
    """Banded Cholesky in float32 then float64, refined by factor-preconditioned CG.

    Returns (x, "band32" | "band64"), or None when A is not positive definite
    (the caller falls back to LU).
    """
    perm, iperm, kd, n = plan.perm, plan.iperm, plan.kd, plan.n
    with _one_blas_thread():
        for dtype, factor, trs in ((np.float32, lapack.spbtrf, lapack.spbtrs),
                                   (np.float64, lapack.dpbtrf, lapack.dpbtrs)):
            ab = np.empty((kd + 1, n), dtype=dtype, order="F")
            _fill_band(A.indptr, A.indices, A.data, iperm, ab)
            c, info = factor(ab, lower=1, overwrite_ab=1)
            del ab
            if info != 0:
                continue                            # not positive definite (in this precision)

            def precondition(r, c=c, trs=trs, dtype=dtype):
                y, _ = trs(c, r[perm].astype(dtype), lower=1, overwrite_b=1)
                z = np.empty(n)
                z[perm] = y
                return z

            x = _refine(A, b, precondition, exact=dtype is np.float64)
            if x is not None:
                return x, "band32" if dtype is np.float32 else "band64"
    return None


def _refine(A, b, M, exact):
    """CG on A x = b preconditioned by M ~ A^-1, from x = M b, to DIRECT_TOL.

    exact (M is a float64 factor): the first iterate is already a direct solve;
    refinement only polishes it and stops when the residual stops dropping.
    Returns None when the iteration does not converge (or breaks down).
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
    for _ in range(_REFINE_MAX):
        if res <= DIRECT_TOL * bnorm:
            return x
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
        z = M(r)
        rz_new = r @ z
        p = z + (rz_new / rz) * p
        rz = rz_new
    true_res = np.linalg.norm(b - A @ best)
    if true_res <= DIRECT_TOL * bnorm or (exact and true_res <= 1e-6 * bnorm):
        return best
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
    The smallest bandwidth wins.
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
    for i in range(out.size):
        acc = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            acc += data[k] * x[indices[k]]
        out[i] = acc


@njit(cache=True)
def _jacobi_pcg(indptr, indices, data, b, inv_diag, x, tol, max_iterations):
    """Jacobi-preconditioned CG in place on x; (iterations, status 0 ok / 1 cap / -1 breakdown).

    Written out in numba rather than scipy's cg: small BLAS calls on tiny
    vectors cost more than the matvec when OpenBLAS threads share busy cores.
    """
    n = b.size
    r, z, p, q = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    _csr_matvec(indptr, indices, data, x, q)
    bnorm = 0.0
    for i in range(n):
        r[i] = b[i] - q[i]
        bnorm += b[i] * b[i]
    stop = tol * np.sqrt(bnorm)
    rz = 0.0
    for i in range(n):
        z[i] = inv_diag[i] * r[i]
        p[i] = z[i]
        rz += r[i] * z[i]
    for it in range(max_iterations + 1):
        rnorm = 0.0
        for i in range(n):
            rnorm += r[i] * r[i]
        if np.sqrt(rnorm) <= stop:
            return it, 0
        if it == max_iterations:
            return it, 1
        _csr_matvec(indptr, indices, data, p, q)
        pq = 0.0
        for i in range(n):
            pq += p[i] * q[i]
        if pq <= 0.0:
            return it, -1
        alpha = rz / pq
        rz_new = 0.0
        for i in range(n):
            x[i] += alpha * p[i]
            r[i] -= alpha * q[i]
            z[i] = inv_diag[i] * r[i]
            rz_new += r[i] * z[i]
        beta = rz_new / rz
        rz = rz_new
        for i in range(n):
            p[i] = z[i] + beta * p[i]
    return max_iterations, 1


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


def ic0(A):
    """IC(0) factor (Lp, Li, Lv, inv_diag) of a canonical CSR A, shifting the diagonal on breakdown; None if all fail."""
    for shift in _IC_SHIFTS:
        Lp, Li, Lv, inv_diag, ok = _ic0_factor(A.indptr, A.indices, A.data, shift)
        if ok:
            return Lp, Li, Lv, inv_diag
    return None


@njit(cache=True)
def _ic_apply(Lp, Li, Lv, inv_diag, r, z):
    """z = (L L^T)^-1 r."""
    n = r.size
    for i in range(n):
        s = r[i]
        for p in range(Lp[i], Lp[i + 1]):
            s -= Lv[p] * z[Li[p]]
        z[i] = s * inv_diag[i]
    for i in range(n - 1, -1, -1):
        zi = z[i] * inv_diag[i]
        z[i] = zi
        for p in range(Lp[i], Lp[i + 1]):
            z[Li[p]] -= Lv[p] * zi


@njit(cache=True)
def _ic_pcg(indptr, indices, data, b, Lp, Li, Lv, inv_diag, x, tol, max_iterations):
    """IC(0)-preconditioned CG in place on x; (iterations, status 0 ok / 1 cap / -1 breakdown)."""
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


class ConstrainedSystem:
    """Dirichlet conditions by elimination on a fixed global CSR pattern.

    The free/free and free/fixed blocks are gathered from the global data with
    index maps computed once: A_ff x_f = b_f - A_fc x_c.
    """

    def __init__(self, pattern, free: np.ndarray, fixed: np.ndarray):
        self.pattern, self.free, self.fixed = pattern, free, fixed
        self.ff = pattern.submatrix_map(free, free)
        self.fc = pattern.submatrix_map(free, fixed) if fixed.size else None

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
