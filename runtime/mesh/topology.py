"""Topology changes of a solid mesh during a run: separating cells along faces, removing cells.

    pairs = plane_pairs(mesh, point, normal, box)      # cells facing each other across a plane
    split = separate(mesh, pairs)                       # unsew them: nodes duplicated, cells renumbered
    mesh2 = split.apply(mesh)                           # the new mesh (the old one is left untouched)
    gone = removal(mesh, cell_ids)                      # removing cells (ablation, resection)
    ref = refine_hexahedra(mesh, cell_ids)              # hexahedra split 1:8 (hanging nodes: runtime.physics.hanging)

The data structure is the mesh itself (point and cell arrays, VTK node order) plus a node -> cell
incidence built on demand in linear time (`incidence`).  We considered a combinatorial map
(darts and involutions, as in the thesis' chapter 5, or CGAL's / OpenVolumeMesh's half-face
structures): they make local queries O(1) but need a dart per (cell, face, edge) — about 24
darts per tetrahedron — kept in sync with every array the solver reads, and no well-kept Python
package provides one for mixed 3D cells.  A cut here only needs, for every node on the cut,
which of the cells around it stay connected once the cut faces are opened; that is a few sorts
over the cells around those nodes, so the arrays stay the single source of truth.

Separating (the cut surface is a set of interior faces, each given by the two cells it joins):
for every node of a cut face, the cells around the node are grouped into the components that
stay joined through faces containing the node that are not cut.  The component holding the
cell of lowest id keeps the node; every other component gets a new node (a copy of its rest
position, appended after the existing points) that replaces the old one in its cells.  A node
on the edge of an incision inside the body keeps one component and is not duplicated: the
incision opens everywhere but along its front.  Cell ids do not change; per-element constants
do not change either (the rest geometry of every cell is the same).

Removal takes cells out of the mesh; the cells after them shift down (`Removal.new_ids`).
Nodes no cell uses any more stay in the point array (the solver pins them).

Refinement splits hexahedra 1:8 at their edge midpoints, face centres and centre (a 3 x 3 x 3
lattice per hexahedron, shared with split neighbours); the created nodes and their parents are
recorded in Mesh.midpoints, from which runtime.physics.hanging finds the ones that hang on whole neighbours.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ... import elements as _types
from ..base.errors import TensormassError
from .container import CellBlock, Mesh
from .checks import check_shared_faces, check_structure
from .faces import face_table, solid_blocks

__all__ = ["TopologyError", "Incidence", "incidence", "cells_around", "face_owners", "plane_pairs", "box_cells", "separate", "Split",
           "removal", "Removal", "check_topology", "refine_hexahedra", "HexRefinement"]


class TopologyError(TensormassError):
    """A topology change that cannot be applied (it names what is wrong)."""


def block_offsets(mesh: Mesh) -> np.ndarray:
    return np.concatenate([[0], np.cumsum([len(b) for b in mesh.blocks])]).astype(np.int64)


def _solid_mesh(mesh: Mesh, what: str) -> None:
    flat = sorted({b.type for b in mesh.blocks if _types.get(b.type).dim != mesh.dim})
    if flat:
        raise TopologyError(f"{what}: only solid cells (tetrahedra, hexahedra, ... in 3D; triangles, quads in 2D) "
                            f"can be cut or removed here; the mesh has {', '.join(flat)} cells")


# --------------------------------------------------------------------------- incidence


@njit(cache=True)
def _count_sort(flat, n_points):
    """(ptr, order): order lists the positions in `flat` grouped by node, in increasing position."""
    ptr = np.zeros(n_points + 1, dtype=np.int64)
    for v in flat:
        ptr[v + 1] += 1
    for i in range(n_points):
        ptr[i + 1] += ptr[i]
    fill = ptr[:-1].copy()
    order = np.empty(flat.size, dtype=np.int64)
    for j in range(flat.size):
        v = flat[j]
        order[fill[v]] = j
        fill[v] += 1
    return ptr, order


@dataclass
class Incidence:
    """Node -> (global cell id, local node index) lists: entries ptr[n]:ptr[n + 1], cells in increasing id."""
    ptr: np.ndarray
    cell: np.ndarray
    local: np.ndarray

    def of(self, nodes: np.ndarray) -> tuple:
        """(node, cell, local) of every incidence of the given nodes (node by node)."""
        nodes = np.asarray(nodes, dtype=np.int64)
        counts = self.ptr[nodes + 1] - self.ptr[nodes]
        starts = np.repeat(self.ptr[nodes] - np.cumsum(counts) + counts, counts)
        at = starts + np.arange(counts.sum())
        return np.repeat(nodes, counts), self.cell[at], self.local[at]


def incidence(mesh: Mesh) -> Incidence:
    """The node -> cell incidence of every block, in linear time (a counting sort)."""
    flats, cells, locals_ = [], [], []
    for off, blk in zip(block_offsets(mesh), mesh.blocks):
        n, k = blk.cells.shape
        flats.append(blk.cells.ravel())
        cells.append(np.repeat(off + np.arange(n, dtype=np.int64), k))
        locals_.append(np.tile(np.arange(k, dtype=np.int64), n))
    flat = np.concatenate(flats) if flats else np.zeros(0, np.int64)
    ptr, order = _count_sort(flat, mesh.n_points)
    return Incidence(ptr, np.concatenate(cells)[order], np.concatenate(locals_)[order])


def _locate(mesh: Mesh, cell_ids: np.ndarray) -> tuple:
    """(block index, row in block) of global cell ids."""
    off = block_offsets(mesh)
    block = np.searchsorted(off, cell_ids, side="right") - 1
    return block, cell_ids - off[block]


def nodes_of_cells(mesh: Mesh, cell_ids: np.ndarray) -> list:
    block, row = _locate(mesh, cell_ids)
    return [mesh.blocks[b].cells[r] for b, r in zip(block, row)]


def cells_around(mesh: Mesh, inc: Incidence, nodes: np.ndarray) -> tuple:
    """(which, cells, cell nodes): every cell around each of the given nodes, `which` the index of the
    node it is around, and its nodes (-1 padded to the widest cell type)."""
    nodes = np.asarray(nodes, dtype=np.int64)
    counts = inc.ptr[nodes + 1] - inc.ptr[nodes]
    which = np.repeat(np.arange(nodes.size), counts)
    at = np.repeat(inc.ptr[nodes] - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())
    cells = inc.cell[at]
    block, row = _locate(mesh, cells)
    k = max(b.cells.shape[1] for b in mesh.blocks)
    out = np.full((cells.size, k), -1, dtype=np.int64)
    for b in np.unique(block):
        mine = block == b
        out[mine, :mesh.blocks[b].cells.shape[1]] = mesh.blocks[b].cells[row[mine]]
    return which, cells, out


def face_owners(mesh: Mesh, faces: np.ndarray, inc: Incidence | None = None) -> np.ndarray:
    """The cell owning each boundary face (n, kf): the first cell around its first node holding all of
    its nodes (-1: none)."""
    faces = np.asarray(faces, dtype=np.int64)
    if not len(faces):
        return np.zeros(0, dtype=np.int64)
    faces = faces.reshape(len(faces), -1)
    inc = incidence(mesh) if inc is None else inc
    which, cells, nodes = cells_around(mesh, inc, faces[:, 0])
    holds = (faces[which][:, :, None] == nodes[:, None, :]).any(axis=2).all(axis=1)
    owners = np.full(len(faces), -1, dtype=np.int64)
    hit = np.flatnonzero(holds)
    face, firsts = np.unique(which[hit], return_index=True)     # candidates in increasing cell id
    owners[face] = cells[hit[firsts]]
    return owners


# --------------------------------------------------------------------------- choosing faces


def _centroids(mesh: Mesh, block: CellBlock) -> np.ndarray:
    el = _types.get(block.type)
    return mesh.points[block.cells[:, :el.n_corners]].mean(axis=1)


def box_cells(mesh: Mesh, box, tol: float = 0.0) -> np.ndarray:
    """Global ids of the cells whose centroid lies inside the box [[min...], [max...]]."""
    lo, hi = (np.asarray(c, float) for c in box)
    out = []
    for off, blk in zip(block_offsets(mesh), mesh.blocks):
        c = _centroids(mesh, blk)
        inside = np.all((c >= lo - tol) & (c <= hi + tol), axis=1)
        out.append(off + np.flatnonzero(inside))
    return np.concatenate(out) if out else np.zeros(0, np.int64)


def face_rows(mesh: Mesh, cell_ids: np.ndarray):
    """Every face of the given cells: (sorted corner keys padded with -1 (m, 4), owner cell)."""
    block, row = _locate(mesh, cell_ids)
    keys, owner = [], []
    for b in np.unique(block):
        blk, el = mesh.blocks[b], _types.get(mesh.blocks[b].type)
        rows, ids = row[block == b], cell_ids[block == b]
        for face in el.faces:
            k = np.full((rows.size, 4), -1, dtype=np.int64)
            k[:, :len(face.corners)] = np.sort(blk.cells[rows][:, list(face.corners)], axis=1)
            keys.append(k)
            owner.append(ids)
    if not keys:
        return np.zeros((0, 4), np.int64), np.zeros(0, np.int64)
    return np.vstack(keys), np.concatenate(owner)


def shared_faces(keys: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """(m, 2) owner pairs of the face keys that occur twice (each pair sorted, pairs sorted)."""
    order = np.lexsort(keys.T[::-1])
    k, o = keys[order], owner[order]
    same = np.all(k[1:] == k[:-1], axis=1)
    i = np.flatnonzero(same)
    pairs = np.sort(np.stack([o[i], o[i + 1]], axis=1), axis=1)
    return pairs[np.lexsort(pairs.T[::-1])] if len(pairs) else pairs.reshape(0, 2)


def plane_pairs(mesh: Mesh, point, normal, box=None, tol: float = 0.0) -> np.ndarray:
    """Cell pairs (m, 2) to separate so that the mesh opens along a plane, staircase-wise on its faces.

    Cells are on the plane's positive side when their centroid is (strictly); the pairs are the
    face neighbours on opposite sides.  With a box, only cells with a node inside it take part and
    the shared face's centroid must be inside it too (an incision of limited extent).
    """
    _solid_mesh(mesh, "cut")
    p = np.asarray(point, float).reshape(-1)
    n = np.asarray(normal, float).reshape(-1)
    if p.size != mesh.dim or n.size != mesh.dim or not np.all(np.isfinite(np.r_[p, n])) or not np.any(n):
        raise TopologyError(f"cut plane: point and normal need {mesh.dim} finite components, the normal non-zero")
    n = n / np.linalg.norm(n)
    if box is not None:
        lo, hi = (np.asarray(c, float) - s * tol for c, s in zip(box, (1, -1)))
        near = np.all((mesh.points >= lo) & (mesh.points <= hi), axis=1)
    ids, side = [], []
    for off, blk in zip(block_offsets(mesh), mesh.blocks):
        rows = np.arange(len(blk)) if box is None else np.flatnonzero(near[blk.cells].any(axis=1))
        ids.append(off + rows)
        side.append((_centroids(mesh, blk)[rows] - p) @ n > 0)
    ids, side = np.concatenate(ids), np.concatenate(side)
    keys, owner = face_rows(mesh, ids)
    pairs = shared_faces(keys, owner)
    where = np.zeros(mesh.n_cells, dtype=np.int8)
    where[ids] = np.where(side, 1, -1)
    pairs = pairs[where[pairs[:, 0]] != where[pairs[:, 1]]]
    if box is not None and len(pairs):
        centre = np.array([mesh.points[np.intersect1d(a, b)].mean(axis=0)
                           for a, b in zip(nodes_of_cells(mesh, pairs[:, 0]), nodes_of_cells(mesh, pairs[:, 1]))])
        inside = np.all((centre >= lo) & (centre <= hi), axis=1)
        pairs = pairs[inside]
    return pairs


# --------------------------------------------------------------------------- separating


@dataclass
class Split:
    """The result of `separate`: new nodes and the cells that now use them (nothing applied yet)."""
    n_points: int                # points before
    parents: np.ndarray          # (n_new,) the node each new node copies (new ids n_points + i)
    cells: np.ndarray            # (m,) global ids of the cells renumbered
    local: np.ndarray            # (m,) the local node index renumbered in that cell
    node: np.ndarray             # (m,) the new node id it takes
    faces: int                   # cut faces opened (a face whose nodes all stay on the front is not)

    @property
    def n_new(self) -> int:
        return int(self.parents.size)

    @property
    def changed_cells(self) -> np.ndarray:
        return np.unique(self.cells)

    @property
    def touched_nodes(self) -> np.ndarray:
        """The nodes whose cells changed: the parents and the new nodes."""
        return np.unique(np.concatenate([self.parents, self.n_points + np.arange(self.n_new)]))

    def apply(self, mesh: Mesh) -> Mesh:
        """The separated mesh (new arrays where something changed; `mesh` is left as it was)."""
        points = np.vstack([mesh.points, mesh.points[self.parents]])
        block, row = _locate(mesh, self.cells)
        blocks = []
        for b, blk in enumerate(mesh.blocks):
            mine = block == b
            if not mine.any():
                blocks.append(blk)
                continue
            cells = blk.cells.copy()
            cells[row[mine], self.local[mine]] = self.node[mine]
            blocks.append(CellBlock(blk.type, cells, blk.tags))
        return Mesh(points, blocks, self._groups(mesh), mesh.midpoints)

    def _groups(self, mesh: Mesh) -> list:
        """Mesh groups: their faces (surface groups) follow the cells that own them."""
        touched = np.zeros(mesh.n_points, dtype=bool)
        touched[self.parents] = True
        out = []
        for g in mesh.groups:
            faces = {}
            for name, f in g.cells.items():
                f = np.asarray(f, dtype=np.int64)
                hit = touched[f].any(axis=1) if f.ndim == 2 and f.size else np.zeros(len(f), bool)
                if hit.any():
                    f = f.copy()
                    f[hit] = self.map_faces(f[hit], face_owners(mesh, f[hit], getattr(self, "incidence", None)))
                faces[name] = f
            out.append(replace(g, cells=faces) if faces else g)
        return out

    def map_faces(self, faces: np.ndarray, owners: np.ndarray) -> np.ndarray:
        """Boundary faces (n, kf) owned by the given cells, with the owners' new node ids."""
        faces = np.array(faces, dtype=np.int64, copy=True)
        if not self.cells.size or not faces.size:
            return faces
        n = self.n_points
        old = self.parents[self.node - n]
        key = self.cells * n + old                     # (cell, old node) of every renumbering
        order = np.argsort(key)
        key, new = key[order], self.node[order]
        for j in range(faces.shape[1]):
            want = np.asarray(owners, dtype=np.int64) * n + faces[:, j]
            at = np.minimum(np.searchsorted(key, want), key.size - 1)
            hit = key[at] == want
            faces[hit, j] = new[at[hit]]
        return faces


