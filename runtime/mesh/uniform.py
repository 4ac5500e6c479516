"""Uniform refinement and order changes of simplicial meshes (for convergence studies on mesh files).

    fine = refine_uniform(mesh)          # every edge halved: triangles -> 4, tetrahedra -> 8 children
    quad = to_quadratic(mesh)            # triangle -> triangle6, tetra -> tetra10 (straight sides)
    lin = to_linear(quad)                # the corners only (midside nodes dropped)

Supported: triangle, tetra and their quadratic counterparts triangle6, tetra10 (SIMPLICIAL);
any other cell type raises MeshError naming it.  Blocks (and their tags) are kept in order,
the children of a cell follow each other in its block; the old points keep their ids (points no cell uses
are dropped) and the new ones follow.  Nothing here changes the input mesh.

Why not runtime.mesh.refine (conforming longest-edge bisection) for "uniform" levels: marking every
cell bisects each cell once along its longest edge *and* every other cell around that edge, so
a pass multiplies the cell count by an uneven 2-4 and h is not halved everywhere; red refinement
(this module) halves every edge in one pass, so level k has exactly 4^k / 8^k times the cells
and h / 2^k: the clean sequence a convergence study needs.

Red refinement: every edge gets its midpoint (shared by all the cells around it); a triangle
is cut into its 3 corner triangles and the middle one; a tetrahedron into its 4 corner
tetrahedra and the inner octahedron, split into 4 along its SHORTEST diagonal (the choice that
keeps the children's shapes bounded over repeated passes, Bey 1995; ties: the first of
m01-m23, m02-m13, m03-m12).  Children are oriented like their parent (det J > 0).

Quadratic cells (tetra10, triangle6, possibly curved): the corner children are cut from the
corners and the existing midside nodes, and the children's new midside nodes are placed by the
parent's quadratic map at the midpoints of the children's edges in reference coordinates, so
a curved boundary stays exactly where the file put it.  Cells sharing an edge share its new
nodes (keyed by the sorted pair of the edge's end nodes).

to_quadratic puts one node at the middle of every edge (straight-sided cells; shared between
all cells around the edge), in the VTK order of runtime.elements.
"""
from __future__ import annotations

import numpy as np

from ... import elements as _types
from .container import CellBlock, Mesh, MeshError
from .probes import shape_functions

__all__ = ["refine_uniform", "to_quadratic", "to_linear", "SIMPLICIAL", "QUADRATIC_OF", "LINEAR_OF"]

QUADRATIC_OF = {"triangle": "triangle6", "tetra": "tetra10"}
LINEAR_OF = {q: lin for lin, q in QUADRATIC_OF.items()}
SIMPLICIAL = tuple(QUADRATIC_OF) + tuple(LINEAR_OF)

# Children of a triangle6 / tetra10 as local node ids (corners 0..n-1, then the midside nodes in
# the element table's midside_edges order: triangle6 01 12 20; tetra10 01 12 20 03 13 23).
_TRI_CHILDREN = np.array([[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]])
_TET_CORNER_CHILDREN = [[0, 4, 6, 7], [4, 1, 5, 8], [6, 5, 2, 9], [7, 8, 9, 3]]
# the inner octahedron along each of its diagonals (m01-m23, m02-m13, m03-m12), 4 tetrahedra each
_TET_OCTAHEDRON = {
    (4, 9): [[4, 9, 6, 7], [4, 9, 7, 8], [4, 9, 8, 5], [4, 9, 5, 6]],
    (6, 8): [[6, 8, 4, 7], [6, 8, 7, 9], [6, 8, 9, 5], [6, 8, 5, 4]],
    (7, 5): [[7, 5, 4, 6], [7, 5, 6, 9], [7, 5, 9, 8], [7, 5, 8, 4]],
}


def _check(mesh: Mesh, allowed, what: str) -> None:
    bad = [b.type for b in mesh.blocks if b.type not in allowed]
    if bad:
        raise MeshError(f"{what} is defined for {', '.join(allowed)} cells; the mesh has {bad[0]} cells")


def _signed_measure(P: np.ndarray) -> np.ndarray:
    """Signed area / volume (times 2 / 6) of simplices P (n, dim + 1, dim) from their corners."""
    E = P[:, 1:] - P[:, :1]
    return np.linalg.det(E) if E.shape[1] == E.shape[2] else np.zeros(len(P))


