"""Point probes: the cell a probe point lies in, and the displacement there.

    probe = locate_point(mesh, (1.2, 0.1, 0.1), name="tip")   # PointProbe, or ProbeError
    probe.value(U)                                           # (dim,) displacement at the point

A probe reports the displacement **interpolated at its point** with the shape functions of the
cell that contains it: u(p) = sum_i N_i(xi) u_i, where xi are the point's reference coordinates
in that cell (the inverse of the cell's isoparametric map, by Newton's method from the cell's
centre; exact after one step for straight-sided simplices).  A probe on a node gives that node's
value; a probe on a face or an edge shared by several cells gives the same value from each of
them (the meshes are conforming), and the cell with the lowest global id is used.

A probe must lie inside the body, or on its surface within a tolerance:

    tolerance = max(PROBE_CELL_FRACTION x the size of the nearest cell, PROBE_BODY_FRACTION x the body's size)

(sizes: bounding-box diagonals; 10 % of a cell and 1e-6 of the body).  The cell share covers a
point placed on the true, curved surface of a body whose mesh is faceted (the chord of a
facet lies within a few % of the facet's size of the surface it approximates), the body
share round-off in coordinates.  A point outside by at most the tolerance reports the
displacement at the nearest point of the nearest cell (reference coordinates clamped onto the
reference element).  Farther out: ProbeError naming the probe, its point, its distance to the
body's surface (boundary faces taken as flat) and the nearest node.  The probe values are
weights on nodes (PointProbe.nodes, .weights): any linear combination of nodal values is a probe.

Element types: every registered solid type; polynomial ones (simplices, boxes, prisms, any
order) through their Lagrange basis built from the element table's reference nodes, the
pyramid through its rational basis (the one of runtime.mesh.faces).  Shell triangles: the
nearest point of the nearest triangle, with its barycentric weights (the displacement only).
Bars and springs: a probe must sit on a node.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ... import elements as _types
from ...elements import BOX, PRISM, PYRAMID, SIMPLEX, monomial_exponents
from ..base.errors import TensormassError
from .faces import boundary_faces

__all__ = ["PointProbe", "ProbeError", "locate_point", "shape_functions", "PROBE_CELL_FRACTION",
           "PROBE_BODY_FRACTION"]

# A probe outside the body by at most max(this share of the nearest cell's size, ...
PROBE_CELL_FRACTION = 0.1
# ... this share of the body's size) is on the body (see the module doc).
PROBE_BODY_FRACTION = 1e-6

_NEWTON_STEPS = 12
_CHUNK = 65536


class ProbeError(TensormassError):
    """A probe point that is not on the body."""


@dataclass
class PointProbe:
    """Where a probe point lies: u(point) = weights @ U[nodes]."""
    name: str
    point: np.ndarray            # (dim,) the probe point as given
    cell: int                    # global id of the cell used (blocks in order)
    nodes: np.ndarray            # (k,) node ids of that cell
    weights: np.ndarray          # (k,) shape functions at the point (sum 1)
    xi: np.ndarray               # reference coordinates in that cell
    distance: float              # 0 inside; how far outside the body (within the tolerance)

    def value(self, U: np.ndarray) -> np.ndarray:
        """The interpolated value of nodal data U (n_points, ...) at the probe point."""
        return np.tensordot(self.weights, np.asarray(U)[self.nodes], axes=1)


# ============================================================================== shape functions


@functools.cache
def _inverse_vandermonde(name: str):
    el = _types.get(name)
    E = np.array(monomial_exponents(el.domain, el.dim, el.order), dtype=float)      # (m, r)
    X = np.array([[float(c) for c in p] for p in el.nodes])                        # (k, r)
    return E, np.linalg.inv(np.prod(X[:, None, :] ** E[None], axis=2))             # N = phi @ C


def _pyramid(xi):
    """Rational pyramid basis on base [-1, 1]^2 (zeta = 0), apex (0, 0, 1): values and gradients."""
    x, y, z = xi[:, 0], xi[:, 1], np.minimum(xi[:, 2], 1.0 - 1e-12)
    base = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    n = len(xi)
    N, G = np.empty((n, 5)), np.zeros((n, 5, 3))
    q = 1.0 / (1.0 - z)
    for a, (xa, ya) in enumerate(base):
        N[:, a] = 0.25 * ((1 + xa * x) * (1 + ya * y) - z + xa * ya * x * y * z * q)
        G[:, a, 0] = 0.25 * (xa * (1 + ya * y) + xa * ya * y * z * q)
        G[:, a, 1] = 0.25 * (ya * (1 + xa * x) + xa * ya * x * z * q)
        G[:, a, 2] = 0.25 * (-1.0 + xa * ya * x * y * q * q)
    N[:, 4], G[:, 4, 2] = z, 1.0
    return N, G


def shape_functions(name: str, xi) -> tuple:
    """(N (n, k), dN/dxi (n, k, r)) of element type `name` at reference points xi (n, r)."""
    el = _types.get(name)
    xi = np.atleast_2d(np.asarray(xi, dtype=float))
    if el.domain == PYRAMID:
        if el.n_nodes != 5:
            raise TensormassError(f"{name}: no shape functions for a {el.n_nodes}-node pyramid")
        return _pyramid(xi)
    E, C = _inverse_vandermonde(name)
    P = xi[:, None, :] ** E[None]                                                 # (n, m, r)
    N = np.prod(P, axis=2) @ C
    G = np.empty((len(xi), el.n_nodes, el.dim))
    for r in range(el.dim):
        D = P.copy()
        D[:, :, r] = np.where(E[None, :, r] > 0, E[None, :, r] * xi[:, None, r] ** np.maximum(E[None, :, r] - 1, 0),
                              0.0)
        G[:, :, r] = np.prod(D, axis=2) @ C
    return N, G


def _centre(el) -> np.ndarray:
    return np.array([[float(c) for c in p] for p in el.corner_nodes]).mean(axis=0)


def _clamp(el, xi: np.ndarray) -> np.ndarray:
    """Reference points moved onto the reference element (unchanged inside it)."""
    xi = xi.copy()
    if el.domain == BOX:
        return np.clip(xi, -1.0, 1.0)
    if el.domain == SIMPLEX:
        return _onto_simplex(xi)
    if el.domain == PRISM:
        xi[:, :2] = _onto_simplex(xi[:, :2])
        xi[:, 2] = np.clip(xi[:, 2], -1.0, 1.0)
        return xi
    if el.domain == PYRAMID:
        xi[:, 2] = np.clip(xi[:, 2], 0.0, 1.0)
        half = 1.0 - xi[:, 2]
        xi[:, 0] = np.clip(xi[:, 0], -half, half)
        xi[:, 1] = np.clip(xi[:, 1], -half, half)
        return xi
    raise TensormassError(f"{el.name}: unknown reference domain {el.domain.name!r}")


def _onto_simplex(xi: np.ndarray) -> np.ndarray:
    """A point of the unit simplex near xi: barycentric coordinates clipped at 0 and renormalised."""
    lam = np.column_stack([1.0 - xi.sum(axis=1), xi])
    outside = (lam < 0).any(axis=1)
    if outside.any():
        c = np.maximum(lam[outside], 0.0)
        lam[outside] = c / c.sum(axis=1, keepdims=True)
    return lam[:, 1:]


def _invert(el, X: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Reference coordinates (c, r) of point p in each of the cells X (c, k, d) (Newton, from the centre)."""
    xi = np.repeat(_centre(el)[None], len(X), axis=0)
    lo = np.array([[float(c) for c in q] for q in el.nodes]).min(axis=0) - 1.0   # keeps Newton bounded
    hi = np.array([[float(c) for c in q] for q in el.nodes]).max(axis=0) + 1.0
    for _ in range(_NEWTON_STEPS):
        N, G = shape_functions(el.name, xi)
        r = np.einsum("ck,ckd->cd", N, X) - p
        J = np.einsum("ckd,ckr->cdr", X, G)
        try:
            step = np.linalg.solve(J, r[..., None])[..., 0]
        except np.linalg.LinAlgError:            # a degenerate cell (check_mesh refuses those): stay
            break
        xi = np.clip(xi - step, lo, hi)
        if el.order == 1 and el.domain == SIMPLEX:
            break                                # affine: exact after one step
    return xi


