"""Generated bars: conforming hexahedron, tetra, tetra10, wedge, pyramid and mixed bars in 3D and
triangle, triangle6, quad and mixed bars in 2D, and their counts without building them."""
from __future__ import annotations

from itertools import permutations

import numpy as np
from .container import CellBlock, Mesh, MeshError

from ... import elements as _types

# What generate_bar builds, by space dimension (a capability of the bar generator, not of the table).
BAR_ELEMENTS = {3: ("hexahedron", "tetra", "tetra10", "wedge", "pyramid", "mixed"),
                2: ("triangle", "triangle6", "quad", "mixed")}

# gmsh node order -> VTK node order where meshio keeps gmsh's (meshio converts tetra10, wedge15,

# --------------------------------------------------------------------------- bar generators
#
# All 3D bars start from a structured grid of hexes (VTK node order, axes
# aligned so det J > 0) and split each hex in a way that matches its neighbours.

_HEX_OFFSETS = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
_QUAD_OFFSETS = [(0, 0), (1, 0), (1, 1), (0, 1)]


def _kuhn_table() -> np.ndarray:
    """The 6 Kuhn tets of a hex: monotone paths from corner (0,0,0) to (1,1,1).

    Every hex is cut the same way, so each face diagonal runs from the face's
    lowest to its highest corner on both sides: the split is conforming.  Odd
    axis permutations give negative tets, fixed by swapping two nodes.
    """
    local = {o: i for i, o in enumerate(_HEX_OFFSETS)}
    tets = []
    for perm in permutations(range(3)):
        v = np.zeros(3, int)
        path = [local[tuple(v)]]
        for ax in perm:
            v[ax] = 1
            path.append(local[tuple(v)])
        if np.linalg.det(np.eye(3)[list(perm)]) < 0:
            path[1], path[2] = path[2], path[1]
        tets.append(path)
    return np.array(tets)


_KUHN = _kuhn_table()
# Two wedges per hex, extruded along z, bottom quad cut along its diagonal 0-2.
# The base triangles wind clockwise seen from +z (VTK wedge convention).  The
# x = const and y = const faces stay whole quads; z faces get the same diagonal
# in every layer.
_WEDGE_SPLIT = np.array([[0, 2, 1, 4, 6, 5], [0, 3, 2, 4, 7, 6]])
# Six pyramids per hex, one per face, apex at a new centre node; each base
# winds so its right-hand normal points into the hex (towards the apex).
_PYRAMID_BASES = np.array([(0, 1, 2, 3), (4, 7, 6, 5), (0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0)])
_XPLUS_FACE = 3
# The x+ pyramid of a transition hex cut into two tets along diagonal 1-6, the
# diagonal a Kuhn-split neighbour has on its x- face (corners (0,0,0)-(0,1,1)).
_XPLUS_TETS = np.array([(1, 5, 6), (1, 6, 2)])


def _hex_grid(size, cells, origin):
    """Points and hexes (nx, ny, nz, 8) of a structured box."""
    axes = [o + np.linspace(0.0, s, n + 1) for o, s, n in zip(origin, size, cells)]
    grid = np.meshgrid(*axes, indexing="ij")
    points = np.column_stack([g.ravel() for g in grid])
    idx = np.arange(len(points)).reshape([n + 1 for n in cells])
    offsets = _HEX_OFFSETS if len(cells) == 3 else _QUAD_OFFSETS
    sl = [tuple(slice(d, d + n) for d, n in zip(off, cells)) for off in offsets]
    return points, np.stack([idx[s] for s in sl], axis=-1)


def _add_centres(points, hexes):
    """Append one node at the centre of each hex; returns points and the new ids."""
    centres = points[hexes].mean(axis=1)
    ids = len(points) + np.arange(len(hexes))
    return np.vstack([points, centres]), ids


def _pyramids(hexes, centres, skip_face=None):
    faces = [f for f in range(6) if f != skip_face]
    base = hexes[:, _PYRAMID_BASES[faces]]                           # (m, f, 4)
    apex = np.broadcast_to(centres[:, None, None], base.shape[:2] + (1,))
    return np.concatenate([base, apex], axis=2).reshape(-1, 5)


def _transition_tets(hexes, centres):
    tri = hexes[:, _XPLUS_TETS]                                      # (m, 2, 3)
    apex = np.broadcast_to(centres[:, None, None], tri.shape[:2] + (1,))
    return np.concatenate([tri, apex], axis=2).reshape(-1, 4)


