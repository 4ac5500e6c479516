"""Triangle surface generators for thin shells (thesis chapter 6): plates, strips, spheres,
tubes and the pinched hemisphere.

    points, triangles = plate(a, b, nx, ny, pattern="right")   # [0,a]x[0,b] at z = 0
    points, triangles = icosphere(radius, subdivisions)        # 20 * 4**s triangles
    points, triangles = sphere_with_triangles(radius, n_min)   # smallest icosphere with >= n_min
    points, triangles = cylinder(radius, length, n_around, n_along)   # open tube along x
    points, triangles = hemisphere(radius, n_rings, n_around, hole_degrees=None)
    points, triangles = strip(length, width, nx, ny)            # a plate, for cantilever strips
    triangles, notes = orient_triangles(points, triangles)      # a file's windings made consistent
    points, triangles, notes = read_shell_triangles(path)       # a surface file's triangles, oriented

Every generator returns points float64 (n, 3) and triangles int64 (m, 3).  Winding: the triangles
are counter-clockwise seen from outside (normal (x1 - x0) x (x2 - x0) outward) on the closed
icosphere and on the open tube and hemisphere, and counter-clockwise seen from +z on the plate.
The shell kernels and runtime.physics.volume_constraint read the normal from this winding, so it is the
one convention the generators promise; the tests check it triangle by triangle.

A file's triangles may come wound either way.  orient_triangles makes the windings of each
connected surface agree across its shared edges (a Moebius strip, which has no consistent
winding, is refused), winds a closed surface outward and an open one like the majority of its
triangles (the first triangle's side on a tie), and says what it turned.

Sizes: icosphere(r, s) has 10 * 4**s + 2 nodes and 20 * 4**s triangles (s = 3: 1280 triangles;
the 10 000-triangle benchmark gets s = 5, 20 480 triangles, from sphere_with_triangles).
"""
from __future__ import annotations

import itertools
import math
from numbers import Integral, Real

import numpy as np
from .container import MeshError, topological_dim
from .io import read_meshio

__all__ = ["plate", "strip", "icosphere", "sphere_with_triangles", "cylinder", "hemisphere", "orient_triangles",
           "winding_conflicts", "read_shell_triangles", "shell_groups"]

PATTERNS = ("right", "cross")


def _positive(name: str, value) -> float:
    """A finite length > 0 (a zero or NaN size gives degenerate triangles, never an error later)."""
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return float(value)


def _count(name: str, value, minimum: int) -> int:
    """An integer count >= minimum (floats are refused: 2.5 cells has no meaning)."""
    if isinstance(value, bool) or not isinstance(value, Integral) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _quads(rows: int, cols: int, periodic: bool) -> np.ndarray:
    """Corner ids (a, b, c, d) of the quads of a (rows + 1) x ncols node grid, row-major.

    Node (k, j) has id k * ncols + j with ncols = cols (periodic: column cols wraps to 0) or
    cols + 1.  a = (k, j), b = (k, j + 1), c = (k + 1, j + 1), d = (k + 1, j): counter-clockwise
    when j runs along the first tangent and k along the second."""
    ncols = cols if periodic else cols + 1
    k, j = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    k, j = k.ravel(), j.ravel()
    j1 = (j + 1) % ncols if periodic else j + 1
    a, b = k * ncols + j, k * ncols + j1
    c, d = (k + 1) * ncols + j1, (k + 1) * ncols + j
    return np.stack([a, b, c, d], axis=1).astype(np.int64)


def _split(quads: np.ndarray, flip: np.ndarray | None = None) -> np.ndarray:
    """Two triangles per quad, keeping its winding: along a-c, or along b-d where flip is True."""
    a, b, c, d = quads.T
    t1 = np.stack([a, b, c], axis=1)
    t2 = np.stack([a, c, d], axis=1)
    if flip is not None:
        t1 = np.where(flip[:, None], np.stack([a, b, d], axis=1), t1)
        t2 = np.where(flip[:, None], np.stack([b, c, d], axis=1), t2)
    return np.stack([t1, t2], axis=1).reshape(-1, 3).astype(np.int64)