# ============================================================================== locating a point


def solid_blocks(mesh):
    return [(b, blk, _types.get(blk.type)) for b, blk in enumerate(mesh.blocks)
            if _types.get(blk.type).dim == mesh.dim and len(blk)]


def _body_size(points) -> float:
    return float(np.linalg.norm(np.ptp(points, axis=0))) if len(points) else 0.0


def locate_point(mesh, point, name: str = "probe") -> PointProbe:
    """The PointProbe of `point` in `mesh`; ProbeError when it is not on the body (see the module doc)."""
    p = np.asarray(point, dtype=float).reshape(-1)
    if p.size != mesh.dim or not np.all(np.isfinite(p)):
        raise ProbeError(f"probe {name!r}: point must be {mesh.dim} finite numbers, got {list(np.ravel(point))}")
    body = PROBE_BODY_FRACTION * _body_size(mesh.points)
    if mesh.n_points and not solid_blocks(mesh):
        if any(blk.type == "shell" and len(blk) for blk in mesh.blocks):
            return _shell_probe(mesh, p, name, body)
        return _node_probe(mesh, p, name, body)
    best = None                                  # (distance, tolerance, global cell, block, local, xi)
    offset = 0
    for b, blk, el in solid_blocks(mesh):
        for start in range(0, len(blk), _CHUNK):
            cells = blk.cells[start:start + _CHUNK]
            X = mesh.points[cells]
            lo, hi = X.min(axis=1), X.max(axis=1)
            size = np.linalg.norm(hi - lo, axis=1)
            margin = (PROBE_CELL_FRACTION * size + body)[:, None]
            cand = np.flatnonzero(np.all((p >= lo - margin) & (p <= hi + margin), axis=1))
            if not cand.size:
                continue
            xi = _clamp(el, _invert(el, X[cand], p))
            N, _ = shape_functions(el.name, xi)
            dist = np.linalg.norm(np.einsum("ck,ckd->cd", N, X[cand]) - p, axis=1)
            tol = np.maximum(PROBE_CELL_FRACTION * size[cand], body)
            ok = np.flatnonzero(dist <= tol)
            if not ok.size:
                continue
            j = ok[np.argmin(dist[ok])]          # argmin: the first (lowest id) of equal distances
            if best is None or dist[j] < best[0]:
                best = (float(dist[j]), float(tol[j]), offset + start + int(cand[j]), b,
                        start + int(cand[j]), xi[j])
        offset += len(blk)
    if best is None:
        raise ProbeError(_outside_message(mesh, p, name))
    dist, _, cell, b, local, xi = best
    blk = mesh.blocks[b]
    N, _ = shape_functions(blk.type, xi[None])
    weights = N[0]
    # inside (not clamped): round-off only; keep the distance for what it is
    return PointProbe(name=name, point=p, cell=cell, nodes=blk.cells[local].copy(), weights=weights,
                      xi=np.asarray(xi), distance=dist if dist > 1e-12 * max(_body_size(mesh.points), 1e-300) else 0.0)


