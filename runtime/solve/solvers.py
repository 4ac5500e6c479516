"""Linear solvers for the free dofs: PARDISO, banded Cholesky, SuperLU, and CG (IC(0) or multigrid).

    solver = LinearSolver("auto", tol=1e-8, max_iterations=1000)
    x, iterations = solver.solve(A, b)          # iterations: CG steps, 1 for a direct solve
    solver.last                                 # what solved it: "pardiso32", "band32", "lu", "cg-ic", "cg-amg", ...
    solver.inertia                              # (positive, negative) pivots of the last factor, when known

Methods:
  "direct"   the cheapest factorisation for the matrix by the cost model below: PARDISO
             (runtime/solve/pardiso.py, MKL's nested-dissection LDL^T) on compact bodies, the banded
             Cholesky (runtime/solve/band.py) on bars and slabs; SuperLU where neither is there;
  "auto"     "direct", or CG with algebraic multigrid past the size where a factor costs more
             (memory or modelled time) than multigrid; without MKL, band or IC(0)-CG as before;
  "cg"       CG preconditioned by IC(0) (or the `preconditioner`: "jacobi", "amg");
  "amg"      CG preconditioned by smoothed-aggregation multigrid with the rigid-body
             near-nullspace (runtime/solve/amg.py; `ConstrainedSystem` passes the modes);
  "band", "pardiso", "lu": one direct solver by name.

Indefinite matrices never fail a run by themselves: PARDISO factors them (symmetric
indefinite pivoting, and reports the inertia), the band path hands them to PARDISO or
SuperLU, and a CG that breaks down (or meets a non-positive diagonal) falls back to the
direct solver (`fallback` says why).  Newton (runtime.physics.integrators) reads the direction it
gets and switches on PSD projection where it does not descend.

Factor reuse: a kept band or PARDISO factor first preconditions CG on the next matrix of the
same pattern (the next Newton iteration or implicit step), for at most as many iterations
as cost half a new factorisation by the cost model; `last` then ends in "-reuse".

Every decision (which solver, reuse or refactor, how many iterations) comes from the
matrix's size, pattern and values, never from measured times or the thread count: the same
sequence of systems gives the same bits on an idle or a loaded machine, with one thread or
two (issue #10; PARDISO runs in MKL's reproducible mode).  Times are only reported.

Dirichlet conditions are applied by elimination before calling these (see
`ConstrainedSystem`): K_ff x_f = r_f - K_fc x_c.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import amg, pardiso
from .choices import (AUTO_BAND_WORK_PER_NNZ, AUTO_DIRECT_BELOW, DIRECT_LIMIT, PARDISO_ANALYSE_ABOVE,
                      PARDISO_FLOPS)
from .band import (BAND_MAX_ENTRIES, BandPlan, band_costs, band_ordering, band_solve, one_blas_thread,
    reuse_cap)
from .cg import DIRECT_TOL, REFINE_MAX, ic0, jacobi_factor, pcg, refine, reuse_iterations, unsigned
from ..base.errors import TensormassError
from ..base.parallel import worker_threads

__all__ = ["LinearSolver", "ConstrainedSystem", "DIRECT_LIMIT", "METHODS", "PRECONDITIONERS",
           "has_pardiso", "has_pyamg", "unavailable", "warm_up", "band_ordering", "band_costs", "reuse_cap",
           "pardiso_costs", "amg_cost"]

METHODS = ("auto", "direct", "cg", "amg", "band", "pardiso", "lu")
PRECONDITIONERS = ("ic", "jacobi", "amg")

# --------------------------------------------------------------------------- the cost model
#
# Modelled seconds on the benchmark machine (2-core AMD EPYC, one thread), from the pattern
# alone: the same matrices get the same decisions on any load and any thread count.
#
# Measured, one fresh solve each (analysis + factor; band: its factor + refinement):
#   system (free dofs, nnz, kd, PARDISO factor flops)        band32    PARDISO 32-bit    SuperLU  IC-CG
#   10k-tet StVK bar (6 552, 0.26 M, 278, 0.49 G)             14 ms*   21 + 21 ms       114 ms*   30 ms*
#   3072-hex bar (11 664, 0.80 M, 275, 1.3 G)                 48 ms    48 + 47 ms       294 ms*  132 ms*
#   20k-hex bar (64 980, 4.8 M, 1145, 53 G)                  1.6 s     0.40 + 1.4 s      16 s*   0.6 s*
#   tetra organ h 6 mm (9 819, 0.39 M, 863, 1.3 G)            133 ms   37 + 40 ms        0.67 s    68 ms
#   tetra10 organ h 8 mm (34 434, 2.6 M, 3677, 18 G)         8.2 s    0.29 + 0.81 s        -     1.3 s
#   tetra10 organ h 6 mm (77 085, 6.0 M, 6713, 105 G)         58 s    0.48 + 1.4 s (2 threads)
# (* session 3's `bench steps` measurements; the organ: tensormass.apps.organ_mesh scaled 2.2x,
# liver-sized, `tensormass bench organ`.)
# PARDISO's factor runs at 24-37 Gflop/s in single precision on one thread (13-20 in double),
# its solve streams the factor: ~2.2e-9 s per factor entry (single), its analysis (nested
# dissection, once per pattern) ~1.6e-7 s per stored entry.  Multigrid-CG (pyamg, rigid-body
# modes): setup ~4e-7 s and ~2.5e-8 s per iteration per stored entry, ~40 iterations.
PARDISO_OVERHEAD = 2e-3
PARDISO_SOLVE_PER_ENTRY = 2.2e-9     # per factor entry, single precision (double: 1.5x)
PARDISO_MAX_BYTES = 8 * 2**30        # "auto" takes multigrid past this factor memory
# Smaller systems factor on one thread: on 2 shared cores a second OpenMP thread made the
# 9 819-dof organ's 1.3 Gflop factor slower (40 -> 77 ms idle, 0.10 -> 0.18 s loaded); the
# 34 434-dof one's 18 Gflop ran 2.4x faster.  Decided from the size before the analysis: a
# handle keeps one thread count (analysing on two threads and factoring on one crashed MKL
# 2026.2 on an implicit Euler matrix).  Bits do not depend on it (MKL's reproducible mode).
PARDISO_PARALLEL_DOFS = 15_000
AMG_SECONDS_PER_NNZ = 4e-7 + 40 * 2.5e-8
# An AMG hierarchy is reused on later matrices of the pattern until CG needs more than this
# many times the iterations it took when it was built (plus a margin): then it is rebuilt.
AMG_REBUILD_RATIO = 2.0
AMG_REBUILD_MARGIN = 10


def unavailable(method: str) -> str | None:
    """Why the linear solver `method` cannot run here (None: it can)."""
    if method == "pardiso" and not pardiso.available():
        return pardiso.unavailable_reason() or "MKL's PARDISO is not available"
    if method == "amg" and not amg.available():
        return "pyamg is not installed (pip install pyamg)"
    return None


def has_pardiso() -> bool:
    return pardiso.available()


def has_pyamg() -> bool:
    return amg.available()


def pardiso_costs(flops: float, factor_nnz: float, single: bool = True) -> tuple[float, float]:
    """(factorisation, one solve) of PARDISO in modelled seconds, from its analysis' statistics."""
    slower = 1.0 if single else 2.0
    return (PARDISO_OVERHEAD + slower * flops / PARDISO_FLOPS,
            (1.0 if single else 1.5) * PARDISO_SOLVE_PER_ENTRY * factor_nnz + 25e-6)


