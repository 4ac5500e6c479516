"""Intel MKL PARDISO (from the `mkl` wheel) through ctypes: a fill-reducing sparse LDL^T.

    if pardiso.available():
        solver = pardiso.Pardiso(n, indptr, indices, single=False, threads=2)   # upper triangle, CSR
        stats = solver.analyse()              # nested-dissection ordering + symbolic factor, once per pattern
        solver.factor(values)                 # numeric factor of one matrix of that pattern
        x = solver.solve(b)
        solver.inertia                        # (positive, negative) pivots of the last factor

The matrix type is real symmetric indefinite (mtype -2: Bunch-Kaufman pivoting), so one
path factors positive definite and indefinite tangents alike and reports the inertia: the
number of negative pivots tells the caller whether a Newton matrix is indefinite.

Reproducibility: MKL's conditional numerical reproducibility mode for PARDISO (iparm[33],
set to REPRODUCIBLE_THREADS) makes the factor and the solution the same bits for any
thread count up to that number (checked by tests/runtime/solve/test_pardiso.py for 1 and 2).

Why not pypardiso: it hides the phases (it factors and solves in one call, keyed by a hash
of the matrix), where the runtime needs one symbolic analysis per sparsity pattern, a
numeric factorisation per matrix, the inertia and the single-precision factor.
"""
from __future__ import annotations

import ctypes
import glob
import os
import site
import sys
from ctypes.util import find_library

import numpy as np

from ..base.errors import TensormassError

__all__ = ["Pardiso", "available", "unavailable_reason", "REPRODUCIBLE_THREADS"]

# iparm[33]: results are bit-identical for any thread count up to this (CNR mode).
REPRODUCIBLE_THREADS = 8

_MESSAGES = {
    -1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
    -4: "zero pivot (the matrix is singular)", -5: "unclassified internal error",
    -6: "reordering failed", -7: "diagonal matrix is singular", -8: "32-bit integer overflow",
    -9: "not enough memory for out-of-core", -10: "error opening out-of-core files",
    -11: "read/write error with out-of-core files", -12: "wrong mtype for pardiso_64",
}

_lib = None
_why = None


def _candidates():
    env = os.environ.get("TENSORMASS_MKL_RT")
    if env:                                     # the user's choice, and only it
        yield env
        return
    for prefix in (sys.prefix, getattr(site, "USER_BASE", None) or ""):
        for path in sorted(glob.glob(os.path.join(prefix, "lib", "libmkl_rt.so*")), key=len):
            yield path
    found = find_library("mkl_rt")
    if found:
        yield found


def _load():
    """The mkl_rt library (None with the reason in _why when it does not load)."""
    global _lib, _why
    if _lib is not None or _why is not None:
        return _lib
    errors = []
    # Intel OpenMP spins 200 ms after each parallel region by default: on shared cores that
    # spinning thread steals the core the assembly runs on next.  Read when MKL starts its
    # threads, so set before the first call (a user's own setting wins).
    os.environ.setdefault("KMP_BLOCKTIME", "0")
    for path in _candidates():
        try:
            lib = ctypes.CDLL(path)
            lib.pardiso                                   # noqa: B018 - the symbol must exist
        except (OSError, AttributeError) as exc:
            errors.append(f"{path}: {exc}")
            continue
        p = ctypes.POINTER
        lib.pardiso.restype = None
        lib.pardiso.argtypes = [ctypes.c_void_p, p(ctypes.c_int32), p(ctypes.c_int32), p(ctypes.c_int32),
                                p(ctypes.c_int32), p(ctypes.c_int32), ctypes.c_void_p, ctypes.c_void_p,
                                ctypes.c_void_p, ctypes.c_void_p, p(ctypes.c_int32), ctypes.c_void_p,
                                p(ctypes.c_int32), ctypes.c_void_p, ctypes.c_void_p, p(ctypes.c_int32)]
        lib.pardisoinit.restype = None
        lib.MKL_Set_Num_Threads_Local.restype = ctypes.c_int
        lib.MKL_Set_Num_Threads_Local.argtypes = [ctypes.c_int]
        _lib = lib
        return lib
    _why = ("MKL's mkl_rt library was not found (pip install mkl; or set TENSORMASS_MKL_RT to its path)"
            if not errors else "MKL's mkl_rt did not load: " + "; ".join(errors))
    return None


def available() -> bool:
    return _load() is not None


def unavailable_reason() -> str | None:
    _load()
    return _why


class PardisoError(TensormassError):
    def __init__(self, phase: str, code: int):
        self.code = code
        super().__init__(f"PARDISO {phase} failed: {_MESSAGES.get(code, 'error')} (code {code})")