# ============================================================================== the message


def _fmt(v) -> str:
    return "[" + ", ".join(f"{float(x):g}" for x in v) + "]"


def surface_distance(mesh, p) -> float:
    """Distance from p to the nearest boundary face (edge in 2D), faces taken flat (their corners)."""
    corners = {2: {2: 2, 3: 2}, 3: {3: 3, 4: 4, 6: 3, 8: 4, 9: 4}}[mesh.dim]
    tris, segs = [], []
    for _, _, nodes in boundary_faces(mesh):
        c = nodes[:corners.get(len(nodes), len(nodes))]
        if mesh.dim == 2:
            segs.append(c)
        else:
            tris.append(c[:3])
            if len(c) == 4:
                tris.append((c[0], c[2], c[3]))
    if mesh.dim == 2:
        if not segs:
            return math.inf
        S = mesh.points[np.array(segs)]
        return float(_segment_distance(S[:, 0], S[:, 1], p).min())
    if not tris:
        return math.inf
    T = mesh.points[np.array(tris)]
    return float(_triangle_distance(T, p).min())


def _node_probe(mesh, p, name, tol) -> PointProbe:
    """Meshes of lower-dimensional elements only (bars, springs: runtime.base.dofs): a probe must sit on
    a node (within 1e-6 of the body's size); it reports that node's value."""
    d = np.linalg.norm(mesh.points - p, axis=1)
    node = int(np.argmin(d))
    if d[node] > tol:
        raise ProbeError(f"probe {name!r} at {_fmt(p)} is not on a node: the mesh has no cells of its dimension "
                         f"(bars, springs), so probes must sit on nodes; nearest node {node} is {d[node]:.3g} away")
    return PointProbe(name, p, -1, np.array([node]), np.ones(1), np.zeros(0), float(d[node]))