def amg_cost(nnz: int) -> float:
    """Modelled seconds of one multigrid-preconditioned CG solve (setup included)."""
    return AMG_SECONDS_PER_NNZ * float(nnz)


def _worker_threads() -> int:
    """The runtime's thread count (tests replace it to try PARDISO's thread choice)."""
    return int(worker_threads())


# --------------------------------------------------------------------------- per pattern


class _Pattern:
    """What is computed once per sparsity pattern: the band ordering and PARDISO's analysis (lazily)."""

    def __init__(self, A):
        self.indptr, self.indices = A.indptr, A.indices
        self.n, self.nnz = A.shape[0], int(A.nnz)
        self._band = None
        self._pardiso = None

    def matches(self, A) -> bool:
        if A.shape[0] != self.n:
            return False
        if A.indices is self.indices and A.indptr is self.indptr:
            return True
        return (A.indices.size == self.indices.size and np.array_equal(A.indptr, self.indptr)
                and np.array_equal(A.indices, self.indices))

    def band(self, A) -> BandPlan:
        if self._band is None:
            self._band = BandPlan(A)
        return self._band

    def band_seconds(self, A) -> float:
        """Modelled seconds of a band solve (factor + a few refinement iterations)."""
        plan = self.band(A)
        if plan.entries > BAND_MAX_ENTRIES:
            return np.inf
        factor, iteration = band_costs(plan.n, plan.kd, plan.nnz)
        return factor + 3.0 * iteration

    def pardiso(self, A) -> "_PardisoPlan":
        if self._pardiso is None:
            self._pardiso = _PardisoPlan(A)
        return self._pardiso


