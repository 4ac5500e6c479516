"""Validity checks of a mesh (check_mesh): types, coordinates, node ids, duplicated cells, shell
windings, det J, shared and overlapping faces, midside nodes, groups on the surface; and
orient_cells, which turns inverted cells of a mirrored mesh."""
from __future__ import annotations


import numpy as np
from .container import COORD_MAX, CellBlock, DET_TOL, INSIDE_TOL, Mesh, MeshError, PLANE_TOL, SIZE_MIN, block_offsets, format_ids
from .faces import FaceTable, boundary_rows, cell_sizes, face_table, group_rows, sample_dets, solid_blocks
from .mesh_groups import check_groups_on_surface
from .surfaces import winding_conflicts

from ... import elements as _types

# --------------------------------------------------------------------------- checks


def check_mesh(mesh: Mesh) -> None:
    """Raise MeshError unless the mesh is a valid, conforming, positively oriented FE mesh.

    Checks, in order: cell types fit the dimension and there is at least one
    cell; finite coordinates; indices in range; no repeated node in a cell;
    det J > 0 (relative to cell size) at every corner and the centroid; every
    face shared by at most two cells, from opposite sides, with equal node
    order and midside nodes; no non-conforming interface (a face covered by
    other faces with different nodes: hanging nodes, a quad against two
    triangles, mismatched diagonals, unmerged duplicate nodes).  Unused points
    are allowed.
    """
    check_structure(mesh)
    _check_jacobians(mesh)
    if not solid_blocks(mesh):     # only lower-dimensional cells (bars in 3D, ...): no faces to match
        _check_midsides(mesh)
        return
    ft = face_table(mesh)
    check_shared_faces(mesh, ft)
    _check_midsides(mesh)
    _check_quad_against_triangles(ft)
    _check_overlapping_faces(mesh, ft)
    check_groups_on_surface(mesh, ft, boundary_rows(ft), MeshError)


def check_structure(mesh: Mesh) -> None:
    if mesh.n_cells == 0:
        raise MeshError("mesh has no cells")
    wrong = sorted({b.type for b in mesh.blocks if mesh.dim not in _types.get(b.type).space_dims})
    if wrong:
        raise MeshError(f"cell type(s) {', '.join(wrong)} do not fit a {mesh.dim}D mesh")
    check_coordinates(mesh.points)
    off = block_offsets(mesh)
    out_of_range, repeated = [], []
    for bi, blk in enumerate(mesh.blocks):
        c = blk.cells
        out_of_range.append(off[bi] + np.flatnonzero(np.any((c < 0) | (c >= mesh.n_points), axis=1)))
        s = np.sort(c, axis=1)
        repeated.append(off[bi] + np.flatnonzero(np.any(s[:, 1:] == s[:, :-1], axis=1)))
    out_of_range, repeated = np.concatenate(out_of_range), np.concatenate(repeated)
    if out_of_range.size:
        raise MeshError(f"node index out of range 0..{mesh.n_points - 1} in cells {format_ids(out_of_range)}")
    if repeated.size:
        raise MeshError(f"repeated node within a cell in cells {format_ids(repeated)}")
    _check_duplicated_cells(mesh, off)
    _check_shell_windings(mesh, off)