def _faces_at(el) -> np.ndarray:
    """(k, f) for each local node, the faces of the element that contain it (-1 padded)."""
    rows = [[i for i, f in enumerate(el.faces) if a in f.nodes] for a in range(el.n_nodes)]
    width = max(len(r) for r in rows)
    out = np.full((el.n_nodes, width), -1, dtype=np.int64)
    for a, r in enumerate(rows):
        out[a, :len(r)] = r
    return out


def _pair_faces(mesh: Mesh, pairs: np.ndarray) -> np.ndarray:
    """Sorted corner keys (m, 4) of the faces the cell pairs share; refused where they share none."""
    keys, owner = face_rows(mesh, np.unique(pairs))
    order = np.lexsort(keys.T[::-1])
    k, o = keys[order], owner[order]
    same = np.flatnonzero(np.all(k[1:] == k[:-1], axis=1))
    n = np.int64(mesh.n_cells)
    code = np.minimum(o[same], o[same + 1]) * n + np.maximum(o[same], o[same + 1])
    by_code = np.argsort(code)
    code, shared = code[by_code], k[same][by_code]
    want = pairs.min(axis=1) * n + pairs.max(axis=1)
    at = np.minimum(np.searchsorted(code, want), max(code.size - 1, 0))
    found = (code.size > 0) & (code[at] == want) if code.size else np.zeros(len(pairs), bool)
    if not np.all(found):
        bad = pairs[~found]
        shown = ", ".join(f"{a}-{b}" for a, b in bad[:6]) + (" ..." if len(bad) > 6 else "")
        raise TopologyError(f"cut: {len(bad)} cell pair(s) share no face (already separated, or not "
                            f"neighbours): {shown}")
    return shared[at].reshape(-1, 4)