class _PardisoPlan:
    """PARDISO for one pattern: the upper-triangle entries of A and two handles (float32 first,
    float64 on demand), each analysed once.  `stats`: the analysis' flops, factor size, memory."""

    def __init__(self, A):
        rows = np.repeat(np.arange(A.shape[0], dtype=np.int64), np.diff(A.indptr))
        self.upper = np.flatnonzero(A.indices >= rows)                    # A is canonical CSR
        counts = np.bincount(rows[self.upper], minlength=A.shape[0])
        self.indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
        self.indices = A.indices[self.upper].astype(np.int32)
        self.n = A.shape[0]
        self.handles = {}
        self.stats = self.handle(True).statistics()

    def handle(self, single: bool) -> pardiso.Pardiso:
        if single not in self.handles:
            threads = _worker_threads() if self.n >= PARDISO_PARALLEL_DOFS else 1
            h = pardiso.Pardiso(self.n, self.indptr, self.indices, single=single, threads=threads)
            h.analyse()
            self.handles[single] = h
        return self.handles[single]


    def costs(self, single: bool = True) -> tuple[float, float]:
        return pardiso_costs(self.stats["factor_flops"], self.stats["factor_nnz"], single)


class _PardisoFactor:
    """A PARDISO factor of one matrix; calling it applies A^-1 (in the factor's precision)."""

    def __init__(self, plan: _PardisoPlan, single: bool):
        self.plan, self.single = plan, single
        self.handle = plan.handle(single)
        self.name = "pardiso32" if single else "pardiso64"
        self.reuse_cap = reuse_iterations(*plan.costs(single))

    def factor(self, A) -> tuple[int, int]:
        self.handle.factor(A.data[self.plan.upper])
        return self.handle.inertia

    def __call__(self, r):
        return self.handle.solve(r)


# --------------------------------------------------------------------------- the solver


