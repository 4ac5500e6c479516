"""Surface simplification and its precision criterion (thesis ch. 8, B26).

    points, triangles = simplify(points, triangles, reduction=0.9)   # quadric decimation, 90 % fewer triangles
    d = mean_distance((P0, T0), (P1, T1))         # symmetric mean distance between two surfaces (m)
    alpha = precision(d, size)                     # 100 (d_organ - d_mean) / d_organ, in %

The thesis simplified its organ surfaces with ReMESH and judged them by the mean distance between
the initial and the simplified surface (Aspert et al.'s MESH) against a characteristic size of the
organ: the iliac wing's thickness for the pelvis, the uterine wall's for the uterus, the head's
diameter for the fetus. At 90 % simplification it kept alpha above 85 %.

The decimation is fast-simplification's by default (quadric error metric) or pymeshlab's; the distance is
computed here: points sampled uniformly by area on each surface (a fixed seed: the same surfaces give
the same number), and each one's exact distance to the nearest triangle of the other surface.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..base.errors import TensormassError
from .probes import _triangle_distance

__all__ = ["simplify", "mean_distance", "distances", "precision", "check_closed", "SAMPLES", "METHODS"]

SAMPLES = 20_000            # points sampled on each surface for mean_distance


def _surface(points, triangles):
    points = np.asarray(points, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    if points.ndim != 2 or points.shape[1] != 3 or triangles.ndim != 2 or triangles.shape[1] != 3:
        raise TensormassError(f"a surface is points (n, 3) and triangles (m, 3), got {points.shape} and {triangles.shape}")
    if not len(triangles):
        raise TensormassError("the surface has no triangles")
    if triangles.min() < 0 or triangles.max() >= len(points):
        raise TensormassError("the triangles name points that do not exist")
    return points, triangles


def check_closed(triangles) -> None:
    """TensormassError unless every edge borders exactly two triangles (a closed surface, which a
    volume mesh needs)."""
    t = np.asarray(triangles)
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    open_edges, crowded = int(np.sum(counts == 1)), int(np.sum(counts > 2))
    if open_edges or crowded:
        raise TensormassError(f"the surface is not closed: {open_edges} edge(s) border one triangle and {crowded} "
                              "more than two")


METHODS = ("fast-simplification", "pymeshlab")


def simplify(points, triangles, reduction: float, method: str = "fast-simplification") -> tuple[np.ndarray, np.ndarray]:
    """The surface with about `reduction` (0 to 1) of its triangles removed by quadric decimation;
    unused points dropped. method: "fast-simplification" (the `mesh` extra: a 0.3 MB wheel) or
    "pymeshlab" (MeshLab's quadric edge collapse, topology kept: more precise on sharp features,
    about 10 times slower, a 100 MB wheel; docs/guide/meshes.md compares them)."""
    points, triangles = _surface(points, triangles)
    if not 0.0 <= reduction < 1.0:
        raise TensormassError(f"the reduction is a fraction of the triangles to remove, 0 <= r < 1, got {reduction}")
    if method not in METHODS:
        raise TensormassError(f"unknown simplification method {method!r}; known: {', '.join(METHODS)}")
    if reduction == 0.0:
        return points.copy(), triangles.copy()
    if method == "pymeshlab":
        try:
            import pymeshlab
        except ImportError:
            raise TensormassError("method \"pymeshlab\" needs the pymeshlab package: pip install pymeshlab") from None
        meshes = pymeshlab.MeshSet()
        meshes.add_mesh(pymeshlab.Mesh(points, triangles))
        meshes.meshing_decimation_quadric_edge_collapse(targetfacenum=max(int(round(len(triangles) * (1 - reduction))), 4),
                                                        preservetopology=True, preserveboundary=True)
        out = meshes.current_mesh()
        return np.asarray(out.vertex_matrix(), dtype=np.float64), np.asarray(out.face_matrix(), dtype=np.int64)
    try:
        import fast_simplification
    except ImportError:
        raise TensormassError("mesh simplification needs the fast-simplification package: "
                              "pip install 'tensormass[mesh]' (or pip install fast-simplification)") from None
    out_points, out_triangles = fast_simplification.simplify(points, triangles, target_reduction=float(reduction))
    return np.asarray(out_points, dtype=np.float64), np.asarray(out_triangles, dtype=np.int64)


def _areas(P, T):
    return 0.5 * np.linalg.norm(np.cross(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]]), axis=1)


def _samples(P, T, n: int, seed: int) -> np.ndarray:
    """n points uniformly distributed by area on the surface."""
    rng = np.random.default_rng(seed)
    areas = _areas(P, T)
    tri = rng.choice(len(T), size=n, p=areas / areas.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    a, b, c = P[T[tri, 0]], P[T[tri, 1]], P[T[tri, 2]]
    return (1 - s)[:, None] * a + (s * (1 - r2))[:, None] * b + (s * r2)[:, None] * c


def distances(points, surface, chunk: int = 4096) -> np.ndarray:
    """The exact distance of each point to the surface (points, triangles): the triangles whose
    centroid lies within (distance to the nearest centroid + the largest circumradius) are the only
    candidates (the nearest point of the nearest triangle is no farther than the nearest centroid)."""
    P, T = _surface(*surface)
    points = np.asarray(points, dtype=np.float64)
    corners = P[T]                                             # (m, 3, 3)
    centroids = corners.mean(axis=1)
    reach = float(np.linalg.norm(corners - centroids[:, None], axis=2).max())
    tree = cKDTree(centroids)
    nearest, _ = tree.query(points)
    out = np.empty(len(points))
    for start in range(0, len(points), chunk):
        block = points[start:start + chunk]
        lists = tree.query_ball_point(block, nearest[start:start + chunk] + reach * (1 + 1e-12) + 1e-300)
        counts = np.fromiter((len(c) for c in lists), dtype=np.int64, count=len(lists))
        candidates = np.concatenate([np.asarray(c, dtype=np.int64) for c in lists])
        owners = np.repeat(np.arange(len(block)), counts)
        d = _triangle_distance(corners[candidates], block[owners])
        out[start:start + len(block)] = np.minimum.reduceat(d, np.concatenate([[0], np.cumsum(counts)[:-1]]))
    return out


def mean_distance(a, b, samples: int = SAMPLES, seed: int = 0) -> float:
    """The symmetric mean distance between surfaces a and b ((points, triangles) each): the mean over
    points sampled on a of their distance to b, and over points sampled on b of theirs to a, averaged."""
    Pa, Ta = _surface(*a)
    Pb, Tb = _surface(*b)
    forth = distances(_samples(Pa, Ta, samples, seed), (Pb, Tb)).mean()
    back = distances(_samples(Pb, Tb, samples, seed + 1), (Pa, Ta)).mean()
    return float(0.5 * (forth + back))


def precision(d_mean: float, size: float) -> float:
    """The thesis' alpha = 100 (d_organ - d_mean) / d_organ, in %, d_organ the organ's characteristic size."""
    if not size > 0:
        raise TensormassError(f"the characteristic size d_organ must be > 0, got {size}")
    return 100.0 * (size - d_mean) / size