def separate(mesh: Mesh, pairs, inc: Incidence | None = None) -> Split:
    """Unsew the faces shared by the cell pairs (m, 2): see the module docstring.

    Refused: pairs that share no face; a cut that separates nothing (every node of its faces lies on
    its front inside the body).  inc: the mesh's incidence when the caller keeps one.
    """
    _solid_mesh(mesh, "cut")
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if not len(pairs):
        raise TopologyError("cut: no face to cut (the cut surface meets no interior face of the mesh)")
    if pairs.min() < 0 or pairs.max() >= mesh.n_cells:
        raise TopologyError(f"cut: cell ids must be in 0..{mesh.n_cells - 1}")
    pair_keys = _pair_faces(mesh, pairs)
    cut_keys = np.unique(pair_keys, axis=0)
    inc = incidence(mesh) if inc is None else inc
    nodes = np.unique(cut_keys[cut_keys >= 0])
    nodes = _with_midsides(mesh, nodes, pairs)
    node, cell, local = inc.of(nodes)
    edges = _joins(mesh, node, cell, local, cut_keys)
    P = node.size
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(P, P)) if len(edges) \
        else coo_matrix((P, P))
    _, comp = connected_components(graph, directed=False)
    # per node, its components ordered by their lowest cell: the first keeps the node
    lowest = np.full(comp.max(initial=-1) + 1, np.iinfo(np.int64).max)
    np.minimum.at(lowest, comp, cell)
    order = np.lexsort((lowest[comp], node))
    n_sorted, c_sorted = node[order], comp[order]
    first_of_node = np.r_[True, n_sorted[1:] != n_sorted[:-1]]
    new_comp = np.r_[True, (c_sorted[1:] != c_sorted[:-1]) | first_of_node[1:]]
    # runs of entries of one component; the first run of every node keeps the node
    starts = np.flatnonzero(new_comp)
    run = np.cumsum(new_comp) - 1
    new_runs = run[new_comp & ~first_of_node]
    new_id = np.full(starts.size, -1, dtype=np.int64)
    new_id[new_runs] = mesh.n_points + np.arange(new_runs.size)
    target = np.empty(P, dtype=np.int64)
    target[order] = new_id[run]
    moved = np.flatnonzero(target >= 0)
    if new_runs.size == 0:
        raise TopologyError(f"cut: the {len(cut_keys)} face(s) separate nothing: every node of them lies on the "
                            "cut's front inside the body; make the cut reach the surface or cover more faces")
    parents = n_sorted[starts[new_runs]]
    split = Split(mesh.n_points, parents, cell[moved], local[moved], target[moved], 0)
    split.faces = _opened(split, pairs, pair_keys)
    split.incidence = inc                   # of the mesh before: face owners for its groups and loads
    return split