class LinearSolver:
    """Solve A x = b for a sparse symmetric A; see the module docstring for the methods.

    preconditioner for "cg": "ic" (default: incomplete Cholesky IC(0), with a diagonal
    shift if it breaks down, Jacobi if it still does), "jacobi" or "amg".  A CG run that
    hits the iteration cap returns its last iterate (an inexact Newton step, like the
    thesis' fixed 20 iterations); `self.converged` says whether it met tol.

    reuse: keep the band / PARDISO factor (and the multigrid hierarchy) for the next
    matrix of the same pattern (see the module docstring).
    factor_tol: the relative residual CG refines a factor's solve to: a fresh PARDISO factor, or a kept
    band or PARDISO factor (DIRECT_TOL; a budgeted step takes less: solver.factor_tolerance).
    near_nullspace: (n, k) rigid-body modes of the unknowns for multigrid (set by
    ConstrainedSystem), or None.
    time: seconds spent in solve, reported only (no decision reads it).
    """

    def __init__(self, method: str = "auto", tol: float = 1e-8, max_iterations: int = 1000,
                 preconditioner: str = "ic", reuse: bool = True, factor_tol: float = DIRECT_TOL):
        if method not in METHODS:
            raise TensormassError(f"unknown linear solver {method!r}; use {', '.join(METHODS)}")
        if preconditioner not in PRECONDITIONERS:
            raise TensormassError(f"unknown preconditioner {preconditioner!r}; use {', '.join(PRECONDITIONERS)}")
        if method == "pardiso" and not pardiso.available():
            raise TensormassError(f"linear solver 'pardiso' is unavailable: {pardiso.unavailable_reason()}")
        self.method, self.tol, self.max_iterations = method, float(tol), int(max_iterations)
        self.factor_tol = float(factor_tol)      # relative residual a factor's solve is refined to
        self.preconditioner = preconditioner
        self.converged = True
        self.time = 0.0                          # statistics only: never an input to a decision
        self.last = None
        self.fallback = None                     # why the last solve left the chosen solver, if it did
        self.inertia = None                      # (positive, negative) pivots of the last PARDISO factor
        self.counts = {}                         # solves per `last` value (reported by runs)
        self.reuse = bool(reuse)
        self.near_nullspace = None
        self._pattern = None
        self._choice = None                      # (pattern, method) -> kind, cached per pattern
        self._factor = None                      # last band / PARDISO factor (reuse)
        self._skip_reuse = 0                     # calls left that refactor without trying reuse
        self._reuse_backoff = 0
        self._amg = None                         # (hierarchy, iterations when built)

    # -- choice -------------------------------------------------------------------------------
    def pattern(self, A) -> _Pattern:
        """What is kept for A's sparsity pattern (computed once per pattern)."""
        if self._pattern is None or not self._pattern.matches(A):
            self._pattern = _Pattern(A)
            self._factor = self._amg = self._choice = self.inertia = None
        return self._pattern

    def plan(self, A) -> BandPlan:
        """The band ordering of A's pattern."""
        return self.pattern(A).band(A)

    def choose(self, A) -> str:
        """The solver "solve" uses for A: "band", "pardiso", "lu", "cg" or "amg" (cached per pattern)."""
        pattern = self.pattern(A)
        if self._choice is None:
            self._choice = self._choose(A, pattern)
        return self._choice

    def _choose(self, A, pattern) -> str:
        method, n = self.method, A.shape[0]
        if method == "cg" and self.preconditioner == "amg":
            return "amg" if amg.available() else "cg"
        if method in ("band", "pardiso", "lu", "cg"):
            return method
        if method == "amg":
            return "amg" if amg.available() else "cg"
        if n <= AUTO_DIRECT_BELOW:
            return "band"
        if not pardiso.available():                       # the rules from before MKL
            plan = pattern.band(A)
            if method == "auto" and (n > DIRECT_LIMIT or plan.entries > BAND_MAX_ENTRIES
                                     or plan.work > AUTO_BAND_WORK_PER_NNZ * A.nnz):
                return "cg"
            return "band" if plan.entries <= BAND_MAX_ENTRIES else "lu"
        if method == "auto" and n > DIRECT_LIMIT:
            return "amg" if amg.available() else "cg"
        band = pattern.band_seconds(A)
        if band <= PARDISO_ANALYSE_ABOVE:
            return "band"
        plan = pattern.pardiso(A)
        factor, solve = plan.costs(single=True)
        if band <= factor + 3.0 * solve:
            return "band"
        if method == "auto" and amg.available() and (plan.stats["memory_bytes"] > PARDISO_MAX_BYTES
                                                     or factor > amg_cost(A.nnz)):
            return "amg"
        return "pardiso"

    def kind_for(self, A) -> str:
        """"direct" or "cg" (A: the matrix, or only its size for the fixed methods)."""
        if isinstance(A, (int, np.integer)):
            if self.method == "auto":
                return "direct" if A <= AUTO_DIRECT_BELOW else "cg"
            return "cg" if self.method in ("cg", "amg") else "direct"
        return "cg" if self.choose(A) in ("cg", "amg") else "direct"

    def warm_up(self, A) -> None:
        """Load (or compile, once per machine) the numba loops of the method chosen for A's pattern
        before the first solve: setup time, not the first step's.  A direct solve compiles no CG
        loops (the fallbacks of a breakdown compile theirs if they ever run); A None: every path."""
        if A is None:
            warm_up()
            return
        kind = self.choose(A)
        if kind == "band":
            warm_up(A.indices.dtype, A.indptr.dtype, (("band", "ic"),))
        elif kind == "cg":
            warm_up(A.indices.dtype, A.indptr.dtype, (("cg", "jacobi" if self.preconditioner == "jacobi" else "ic"),))

    def drop_factor(self) -> None:
        """Factorise the next matrix afresh (a budgeted step's refresh), whatever reuse would do."""
        self._factor, self._skip_reuse, self._reuse_backoff = None, 0, 0

    # -- solve --------------------------------------------------------------------------------
    def solve(self, A, b: np.ndarray, x0: np.ndarray | None = None):
        """(x, iterations); raises TensormassError on a singular system or NaN/Inf."""
        start = time.perf_counter()
        self.fallback = None
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
            if not A.has_canonical_format:
                A = A.copy()
                A.sum_duplicates()
            kind = self.choose(A)
            if kind in ("cg", "amg"):
                x, its, self.converged = self._iterative(A, b, x0, kind)
            else:
                x, its = self._direct(A, b, kind), 1
                self.converged = True
            if not np.all(np.isfinite(x)):
                raise TensormassError("linear solve produced NaN/Inf: the system matrix is singular or "
                                      "badly conditioned (is every rigid motion fixed? inverted elements?)")
            key = self.last if self.fallback is None else f"{self.last} (after {kind} broke down)"
            self.counts[key] = self.counts.get(key, 0) + 1
            return x, its
        finally:
            self.time += time.perf_counter() - start

    def _iterative(self, A, b, x0, kind):
        """CG (IC(0)/Jacobi or multigrid); on breakdown (not positive definite) the direct solver."""
        try:
            if np.any(A.diagonal() <= 0):
                raise _Breakdown("a non-positive diagonal entry")
            return self._amg_cg(A, b, x0) if kind == "amg" else self._cg(A, b, x0)
        except _Breakdown as why:
            self.fallback = f"{kind} stopped ({why}: the matrix is not positive definite); solved directly"
            return self._direct(A, b, self._direct_kind(A)), 1, True

    def _direct_kind(self, A) -> str:
        if pardiso.available() and A.shape[0] > AUTO_DIRECT_BELOW:
            return "pardiso"
        return "band" if self.pattern(A).band(A).entries <= BAND_MAX_ENTRIES else "lu"

    def _direct(self, A, b, kind):
        if kind in ("band", "pardiso"):
            x = self._reused(A, b)
            if x is not None:
                return x
            self._factor = None
            x = self._band(A, b) if kind == "band" else self._pardiso(A, b)
            if x is not None:
                return x
            if kind == "band" and pardiso.available():      # not positive definite: LDL^T
                x = self._pardiso(A, b)
                if x is not None:
                    return x
        self._factor = None
        self.last = "lu"
        return _lu(A, b)

    def _reused(self, A, b):
        """CG preconditioned by the kept factor of this pattern, while that pays (cost model)."""
        old = self._factor
        if not (self.reuse and old is not None and old.plan is not None):
            return None
        if self._skip_reuse > 0:
            self._skip_reuse -= 1
            return None
        out = refine(A, b, old, exact=False, max_iterations=old.reuse_cap, tol=self.factor_tol)
        if out is not None:
            self._reuse_backoff = 0
            self.last = old.name + "-reuse"
            return out[0]
        # the matrix moved on (large Newton steps): refactor the next 1, 2, 4, ... times directly
        self._skip_reuse = self._reuse_backoff = min(2 * self._reuse_backoff + 1, 63)
        return None

    def _band(self, A, b):
        with one_blas_thread():
            out = band_solve(A, b, self.plan(A))
        if out is None:
            return None
        x, factor = out
        self._keep(factor)
        return x

    def _pardiso(self, A, b):
        """PARDISO: float32 LDL^T refined by CG when positive definite; float64 (refined by
        plain iterative refinement) when indefinite or when float32 does not converge."""
        plan = self.pattern(A).pardiso(A)
        for single in (True, False):
            factor = _PardisoFactor(plan, single)
            try:
                positive, negative = factor.factor(A)
            except pardiso.PardisoError:
                continue
            self.inertia = (positive, negative)
            if negative == 0 and positive == A.shape[0]:
                out = refine(A, b, factor, exact=not single, max_iterations=REFINE_MAX, tol=self.factor_tol)
                if out is not None:
                    self._keep(factor)
                    return out[0]
            elif not single:
                x = _iterative_refinement(A, b, factor)
                if x is not None:
                    self.last = factor.name
                    return x
        return None

    def _keep(self, factor):
        self._factor = factor if self.reuse else None
        self.last = factor.name

    def _cg(self, A, b, x0):
        x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
        factor = None
        if self.preconditioner != "jacobi":
            factor = ic0(A)
        self.last = "cg-ic" if factor is not None else "cg-jacobi"
        if factor is None:
            factor = jacobi_factor(A.diagonal(), unsigned(A.indices).dtype)
        its, status = pcg(A.indptr, unsigned(A.indices), A.data, b, *factor, x, self.tol, self.max_iterations)
        if status < 0:
            raise _Breakdown("CG met a direction of non-positive curvature")
        return x, its, status == 0

    def _amg_cg(self, A, b, x0):
        """CG preconditioned by multigrid; the hierarchy is kept while it keeps CG short."""
        self.last = "cg-amg"
        modes = self.near_nullspace
        if self._amg is None or not self.reuse:
            self._amg = (amg.build(A, modes), None)
        M, built_its = self._amg
        try:
            x, its, ok = amg.solve(A, b, M, x0, self.tol, self.max_iterations)
        except TensormassError:
            raise _Breakdown("multigrid CG broke down") from None
        if built_its is None:
            self._amg = (M, its)
        elif its > AMG_REBUILD_RATIO * built_its + AMG_REBUILD_MARGIN:
            self._amg = None                      # the matrix moved on: a new hierarchy next time
        return x, its, ok


