"""Linear solvers for the free dofs: sparse direct (CHOLMOD or SuperLU) and preconditioned CG.

    solver = LinearSolver("auto", tol=1e-8, max_iterations=1000)
    x, iterations = solver.solve(A, b)          # iterations: CG steps, 1 for a direct solve

Dirichlet conditions are applied by elimination before calling these (see
`ConstrainedSystem`): K_ff x_f = r_f - K_fc x_c.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from .errors import TensormassError

__all__ = ["LinearSolver", "ConstrainedSystem", "DIRECT_LIMIT", "has_cholmod", "has_pyamg"]

# Above this many unknowns "auto" switches from a direct factorisation to CG.
DIRECT_LIMIT = 200_000

try:                                    # optional accelerators (pip install tensormass[fast])
    from sksparse import cholmod as _cholmod
except ImportError:                     # pragma: no cover - depends on the environment
    _cholmod = None
try:
    import pyamg as _pyamg
except ImportError:                     # pragma: no cover
    _pyamg = None


def has_cholmod() -> bool:
    return _cholmod is not None


def has_pyamg() -> bool:
    return _pyamg is not None


class LinearSolver:
    """Solve A x = b for a sparse symmetric A: "direct", "cg" or "auto".

    preconditioner for CG: "jacobi" (default) or "amg" (smoothed aggregation,
    only when pyamg imports; Jacobi otherwise).  A CG run that hits the
    iteration cap returns its last iterate (an inexact Newton step, like the
    thesis' fixed 20 iterations); `self.converged` says whether it met tol.
    """

    def __init__(self, method: str = "auto", tol: float = 1e-8, max_iterations: int = 1000,
                 preconditioner: str = "jacobi"):
        if method not in ("auto", "direct", "cg"):
            raise TensormassError(f"unknown linear solver {method!r}; use auto, direct or cg")
        self.method, self.tol, self.max_iterations = method, float(tol), int(max_iterations)
        self.preconditioner = preconditioner
        self.converged = True
        self.time = 0.0

    def kind_for(self, n: int) -> str:
        if self.method != "auto":
            return self.method
        return "direct" if n <= DIRECT_LIMIT else "cg"

    def solve(self, A: sp.csr_matrix, b: np.ndarray, x0: np.ndarray | None = None):
        """(x, iterations); raises TensormassError on a singular system or NaN/Inf."""
        start = time.perf_counter()
        try:
            if not np.all(np.isfinite(b)):
                raise TensormassError("linear solve: right-hand side contains NaN/Inf")
            if b.size == 0 or not np.any(b):
                return np.zeros_like(b), 0
            if self.kind_for(b.size) == "direct":
                x, its = _direct(A, b), 1
            else:
                x, its, self.converged = _cg(A, b, x0, self.tol, self.max_iterations, self.preconditioner)
            if not np.all(np.isfinite(x)):
                raise TensormassError("linear solve produced NaN/Inf: the system matrix is singular or "
                                      "badly conditioned (is every rigid motion fixed? inverted elements?)")
            return x, its
        finally:
            self.time += time.perf_counter() - start


def _direct(A, b):
    """CHOLMOD for SPD matrices when available, SuperLU otherwise (or when not SPD)."""
    if _cholmod is not None:
        try:
            return _cholmod.cholesky(A.tocsc())(b)
        except _cholmod.CholmodNotPositiveDefiniteError:
            pass                                  # indefinite: LU below
    try:
        # symmetric pattern: minimum degree on A^T + A beats COLAMD by far
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


def _cg(A, b, x0, tol, max_iterations, preconditioner):
    if preconditioner == "amg" and _pyamg is not None:
        return _scipy_cg(A, b, x0, tol, max_iterations, _amg(A))
    d = A.diagonal()
    if np.any(d <= 0):
        raise TensormassError("cg needs a positive diagonal; the system matrix is not positive definite "
                              "(use linear = 'direct' or enable project_psd)")
    A = A.tocsr()
    x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
    its, status = _jacobi_pcg(A.indptr, A.indices, A.data, b, 1.0 / d, x, tol, max_iterations)
    if status < 0:
        raise TensormassError("linear solve (cg) broke down: the system matrix is not positive definite "
                              "(use linear = 'direct' or enable project_psd)")
    return x, its, status == 0


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