def _shell_probe(mesh, p, name, body) -> PointProbe:
    """Shell triangles (3D surfaces): the nearest point of the nearest triangle, its barycentric weights
    on the triangle's 3 nodes (the shell's translations are linear there; its rotations are not probed).
    The same tolerance as solids: 10 % of that triangle's size, at least 1e-6 of the body's."""
    offset, best = 0, None                       # (distance, tolerance, global cell, nodes)
    for blk in mesh.blocks:
        if blk.type == "shell" and len(blk):
            T = mesh.points[blk.cells[:, :3]]
            d = _triangle_distance(T, p)
            size = np.linalg.norm(T.max(axis=1) - T.min(axis=1), axis=1)
            tol = np.maximum(PROBE_CELL_FRACTION * size, body)
            ok = np.flatnonzero(d <= tol)
            if ok.size:
                j = ok[np.argmin(d[ok])]
                if best is None or d[j] < best[0]:
                    best = (float(d[j]), float(tol[j]), offset + int(j), blk.cells[j, :3].copy())
        offset += len(blk)
    if best is None:
        nearest = float(np.min(np.linalg.norm(mesh.points - p, axis=1)))
        raise ProbeError(f"probe {name!r} at {_fmt(p)} is not on the shell surface (nearest node {nearest:.3g} "
                         f"away); a probe on shells must lie on a triangle within {PROBE_CELL_FRACTION:.0%} of "
                         "its size")
    dist, _, cell, nodes = best
    weights = _closest_barycentric(mesh.points[nodes], p)
    return PointProbe(name, p, cell, nodes, weights, weights[1:].copy(),
                      dist if dist > 1e-12 * max(_body_size(mesh.points), 1e-300) else 0.0)


def _closest_barycentric(T, p) -> np.ndarray:
    """Barycentric weights (3,) of the point of triangle T (3, 3) nearest to p."""
    a, b, c = T
    ab, ac = b - a, c - a
    G = np.array([[ab @ ab, ab @ ac], [ab @ ac, ac @ ac]])
    s, t = np.linalg.solve(G, [ab @ (p - a), ac @ (p - a)])
    if s >= 0 and t >= 0 and s + t <= 1:
        return np.array([1 - s - t, s, t])
    best = None
    for i, j in ((0, 1), (1, 2), (2, 0)):        # outside: the nearest point of the nearest edge
        u, v = T[i], T[j]
        w = float(np.clip((p - u) @ (v - u) / max((v - u) @ (v - u), 1e-300), 0.0, 1.0))
        d = float(np.linalg.norm(u + w * (v - u) - p))
        if best is None or d < best[0]:
            weights = np.zeros(3)
            weights[i], weights[j] = 1 - w, w
            best = (d, weights)
    return best[1]


def _segment_distance(a, b, p):
    ab = b - a
    t = np.clip(np.einsum("nd,nd->n", p - a, ab) / np.maximum(np.einsum("nd,nd->n", ab, ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * ab - p, axis=1)


def _triangle_distance(T, p):
    """Distance from p to each triangle T (n, 3, 3): inside the projection the plane's, else the edges'."""
    a, b, c = T[:, 0], T[:, 1], T[:, 2]
    n = np.cross(b - a, c - a)
    nn = np.linalg.norm(n, axis=1)
    unit = n / np.maximum(nn, 1e-300)[:, None]
    h = np.einsum("nd,nd->n", p - a, unit)
    q = p - h[:, None] * unit                                  # projection onto the plane
    inside = np.ones(len(T), bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("nd,nd->n", np.cross(v - u, q - u), n) >= 0
    edges = np.minimum(np.minimum(_segment_distance(a, b, p), _segment_distance(b, c, p)), _segment_distance(c, a, p))
    return np.where(inside & (nn > 0), np.abs(h), edges)


def _outside_message(mesh, p, name) -> str:
    if not mesh.n_points or not solid_blocks(mesh):
        return f"probe {name!r} at {_fmt(p)} is not on the body: the mesh has no cells of its dimension"
    d2 = np.sum((mesh.points - p) ** 2, axis=1)
    node = int(np.argmin(d2))
    dist = surface_distance(mesh, p)
    if not math.isfinite(dist):
        dist = math.sqrt(float(d2[node]))
    return (f"probe {name!r} at {_fmt(p)} is not on the body: it is {dist:.3g} m outside it (from the nearest "
            f"boundary face; nearest node {node} at {_fmt(mesh.points[node])}); a probe must lie inside the body "
            f"or on its surface within {PROBE_CELL_FRACTION:.0%} of the nearest cell's size (at least "
            f"{PROBE_BODY_FRACTION:g} of the body's size), and reports the displacement interpolated there")