class _Breakdown(Exception):
    """CG cannot go on: the matrix is not positive definite."""


def _iterative_refinement(A, b, M, tol=1e-10, steps=10):
    """x = M b refined by x += M (b - A x) (any symmetric matrix, definite or not); None
    when it does not reach a relative residual of 1e-8 (tol is the target)."""
    bnorm = np.linalg.norm(b)
    x = M(b)
    best, best_res = x, np.linalg.norm(b - A @ x)
    for _ in range(steps):
        if not np.isfinite(best_res) or best_res <= tol * bnorm:
            break
        x = best + M(b - A @ best)
        res = np.linalg.norm(b - A @ x)
        if not res < best_res:
            break
        best, best_res = x, res
    return best if best_res <= 1e-8 * bnorm else None


# --------------------------------------------------------------------------- SuperLU


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


_warm = set()
# The solver paths that run numba loops, as (method, preconditioner); PARDISO, multigrid, SuperLU
# and the refinement of a kept factor run none.
NUMBA_PATHS = (("band", "ic"), ("cg", "ic"), ("cg", "jacobi"))


def warm_up(index_dtype=np.int32, pointer_dtype=np.int32, paths=NUMBA_PATHS) -> None:
    """Load (or compile) the numba loops of these solver paths for these index types, once per
    process: setup time, like the kernels' and the scatter loops' warm-up, not the first solve."""
    A = sp.csr_matrix((np.array([2.0, -1.0, -1.0, 2.0]), np.array([0, 1, 0, 1], dtype=index_dtype),
                       np.array([0, 2, 4], dtype=pointer_dtype)), shape=(2, 2))
    b = np.array([1.0, 0.5])
    for method, preconditioner in paths:
        key = (method, preconditioner, np.dtype(index_dtype).str, np.dtype(pointer_dtype).str)
        if key not in _warm:
            LinearSolver(method, preconditioner=preconditioner, reuse=False).solve(A, b)
            _warm.add(key)