def to_quadratic(mesh: Mesh) -> Mesh:
    """triangle -> triangle6, tetra -> tetra10 with straight-sided shared midside nodes."""
    _check(mesh, tuple(QUADRATIC_OF), "raising to quadratic")
    if not mesh.blocks:
        return Mesh(mesh.points.copy(), [])
    edges = [np.array(_types.get(QUADRATIC_OF[b.type]).midside_edges) for b in mesh.blocks]
    pairs = np.concatenate([np.sort(b.cells[:, e], axis=2).reshape(-1, 2) for b, e in zip(mesh.blocks, edges)])
    uniq, inv = np.unique(pairs, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    points = np.vstack([mesh.points, mesh.points[uniq].mean(axis=1)])
    blocks, start = [], 0
    for b, e in zip(mesh.blocks, edges):
        n = len(b) * len(e)
        mids = mesh.n_points + inv[start:start + n].reshape(len(b), len(e))
        start += n
        blocks.append(CellBlock(QUADRATIC_OF[b.type], np.hstack([b.cells, mids]),
                                None if b.tags is None else b.tags.copy()))
    return Mesh(points, blocks)


def to_linear(mesh: Mesh) -> Mesh:
    """tetra10 -> tetra, triangle6 -> triangle: the corners only; unused points are dropped (renumbered)."""
    _check(mesh, SIMPLICIAL, "lowering to linear")
    cells = [b.cells[:, :_types.get(b.type).n_corners] for b in mesh.blocks]
    used = np.unique(np.concatenate([c.ravel() for c in cells])) if cells else np.zeros(0, np.int64)
    new_id = np.full(mesh.n_points, -1, dtype=np.int64)
    new_id[used] = np.arange(used.size)
    blocks = [CellBlock(LINEAR_OF.get(b.type, b.type), new_id[c], None if b.tags is None else b.tags.copy())
              for b, c in zip(mesh.blocks, cells)]
    return Mesh(mesh.points[used], blocks)


def refine_uniform(mesh: Mesh) -> Mesh:
    """One pass of red refinement (see the module doc); linear and quadratic simplices."""
    _check(mesh, SIMPLICIAL, "uniform refinement")
    linear = all(b.type in QUADRATIC_OF for b in mesh.blocks)
    if linear and any(b.type in LINEAR_OF for b in mesh.blocks):
        raise MeshError("uniform refinement: the mesh mixes linear and quadratic cells")
    quad = to_quadratic(mesh) if linear else mesh
    fine = _refine_quadratic(quad)
    return to_linear(fine) if linear else fine


def _children(X: np.ndarray, el) -> np.ndarray:
    """(n, c, n_corners) local ids of the children's corners, oriented like the parent."""
    n = len(X)
    if el.dim == 2:
        return np.broadcast_to(_TRI_CHILDREN, (n,) + _TRI_CHILDREN.shape)
    diagonals = list(_TET_OCTAHEDRON)
    lengths = np.stack([np.linalg.norm(X[:, a] - X[:, b], axis=1) for a, b in diagonals], axis=1)
    choice = np.argmin(lengths, axis=1)                     # argmin: the first of equal lengths
    table = np.array([_TET_CORNER_CHILDREN + _TET_OCTAHEDRON[d] for d in diagonals])   # (3, 8, 4)
    return table[choice]


def _refine_quadratic(mesh: Mesh) -> Mesh:
    """Red refinement of a triangle6 / tetra10 mesh (new midside nodes through each parent's map)."""
    keys, positions, plans = [], [], []
    for blk in mesh.blocks:
        el = _types.get(blk.type)
        k = el.n_corners
        X = mesh.points[blk.cells]                                      # (n, nodes, dim)
        local = _children(X, el).copy()                                 # (n, c, k)
        corners = X[np.arange(len(X))[:, None, None], local]            # (n, c, k, dim)
        flip = _signed_measure(corners.reshape(-1, k, X.shape[2])).reshape(local.shape[:2]) < 0
        local[flip] = local[flip][:, [0, 2, 1] + list(range(3, k))]      # orientation: swap corners 1, 2
        ref = np.array([[float(c) for c in q] for q in el.nodes])       # reference nodes of the parent
        edges = np.array(el.midside_edges)                               # the child's edges, VTK order
        # reference midpoints of the children's edges in the parent, and the parent's map there
        xi = 0.5 * (ref[local[..., edges[:, 0]]] + ref[local[..., edges[:, 1]]])   # (n, c, e, r)
        N, _ = shape_functions(blk.type, xi.reshape(-1, el.dim))
        at = np.einsum("nqk,nkd->nqd", N.reshape(len(X), -1, el.n_nodes), X)      # (n, c * e, dim)
        glob = np.take_along_axis(blk.cells[:, None, :], local.reshape(len(X), 1, -1), axis=2).reshape(local.shape)
        ends = np.sort(np.stack([glob[..., edges[:, 0]], glob[..., edges[:, 1]]], axis=-1), axis=-1)
        keys.append(ends.reshape(-1, 2))
        positions.append(at.reshape(-1, X.shape[2]))
        plans.append((blk, glob, len(edges)))
    allkeys = np.concatenate(keys)
    uniq, first, inv = np.unique(allkeys, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    points = np.vstack([mesh.points, np.concatenate(positions)[first]])
    blocks, start = [], 0
    for blk, glob, ne in plans:
        n, c, k = glob.shape
        mids = mesh.n_points + inv[start:start + n * c * ne].reshape(n, c, ne)
        start += n * c * ne
        cells = np.concatenate([glob, mids], axis=2).reshape(n * c, k + ne)
        blocks.append(CellBlock(blk.type, cells, None if blk.tags is None else np.repeat(blk.tags, c)))
    return Mesh(points, blocks)
