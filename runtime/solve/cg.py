"""Conjugate gradients: IC(0) and Jacobi preconditioned CG in numba, and factor-preconditioned refinement.

    x, its = refine(A, b, M, exact, max_iterations)   # CG preconditioned by a factor M ~ A^-1
    factor = ic0(A)                                   # incomplete Cholesky (or None)
    its, status = pcg(A.indptr, unsigned(A.indices), A.data, b, *factor, x, tol, max_iterations)
"""
from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla
from numba import njit

from ..base.errors import TensormassError

__all__ = ["refine", "ic0", "jacobi_factor", "pcg", "unsigned", "scipy_cg", "DIRECT_TOL", "REFINE_MAX", "reuse_iterations"]

# Relative residual a direct solve is refined to, and the refinement budget of a fresh factor.
DIRECT_TOL = 1e-10
REFINE_MAX = 30
# IC(0) breaks down on some SPD matrices: retry with these diagonal shifts, then use Jacobi.
_IC_SHIFTS = (0.0, 1e-3, 1e-2, 1e-1)
# A kept factor (band or PARDISO) preconditions CG on the next matrix of the same pattern (the
# next implicit step or Newton iteration) for at most REUSE_MAX iterations, and at most half of
# a new factorisation's modelled cost, before it is refactored.
REUSE_MAX = 20
REUSE_MIN = 3


def reuse_iterations(factor_seconds: float, iteration_seconds: float) -> int:
    """CG iterations a kept factor may precondition: as many as cost half a new factorisation
    by the cost model (never a timing), within [REUSE_MIN, REUSE_MAX]."""
    return int(min(REUSE_MAX, max(REUSE_MIN, 0.5 * factor_seconds / iteration_seconds)))


def refine(A, b, M, exact, max_iterations, tol=DIRECT_TOL):
    """CG on A x = b preconditioned by M ~ A^-1 (see _refine); overflow on a singular matrix is
    expected there (the caller checks the result), not worth a warning."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        return _refine(A, b, M, exact, max_iterations, tol)


def _refine(A, b, M, exact, max_iterations, tol):
    """CG on A x = b preconditioned by M ~ A^-1, from x = M b, to the relative residual tol
    (DIRECT_TOL unless a budgeted step asks for less: solver.factor_tolerance).

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
    if res <= tol * bnorm:
        return x, 0                                  # the factor's solve alone: no second solve for z
    best, best_res = x, res
    res0 = res
    z = M(r)
    p = z.copy()
    rz = r @ z
    its = 0
    while res > tol * bnorm and its < max_iterations:
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
        if res <= tol * bnorm:
            break
        if not exact and its >= 2 and _hopeless(res0, res, its, tol * bnorm, max_iterations):
            return None                              # a kept factor too far from A: refactor now
        z = M(r)
        rz_new = r @ z
        p = z + (rz_new / rz) * p
        rz = rz_new
    if best_res > tol * bnorm:               # the recursive residual may drift: check
        true_res = np.linalg.norm(b - A @ best)
        if not (true_res <= tol * bnorm or (exact and true_res <= 1e-6 * bnorm)):
            return None
    return best, its


def _hopeless(res0, res, its, target, max_iterations) -> bool:
    """Whether the mean contraction so far misses the target residual by far (twice the budget):
    a kept factor that clearly will not do is dropped after two iterations instead of
    max_iterations; a borderline one gets its whole budget (the same numbers give the same
    answer: no timing involved)."""
    if res >= res0:
        return True
    rate = (res / res0) ** (1.0 / its)
    needed = np.log(target / res) / np.log(rate)
    return its + needed > 2.0 * max_iterations


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


def unsigned(indices):
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
        Lp, Li, Lv, inv_diag, ok = _ic0_factor(A.indptr, unsigned(A.indices), A.data, shift)
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
def pcg(indptr, indices, data, b, Lp, Li, Lv, inv_diag, x, tol, max_iterations):
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


def scipy_cg(A, b, x0, tol, max_iterations, M):
    count = [0]

    def callback(_):
        count[0] += 1

    x, info = spla.cg(A, b, x0=x0, rtol=tol, maxiter=max_iterations, M=M, callback=callback)
    if info < 0:
        raise TensormassError("linear solve (cg) broke down: the system matrix is not positive definite")
    return x, count[0], info == 0
