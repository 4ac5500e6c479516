"""Reference maps and faces: shape-function gradient tables at the corners and centroid of every
type (det J > 0: positively oriented), cell sizes, the face table of a mesh, its boundary faces and
face measures."""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from .container import CellBlock, Mesh, MeshError, NODES_PER_CELL, block_offsets

from ... import elements as _types
from ...elements import BOX, PRISM, PYRAMID, SIMPLEX, ElementType, monomial_exponents

# --------------------------------------------------------------------------- reference maps
#
# For each type a table G (q, k, r) of shape-function gradients at q sample
# points (corners, then the centroid): J[cell, q] = X[cell]^T G[q] and det J > 0
# means correctly oriented.

def _grad_simplex(xi, quadratic_edges=None):
    """Gradients (k, r) of linear or (VTK-ordered) quadratic simplex shape functions."""
    r = len(xi)
    lam = np.concatenate([[1.0 - sum(xi)], xi])
    dlam = np.vstack([-np.ones(r), np.eye(r)])
    if quadratic_edges is None:
        return dlam
    corners = [(4 * lam[i] - 1) * dlam[i] for i in range(r + 1)]
    mids = [4 * (lam[a] * dlam[b] + lam[b] * dlam[a]) for a, b in quadratic_edges]
    return np.array(corners + mids)


def _grad_tensor(xi, corners):
    """Gradients of (bi/tri)linear shape functions on [-1, 1]^r."""
    c = np.asarray(corners, float)
    f = 1 + c * np.asarray(xi)  # (k, r) one-dimensional factors
    g = np.empty_like(c)
    for d in range(c.shape[1]):
        g[:, d] = c[:, d] * np.prod(np.delete(f, d, axis=1), axis=1)
    return g / 2 ** c.shape[1]


def _grad_wedge(xi):
    x, y, z = xi
    tri = np.array([1 - x - y, y, x])           # node (0,0), (0,1), (1,0)
    dtri = np.array([[-1, -1], [0, 1], [1, 0]], float)
    g = np.zeros((6, 3))
    for a in range(6):
        s = -1 if a < 3 else 1
        g[a, :2] = dtri[a % 3] * (1 + s * z) / 2
        g[a, 2] = tri[a % 3] * s / 2
    return g


def _grad_lagrange(el: ElementType, xi) -> np.ndarray:
    """Gradients (k, r) of any Lagrange element on a polynomial domain (the numeric Vandermonde way):
    element types without a closed form below (hexahedron27, wedge15, ...) get their tables from here."""
    E = np.array(monomial_exponents(el.domain, el.dim, el.order), dtype=float)      # (m, r)
    X = np.array(el.nodes, dtype=float)                                           # (k, r)
    C = np.linalg.inv(np.prod(X[:, None, :] ** E[None], axis=2))                  # (m, k): N_i = sum_m phi_m C[m, i]
    x = np.asarray(xi, dtype=float)
    dphi = np.empty(E.shape)
    for r in range(E.shape[1]):
        P = x ** E
        P[:, r] = np.where(E[:, r] > 0, E[:, r] * x[r] ** np.maximum(E[:, r] - 1, 0), 0.0)
        dphi[:, r] = np.prod(P, axis=1)
    return C.T @ dphi


def _pyramid_table(el: ElementType):
    """Pyramid det J samples (the rational map's Jacobian reduces to linear forms).

    With x = (1-z) B(x/(1-z), y/(1-z)) + z x_apex (B the bilinear base), det J at
    base corner a, and its limit at the apex along the edge to a, both equal
    det[B_u(a), B_v(a), x_apex - x_a]; at the centroid (0,0,1/4) it is
    det[B_u(0), B_v(0), x_apex - B(0)].
    """
    base = np.array([p[:2] for p in el.corner_nodes[:4]], float)
    rows = []
    for a, uv in enumerate(list(base) + [np.zeros(2)]):
        g = np.zeros((5, 3))
        g[:4, :2] = _grad_tensor(uv, base)
        g[4, 2] = 1.0
        if a < 4:
            g[a, 2] -= 1.0
        else:
            g[:4, 2] -= 0.25
        rows.append(g)
    return np.array(rows)


@functools.cache
def _gradient_table(el: ElementType) -> np.ndarray:
    """Closed forms by reference domain (and order); any other Lagrange element numerically."""
    if el.domain == PYRAMID:
        if el.n_nodes != 5:
            raise MeshError(f"{el.name}: no gradient table for a {el.n_nodes}-node pyramid")
        return _pyramid_table(el)
    corners = np.array(el.corner_nodes, float)
    samples = list(corners) + [corners.mean(axis=0)]
    if el.domain == SIMPLEX and el.order <= 2 and len(el.midside_edges) == el.n_nodes - el.n_corners:
        edges = el.midside_edges or None
        return np.array([_grad_simplex(x, edges) for x in samples])
    if el.domain == PRISM and el.order == 1:
        return np.array([_grad_wedge(x) for x in samples])
    if el.domain == BOX and el.order == 1:
        return np.array([_grad_tensor(x, corners) for x in samples])
    return np.array([_grad_lagrange(el, x) for x in samples])


GRADIENT_TABLES = {t: _gradient_table(_types.get(t)) for t in NODES_PER_CELL}


def jacobian_det(J: np.ndarray) -> np.ndarray:
    """Determinants of (..., d, d) with d = 2 or 3, written out (much faster than linalg)."""
    if J.shape[-1] == 2:
        return J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    return (J[..., 0, 0] * (J[..., 1, 1] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 1])
            - J[..., 0, 1] * (J[..., 1, 0] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 0])
            + J[..., 0, 2] * (J[..., 1, 0] * J[..., 2, 1] - J[..., 1, 1] * J[..., 2, 0]))


