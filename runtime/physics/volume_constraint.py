"""Exact volume preservation of a closed triangle surface (thesis chapter 6: inflated thin shells).

    C = VolumeConstraint(triangles, rest_points)   # closed, consistently oriented, outward
    V = C.volume(x)                                # sum over triangles x0 . (x1 x x2) / 6
    g = C.vertex_normals(x)                        # dV/dx, (n, 3), exact
    c = C.cubic_coefficients(x, D)                 # V(x + lam D) = c0 + c1 lam + c2 lam^2 + c3 lam^3
    x_new, lam = C.project(x, directions=None, free=None)   # V(x_new) = V0 to 1e-12 relative
    P = C.pressure_penalty_forces(x, k)            # the soft alternative: -k (V - V0) / V0 dV/dx

Why a projection and not a penalty: a gas-filled or incompressible shell keeps its volume exactly,
and a stiff penalty makes the time step (explicit) or the Newton systems (implicit) pay for it.
After each step the nodes are moved along fixed directions D_i (by default the volume gradient,
the area-weighted vertex normals: the shortest move in the least-squares sense to first order):
x_new = x + lam D.  Because the enclosed volume is a sum of triple products of node positions, it
is a cubic polynomial in lam, so the constraint V(x + lam D) = V0 is solved exactly (numpy.roots
then Newton refinement) rather than by a linearised step that leaves a drift.  Nodes that are
clamped or in contact get D_i = 0 through `free` and do not move.  The root taken is the real one
of smallest magnitude: the smallest correction, the one continuous with lam = 0 at V = V0.

Orientation: triangles counter-clockwise seen from outside (runtime.mesh.surfaces' convention), so that
V0 > 0; an inward-oriented surface is refused rather than silently negated.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["VolumeConstraint", "VolumeConstraintError", "PenaltyForces", "check_closed_surface"]

RELATIVE_TOLERANCE = 1e-12   # |V(x_new) - V0| / V0 after project
_ZERO_COEFFICIENT = 1e-12    # a coefficient below this fraction of its terms' bound is roundoff


def _triple(a, b, c) -> np.ndarray:
    """Row-wise a . (b x c)."""
    return np.einsum("ij,ij->i", a, np.cross(b, c))


class VolumeConstraintError(RuntimeError):
    """The projection cannot restore the volume (no real root, or directions that do not change V)."""


class PenaltyForces(NamedTuple):
    """Penalty energy E = k/2 (V - V0)^2 / V0, forces f = -dE/dx = -k (V - V0)/V0 dV/dx.

    Stiffness K = -df/dx = stiffness_scale g g^T + k (V - V0)/V0 d2V/dx2 with g = gradient.ravel();
    the rank-one first term (stiffness_scale = k / V0) is exact at V = V0 and is the part to add to
    a Newton matrix (as a low-rank update: it couples every node of the surface, so it is never
    assembled into the sparse pattern)."""
    forces: np.ndarray
    energy: float
    gradient: np.ndarray
    stiffness_scale: float


def _triangles(triangles) -> np.ndarray:
    t = np.asarray(triangles)
    if t.ndim != 2 or t.shape[1] != 3 or len(t) == 0:
        raise ValueError(f"triangles must be an (m, 3) integer array with m >= 1, got shape {t.shape}")
    if not np.issubdtype(t.dtype, np.integer):
        raise ValueError(f"triangles must hold integer node ids, got dtype {t.dtype}")
    return t.astype(np.int64)


def check_closed_surface(triangles) -> None:
    """ValueError unless every edge is shared by exactly two triangles in opposite directions.

    Half-edge test: each directed edge (a, b) of a triangle must occur once, and its reverse (b, a)
    once.  A directed edge seen twice means two neighbours with opposite windings (or more than two
    triangles on the edge); a missing reverse means a boundary (hole) edge.  The message names the
    first bad edge in triangle order, so a flipped triangle is found by its id."""
    t = _triangles(triangles)
    same = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 2] == t[:, 0])
    if same.any():
        k = int(np.argmax(same))
        raise ValueError(f"triangle {k} {t[k].tolist()} repeats a node: degenerate, the surface is not closed")
    if t.min() < 0:
        raise ValueError(f"triangles hold a negative node id ({int(t.min())})")
    a = t.reshape(-1)                           # half-edge 3 k + i goes from t[k, i] to t[k, i + 1]
    b = np.roll(t, -1, axis=1).reshape(-1)
    n = int(t.max()) + 1
    keys, reverse = a * n + b, b * n + a
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    twice = counts[inverse.reshape(-1)] > 1
    unpaired = ~np.isin(reverse, keys)
    bad = twice | unpaired
    if bad.any():
        h = int(np.argmax(bad))
        why = ("is used twice in the same direction: two neighbouring triangles are wound oppositely"
               " (or more than two triangles share it)" if twice[h] else
               "has no opposite half-edge: a boundary (the surface is open) or a flipped neighbour")
        raise ValueError(f"not a closed, consistently oriented surface: edge ({int(a[h])}, {int(b[h])}) "
                         f"of triangle {h // 3} {why}")


class VolumeConstraint:
    """Enclosed volume of a closed triangle surface, its exact gradient and the exact projection."""

    def __init__(self, triangles, rest_points):
        self.triangles = _triangles(triangles)
        rest = np.asarray(rest_points, dtype=np.float64)
        if rest.ndim != 2 or rest.shape[1] != 3:
            raise ValueError(f"rest_points must be an (n, 3) array, got shape {rest.shape}")
        self.n_nodes = len(rest)
        if self.triangles.max() >= self.n_nodes or self.triangles.min() < 0:
            raise ValueError(f"triangles reference node ids outside 0..{self.n_nodes - 1}")
        check_closed_surface(self.triangles)
        self.rest_volume = self.volume(rest)
        if not self.rest_volume > 0.0:
            raise ValueError(f"rest volume V0 = {self.rest_volume:.6g} <= 0: the surface is inward-oriented "
                             "(triangles clockwise seen from outside); reverse every triangle's winding")

    # ------------------------------------------------------------------ evaluation
    def _positions(self, x, name="x") -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.n_nodes, 3):
            raise ValueError(f"{name} must have shape ({self.n_nodes}, 3), got {x.shape}")
        if not np.isfinite(x).all():
            raise ValueError(f"{name} holds non-finite values")
        return x

    def volume(self, x) -> float:
        """Signed enclosed volume (divergence theorem): sum over triangles of x0 . (x1 x x2) / 6.

        Summed exactly as the cubic's c0 (same order), so that project(rest) returns lam = 0."""
        p = self._positions(x)[self.triangles]
        return float(_triple(p[:, 0], p[:, 1], p[:, 2]).sum()) / 6.0

    def vertex_normals(self, x) -> np.ndarray:
        """dV/dx_i (n, 3): sum over the incident triangles of (x_j x x_k) / 6, (i, j, k) cyclic.

        The exact gradient of volume(); also 1/3 of the area-weighted normals at the nodes (the
        discrete normal that moves the volume fastest)."""
        p = self._positions(x)[self.triangles]
        g = np.stack([np.cross(p[:, 1], p[:, 2]), np.cross(p[:, 2], p[:, 0]),
                      np.cross(p[:, 0], p[:, 1])], axis=1) / 6.0
        ids = self.triangles.reshape(-1)
        flat = g.reshape(-1, 3)
        return np.stack([np.bincount(ids, weights=flat[:, c], minlength=self.n_nodes) for c in range(3)],
                        axis=1)

    def _cubic_terms(self, x, d):
        """Coefficients (c0, c1, c2, c3) of V(x + lam d) and bounds of their terms.

        Expanding (x0 + lam d0) . ((x1 + lam d1) x (x2 + lam d2)): each power of lam collects the
        triple products with that many d's.  The bounds (the same sums with |x_a| |x_b| |d_c| for
        each triple product) tell roundoff from a true coefficient, also when every term is
        roundoff (a translation: d x d = 0 for equal d's)."""
        px, pd = x[self.triangles], d[self.triangles]
        x0, x1, x2 = px[:, 0], px[:, 1], px[:, 2]
        d0, d1, d2 = pd[:, 0], pd[:, 1], pd[:, 2]
        groups = [[_triple(x0, x1, x2)],
                  [_triple(d0, x1, x2), _triple(x0, d1, x2), _triple(x0, x1, d2)],
                  [_triple(x0, d1, d2), _triple(d0, x1, d2), _triple(d0, d1, x2)],
                  [_triple(d0, d1, d2)]]
        coefficients = np.array([sum(float(t.sum()) for t in g) for g in groups]) / 6.0
        nx, nd = np.linalg.norm(px, axis=2).T, np.linalg.norm(pd, axis=2).T
        bounds = [nx[0] * nx[1] * nx[2],
                  nd[0] * nx[1] * nx[2] + nx[0] * nd[1] * nx[2] + nx[0] * nx[1] * nd[2],
                  nx[0] * nd[1] * nd[2] + nd[0] * nx[1] * nd[2] + nd[0] * nd[1] * nx[2],
                  nd[0] * nd[1] * nd[2]]
        return coefficients, np.array([float(b.sum()) for b in bounds]) / 6.0

    def cubic_coefficients(self, x, directions) -> np.ndarray:
        """[c0, c1, c2, c3] with V(x + lam directions) = c0 + c1 lam + c2 lam^2 + c3 lam^3, exactly."""
        x = self._positions(x)
        return self._cubic_terms(x, self._positions(directions, "directions"))[0]

    # ------------------------------------------------------------------ projection
    def _directions(self, x, directions, free) -> np.ndarray:
        d = self.vertex_normals(x) if directions is None else self._positions(directions, "directions")
        if free is None:
            return d
        mask = np.asarray(free)
        if mask.shape not in ((self.n_nodes,), (self.n_nodes, 3)):
            raise ValueError(f"free must have shape ({self.n_nodes},) or ({self.n_nodes}, 3), got {mask.shape}")
        mask = mask.astype(np.float64)
        if not np.isin(mask, (0.0, 1.0)).all():
            raise ValueError("free must hold 0/1 (or booleans): 1 lets a node (component) move, 0 holds it")
        return d * (mask[:, None] if mask.ndim == 1 else mask)

    def project(self, x, directions=None, free=None):
        """(x_new, lam): x_new = x + lam D with volume(x_new) = V0 to 1e-12 relative.

        D_i = directions[i] (default: vertex_normals(x)[i]) times free[i] (0/1 per node, or a 0/1
        3-vector per node masking components): held nodes are returned bit for bit unchanged.
        lam is the real root of smallest magnitude of the cubic V(x + lam D) - V0, refined by
        Newton steps on the cubic and then on the recomputed volume.  VolumeConstraintError when
        D is zero, when D does not change the volume, or when no real root restores it."""
        x = self._positions(x)
        d = self._directions(x, directions, free)
        if not d.any():
            raise VolumeConstraintError("all directions are zero (every node held?): nothing can restore the volume")
        v0 = self.rest_volume
        c, size = self._cubic_terms(x, d)
        c[1:] = np.where(np.abs(c[1:]) <= _ZERO_COEFFICIENT * size[1:], 0.0, c[1:])
        c[0] = c[0] - v0                 # exactly 0 at x = rest: volume() sums as c0 does
        lam = self._smallest_real_root(c, v0)
        x_new = x + lam * d
        for step in range(5):   # the cubic's root is exact; this absorbs the roundoff of x + lam d
            error = self.volume(x_new) - v0
            if abs(error) <= RELATIVE_TOLERANCE * v0:
                return x_new, float(lam)
            slope = c[1] + lam * (2.0 * c[2] + 3.0 * lam * c[3])
            if slope == 0.0 or step == 4:
                break
            lam -= error / slope
            x_new = x + lam * d
        raise VolumeConstraintError(
            f"volume not restored: relative error {abs(self.volume(x_new) - v0) / v0:.3g} after projection "
            f"(lam = {lam:.6g}); the directions barely change the volume near this root")

    @staticmethod
    def _smallest_real_root(c, v0) -> float:
        """Smallest-magnitude real root of c0 + c1 l + c2 l^2 + c3 l^3 (c0 already minus V0).

        Every eigenvalue of numpy.roots is a start for Newton on the real cubic; the converged ones
        are real roots (a double root comes back as a complex pair with tiny imaginary parts, which
        Newton from the real part still reaches)."""
        if c[0] == 0.0:
            return 0.0
        if not c[1:].any():
            raise VolumeConstraintError(
                "the directions do not change the volume (a rigid motion or tangential moves): "
                f"the volume stays {c[0] + v0:.6g}, not V0 = {v0:.6g}")
        starts = np.roots(c[::-1])
        roots = []
        for start in starts:
            lam = float(start.real)
            for _ in range(30):
                value = c[0] + lam * (c[1] + lam * (c[2] + lam * c[3]))
                terms = abs(c[0]) + abs(lam * c[1]) + abs(lam * lam * c[2]) + abs(lam ** 3 * c[3])
                if abs(value) <= max(1e-3 * RELATIVE_TOLERANCE * v0, 16 * np.finfo(float).eps * terms):
                    roots.append(lam)
                    break
                slope = c[1] + lam * (2.0 * c[2] + 3.0 * lam * c[3])
                if slope == 0.0 or not np.isfinite(slope):
                    break
                lam -= value / slope
        if not roots:
            raise VolumeConstraintError(
                f"no real lam restores the volume V0 = {v0:.6g} along these directions "
                f"(cubic coefficients {np.array2string(c, precision=6)} with c0 - V0)")
        return min(roots, key=abs)

    # ------------------------------------------------------------------ penalty variant
    def pressure_penalty_forces(self, x, k) -> PenaltyForces:
        """The soft variant: forces -k (V - V0)/V0 dV/dx from the energy k/2 (V - V0)^2 / V0.

        k has units of pressure (Pa): (V - V0)/V0 is the volumetric strain, so k is a bulk modulus
        of the enclosed gas or fluid.  See PenaltyForces for the stiffness."""
        if isinstance(k, bool) or not np.isscalar(k) or not np.isfinite(k) or k < 0:
            raise ValueError(f"k must be a finite number >= 0, got {k!r}")
        g = self.vertex_normals(x)
        v0 = self.rest_volume
        strain = (self.volume(x) - v0) / v0
        return PenaltyForces(forces=-k * strain * g, energy=0.5 * k * strain * strain * v0,
                             gradient=g, stiffness_scale=k / v0)