def _check_duplicated_cells(mesh: Mesh, off) -> None:
    """Two cells on the same nodes (a file listing a cell twice) would count its stiffness, mass and
    loads twice: refused, naming the pairs."""
    pairs = []
    for ctype in dict.fromkeys(b.type for b in mesh.blocks):
        mine = [bi for bi, b in enumerate(mesh.blocks) if b.type == ctype and len(b)]
        if not mine:
            continue
        rows = np.sort(np.concatenate([mesh.blocks[bi].cells for bi in mine]), axis=1)
        ids = np.concatenate([off[bi] + np.arange(len(mesh.blocks[bi])) for bi in mine])
        _, first, inverse = np.unique(rows, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.reshape(-1)
        again = np.flatnonzero(first[inverse] != np.arange(len(rows)))
        pairs += [(ctype, int(ids[first[inverse[i]]]), int(ids[i])) for i in again]
    if pairs:
        head = "; ".join(f"{t} cells {a} and {b}" for t, a, b in pairs[:5])
        raise MeshError(f"duplicated cells (overlapping: the same nodes twice, their stiffness, mass and "
                        f"loads would count twice): {head}{' ...' if len(pairs) > 5 else ''} ({len(pairs)} duplicate(s) in all)")


def _check_shell_windings(mesh: Mesh, off) -> None:
    """Shell triangles take their normal (pressure, the enclosed volume) from their winding:
    neighbours wound against each other would push opposite ways.  A file's shell triangles are
    oriented when read (runtime.mesh.surfaces.orient_triangles); a mesh that still disagrees is refused."""
    for bi, blk in enumerate(mesh.blocks):
        if blk.type != "shell" or not len(blk):
            continue
        bad = winding_conflicts(blk.cells)
        if bad.size:
            pairs = ", ".join(f"{off[bi] + a}-{off[bi] + b}" for a, b in bad[:5].tolist())
            raise MeshError(f"shell triangles wound against their neighbours (their normals point to "
                            f"opposite sides across a shared edge): cell pairs {pairs}"
                            f"{' ...' if len(bad) > 5 else ''} ({len(bad)} edge(s)); wind every triangle "
                            f"of a surface the same way (in gmsh: ReverseMesh Surface{{...}} on the surfaces that face the "
                            f"other way)")


def _fmt_point(p) -> str:
    return "(" + ", ".join(f"{float(v):g}" for v in p) + ")"


def check_coordinates(points) -> None:
    """Raise MeshError naming a node whose coordinates are NaN/Inf or out of float64's safe range.

    Run before anything that measures the mesh: a NaN coordinate otherwise turns box
    tolerances into NaN ("no mesh node inside") and 1e200 overflows det J ("degenerate").
    """
    points = np.asarray(points, dtype=float)
    if points.size == 0:
        return
    bad = np.flatnonzero(~np.all(np.isfinite(points), axis=1))
    if bad.size:
        raise MeshError(f"non-finite (NaN/Inf) coordinates at nodes {format_ids(bad, noun='node')}: "
                        f"node {int(bad[0])} is at {_fmt_point(points[bad[0]])}")
    far = np.abs(points).max(axis=1)
    if far.max() > COORD_MAX:
        i = int(np.argmax(far))
        raise MeshError(f"coordinates too large: node {i} is at {_fmt_point(points[i])}, beyond +-{COORD_MAX:g} "
                        f"({int(np.count_nonzero(far > COORD_MAX))} node(s)); element volumes and energies "
                        "would overflow float64 (a unit mix-up? coordinates are in meters)")
    size = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    if len(points) > 1 and 0.0 < size < SIZE_MIN:
        raise MeshError(f"mesh too small: its bounding box diagonal is {size:g} m, below {SIZE_MIN:g}; element "
                        "volumes and energies would underflow float64 (a unit mix-up? coordinates are in meters)")


def _check_jacobians(mesh: Mesh) -> None:
    off = block_offsets(mesh)
    inverted, degenerate = [], []
    for bi, blk in enumerate(mesh.blocks):
        dets = sample_dets(mesh.points, blk)
        tol = DET_TOL * cell_sizes(mesh.points, blk) ** _types.get(blk.type).dim
        lo = dets.min(axis=1)
        inverted.append(off[bi] + np.flatnonzero(lo < -tol))
        degenerate.append(off[bi] + np.flatnonzero((lo >= -tol) & (lo <= tol)))
    inverted, degenerate = np.concatenate(inverted), np.concatenate(degenerate)
    msgs = []
    if inverted.size:
        msgs.append(f"inverted cells (det J < 0 at a corner or the centroid) {format_ids(inverted)}"
                    + _node_order_hint(mesh, inverted))
    if degenerate.size:
        msgs.append(f"degenerate cells (det J ~ 0, collapsed or flat) {format_ids(degenerate)}")
    if msgs:
        raise MeshError("; ".join(msgs))


def _node_order_hint(mesh: Mesh, inverted: np.ndarray) -> str:
    """When every cell of a type is inverted, the file's node order (or orientation) is the likely cause."""
    off = block_offsets(mesh)
    count: dict = {}
    for bi, blk in enumerate(mesh.blocks):
        hit = int(np.count_nonzero((inverted >= off[bi]) & (inverted < off[bi + 1])))
        total, bad = count.get(blk.type, (0, 0))
        count[blk.type] = (total + len(blk), bad + hit)
    whole = [t for t, (total, bad) in count.items() if total and bad == total]
    if not whole:
        return ""
    return (f"; every {' and every '.join(whole)} cell is inverted: the file's node order for "
            f"{'this type' if len(whole) == 1 else 'these types'} is probably not VTK's (meshio's), or the "
            "cells are mirrored (a surface mesh with its normal along -z, a mirrored part); tensormass reads "
            "gmsh .msh files with their node order converted (see README, node order), "
            "runtime.mesh.checks.orient_cells renumbers mirrored cells")


def _face_orientation(ft: FaceTable, rows: np.ndarray):
    """Cyclic orientation of faces: (sign, node opposite the minimum or -1).

    Rotating each face so that its smallest node comes first, the face runs one
    way if the next node is smaller than the previous one.  Two cells on opposite
    sides of a face traverse it in opposite directions.
    """
    F, nv = ft.nodes[rows], ft.nvert[rows]
    sign = np.empty(len(rows), dtype=bool)
    opp = np.full(len(rows), -1, dtype=np.int64)
    for v in np.unique(nv):
        sel = np.flatnonzero(nv == v)
        R = F[sel, :v]
        if v == 2:  # an edge: its direction
            sign[sel] = R[:, 0] < R[:, 1]
            continue
        m = np.argmin(R, axis=1)
        ar = np.arange(len(sel))
        sign[sel] = R[ar, (m + 1) % v] < R[ar, (m - 1) % v]
        if v == 4:
            opp[sel] = R[ar, (m + 2) % v]
    return sign, opp


def check_shared_faces(mesh: Mesh, ft: FaceTable) -> None:
    kind = "edge" if mesh.dim == 2 else "face"
    over = np.flatnonzero(ft.count[ft.group] > 2)
    if over.size:
        raise MeshError(f"{kind}s shared by more than two cells (overlapping cells) in cells {format_ids(ft.cell[over])}")
    # rows of shared faces come in adjacent pairs in the sorted order
    srt = ft.order
    starts = np.flatnonzero(ft.count[ft.group[srt]] == 2)
    starts = starts[ft.group[srt[starts]] != np.concatenate([[-1], ft.group[srt]])[starts]]
    a, b = srt[starts], srt[starts + 1]
    sign, opp = _face_orientation(ft, np.concatenate([a, b]))
    n = len(a)
    same_side = sign[:n] == sign[n:]
    twisted = opp[:n] != opp[n:]
    mixed = ft.quadratic[a] != ft.quadratic[b]
    for mask, what in ((same_side, f"cells on the same side of a shared {kind} (overlapping or inconsistently oriented)"),
                       (twisted, "shared quad faces with different node order (twisted)"),
                       (mixed, f"linear and quadratic cells sharing a {kind} (hanging midside nodes)")):
        if np.any(mask):
            raise MeshError(f"{what}: {_fmt_pairs(ft.cell[a[mask]], ft.cell[b[mask]])}")


def _fmt_pairs(ca, cb, first: int = 5) -> str:
    pairs = sorted({(int(min(x, y)), int(max(x, y))) for x, y in zip(ca, cb)})
    head = ", ".join(f"{x} and {y}" for x, y in pairs[:first])
    more = ", ..." if len(pairs) > first else ""
    return f"cells {head}{more} ({len(pairs)} pair{'' if len(pairs) == 1 else 's'})"


def _check_midsides(mesh: Mesh) -> None:
    """Cells sharing a corner edge must share its midside node."""
    keys, mids, cells = [], [], []
    off = block_offsets(mesh)
    for bi, blk in enumerate(mesh.blocks):
        el = _types.get(blk.type)
        nc = el.n_corners
        for m, (p, q) in enumerate(el.midside_edges):
            keys.append(np.sort(blk.cells[:, [p, q]], axis=1))
            mids.append(blk.cells[:, nc + m])
            cells.append(off[bi] + np.arange(len(blk)))
    if not keys:
        return
    keys, mids, cells = np.concatenate(keys), np.concatenate(mids), np.concatenate(cells)
    order = np.lexsort((mids, keys[:, 1], keys[:, 0]))
    k, m, c = keys[order], mids[order], cells[order]
    bad = np.flatnonzero(np.all(k[1:] == k[:-1], axis=1) & (m[1:] != m[:-1]))
    if bad.size:
        raise MeshError(f"cells sharing an edge but not its midside node: {_fmt_pairs(c[bad], c[bad + 1])}")


def _check_quad_against_triangles(ft: FaceTable) -> None:
    """A boundary triangle whose three nodes all belong to one boundary quad splits that quad."""
    rows = boundary_rows(ft)
    quads, tris = rows[ft.nvert[rows] == 4], rows[ft.nvert[rows] == 3]
    if quads.size == 0 or tris.size == 0:
        return
    Q = ft.nodes[quads]
    triples = np.concatenate([np.sort(Q[:, [i for i in range(4) if i != skip]], axis=1) for skip in range(4)])
    owner = np.tile(quads, 4)
    T = np.sort(ft.nodes[tris, :3], axis=1)
    keys = np.concatenate([triples, T])
    src = np.concatenate([owner, tris])
    is_tri = np.concatenate([np.zeros(len(triples), bool), np.ones(len(T), bool)])
    order, gid, count = group_rows(keys)
    # a group holding both a quad triple and a triangle is a conflict
    has_tri = np.bincount(gid, weights=is_tri, minlength=len(count)) > 0
    has_quad = np.bincount(gid, weights=~is_tri, minlength=len(count)) > 0
    hit = np.flatnonzero(has_tri & has_quad)
    if hit.size == 0:
        return
    mask = np.isin(gid, hit)
    qa = {g: src[i] for i, g in zip(np.flatnonzero(mask & ~is_tri), gid[mask & ~is_tri])}
    tr = [(ft.cell[qa[g]], ft.cell[src[i]]) for i, g in zip(np.flatnonzero(mask & is_tri), gid[mask & is_tri])]
    raise MeshError("non-conforming: quad face split into triangles by the neighbour, "
                    + _fmt_pairs(*zip(*tr)))


def _check_overlapping_faces(mesh: Mesh, ft: FaceTable) -> None:
    """Boundary faces that lie on top of other boundary faces mean a non-conforming interface.

    In a conforming mesh the boundary faces only meet along edges.  A hanging
    node, a quad against two triangles, mismatched diagonals or unmerged
    duplicate nodes all leave boundary faces on both sides of the interface
    that cover the same area.  Each face gets a test point at a generic interior
    position (so it does not fall on the other side's edges); it must not lie
    inside another boundary face (within PLANE_TOL of its plane).
    """
    rows = boundary_rows(ft)
    if rows.size < 2:
        return
    geo = _face_geometry_3d if mesh.dim == 3 else _face_geometry_2d
    centre, radius, normal, test = geo(mesh.points, ft.nodes[rows], ft.nvert[rows])
    i, j = _within(test, centre, radius * (1 + 1e-9) + 1e-300)     # test point i near face j
    keep = ft.cell[rows[i]] != ft.cell[rows[j]]
    keep &= np.abs(np.einsum("nd,nd->n", normal[i], normal[j])) > 0.5
    i, j = i[keep], j[keep]
    off_plane = np.abs(np.einsum("nd,nd->n", test[i] - centre[j], normal[j]))
    keep = off_plane <= PLANE_TOL * radius[j]
    i, j = i[keep], j[keep]
    inside = _inside_3d if mesh.dim == 3 else _inside_2d
    hit = inside(mesh.points, ft.nodes[rows[j]], ft.nvert[rows[j]], test[i], normal[j])
    if np.any(hit):
        raise MeshError("non-conforming interface (hanging node, split or mismatched faces, "
                        "or unmerged duplicate nodes): faces of "
                        + _fmt_pairs(ft.cell[rows[i[hit]]], ft.cell[rows[j[hit]]]))


def _within(points, centres, radii):
    """(i, j): every point i within radii[j] of centres[j], sorted by j then i.  A grid of cells as
    wide as the largest radius: each ball is looked for in its cell and the neighbouring ones (numpy
    only: a k-d tree's import alone costs more than this check on an organ mesh)."""
    dim = points.shape[1]
    width = float(radii.max())
    if not (width > 0 and np.isfinite(width)):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    low = np.minimum(points.min(axis=0), centres.min(axis=0))
    cell_of = lambda x: np.floor((x - low) / width).astype(np.int64)
    span = np.maximum(cell_of(points).max(axis=0), cell_of(centres).max(axis=0)) + 3
    key = lambda c: np.ravel_multi_index(tuple((c + 1).T), tuple(span))   # +1: offsets of -1 stay >= 0
    order = np.argsort(key(cell_of(points)), kind="stable")
    sorted_keys = key(cell_of(points))[order]
    home = cell_of(centres)
    found_i, found_j = [], []
    for offset in np.array(np.meshgrid(*[(-1, 0, 1)] * dim, indexing="ij")).reshape(dim, -1).T:
        k = key(home + offset)
        lo, hi = np.searchsorted(sorted_keys, k, "left"), np.searchsorted(sorted_keys, k, "right")
        count = hi - lo
        j = np.repeat(np.arange(len(centres)), count)
        start = np.repeat(lo - np.concatenate([[0], np.cumsum(count)[:-1]]), count)
        found_i.append(order[start + np.arange(count.sum())])
        found_j.append(j)
    i, j = np.concatenate(found_i), np.concatenate(found_j)
    close = np.einsum("nd,nd->n", points[i] - centres[j], points[i] - centres[j]) <= radii[j] ** 2
    i, j = i[close], j[close]
    by = np.lexsort((i, j))
    return i[by], j[by]


# generic (irrational-looking) interior positions for test points
_TRI_W = np.array([0.5127, 0.3089, 0.1784])
_QUAD_UV = (0.2371, -0.1638)
_EDGE_T = 0.3719


def _pad_triangles(F, nv):
    """Repeat the last vertex of triangles so all faces have 4 columns."""
    F = F.copy()
    tri = nv == 3
    F[tri, 3] = F[tri, 2]
    return F


def _face_geometry_3d(points, F, nv):
    V = points[_pad_triangles(F, nv)]                           # (m, 4, 3)
    tri = (nv == 3)[:, None]
    centre = np.where(tri, V[:, :3].mean(axis=1), V.mean(axis=1))
    normal = np.where(tri, np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]),
                      np.cross(V[:, 2] - V[:, 0], V[:, 3] - V[:, 1]))
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    radius = np.linalg.norm(V - centre[:, None], axis=2).max(axis=1)
    u, v = _QUAD_UV
    qw = np.array([(1 - u) * (1 - v), (1 + u) * (1 - v), (1 + u) * (1 + v), (1 - u) * (1 + v)]) / 4
    test = np.where(tri, np.einsum("w,nwd->nd", _TRI_W, V[:, :3]), np.einsum("w,nwd->nd", qw, V))
    return centre, radius, normal, test