def sample_dets(points: np.ndarray, block: CellBlock) -> np.ndarray:
    """det J at the corners and the centroid of every cell: (n, q).

    Cells of a lower topological dimension r < d have no orientation: their
    measure sqrt(det(J^T J)) (length, area) instead, never negative."""
    el = _types.get(block.type)
    X = points[block.cells]                                  # (n, k, d)
    J = np.einsum("nkd,qkr->nqdr", X, _gradient_table(el), optimize=True)
    if el.dim == points.shape[1]:
        return jacobian_det(J)
    G = np.einsum("nqdr,nqds->nqrs", J, J)
    gram = G[..., 0, 0] if el.dim == 1 else jacobian_det(G)
    return np.sqrt(np.maximum(gram, 0.0))


def cell_sizes(points: np.ndarray, block: CellBlock) -> np.ndarray:
    X = points[block.cells[:, :_types.get(block.type).n_corners]]
    return np.linalg.norm(X.max(axis=1) - X.min(axis=1), axis=1)


# --------------------------------------------------------------------------- faces
#
# Faces (edges in 2D) in outward order for a positively oriented cell, corners
# only; quadratic midside nodes are looked up separately.

def solid_blocks(mesh: Mesh) -> list:
    """(index, block, ElementType) of the blocks whose topological dimension is the space dimension."""
    out = []
    for bi, blk in enumerate(mesh.blocks):
        el = _types.get(blk.type)
        if el.dim == mesh.dim:
            out.append((bi, blk, el))
    return out


@dataclass
class FaceTable:
    """All cell faces as rows: nodes (m, w) padded with -1, and who owns them."""
    nodes: np.ndarray
    nvert: np.ndarray
    cell: np.ndarray       # global cell id
    block: np.ndarray
    local: np.ndarray      # cell index within its block
    lface: np.ndarray      # face index within the cell
    quadratic: np.ndarray  # owner is a quadratic cell
    group: np.ndarray      # id of the geometric face (same sorted corner set)
    count: np.ndarray      # per group: how many cells use it
    order: np.ndarray      # rows sorted by group


def group_rows(keys: np.ndarray):
    """Group equal rows: (order, group id per row, count per group)."""
    order = np.lexsort(keys.T[::-1])
    sk = keys[order]
    new = np.empty(len(keys), dtype=bool)
    new[:1] = True
    new[1:] = np.any(sk[1:] != sk[:-1], axis=1)
    gid = np.empty(len(keys), dtype=np.int64)
    gid[order] = np.cumsum(new) - 1
    return order, gid, np.bincount(gid)


def face_table(mesh: Mesh) -> FaceTable:
    width = 4 if mesh.dim == 3 else 2
    off = block_offsets(mesh)
    parts = []
    for bi, blk, el in solid_blocks(mesh):
        n = len(blk)
        for fi, f in enumerate(el.faces):
            face = f.corners
            rows = np.full((n, width), -1, dtype=np.int64)
            rows[:, :len(face)] = blk.cells[:, face]
            parts.append((rows, np.full(n, len(face)), off[bi] + np.arange(n), np.full(n, bi),
                          np.arange(n), np.full(n, fi), np.full(n, el.quadratic)))
    if not parts:
        e = np.zeros(0, np.int64)
        return FaceTable(np.zeros((0, width), np.int64), e, e, e, e, e, e.astype(bool), e, e, e)
    cols = [np.concatenate(c) for c in zip(*parts)]
    nodes = cols[0]
    order, gid, count = group_rows(np.sort(nodes, axis=1))
    return FaceTable(nodes, cols[1], cols[2], cols[3], cols[4], cols[5], cols[6].astype(bool),
                      gid, count, order)


def boundary_rows(ft: FaceTable) -> np.ndarray:
    return np.flatnonzero(ft.count[ft.group] == 1)


def boundary_faces(mesh: Mesh) -> list:
    """Faces (edges in 2D) used by exactly one cell: (block index, cell index, nodes).

    Nodes are in outward order (right-hand normal, or edge direction with the
    cell on the left, points out of a positively oriented cell); quadratic
    cells give their midside nodes too (triangle6 / line3 order).
    """
    if mesh.n_cells == 0:
        return []
    ft = face_table(mesh)
    out = []
    for r in boundary_rows(ft):
        blk = mesh.blocks[ft.block[r]]
        local = _types.get(blk.type).faces[ft.lface[r]].nodes
        out.append((int(ft.block[r]), int(ft.local[r]), tuple(int(v) for v in blk.cells[ft.local[r], list(local)])))
    return out


@functools.cache
def _face_corner_counts(dim: int, types: tuple) -> dict:
    """{node count: corner count} of the face types of the registered dim-dimensional element types."""
    return {len(f.nodes): len(f.corners) for t in types for f in _types.get(t).faces
            if _types.get(t).dim == dim}


def face_measure(points, nodes, dim) -> float:
    """Area of a boundary face of a dim-dimensional cell (length of an edge in 2D) from its corners.

    `nodes` as boundary_faces gives them (the face type's order, corners first); the face type
    follows from the node count among the faces of the element table."""
    k = _face_corner_counts(dim, _types.names()).get(len(nodes), len(nodes))
    corners = points[np.asarray(nodes)[:k]]
    if k == 2:
        return float(np.linalg.norm(corners[1] - corners[0]))
    if k == 3:
        return 0.5 * float(np.linalg.norm(np.cross(corners[1] - corners[0], corners[2] - corners[0])))
    return 0.5 * float(np.linalg.norm(np.cross(corners[2] - corners[0], corners[3] - corners[1])))