def plate(a, b, nx, ny, pattern: str = "right"):
    """Rectangle [0, a] x [0, b] at z = 0: nx * ny cells, two triangles each, normal +z.

    Nodes row by row (id = j * (nx + 1) + i, x = a i / nx, y = b j / ny).  pattern "right" splits
    every cell along the same diagonal (from (i, j) to (i + 1, j + 1)); "cross" alternates the
    diagonal in a checkerboard, which removes the directional bias of "right" meshes in plate
    bending benchmarks."""
    a, b = _positive("a", a), _positive("b", b)
    nx, ny = _count("nx", nx, 1), _count("ny", ny, 1)
    if pattern not in PATTERNS:
        raise ValueError(f"pattern must be one of {PATTERNS}, got {pattern!r}")
    y, x = np.meshgrid(np.linspace(0.0, b, ny + 1), np.linspace(0.0, a, nx + 1), indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    quads = _quads(ny, nx, periodic=False)            # j along x, k along y: counter-clockwise from +z
    flip = None
    if pattern == "cross":
        j, i = np.divmod(np.arange(nx * ny), nx)
        flip = (i + j) % 2 == 1
    return points, _split(quads, flip)


def strip(length, width, nx, ny, pattern: str = "right"):
    """A cantilever strip: plate(length, width, nx, ny, pattern) (x along the length, normal +z)."""
    return plate(length, width, nx, ny, pattern)


def _icosahedron():
    """The regular icosahedron on the unit sphere, faces wound outward.

    The faces are found rather than listed: the triples of vertices pairwise at the edge length
    (2 for the vertices (0, +-1, +-phi) and cyclic permutations), oriented by the sign of
    x0 . (x1 x x2), which is positive for an outward face of a body around the origin."""
    phi = (1.0 + math.sqrt(5.0)) / 2.0
    base = [(0.0, s1, s2 * phi) for s1 in (-1.0, 1.0) for s2 in (-1.0, 1.0)]
    verts = np.array([np.roll(v, r) for r in range(3) for v in base])
    faces = []
    for tri in itertools.combinations(range(12), 3):
        p = verts[list(tri)]
        edges = np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1)
        if np.allclose(edges, 2.0):
            faces.append(tri if np.dot(p[0], np.cross(p[1], p[2])) > 0 else tri[::-1])
    faces = np.array(faces, dtype=np.int64)
    assert faces.shape == (20, 3)
    return verts / np.linalg.norm(verts, axis=1, keepdims=True), faces