def _opened(split: Split, pairs: np.ndarray, keys: np.ndarray) -> int:
    """How many of the cut faces the split opens (some corner differs between the two cells); the
    others wait for more faces (an incision's front)."""
    a = split.map_faces(np.where(keys >= 0, keys, 0), pairs[:, 0])
    b = split.map_faces(np.where(keys >= 0, keys, 0), pairs[:, 1])
    return int(np.count_nonzero(np.any((a != b) & (keys >= 0), axis=1)))


def _with_midsides(mesh: Mesh, nodes: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """The cut faces' corner nodes plus, for quadratic cells, the midside nodes on those faces."""
    if not any(_types.get(b.type).quadratic for b in mesh.blocks):
        return nodes
    extra = []
    corners = set(nodes.tolist())
    for ids in (pairs[:, 0], pairs[:, 1]):
        block, row = _locate(mesh, ids)
        for b, r in zip(block, row):
            blk, el = mesh.blocks[b], _types.get(mesh.blocks[b].type)
            for face in el.faces:
                c = blk.cells[r]
                if all(int(c[i]) in corners for i in face.corners):
                    extra.extend(int(c[i]) for i in face.nodes[len(face.corners):])
    return np.unique(np.concatenate([nodes, np.asarray(extra, dtype=np.int64)]))


def _type_tables(mesh):
    """Per block: (faces containing each local node (k, f), face corners (F, 4)), padded with -1 and
    stacked over the blocks' types so numba reads them by block index."""
    els = [_types.get(b.type) for b in mesh.blocks]
    k = max(el.n_nodes for el in els)
    nf = max(len(el.faces) for el in els)
    at = [_faces_at(el) for el in els]
    width = max(t.shape[1] for t in at)
    faces_at = np.full((len(els), k, width), -1, dtype=np.int64)
    corners = np.full((len(els), nf, 4), -1, dtype=np.int64)
    for i, (el, t) in enumerate(zip(els, at)):
        faces_at[i, :t.shape[0], :t.shape[1]] = t
        for f, face in enumerate(el.faces):
            corners[i, f, :len(face.corners)] = face.corners
    return faces_at, corners


@njit(cache=True)
def _face_key(nodes, corners, out):
    """out = the face's global corner ids sorted ascending, -1 padded at the front (so -1 sort first)."""
    for j in range(4):
        out[j] = nodes[corners[j]] if corners[j] >= 0 else -1
    for i in range(1, 4):            # insertion sort of 4
        v = out[i]
        j = i - 1
        while j >= 0 and out[j] > v:
            out[j + 1] = out[j]
            j -= 1
        out[j + 1] = v


@njit(cache=True)
def _is_cut(key, cut_keys):
    """Binary search of a key (4,) among the lexicographically sorted rows of cut_keys."""
    lo, hi = 0, cut_keys.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        less = False
        equal = True
        for j in range(4):
            if cut_keys[mid, j] != key[j]:
                less = cut_keys[mid, j] < key[j]
                equal = False
                break
        if equal:
            return True
        if less:
            lo = mid + 1
        else:
            hi = mid
    return False


@njit(cache=True)
def _join_pairs(node, block, cell_nodes, local, faces_at, corners, cut_keys):
    """Pairs of entries (same node, consecutive runs) whose cells share a face holding the node that is
    not cut.  cell_nodes: (P, k) the entry's cell nodes (-1 padded).  Per node, its faces are sorted by a
    hash of their corners and equal keys are looked for among equal hashes only."""
    P, S = node.shape[0], faces_at.shape[2]
    keys = np.full((P * S, 4), -2, dtype=np.int64)
    owner = np.empty(P * S, dtype=np.int64)
    hashes = np.empty(P * S, dtype=np.int64)
    n = 0
    for e in range(P):
        for s in range(S):
            f = faces_at[block[e], local[e], s]
            if f >= 0:
                _face_key(cell_nodes[e], corners[block[e], f], keys[n])
                owner[n] = e
                h = np.int64(1469598103934665603)
                for j in range(4):
                    h = (h ^ keys[n, j]) * np.int64(1099511628211)       # FNV-1a, wrapping
                hashes[n] = h
                n += 1
    out = np.empty((P * 4, 2), dtype=np.int64)
    m = 0
    start = 0
    while start < n:                  # the rows of one node are consecutive (entries node by node)
        stop = start
        while stop < n and node[owner[stop]] == node[owner[start]]:
            stop += 1
        order = start + np.argsort(hashes[start:stop], kind="mergesort")
        i = 0
        while i < order.size:
            j = i
            while j < order.size and hashes[order[j]] == hashes[order[i]]:
                j += 1
            for x in range(i, j):
                for y in range(x + 1, j):
                    r, q = order[x], order[y]
                    if (keys[r, 0] == keys[q, 0] and keys[r, 1] == keys[q, 1] and keys[r, 2] == keys[q, 2]
                            and keys[r, 3] == keys[q, 3] and owner[r] != owner[q] and not _is_cut(keys[r], cut_keys)):
                        if m == out.shape[0]:
                            grown = np.empty((2 * m, 2), dtype=np.int64)
                            grown[:m] = out
                            out = grown
                        out[m, 0] = min(owner[r], owner[q])
                        out[m, 1] = max(owner[r], owner[q])
                        m += 1
            i = j
        start = stop
    return out[:m]


def _joins(mesh, node, cell, local, cut_keys) -> np.ndarray:
    """Edges (e, 2) between incidence entries (same node) whose cells share an uncut face holding it."""
    block, row = _locate(mesh, cell)
    k = max(b.cells.shape[1] for b in mesh.blocks)
    cell_nodes = np.full((node.size, k), -1, dtype=np.int64)
    for b in np.unique(block):
        mine = block == b
        cell_nodes[mine, :mesh.blocks[b].cells.shape[1]] = mesh.blocks[b].cells[row[mine]]
    faces_at, corners = _type_tables(mesh)
    # cut keys sorted ascending with the -1 padding first, as _face_key writes them
    keys = np.sort(np.where(cut_keys >= 0, cut_keys, -1), axis=1)
    keys = keys[np.lexsort(keys.T[::-1])]
    return _join_pairs(node, block, cell_nodes, local, faces_at, corners, np.ascontiguousarray(keys))


def _rows_in(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """For each row of a, whether it is a row of b (both int64, same width)."""
    if not len(b) or not len(a):
        return np.zeros(len(a), dtype=bool)
    width = a.shape[1]
    view = np.dtype((np.void, 8 * width))
    av = np.ascontiguousarray(a).view(view).ravel()
    bv = np.ascontiguousarray(b).view(view).ravel()
    return np.isin(av, bv)


# --------------------------------------------------------------------------- removal


@dataclass
class Removal:
    """Cells taken out of a mesh: `new_ids[c]` is cell c's id afterwards (-1: removed)."""
    removed: np.ndarray          # sorted global ids of the removed cells
    new_ids: np.ndarray          # (n_cells before,) int64
    orphans: np.ndarray          # nodes no remaining cell uses (that some removed cell used)
    touched: np.ndarray          # every node of the removed cells

    def apply(self, mesh: Mesh) -> Mesh:
        off = block_offsets(mesh)
        blocks = []
        for b, blk in enumerate(mesh.blocks):
            keep = self.new_ids[off[b]:off[b + 1]] >= 0
            if keep.all():
                blocks.append(blk)
            elif keep.any():
                blocks.append(CellBlock(blk.type, blk.cells[keep], None if blk.tags is None else blk.tags[keep]))
        return Mesh(mesh.points, blocks, self._groups(mesh), mesh.midpoints)

    def _groups(self, mesh: Mesh) -> list:
        """Mesh groups: cell ids renumbered (removed ones dropped), faces of removed cells dropped."""
        near = np.zeros(mesh.n_points, dtype=bool)
        near[self.touched] = True
        out = []
        for g in mesh.groups:
            ids = self.new_ids[g.cell_ids] if g.cell_ids.size else g.cell_ids
            faces = {}
            for name, f in g.cells.items():
                f = np.asarray(f, dtype=np.int64)
                if f.ndim == 2 and f.size:
                    hit = np.flatnonzero(near[f].any(axis=1))
                    owners = face_owners(mesh, f[hit])
                    keep = np.ones(len(f), bool)
                    keep[hit[(owners >= 0) & (self.new_ids[np.maximum(owners, 0)] < 0)]] = False
                    f = f[keep]
                faces[name] = f
            out.append(replace(g, cell_ids=ids[ids >= 0], cells=faces))
        return out


def removal(mesh: Mesh, cell_ids, inc: Incidence | None = None) -> Removal:
    """Remove the given cells; refused when nothing is selected or nothing would remain."""
    _solid_mesh(mesh, "remove")
    ids = np.unique(np.asarray(cell_ids, dtype=np.int64))
    if ids.size == 0:
        raise TopologyError("remove: no cell selected")
    if ids.min() < 0 or ids.max() >= mesh.n_cells:
        raise TopologyError(f"remove: cell ids must be in 0..{mesh.n_cells - 1}")
    if ids.size == mesh.n_cells:
        raise TopologyError("remove: every cell of the mesh would be removed")
    keep = np.ones(mesh.n_cells, dtype=bool)
    keep[ids] = False
    new_ids = np.where(keep, np.cumsum(keep) - 1, -1)
    inc = incidence(mesh) if inc is None else inc
    nodes = np.unique(np.concatenate(nodes_of_cells(mesh, ids)))
    node, cell, _ = inc.of(nodes)
    alive = np.zeros(mesh.n_points, dtype=bool)
    alive[node[keep[cell]]] = True
    return Removal(ids, new_ids, nodes[~alive[nodes]], nodes)


# --------------------------------------------------------------------------- checks


def check_topology(mesh: Mesh) -> None:
    """Conformity after a topology change: node ids in range, no repeated node in a cell, every face
    shared by at most two cells (from opposite sides, same nodes).  The lips of a cut are coincident
    boundary faces with different nodes, which `check_mesh` would take for unmerged duplicates."""
    check_structure(mesh)
    if solid_blocks(mesh):
        check_shared_faces(mesh, face_table(mesh))


# --------------------------------------------------------------------------- hexahedral refinement

# The 3 x 3 x 3 lattice of a hexahedron split 1:8: lattice point (i, j, k) in {0, 1, 2}^3 sits at
# reference coordinates (i - 1, j - 1, k - 1); VTK corner c of the hexahedron at _CORNER[c].
_CORNER = np.array([(0, 0, 0), (2, 0, 0), (2, 2, 0), (0, 2, 0), (0, 0, 2), (2, 0, 2), (2, 2, 2), (0, 2, 2)])
_CHILD = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)])