def _add_midsides(points, cells, edges):
    """Quadratic cells: one shared node at the middle of every corner edge."""
    e = np.sort(cells[:, np.array(edges)], axis=2).reshape(-1, 2)
    uniq, inv = np.unique(e, axis=0, return_inverse=True)
    mids = points[uniq].mean(axis=1)
    ids = len(points) + inv.reshape(len(cells), len(edges))
    return np.vstack([points, mids]), np.hstack([cells, ids])


def _mixed_bar_3d(points, hexes):
    """Conforming bar with all four solid types, in 4 sections along x:

        hexahedra | wedges | pyramids (last column: transition) | tetrahedra (Kuhn)

    hex|wedge: wedges are extruded along z, so their x faces are whole quads.
    wedge|pyramid: every hex face is a pyramid base (a quad).  pyramid|tet: the
    Kuhn tets cut their x- face along (0,0,0)-(0,1,1), so in the last pyramid
    column the x+ pyramid is cut into two tets along that same diagonal; its
    triangular sides are kept whole, so it still matches the other pyramids.
    """
    nx = hexes.shape[0]
    if nx < 4:
        raise MeshError("element='mixed' needs at least 4 cells along x")
    s = np.array_split(np.arange(nx), 4)
    flat = lambda cols: hexes[cols].reshape(-1, 8)  # noqa: E731
    pyr_full, transition = flat(s[2][:-1]), flat(s[2][-1:])
    points, c_full = _add_centres(points, pyr_full)
    points, c_tr = _add_centres(points, transition)
    pyramids = np.vstack([_pyramids(pyr_full, c_full), _pyramids(transition, c_tr, skip_face=_XPLUS_FACE)])
    tets = np.vstack([_transition_tets(transition, c_tr), flat(s[3])[:, _KUHN].reshape(-1, 4)])
    blocks = [CellBlock("hexahedron", flat(s[0])),
              CellBlock("wedge", flat(s[1])[:, _WEDGE_SPLIT].reshape(-1, 6)),
              CellBlock("pyramid", pyramids), CellBlock("tetra", tets)]
    return Mesh(points, blocks)


def _bar_3d(size, cells, origin, element):
    points, grid = _hex_grid(size, cells, origin)
    if element == "mixed":
        return _mixed_bar_3d(points, grid)
    hexes = grid.reshape(-1, 8)
    if element == "hexahedron":
        return Mesh(points, [CellBlock("hexahedron", hexes)])
    if element in ("tetra", "tetra10"):
        tets = hexes[:, _KUHN].reshape(-1, 4)
        if element == "tetra10":
            points, tets = _add_midsides(points, tets, _types.get("tetra10").midside_edges)
        return Mesh(points, [CellBlock(element, tets)])
    if element == "wedge":
        return Mesh(points, [CellBlock("wedge", hexes[:, _WEDGE_SPLIT].reshape(-1, 6))])
    if element == "pyramid":
        points, centres = _add_centres(points, hexes)
        return Mesh(points, [CellBlock("pyramid", _pyramids(hexes, centres))])
    raise MeshError(f"unknown 3D element {element!r} ({', '.join(BAR_ELEMENTS[3])})")


def _bar_2d(size, cells, origin, element):
    """Rectangle of quads, or of quads cut into CCW triangles along diagonal 0-2.

    'mixed' puts quads in the first half along x and triangles in the rest
    (conforming: the triangle diagonals stay inside the cells).
    """
    points, grid = _hex_grid(size, cells, origin)
    quads = grid.reshape(-1, 4)
    tri_split = np.array([(0, 1, 2), (0, 2, 3)])
    if element == "quad":
        return Mesh(points, [CellBlock("quad", quads)])
    if element in ("triangle", "triangle6"):
        tris = quads[:, tri_split].reshape(-1, 3)
        if element == "triangle6":
            points, tris = _add_midsides(points, tris, _types.get("triangle6").midside_edges)
        return Mesh(points, [CellBlock(element, tris)])
    if element == "mixed":
        if cells[0] < 2:
            raise MeshError("element='mixed' needs at least 2 cells along x")
        half = cells[0] // 2
        return Mesh(points, [CellBlock("quad", grid[:half].reshape(-1, 4)),
                             CellBlock("triangle", grid[half:].reshape(-1, 4)[:, tri_split].reshape(-1, 3))])
    raise MeshError(f"unknown 2D element {element!r} ({', '.join(BAR_ELEMENTS[2])})")