def _subdivide(points: np.ndarray, triangles: np.ndarray):
    """Each triangle into 4 through its edge midpoints, pushed to the unit sphere.

    The midpoints are numbered once per edge (np.unique of the sorted edges), so neighbours share
    them and there are no duplicated nodes; the four children keep the parent's winding."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    unique, inverse = np.unique(np.sort(edges, axis=1), axis=0, return_inverse=True)
    mid = points[unique[:, 0]] + points[unique[:, 1]]
    mid /= np.linalg.norm(mid, axis=1, keepdims=True)
    m = len(triangles)
    ids = len(points) + inverse.reshape(-1)
    m01, m12, m20 = ids[:m], ids[m:2 * m], ids[2 * m:]
    v0, v1, v2 = triangles.T
    children = np.stack([np.stack([v0, m01, m20], 1), np.stack([v1, m12, m01], 1),
                         np.stack([v2, m20, m12], 1), np.stack([m01, m12, m20], 1)], axis=1)
    return np.concatenate([points, mid]), children.reshape(-1, 3).astype(np.int64)


def icosphere(radius, subdivisions: int):
    """Closed sphere: the icosahedron subdivided `subdivisions` times, nodes on the sphere.

    10 * 4**s + 2 nodes, 20 * 4**s nearly equal triangles (no poles, unlike a UV sphere), wound
    outward.  The enclosed volume approaches 4/3 pi r^3 from below (an inscribed polyhedron)."""
    radius = _positive("radius", radius)
    subdivisions = _count("subdivisions", subdivisions, 0)
    if subdivisions > 8:
        raise ValueError(f"subdivisions must be <= 8 (20 * 4**8 = 1 310 720 triangles), got {subdivisions}")
    points, triangles = _icosahedron()
    for _ in range(subdivisions):
        points, triangles = _subdivide(points, triangles)
    return radius * points, triangles


def sphere_with_triangles(radius, n_min: int):
    """The smallest icosphere with at least n_min triangles (20 * 4**s >= n_min).

    The counts jump by 4: n_min = 10 000 gives s = 5 and 20 480 triangles, not 10 000."""
    n_min = _count("n_min", n_min, 1)
    s = 0
    while 20 * 4 ** s < n_min:
        s += 1
    return icosphere(radius, s)


def cylinder(radius, length, n_around: int, n_along: int):
    """Open tube along x, x in [0, length], with n_around nodes per ring and n_along bands.

    Node k * n_around + j at (length k / n_along, r cos t_j, r sin t_j), t_j = 2 pi j / n_around;
    triangles wound with the outward (radial) normal.  For the pinched cylinder and a rolled
    strip; the ends are open (boundary edges), so it is no input for VolumeConstraint."""
    radius, length = _positive("radius", radius), _positive("length", length)
    n_around, n_along = _count("n_around", n_around, 3), _count("n_along", n_along, 1)
    t = 2.0 * np.pi * np.arange(n_around) / n_around
    x = np.linspace(0.0, length, n_along + 1)
    xx, tt = np.meshgrid(x, t, indexing="ij")
    points = np.stack([xx.ravel(), radius * np.cos(tt).ravel(), radius * np.sin(tt).ravel()], axis=1)
    # j along the angle then k along x: e_t x e_x = e_r, outward.
    return points, _split(_quads(n_along, n_around, periodic=True))


def hemisphere(radius, n_rings: int, n_around: int, hole_degrees=None):
    """Open hemisphere z >= 0 (equator at z = 0), wound with the outward (radial) normal.

    hole_degrees None: a pole node (id 0) with a triangle fan, then n_rings rings of n_around nodes
    at polar angles 90 deg * i / n_rings, i = 1..n_rings.  hole_degrees = h (e.g. 18.0, the
    MacNeal-Harder pinched hemisphere): no pole, an opening of half-angle h around +z, and
    n_rings + 1 rings at polar angles from h to 90 deg (n_rings bands of quads)."""
    radius = _positive("radius", radius)
    n_rings, n_around = _count("n_rings", n_rings, 1), _count("n_around", n_around, 3)
    if hole_degrees is not None:
        h = _positive("hole_degrees", hole_degrees)
        if h >= 90.0:
            raise ValueError(f"hole_degrees must be < 90 (the hole half-angle), got {hole_degrees!r}")
        polar = np.radians(np.linspace(h, 90.0, n_rings + 1))
    else:
        polar = np.linspace(0.0, np.pi / 2, n_rings + 1)[1:]
    t = 2.0 * np.pi * np.arange(n_around) / n_around
    pp, tt = np.meshgrid(polar, t, indexing="ij")
    rings = radius * np.stack([np.sin(pp) * np.cos(tt), np.sin(pp) * np.sin(tt), np.cos(pp)], axis=-1)
    points = rings.reshape(-1, 3)
    # j along the angle (counter-clockwise from +z), k down towards the equator: a -> b -> c turns
    # clockwise seen from +z, so the quads' triangles are reversed to face outward.
    bands = np.ascontiguousarray(_split(_quads(len(polar) - 1, n_around, periodic=True))[:, ::-1])
    if hole_degrees is not None:
        return points, bands
    j = np.arange(n_around)
    fan = np.stack([np.zeros(n_around, dtype=np.int64), 1 + j, 1 + (j + 1) % n_around], axis=1)
    points = np.concatenate([[[0.0, 0.0, radius]], points])
    # the fan is counter-clockwise from +z: pole, t_j, t_j+1
    return points, np.concatenate([fan, 1 + bands]).astype(np.int64)


# ------------------------------------------------------------------------------ windings of a file


def _edge_pairs(triangles: np.ndarray):
    """(t1, t2, same) per edge shared by exactly two triangles: same is True where both run along
    the edge in the same direction (their windings disagree); and the number of triangles on each
    triangle's edges (per triangle, 3 counts) for telling closed surfaces from open ones."""
    m = len(triangles)
    a = triangles.reshape(-1)
    b = triangles[:, [1, 2, 0]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    forward = a < b
    owner = np.repeat(np.arange(m, dtype=np.int64), 3)
    _, inverse, counts = np.unique(np.stack([lo, hi], axis=1), axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")
    manifold = counts[inverse[order]] == 2
    first = order[manifold][0::2]
    second = order[manifold][1::2]
    return owner[first], owner[second], forward[first] == forward[second], counts[inverse].reshape(m, 3)


def winding_conflicts(triangles) -> np.ndarray:
    """(k, 2) pairs of triangles that share an edge and run along it in the same direction (their
    normals point to opposite sides)."""
    t1, t2, same, _ = _edge_pairs(np.asarray(triangles, dtype=np.int64).reshape(-1, 3))
    return np.stack([t1[same], t2[same]], axis=1)


def orient_triangles(points, triangles, what: str = "the surface"):
    """(triangles, notes): each connected surface wound consistently; see the module doc.

    Surfaces are joined through edges that exactly two triangles share (a T-junction of three or
    more leaves its sheets separate).  A closed surface (no edge with one triangle) is wound so
    that its enclosed volume is positive (normals outward); an open one keeps the side of the
    majority of its triangles.  notes: one sentence per surface whose triangles were turned.
    Raises ValueError for a surface with no consistent winding (a Moebius strip), naming a
    triangle where the windings meet."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components

    points = np.asarray(points, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    m = len(triangles)
    if m == 0:
        return triangles.copy(), []
    t1, t2, same, edge_counts = _edge_pairs(triangles)
    rows, cols = np.concatenate([t1, t2]), np.concatenate([t2, t1])
    # parity + 1 so that a parity of 0 is a stored entry
    G = csr_matrix((np.concatenate([same, same]).astype(np.int8) + 1, (rows, cols)), shape=(m, m))
    n_comp, label = connected_components(G, directed=False)
    flip = np.zeros(m, dtype=bool)
    roots = np.full(n_comp, m, dtype=np.int64)
    np.minimum.at(roots, label, np.arange(m))                  # lowest triangle id of each surface
    for root in roots.tolist():
        order, pred = breadth_first_order(G, root, directed=False, return_predecessors=True)
        if order.size < 2:
            continue
        child = order[1:]
        parity = np.asarray(G[child, pred[child]]).reshape(-1) - 1
        f = flip.tolist()
        for c, p, q in zip(child.tolist(), pred[child].tolist(), parity.tolist()):
            f[c] = f[p] ^ bool(q)
        flip[order] = np.asarray(f, dtype=bool)[order]
    bad = (flip[t1] ^ flip[t2]) != same
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{what} has no consistent winding (a Moebius-like surface): triangles {int(t1[i])} "
                         f"and {int(t2[i])} cannot face the same side across their shared edge, whatever "
                         f"triangles are turned; {int(bad.sum())} such edge(s)")
    notes = []
    closed = np.bincount(label, weights=(edge_counts != 2).any(axis=1), minlength=n_comp) == 0
    oriented = np.where(flip[:, None], triangles[:, ::-1], triangles)
    X = points[oriented]
    size = np.bincount(label, minlength=n_comp)
    for k in range(n_comp):
        mine = label == k
        if closed[k]:
            x = X[mine] - X[mine].reshape(-1, 3).mean(axis=0)
            volume = np.einsum("ij,ij->i", x[:, 0], np.cross(x[:, 1], x[:, 2])).sum() / 6.0
            if volume < 0:
                flip[mine] = ~flip[mine]
            why = "wound outward (closed surface)"
        else:
            turned = int(flip[mine].sum())
            if 2 * turned > size[k]:
                flip[mine] = ~flip[mine]
            why = ("wound like the majority of its triangles (open surface)" if 2 * turned != size[k]
                   else f"wound like its first triangle, {int(roots[k])} (open surface, half turned either way)")
        n_turned = int(flip[mine].sum())
        if n_turned:
            ids = np.flatnonzero(mine & flip)
            head = ", ".join(str(int(i)) for i in ids[:8]) + (", ..." if ids.size > 8 else "")
            surface = what if n_comp == 1 else f"{what} (piece {k + 1} of {n_comp}, from triangle {int(roots[k])})"
            notes.append(f"{surface}: {n_turned} of {int(size[k])} triangles turned [{head}] so that "
                         f"the windings agree across shared edges; {why}")
    return np.where(flip[:, None], triangles[:, ::-1], triangles).astype(np.int64), notes


def shell_groups(m, n_triangles: int) -> tuple:
    """(tags, groups) of a meshio mesh read as shells: the physical tag of each triangle (blocks in
    order, as read_shell_triangles stacks them; None when the file has none) and a Group of shell
    cells (dim 2) per tag, named by the file's physical names."""
    from .mesh_groups import Group
    data = getattr(m, "cell_data", {}) or {}
    key = next((k for k in ("gmsh:physical", "cell_tags", "medit:ref") if k in data), None)
    if key is None:
        return None, []
    tags = [np.asarray(values).reshape(-1) for block, values in zip(m.cells, data[key]) if block.type == "triangle"]
    tags = np.concatenate(tags).astype(np.int64) if tags else np.zeros(0, np.int64)
    if len(tags) != n_triangles:
        return None, []
    names = {int(v[0]): name for name, v in (getattr(m, "field_data", {}) or {}).items()
             if len(v) > 1 and int(v[1]) == 2}
    groups = [Group(names.get(int(t)), int(t), 2, np.flatnonzero(tags == t)) for t in np.unique(tags)]
    return tags, groups


def read_shell_triangles(path, with_groups: bool = False, read=None):
    """(points (n, 3), triangles, notes) of a surface mesh file read as shells (with_groups: and
    shell_groups' (tags, groups), so that regions select its triangles): its 3-node triangles
    (curves and points left out, unused points dropped), duplicated triangles refused by id, each
    surface's windings made to agree (orient_triangles; its notes say what was turned).  Volume
    cells and quadratic triangles are refused by name.  Reading goes through mesh.read_meshio (a
    broken .msh file is refused naming the broken part; read: its result when the caller has it)."""
    m = read_meshio(path) if read is None else read
    blocks = [np.asarray(cb.data, dtype=np.int64) for cb in m.cells if cb.type == "triangle"]
    other = sorted({cb.type for cb in m.cells if cb.type != "triangle" and topological_dim(cb.type) not in (0, 1)})
    if other:
        hint = " (shells are linear triangles: mesh with element order 1)" if "triangle6" in other else \
            " (remove them or mesh the surface alone)"
        raise MeshError(f"{path}: element = \"shell\" takes 3-node triangle cells only; the file also has "
                        f"{', '.join(other)}{hint}")
    if not blocks:
        raise MeshError(f"{path}: element = \"shell\" needs triangle cells; the file has none")
    triangles = np.vstack(blocks)
    points = np.asarray(m.points, dtype=np.float64)
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    if triangles.min() < 0 or triangles.max() >= len(points):
        raise MeshError(f"{path}: triangles refer to nodes outside 0..{len(points) - 1}")
    _, first, inverse = np.unique(np.sort(triangles, axis=1), axis=0, return_index=True, return_inverse=True)
    again = np.flatnonzero(first[inverse.reshape(-1)] != np.arange(len(triangles)))
    if again.size:
        pairs = "; ".join(f"{int(first[inverse.reshape(-1)[i]])} and {int(i)}" for i in again[:5])
        raise MeshError(f"{path}: duplicated triangles (the same 3 nodes twice; their stiffness, mass and "
                        f"loads would count twice): triangles {pairs}{' ...' if again.size > 5 else ''} "
                        f"({again.size} in all, counted in the file's order)")
    used, inverse = np.unique(triangles, return_inverse=True)
    points, triangles = points[used], inverse.reshape(triangles.shape)
    try:
        triangles, notes = orient_triangles(points, triangles, what=str(path))
    except ValueError as exc:
        raise MeshError(str(exc)) from None
    if with_groups:
        return points, triangles, notes, shell_groups(m, len(triangles))
    return points, triangles, notes
