"""Broad-phase candidates kept between the calls of a Newton solve.

    cache = CandidateCache(ipctk, mesh, broad_phase, reach=dhat + dmin, margin=dhat)
    cache.at(V)          # candidates holding every pair closer than `reach` at the state V
    cache.along(V0, V1)  # candidates holding every pair that comes closer than `reach` on V0 -> V1

The broad phase (a bounding-volume hierarchy over the whole collision mesh) is the dearest part of
a contact iteration, while Newton's late iterations move the surface by far less than the barrier's
reach.  Two kinds of candidate sets are therefore kept and reused as long as they are provably
complete:

- **near**: built at a state Vref with boxes inflated by reach + margin.  At any state whose every
  vertex lies within margin / 2 of Vref, a pair's distance differs from its distance at Vref by at
  most margin, so every pair closer than reach there is a candidate.  A segment between two such
  states stays within margin / 2 too (each vertex moves on a straight line inside its ball), so the
  CCD of that segment needs no other candidate.
- **swept**: built for one line search, boxes swept from V0 to V1 and inflated by reach plus what a
  state PATH_SLACK reach off the path can close.  The line search's trial states lie on the path
  (up to round-off), so their collisions, and the next iteration's gradient and Hessian, reuse it.

Anything else builds a new near set at the state asked for.  Decisions depend on the states only,
never on timings; `seconds` and `builds` count what the broad phase cost (benchmarks read them).
"""
from __future__ import annotations

import math
import time

import numpy as np

__all__ = ["CandidateCache", "PATH_SLACK"]

# a state within this share of the reach (per coordinate) of the line search's path reuses its candidates
PATH_SLACK = 0.01


class CandidateCache:
    def __init__(self, ipc, mesh, broad_phase, reach: float, margin: float):
        self.ipc, self.mesh, self.broad = ipc, mesh, broad_phase
        self.reach, self.margin = float(reach), float(margin)
        self.swept_reach = self.reach + 2.0 * math.sqrt(3.0) * PATH_SLACK * self.reach
        self._near = None                  # (Vref, candidates)
        self._swept = None                 # (V0, V1 - V0, candidates)
        self.builds = {"near": 0, "swept": 0}
        self.seconds = 0.0

    def at(self, V: np.ndarray):
        """Candidates for the collisions at the state V."""
        if self._within(V):
            return self._near[1]
        if self._on_path(V):
            return self._swept[2]
        return self._build_near(V)

    def along(self, V0: np.ndarray, V1: np.ndarray):
        """Candidates for the CCD of the linear path V0 -> V1 (and for the states on it)."""
        if self._within(V0) and self._within(V1):
            return self._near[1]
        if _largest_move(V1 - V0) <= 0.5 * self.margin:
            return self._build_near(V0)
        start = time.perf_counter()
        candidates = self.ipc.Candidates()
        candidates.build(self.mesh, V0, V1, self.swept_reach, broad_phase=self.broad)
        self._swept = (V0.copy(), V1 - V0, candidates)
        self.builds["swept"] += 1
        self.seconds += time.perf_counter() - start
        return candidates

    def _build_near(self, V):
        start = time.perf_counter()
        candidates = self.ipc.Candidates()
        candidates.build(self.mesh, V, self.reach + self.margin, broad_phase=self.broad)
        self._near = (V.copy(), candidates)
        self.builds["near"] += 1
        self.seconds += time.perf_counter() - start
        return candidates

    def _within(self, V) -> bool:
        return self._near is not None and _largest_move(V - self._near[0]) <= 0.5 * self.margin

    def _on_path(self, V) -> bool:
        """V within PATH_SLACK reach (per coordinate) of a point of the swept path."""
        if self._swept is None:
            return False
        V0, dV, _ = self._swept
        D = V - V0
        norm2 = float(np.vdot(dV, dV))
        a = min(max(float(np.vdot(D, dV)) / norm2, 0.0), 1.0) if norm2 > 0.0 else 0.0
        return bool(np.abs(D - a * dV).max() <= PATH_SLACK * self.reach)


def _largest_move(dV: np.ndarray) -> float:
    """The largest distance one vertex moves (rows of dV)."""
    return float(np.sqrt(np.einsum("ij,ij->i", dV, dV).max())) if dV.size else 0.0