def _sorted_csr(data, indices, indptr, shape, canonical=True) -> sp.csr_matrix:
    """A CSR matrix on index arrays known (canonical=True) to be sorted without duplicates: the flag
    spares the solver its O(nnz) check of every new matrix of a pattern checked once."""
    A = sp.csr_matrix((data, indices, indptr), shape=shape)
    if canonical:
        A.has_sorted_indices = True
        A.has_canonical_format = True
    return A


def _present(keys: np.ndarray, sorted_keys: np.ndarray) -> np.ndarray:
    """Per key: whether it is one of sorted_keys (sorted, unique)."""
    at = np.minimum(np.searchsorted(sorted_keys, keys), max(sorted_keys.size - 1, 0))
    return sorted_keys[at] == keys if sorted_keys.size else np.zeros(keys.shape, dtype=bool)


class ConstrainedSystem:
    """Dirichlet conditions by elimination on a fixed global CSR pattern.

    The free/free and free/fixed blocks are gathered from the global data with
    index maps computed once: A_ff x_f = b_f - A_fc x_c.
    """

    def __init__(self, pattern, free: np.ndarray, fixed: np.ndarray, modes: np.ndarray | None = None,
                 hanging=None):
        """hanging: runtime.physics.hanging.HangingNodes, or None: the system solved is then P^T A P over the
        free dofs (slaves are neither free nor fixed) and the solution is expanded, x = P x."""
        self.pattern, self.free, self.fixed = pattern, free, fixed
        self.hanging = hanging
        # rigid-body modes of the free dofs (multigrid's near-nullspace), or None
        self.modes = None if modes is None else np.ascontiguousarray(modes[free])
        self.ff = pattern.submatrix_map(free, free)
        entries, indices, indptr, shape = self.ff
        self._ff_canonical = bool(sp.csr_matrix((np.ones(entries.size), indices, indptr), shape=shape).has_canonical_format)
        self._fc = None                  # free/fixed block: built on first use (moving constraints only)
        self._seen = None                # every free/free entry an extra matrix (contact) has had so far

    def structure(self):
        """The matrix solve() hands the linear solver, with unit values (its choice of method reads
        the pattern only); None with hanging nodes (P^T A P is formed at each solve) or no free dof."""
        if self.hanging is not None or not self.free.size:
            return None
        _, indices, indptr, shape = self.ff
        return sp.csr_matrix((np.ones(indices.size), indices, indptr), shape=shape)

    @property
    def fc(self):
        """The free/fixed block's map (None without fixed dofs), built when a constraint first moves."""
        if self._fc is None and self.fixed.size:
            self._fc = self.pattern.submatrix_map(self.free, self.fixed)
        return self._fc

    def _block(self, data, block):
        # a read-only data array cannot change: its free block is built once (the kept matrix of a
        # budgeted implicit Euler step, solved again at every step)
        kept = getattr(self, "_kept_block", None)
        if kept is not None and kept[0] is data and kept[1] is block:
            return kept[2]
        entries, indices, indptr, shape = block
        out = _sorted_csr(data[entries], indices, indptr, shape, block is self.ff and self._ff_canonical)
        if not data.flags.writeable:
            self._kept_block = (data, block, out)
        return out

    def solve(self, solver: LinearSolver, data: np.ndarray, b: np.ndarray, x_c=None, x0=None, extra=None):
        """Full x with x[fixed] = x_c (zero if None) and A x = b on the free rows; (x, iterations).

        extra: None, or an (n_dofs x n_dofs) sparse matrix added to A (contact: pairs of nodes the
        mesh does not couple).  The matrix handed to the solver keeps every entry extra has ever had
        (explicit zeros where a pair has let go), so its pattern, and the solver's analysis of it,
        change only when a new pair appears."""
        if self.hanging is not None:
            if extra is not None:
                raise ValueError("contact with hanging nodes is not supported")
            return self._solve_constrained(solver, data, b, x_c, x0)
        x = np.zeros(self.pattern.n_dofs)
        rhs = b[self.free]
        moving = x_c is not None and self.fixed.size and np.any(x_c)
        if moving:
            x[self.fixed] = x_c
            rhs = rhs - self._block(data, self.fc) @ x_c
        if extra is None:
            A = self._block(data, self.ff)
        else:
            E = extra if sp.isspmatrix_coo(extra) else sp.coo_matrix(extra)
            where = self._free_index()
            r, c = where[E.row], where[E.col]
            if moving:
                ext = (r >= 0) & (c < 0)
                rhs = rhs - np.bincount(r[ext], weights=E.data[ext] * x_c[-c[ext] - 1], minlength=self.free.size)
            inner = (r >= 0) & (c >= 0)
            A = self._with_extra(data, r[inner], c[inner], E.data[inner])
        guess = None if x0 is None else x0[self.free]
        solver.near_nullspace = self.modes
        x[self.free], its = solver.solve(A, rhs, guess)
        return x, its

    def _free_index(self) -> np.ndarray:
        """Per dof: its index among the free dofs, or -1 - its index among the fixed ones."""
        if getattr(self, "_where", None) is None:
            where = np.empty(self.pattern.n_dofs, dtype=np.int64)
            where[self.free] = np.arange(self.free.size)
            where[self.fixed] = -1 - np.arange(self.fixed.size)
            self._where = where
        return self._where

    def _with_extra(self, data, rows, cols, values):
        """The free block of `data` plus the entries (rows, cols, values) of E, on the union of the
        block's pattern and every entry E has had (see solve).  The union's index arrays and the map
        from `data` into it are kept, so the solver sees the same pattern object (and keeps its
        analysis) until an entry outside the union appears: a body against an obstacle adds none
        (its pairs couple nodes of one surface triangle or edge, which the mesh couples already).
        Each call is one gather and a scatter of E's few entries."""
        entries, indices, indptr, shape = self.ff
        if not self._ff_canonical:                   # (no pattern builds such a block; kept correct anyway)
            return (self._block(data, self.ff) + sp.coo_matrix((values, (rows, cols)), shape=shape)).tocsr()
        n = shape[0]
        keys = rows * n + cols
        union = self._seen
        if union is None:
            base_keys = np.repeat(np.arange(n, dtype=np.int64), np.diff(indptr)) * n + indices
            union = self._seen = {"base_keys": base_keys, "all": base_keys, "source": entries,
                                  "only_extra": np.zeros(0, dtype=np.int64), "indptr": indptr, "indices": indices}
        present = _present(keys, union["all"])
        if not present.all():
            union = self._seen = self._grown(union, np.unique(keys[~present]), n)
        merged = data[union["source"]]
        merged[union["only_extra"]] = 0.0
        np.add.at(merged, np.searchsorted(union["all"], keys), values)
        return _sorted_csr(merged, union["indices"], union["indptr"], shape)

    def _grown(self, union, new, n) -> dict:
        """The union with the new keys (sorted, unique, none in it) inserted: a sorted merge."""
        all_keys = np.insert(union["all"], np.searchsorted(union["all"], new), new)
        base = np.searchsorted(all_keys, union["base_keys"])
        source = np.zeros(all_keys.size, dtype=np.int64)
        source[base] = self.ff[0]
        only_extra = np.ones(all_keys.size, dtype=bool)
        only_extra[base] = False
        return {"base_keys": union["base_keys"], "all": all_keys, "source": source,
                "only_extra": np.flatnonzero(only_extra),
                "indptr": np.searchsorted(all_keys, np.arange(n + 1, dtype=np.int64) * n).astype(self.ff[2].dtype),
                "indices": (all_keys % n).astype(self.ff[1].dtype)}

    def _solve_constrained(self, solver, data, b, x_c, x0):
        """The hanging-node constrained system: P^T A P, P^T b on the free dofs, then x = P x."""
        h = self.hanging
        A = h.reduce_matrix(self.pattern.matrix(data))
        b = h.reduce(np.asarray(b, dtype=float))
        x = np.zeros(self.pattern.n_dofs)
        A_f = A[self.free]
        rhs = b[self.free]
        if x_c is not None and self.fixed.size and np.any(x_c):
            x[self.fixed] = x_c
            rhs = rhs - A_f[:, self.fixed] @ x_c
        guess = None if x0 is None else x0[self.free]
        solver.near_nullspace = self.modes
        x[self.free], its = solver.solve(A_f[:, self.free].tocsr(), rhs, guess)
        return h.expand(x), its