class Pardiso:
    """One PARDISO handle for one sparsity pattern (upper triangle of a symmetric matrix, CSR,
    sorted column indices, 0-based).  single: factor in float32 (half the flops' time and
    memory; the caller refines the solution in float64)."""

    def __init__(self, n: int, indptr, indices, single: bool = False, threads: int = 1):
        lib = _load()
        if lib is None:
            raise TensormassError(f"the pardiso linear solver is unavailable: {_why}")
        self._lib = lib
        self.n = int(n)
        self.indptr = np.ascontiguousarray(indptr, dtype=np.int32)
        self.indices = np.ascontiguousarray(indices, dtype=np.int32)
        self.single = bool(single)
        self.dtype = np.float32 if single else np.float64
        self._threads = max(1, int(threads))             # fixed for the handle's lifetime (see threads)
        self.mtype = -2
        self.pt = np.zeros(64, dtype=np.int64)            # opaque handle: never moved or copied
        self.iparm = np.zeros(64, dtype=np.int32)
        lib.pardisoinit(self.pt.ctypes.data_as(ctypes.c_void_p), ctypes.byref(ctypes.c_int32(self.mtype)),
                        self.iparm.ctypes.data_as(ctypes.c_void_p))
        self.iparm[34] = 1                                # 0-based indices
        self.iparm[27] = 1 if single else 0               # factor precision
        self.iparm[33] = REPRODUCIBLE_THREADS             # CNR: same bits for 1..N threads
        self.iparm[7] = 0                                 # refinement: the caller's (it checks residuals)
        self._values = None                               # the factored values (PARDISO may read them)
        self._live = False
        self.analysed = False
        self.factored = False

    @property
    def threads(self) -> int:
        """OpenMP threads of every phase of this handle: fixed at construction (an analysis on
        two threads followed by a factorisation on one crashed MKL 2026.2)."""
        return self._threads

    # -- the phases --------------------------------------------------------------------------
    def _call(self, phase: int, values=None, b=None, x=None, what="solve"):
        lib = self._lib
        err = ctypes.c_int32(0)
        one = ctypes.c_int32(1)
        null = ctypes.c_void_p(0)
        previous = lib.MKL_Set_Num_Threads_Local(self._threads)
        try:
            lib.pardiso(self.pt.ctypes.data_as(ctypes.c_void_p), ctypes.byref(one), ctypes.byref(one),
                        ctypes.byref(ctypes.c_int32(self.mtype)), ctypes.byref(ctypes.c_int32(phase)),
                        ctypes.byref(ctypes.c_int32(self.n)),
                        values.ctypes.data_as(ctypes.c_void_p) if values is not None else null,
                        self.indptr.ctypes.data_as(ctypes.c_void_p), self.indices.ctypes.data_as(ctypes.c_void_p),
                        null, ctypes.byref(one), self.iparm.ctypes.data_as(ctypes.c_void_p),
                        ctypes.byref(ctypes.c_int32(0)),
                        b.ctypes.data_as(ctypes.c_void_p) if b is not None else null,
                        x.ctypes.data_as(ctypes.c_void_p) if x is not None else null, ctypes.byref(err))
        finally:
            lib.MKL_Set_Num_Threads_Local(previous)
        if err.value != 0:
            raise PardisoError(what, err.value)

    def analyse(self) -> dict:
        """Fill-reducing ordering and symbolic factorisation (phase 11); returns its statistics."""
        values = np.zeros(self.indices.size, dtype=self.dtype)   # analysis reads the pattern only
        self._live = True
        self._call(11, values, what="analysis")
        self.analysed = True
        return self.statistics()

    def statistics(self) -> dict:
        """From the analysis: nnz of the factor, its flops and memory (bytes)."""
        ip = self.iparm
        return {"factor_nnz": int(ip[17]), "factor_flops": float(ip[18]) * 1e6,
                "memory_bytes": 1024.0 * float(max(int(ip[14]), int(ip[15]) + int(ip[16])))}

    def factor(self, values) -> None:
        """Numeric factorisation of the matrix with these upper-triangle values (phase 22)."""
        if not self.analysed:
            self.analyse()
        self._values = np.ascontiguousarray(values, dtype=self.dtype)
        self.factored = False
        self._call(22, self._values, what="factorisation")
        self.factored = True

    @property
    def inertia(self) -> tuple[int, int]:
        """(positive, negative) pivots of the last factorisation."""
        return int(self.iparm[21]), int(self.iparm[22])

    @property
    def perturbed(self) -> int:
        """Pivots PARDISO perturbed in the last factorisation (tiny ones: a (nearly) singular matrix)."""
        return int(self.iparm[13])

    def solve(self, b) -> np.ndarray:
        """x = A^-1 b with the last factor, in float64 (computed in the factor's precision)."""
        b = np.asarray(b, dtype=np.float64)
        scale = 1.0
        if self.single:                                   # keep a float32 right-hand side in range
            top = float(np.abs(b).max()) if b.size else 0.0
            scale = top if np.isfinite(top) and top > 0.0 else 1.0
        rhs = np.ascontiguousarray(b / scale if scale != 1.0 else b, dtype=self.dtype)
        x = np.empty_like(rhs)
        self._call(33, self._values, rhs, x, what="solve")
        out = x.astype(np.float64)
        if scale != 1.0:
            out *= scale
        return out

    def release(self) -> None:
        """Free PARDISO's memory for this handle (phase -1)."""
        if self._live:
            self._live = False
            try:
                self._call(-1, what="release")
            except PardisoError:                          # pragma: no cover - nothing left to free
                pass

    def __del__(self):
        try:
            self.release()
        except Exception:                                 # pragma: no cover - interpreter shutdown
            pass