def generate_bar(size=(1.0, 0.2, 0.2), cells=(10, 2, 2), element="hexahedron", origin=None) -> Mesh:
    """A structured box [origin, origin + size] of positively oriented, conforming cells.

    3D element: hexahedron; tetra (6 Kuhn tets per hex); tetra10 (the same with
    shared midside nodes); wedge (2 per hex, extruded along z); pyramid (6 per
    hex around a new centre node); mixed (see _mixed_bar_3d: hex | wedge |
    pyramid | tet sections along x).  2D (size and cells of length 2): quad,
    triangle, triangle6, mixed.
    """
    size, cells = tuple(float(s) for s in size), tuple(int(c) for c in cells)
    dim = len(size)
    if dim not in (2, 3) or len(cells) != dim:
        raise MeshError(f"size and cells must both have 2 or 3 entries, got {size} and {cells}")
    if min(cells) < 1 or not all(np.isfinite(size)) or min(size) <= 0:
        raise MeshError(f"need positive cell counts and sizes, got cells={cells}, size={size}")
    origin = np.zeros(dim) if origin is None else np.asarray(origin, dtype=float).reshape(-1)[:dim]
    if origin.shape != (dim,):
        raise MeshError(f"origin must have {dim} entries")
    build = _bar_3d if dim == 3 else _bar_2d
    return build(size, cells, origin, element)


def bar_counts(cells=(10, 2, 2), element="hexahedron") -> tuple:
    """(cells per type, number of nodes) of generate_bar(size, cells, element), without building it.

    Resource estimates need the counts before a bar too big for the machine is generated;
    tests check them against generate_bar for every element.
    """
    cells = tuple(int(c) for c in cells)
    if len(cells) not in (2, 3) or min(cells) < 1:
        raise MeshError(f"need 2 or 3 positive cell counts, got {cells}")
    grid = int(np.prod([c + 1 for c in cells], dtype=object))
    boxes = int(np.prod(cells, dtype=object))                 # hexes (quads in 2D) of the grid
    count = _bar_counts_3d if len(cells) == 3 else _bar_counts_2d
    return count(cells, element, grid, boxes)


def _grid_edges(cells) -> int:
    """Edges along the axes of a structured grid of cells."""
    total = 0
    for axis in range(len(cells)):
        total += int(np.prod([c if a == axis else c + 1 for a, c in enumerate(cells)], dtype=object))
    return total


def _face_squares(cells) -> int:
    """Faces of a 3D hex grid (each one carries one diagonal in the Kuhn split)."""
    nx, ny, nz = cells
    return nx * ny * (nz + 1) + nx * (ny + 1) * nz + (nx + 1) * ny * nz


def _bar_counts_3d(cells, element, grid, hexes):
    nx, ny, nz = cells
    if element == "hexahedron":
        return {"hexahedron": hexes}, grid
    if element == "tetra":
        return {"tetra": 6 * hexes}, grid
    if element == "tetra10":              # one midside node per Kuhn edge: axes, face and body diagonals
        return {"tetra10": 6 * hexes}, grid + _grid_edges(cells) + _face_squares(cells) + hexes
    if element == "wedge":
        return {"wedge": 2 * hexes}, grid
    if element == "pyramid":
        return {"pyramid": 6 * hexes}, grid + hexes
    if element == "mixed":
        if nx < 4:
            raise MeshError("element='mixed' needs at least 4 cells along x")
        s = [len(part) for part in np.array_split(np.arange(nx), 4)]
        column = ny * nz
        counts = {"hexahedron": s[0] * column, "wedge": 2 * s[1] * column,
                  "pyramid": (6 * (s[2] - 1) + 5) * column, "tetra": (2 + 6 * s[3]) * column}
        return counts, grid + s[2] * column
    raise MeshError(f"unknown 3D element {element!r} ({', '.join(BAR_ELEMENTS[3])})")


def _bar_counts_2d(cells, element, grid, quads):
    nx, ny = cells
    if element == "quad":
        return {"quad": quads}, grid
    if element == "triangle":
        return {"triangle": 2 * quads}, grid
    if element == "triangle6":            # midside nodes on the grid edges and one diagonal per quad
        return {"triangle6": 2 * quads}, grid + _grid_edges(cells) + quads
    if element == "mixed":
        if nx < 2:
            raise MeshError("element='mixed' needs at least 2 cells along x")
        half = nx // 2
        return {"quad": half * ny, "triangle": 2 * (nx - half) * ny}, grid
    raise MeshError(f"unknown 2D element {element!r} ({', '.join(BAR_ELEMENTS[2])})")