def _face_geometry_2d(points, F, nv):
    A, B = points[F[:, 0]], points[F[:, 1]]
    d = B - A
    length = np.linalg.norm(d, axis=1)
    normal = np.column_stack([d[:, 1], -d[:, 0]]) / np.maximum(length, 1e-300)[:, None]
    return (A + B) / 2, length / 2, normal, A + _EDGE_T * d


def _bary2(P, A, B, C):
    """Barycentric coordinates (of A, B, C) of 2D points P."""
    def cross(u, v):
        return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    det = cross(B - A, C - A)
    det = np.where(det == 0, 1e-300, det)
    lb = cross(P - A, C - A) / det
    lc = cross(B - A, P - A) / det
    return 1 - lb - lc, lb, lc


def _inside_3d(points, F, nv, P, normal):
    """Is P strictly inside face F (projected onto the face plane)?"""
    V = points[_pad_triangles(F, nv)]
    t1 = V[:, 1] - V[:, 0]
    t1 /= np.maximum(np.linalg.norm(t1, axis=1), 1e-300)[:, None]
    t2 = np.cross(normal, t1)

    def proj(X):
        return np.column_stack([np.einsum("nd,nd->n", X, t1), np.einsum("nd,nd->n", X, t2)])

    p, v = proj(P), [proj(V[:, k]) for k in range(4)]
    e = INSIDE_TOL
    # split the face along v0-v2; the diagonal itself counts as inside a quad
    l0, l1, l2 = _bary2(p, v[0], v[1], v[2])
    quad = nv == 4
    in_a = (l0 > e) & (l2 > e) & np.where(quad, l1 >= -e, l1 > e)
    m0, m2, m3 = _bary2(p, v[0], v[2], v[3])
    in_b = quad & (m0 > e) & (m3 > e) & (m2 >= -e)
    return in_a | in_b