def _lattice_parents() -> list:
    """For each of the 27 lattice points: the corners (local ids) whose mean it is."""
    out = []
    for i in range(3):
        for j in range(3):
            for k in range(3):
                p = np.array([i, j, k])
                # the corners sharing the point's coordinates where those are 0 or 2
                fixed = p != 1
                out.append(tuple(c for c in range(8) if np.all(_CORNER[c][fixed] == p[fixed])))
    return out


_PARENTS = _lattice_parents()


@dataclass
class HexRefinement:
    """Hexahedra split 1:8: `apply` gives the refined mesh; `weights` interpolates nodal values."""
    mesh: Mesh
    parents: list                # per new node, its parent nodes (2, 4 or 8): its value is their mean
    refined: np.ndarray          # global ids (before) of the split hexahedra
    new_ids: np.ndarray          # (n_cells before,) id of each old cell afterwards (the first child for split ones)
    cell_parent: np.ndarray | None = None   # (n_cells after,) the old id of each cell's parent (itself if not split)

    def interpolate(self, values: np.ndarray, n_old: int) -> np.ndarray:
        """Nodal values (n_old, ...) extended to the new nodes (the mean of their parents: exact for the
        trilinear field of the split hexahedra)."""
        values = np.asarray(values)
        out = np.empty((n_old + len(self.parents),) + values.shape[1:], dtype=np.result_type(values, float))
        out[:n_old] = values
        for i, p in enumerate(self.parents):
            out[n_old + i] = values[list(p)].mean(axis=0)
        return out