def _inside_2d(points, F, nv, P, normal):
    A, B = points[F[:, 0]], points[F[:, 1]]
    d = B - A
    s = np.einsum("nd,nd->n", P - A, d) / np.maximum(np.einsum("nd,nd->n", d, d), 1e-300)
    return (s > INSIDE_TOL) & (s < 1 - INSIDE_TOL)


# --------------------------------------------------------------------------- orientation fix

def orient_cells(mesh: Mesh) -> Mesh:
    """A copy with mirrored cells renumbered so that det J > 0.

    Only for users who ask for it (meshes from tools with another orientation
    convention): a cell whose det J is negative at every corner and the centroid
    is a mirror image and gets the mirror permutation of its nodes (e.g. two
    nodes of a simplex swapped).  Tangled cells (mixed signs) are left alone;
    check_mesh still reports them.
    """
    blocks = []
    for blk in mesh.blocks:
        cells = blk.cells.copy()
        flip = np.all(sample_dets(mesh.points, blk) < 0, axis=1)
        cells[flip] = cells[flip][:, list(_types.get(blk.type).flip)]
        blocks.append(CellBlock(blk.type, cells, None if blk.tags is None else blk.tags.copy()))
    return Mesh(mesh.points.copy(), blocks, list(mesh.groups))    # same nodes and cell ids: same groups