def refine_hexahedra(mesh: Mesh, cell_ids) -> HexRefinement:
    """Split the given hexahedra 1:8 (edge midpoints, face centres, the centre), sharing the new
    nodes between neighbours that are both split; neighbours left whole get hanging nodes, which
    Mesh.midpoints records (runtime.physics.hanging constrains them).  The children of a hexahedron take its
    block: the first replaces it, the others follow the block's cells."""
    ids = np.unique(np.asarray(cell_ids, dtype=np.int64))
    if not ids.size:
        raise TopologyError("refine: no cell selected")
    if mesh.groups:
        raise TopologyError("refine: meshes with named groups (a gmsh file's physical groups) cannot be "
                            "refined here yet")
    block, row = _locate(mesh, ids)
    bad = sorted({mesh.blocks[b].type for b in block if mesh.blocks[b].type != "hexahedron"})
    if bad:
        raise TopologyError(f"refine: only hexahedra are split 1:8 here (triangles and tetrahedra refine by "
                            f"bisection: [[adapt]] action = \"refine\"); selected: {', '.join(bad)}")
    points = [mesh.points]
    n = mesh.n_points
    created: dict = {}
    parents_of_new: list = []
    midpoints = [] if mesh.midpoints is None else [np.asarray(mesh.midpoints, dtype=np.int64)]
    # a node an earlier refinement put on an edge or face is that edge's or face's node now too
    # (a new one at the same place would tear the mesh there)
    for known in (midpoints[0].tolist() if midpoints else []):
        created[tuple(sorted(p for p in known[1:] if p >= 0))] = known[0]

    def node_for(corners: tuple):
        nonlocal n
        key = tuple(sorted(corners))
        if key not in created:
            created[key] = n
            parents_of_new.append(key)
            points.append(mesh.points[list(key)].mean(axis=0)[None])
            if len(key) in (2, 4):
                midpoints.append(np.array([[n, *key, *([-1] * (4 - len(key)))]], dtype=np.int64))
            n += 1
        return created[key]

    children = {}
    for b, r in zip(block, row):
        corners = mesh.blocks[b].cells[r]
        lattice = np.empty((3, 3, 3), dtype=np.int64)
        for idx, parents in enumerate(_PARENTS):
            i, j, k = idx // 9, (idx // 3) % 3, idx % 3
            lattice[i, j, k] = corners[parents[0]] if len(parents) == 1 else node_for(tuple(corners[list(parents)]))
        kids = [[lattice[tuple(c + d)] for d in _CORNER // 2] for c in _CHILD]
        children.setdefault(b, []).append((r, np.array(kids, dtype=np.int64)))
    blocks, new_ids, parent = [], [], []
    old_start = np.concatenate([[0], np.cumsum([len(blk) for blk in mesh.blocks])])
    for b, blk in enumerate(mesh.blocks):
        cells = blk.cells
        parent.append(old_start[b] + np.arange(len(blk)))
        if b in children:
            parent += [np.full(7, old_start[b] + r) for r, _ in children[b]]
            cells = cells.copy()
            extra = []
            for r, kids in children[b]:
                cells[r] = kids[0]
                extra.append(kids[1:])
            cells = np.vstack([cells] + extra)
            tags = None if blk.tags is None else np.concatenate(
                [blk.tags] + [np.full(7, blk.tags[r]) for r, _ in children[b]])
            blocks.append(CellBlock(blk.type, cells, tags))
        else:
            blocks.append(blk)
        new_ids.append(sum(len(x) for x in blocks[:-1]) + np.arange(len(blk)))
    refined_mesh = Mesh(np.vstack(points), blocks, [], np.vstack(midpoints) if midpoints else None)
    return HexRefinement(refined_mesh, parents_of_new, ids, np.concatenate(new_ids), np.concatenate(parent))
