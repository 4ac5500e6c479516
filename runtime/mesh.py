"""Meshes for the runtime: a small container, reading, bar generators and validity checks.

    mesh = read_mesh("part.msh")            # or generate_bar(element="tetra")
    check_mesh(mesh)                        # raises MeshError naming the bad cells

Node ordering is meshio's (= VTK's) everywhere.  A cell is correctly oriented
when the Jacobian determinant of its map from the VTK reference coordinates is
positive; note that for the VTK wedge this means the base triangle (0,1,2)
winds so that its right-hand normal points AWAY from (3,4,5).

Element facts (node counts, corners, faces, edges, midside nodes, mirror
permutations, reference domains) come from the element table, tensormass.elements.
Cells whose topological dimension is below the space dimension (bars in 3D, ...)
are accepted where their type allows that space dimension (ElementType.space_dims);
for them the checks test the measure (length, area) instead of an oriented volume,
and they take no part in the face checks.

Cell ids in error messages are global: blocks are numbered in order and the
cells of block b follow those of blocks 0..b-1.
"""
from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field
from itertools import permutations
from pathlib import Path

import functools

import numpy as np

from .. import elements as _types
from ..elements import BOX, PRISM, PYRAMID, SIMPLEX, ElementType, monomial_exponents
from .errors import TensormassError
from .mesh_groups import FACE_CORNERS, check_groups_on_surface, read_groups

__all__ = [
    "MeshError", "Mesh", "CellBlock", "NODES_PER_CELL", "SOLID_TYPES_3D", "SOLID_TYPES_2D",
    "read_mesh", "read_meshio", "to_meshio", "generate_bar", "bar_counts", "check_mesh", "check_coordinates", "orient_cells",
    "boundary_faces", "face_measure", "COORD_MAX", "BAR_ELEMENTS",
]

# Built-in types, read from the element table (types registered later: elements.get).
NODES_PER_CELL = {name: _types.get(name).n_nodes for name in _types.builtin()}
SOLID_TYPES_3D = tuple(n for n in _types.builtin() if _types.get(n).dim == 3 and _types.get(n).solid)
SOLID_TYPES_2D = tuple(n for n in _types.builtin() if _types.get(n).dim == 2 and _types.get(n).solid)
# What generate_bar builds, by space dimension (a capability of the bar generator, not of the table).
BAR_ELEMENTS = {3: ("hexahedron", "tetra", "tetra10", "wedge", "pyramid", "mixed"),
                2: ("triangle", "triangle6", "quad", "mixed")}

# gmsh node order -> VTK node order where meshio keeps gmsh's (meshio converts tetra10, wedge15,
# hexahedron20/27 and pyramid13 itself): gmsh's prism has its base triangle (0, 1, 2) wound the
# other way round (counterclockwise seen from the top face), VTK's wedge clockwise.  The other
# types tensormass supports (tetra, tetra10, hexahedron, pyramid, triangle, triangle6, quad) are
# read from gmsh files with positive volume as they are (tests/runtime/test_msh_node_order.py).
GMSH_TO_VTK = {"wedge": [0, 2, 1, 3, 5, 4]}

# Cell data names that carry integer region tags, most specific first.
_TAG_KEYS = ("gmsh:physical", "cell_tags", "medit:ref")

# Relative tolerances.  _DET_TOL: det J below this times h^dim is "degenerate"
# (h = cell bounding-box diagonal); _PLANE_TOL: how far (relative to the face
# size) a point may sit off a face's plane and still count as lying on it.
_DET_TOL = 1e-10
_PLANE_TOL = 1e-4
_INSIDE_TOL = 1e-8
# Kernels and checks raise coordinates to powers up to 6 (h^dim tolerances, squared
# Jacobian determinants, energies of E h^3 strain^2): beyond 1e50 (1e50^6 = 1e300) they
# overflow float64's 1.8e308, and a body smaller than 1e-50 underflows the same way.
COORD_MAX = 1e50
SIZE_MIN = 1e-50


class MeshError(TensormassError):
    """Bad mesh input; the message names the problem and the cell ids involved."""


def _fmt_ids(ids, first: int = 8, noun: str = "cell") -> str:
    """'[3, 7, ...] (12 cells)': the first few sorted ids and the count."""
    ids = np.unique(np.asarray(ids, dtype=np.int64))
    head = ", ".join(str(int(i)) for i in ids[:first])
    more = ", ..." if ids.size > first else ""
    return f"[{head}{more}] ({ids.size} {noun}{'' if ids.size == 1 else 's'})"


# --------------------------------------------------------------------------- containers


@dataclass
class CellBlock:
    """Cells of one type (and one tag, when the mesh carries tags)."""
    type: str
    cells: np.ndarray
    tags: np.ndarray | None = None

    def __post_init__(self):
        try:
            k = _types.get(self.type).n_nodes
        except ValueError:
            raise MeshError(f"unsupported cell type {self.type!r} (supported: {', '.join(_types.names())})") from None
        cells = np.asarray(self.cells)
        if cells.size == 0:
            cells = cells.reshape(0, k)
        if cells.ndim != 2 or cells.shape[1] != k:
            raise MeshError(f"{self.type} cells must have shape (n, {k}), got {cells.shape}")
        if not np.issubdtype(cells.dtype, np.integer):
            raise MeshError(f"{self.type} cell indices must be integers, got {cells.dtype}")
        self.cells = np.ascontiguousarray(cells, dtype=np.int64)
        if self.tags is not None:
            tags = np.asarray(self.tags).reshape(-1)
            if tags.shape[0] != self.cells.shape[0]:
                raise MeshError(f"{self.type}: {tags.shape[0]} tags for {self.cells.shape[0]} cells")
            self.tags = tags.astype(np.int64)

    def __len__(self) -> int:
        return self.cells.shape[0]


@dataclass
class Mesh:
    """Points (n_points, dim) and cell blocks; dim is 2 or 3."""
    points: np.ndarray
    blocks: list[CellBlock] = field(default_factory=list)
    groups: list = field(default_factory=list)          # runtime.mesh_groups.Group: named regions of the file
    # nodes created by refinement at edge midpoints / face centres: rows (node, 2 or 4 parents, -1
    # padded); runtime.hanging finds those that hang on an unrefined neighbour.  None: no such node
    midpoints: np.ndarray | None = None

    def __post_init__(self):
        pts = np.asarray(self.points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] not in (2, 3):
            raise MeshError(f"points must have shape (n, 2) or (n, 3), got {pts.shape}")
        self.points = np.ascontiguousarray(pts)
        self.blocks = list(self.blocks)
        self.groups = list(self.groups)

    @property
    def dim(self) -> int:
        return self.points.shape[1]

    @property
    def n_points(self) -> int:
        return self.points.shape[0]

    @property
    def n_cells(self) -> int:
        return sum(len(b) for b in self.blocks)

    def cell_types(self) -> list[str]:
        """Distinct cell types in block order."""
        return list(dict.fromkeys(b.type for b in self.blocks))


def _offsets(mesh: Mesh) -> np.ndarray:
    """Global id of the first cell of each block."""
    return np.concatenate([[0], np.cumsum([len(b) for b in mesh.blocks])]).astype(np.int64)


# --------------------------------------------------------------------------- reading / writing


def _topological_dim(cell_type: str) -> int | None:
    """Dimension of a registered element type, or of any meshio cell type by its family name (None if unknown)."""
    try:
        return _types.get(cell_type).dim
    except ValueError:
        pass
    for prefixes, d in ((("tetra", "hexahedron", "wedge", "pyramid", "polyhedron"), 3),
                        (("triangle", "quad", "polygon"), 2), (("line",), 1), (("vertex",), 0)):
        if cell_type.startswith(prefixes):
            return d
    return None


def _int_tags(values, name: str) -> np.ndarray:
    tags = np.asarray(values).reshape(-1)
    if tags.dtype.kind == "f":
        if not np.all(np.isfinite(tags)) or np.any(tags != np.round(tags)):
            raise MeshError(f"cell data {name!r} holds non-integer tags")
    return tags.astype(np.int64)


def read_mesh(path) -> Mesh:
    """Read a mesh with meshio: the solid cells of its dimension, and its groups.

    Tags come from cell data 'gmsh:physical', 'cell_tags' or 'medit:ref'; the
    blocks are one per (type, tag), in order of first appearance, with the
    file's cell order kept within each block.  A 2D mesh stored with z == 0 is
    returned with 2 coordinates.  Physical groups, cell sets and tags of every
    dimension become Mesh.groups (runtime.mesh_groups): lower-dimensional cells
    (boundary triangles/quads/lines/vertices) are kept there, in the groups they
    belong to; those in no group are dropped.  gmsh files (first line
    $MeshFormat) get their node order converted to VTK's where it differs
    (GMSH_TO_VTK: the prism; meshio converts the quadratic types itself).
    """
    path = Path(path)
    m = read_meshio(path)
    dims = {cb.type: _topological_dim(cb.type) for cb in m.cells}
    unknown = sorted(t for t, d in dims.items() if d is None)
    if unknown:
        raise MeshError(f"{path}: unknown cell type(s) {', '.join(unknown)}")
    dim = max(dims.values(), default=-1)
    # the types a file's cells are read as: a shell is a file's triangle read with [mesh] element = "shell"
    solid = tuple(t for t in _types.names(dim=dim) if _types.get(t).file_type == t)
    if dim < 2 and not any(t in solid for t in dims):   # lower-dimensional cells of a registered type only
        raise MeshError(f"{path}: no 2D or 3D cells (found: {', '.join(sorted(dims)) or 'none'})")
    bad = sorted(t for t, d in dims.items() if d == dim and t not in solid)
    if bad:
        raise MeshError(f"{path}: unsupported {dim}D cell type(s) {', '.join(bad)} "
                        f"(supported: {', '.join(solid)})")

    points = _points_for_dim(np.asarray(m.points, dtype=np.float64), dim, path)
    tag_key = next((k for k in _TAG_KEYS if k in m.cell_data), None)
    gmsh = _is_gmsh(path)
    # MSH 2 writes a cell once per physical group it is in: those copies are one cell in several groups
    repeat = _msh2_repeats(m, dims, dim, tag_key) if gmsh and tag_key is not None else {}
    groups: dict = {}
    all_tags, where, lower = [], [], []       # per meshio block: tags, (group key, rows), kept boundary cells
    for i, cb in enumerate(m.cells):
        tags = None if tag_key is None else _int_tags(m.cell_data[tag_key][i], tag_key)
        all_tags.append(tags)
        data = np.asarray(cb.data, dtype=np.int64)
        if gmsh and cb.type in GMSH_TO_VTK:
            data = data[:, GMSH_TO_VTK[cb.type]]
        if dims[cb.type] != dim:
            where.append(None)
            lower.append(data if cb.type in FACE_CORNERS else None)
            continue
        lower.append(None)
        mine = []
        keep = np.flatnonzero(repeat[i] < 0) if i in repeat else None
        for key, rows in _split_rows_by_tag(cb.type, len(data), tags, keep):
            groups.setdefault(key, []).append(data[rows])
            mine.append((key, rows, sum(len(c) for c in groups[key]) - len(rows)))
        where.append(mine)
    blocks, offset = [], {}
    for (ctype, tag), parts in groups.items():
        cells = np.concatenate(parts)
        offset[(ctype, tag)] = sum(len(b) for b in blocks)
        tags = None if tag is None else np.full(len(cells), tag, dtype=np.int64)
        blocks.append(CellBlock(ctype, cells, tags))
    _check_node_ids(blocks, len(points), path)
    solid_ids = []                            # global id of every cell of each solid meshio block
    for i, mine in enumerate(where):
        if mine is None:
            solid_ids.append(None)
            continue
        ids = np.empty(len(m.cells[i].data), np.int64)
        for key, rows, start in mine:
            ids[rows] = offset[key] + start + np.arange(len(rows))
        solid_ids.append(ids)
    for i, rep in repeat.items():             # a copy gets the id of the cell it repeats (blocks come in order)
        copies = np.flatnonzero(rep >= 0)
        block, row = np.divmod(rep[copies], 1 << 32)
        solid_ids[i][copies] = [solid_ids[int(b)][int(r)] for b, r in zip(block, row)]
    for i, cells in enumerate(lower):
        if cells is not None and cells.size and (cells.min() < 0 or cells.max() >= len(points)):
            raise MeshError(f"{path}: {m.cells[i].type} cells (block {i} of the file) refer to nodes outside "
                            f"0..{len(points) - 1}")
    return Mesh(points, blocks, read_groups(m, all_tags, solid_ids, lower))


def read_meshio(path):
    """meshio.read(path), every failure a MeshError naming the file: a gmsh .msh file's sections and
    counts are checked first (runtime.msh_check: a truncated or inconsistent file is refused naming
    the broken part, where meshio would read part of it or fail with an array error)."""
    import meshio

    path = Path(path)
    if not path.is_file():
        raise MeshError(f"mesh file not found: {path}")
    if path.stat().st_size == 0:
        raise MeshError(f"mesh file {path} is empty")
    if _is_gmsh(path):
        from .msh_check import check_msh
        check_msh(path)
    # meshio prints its reasons and may even call sys.exit(); capture both
    said = io.StringIO()
    try:
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            return meshio.read(path)
    except (Exception, SystemExit) as exc:
        detail = " ".join(said.getvalue().split())
        reason = f"{type(exc).__name__}: {exc}" if not isinstance(exc, SystemExit) else ""
        raise MeshError(f"could not read mesh {path}: " + " ".join(x for x in (reason, detail) if x)) from None


def _split_rows_by_tag(cell_type, n, tags, keep=None):
    """Yield ((type, tag), row ids) per distinct tag, tags in order of first appearance (rows in keep only)."""
    rows = np.arange(n) if keep is None else keep
    if tags is None:
        yield (cell_type, None), rows
        return
    tags = tags[rows]
    uniq, first = np.unique(tags, return_index=True)
    for t in uniq[np.argsort(first)]:
        yield (cell_type, int(t)), rows[tags == t]


def _msh2_repeats(m, dims, dim, tag_key) -> dict:
    """{meshio block: per cell, -1, or (block << 32) + row of the earlier cell with the same nodes and
    another tag}: MSH 2 lists a cell in several physical groups once per group."""
    by_type: dict = {}
    for i, cb in enumerate(m.cells):
        if dims[cb.type] == dim and len(cb.data):
            by_type.setdefault(cb.type, []).append(i)
    out = {}
    for blocks in by_type.values():
        data = np.concatenate([np.asarray(m.cells[i].data, np.int64) for i in blocks])
        tags = np.concatenate([np.asarray(m.cell_data[tag_key][i]).reshape(-1) for i in blocks])
        src = np.concatenate([(np.int64(i) << 32) + np.arange(len(m.cells[i].data)) for i in blocks])
        _, first, inverse = np.unique(data, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.reshape(-1)
        orig = first[inverse]
        copy = (orig != np.arange(len(data))) & (tags != tags[orig])
        if not copy.any():
            continue
        rep = np.where(copy, src[orig], -1)
        start = 0
        for i in blocks:
            n = len(m.cells[i].data)
            out[i] = rep[start:start + n]
            start += n
    return out


def _is_gmsh(path) -> bool:
    """A gmsh .msh file (its first line is $MeshFormat), whatever its name."""
    try:
        with open(path, "rb") as fh:
            return fh.read(64).lstrip().startswith(b"$MeshFormat")
    except OSError:
        return False


def _check_node_ids(blocks, n_points: int, path) -> None:
    """Every node id a cell lists must be one of the file's points (0 .. n_points - 1): some
    formats (VTU, VTK) are read without this check and would fail later in indexing."""
    for b, block in enumerate(blocks):
        bad = np.flatnonzero(((block.cells < 0) | (block.cells >= n_points)).any(axis=1))
        if bad.size:
            row = block.cells[bad[0]]
            ids = ", ".join(str(int(i)) for i in row[(row < 0) | (row >= n_points)][:4])
            tag = "" if block.tags is None else f", tag {int(block.tags[0])}"
            raise MeshError(f"{path}: block {b} ({block.type}{tag}): cell {int(bad[0])} of the block refers "
                            f"to node(s) {ids}, but the file has {n_points} nodes (ids 0..{n_points - 1}); "
                            f"{bad.size} such cell(s) in the block")


def _points_for_dim(points, dim, path):
    """3D meshes need 3 coordinates; 2D meshes stored with z == 0 lose z."""
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshError(f"{path}: points have shape {points.shape}")
    if dim < 2:                                 # bars, ...: as many coordinates as the file has
        return points
    if dim == 3:
        if points.shape[1] != 3:
            raise MeshError(f"{path}: 3D cells but {points.shape[1]}D points")
        return points
    if points.shape[1] == 3:
        extent = float(np.ptp(points[:, :2], axis=0).max()) if len(points) else 0.0
        if np.any(np.abs(points[:, 2]) > 1e-12 * max(extent, 1.0)):
            raise MeshError(f"{path}: 2D cells with nonzero z (surface meshes in 3D are not supported)")
        return points[:, :2].copy()
    return points


def to_meshio(mesh: Mesh, pad_to_3d: bool = False, tag_name: str = "cell_tags"):
    """A meshio.Mesh of the same points and blocks; tags (0 where a block has none) under tag_name.

    pad_to_3d appends z = 0 to 2D points (VTU wants 3 coordinates).
    """
    import meshio

    points = mesh.points
    if pad_to_3d and mesh.dim == 2:
        points = np.column_stack([points, np.zeros(mesh.n_points)])
    cells = [(_types.get(b.type).file_type, b.cells) for b in mesh.blocks]     # a shell is a VTK triangle
    cell_data = {}
    if any(b.tags is not None for b in mesh.blocks):
        cell_data[tag_name] = [b.tags if b.tags is not None else np.zeros(len(b), np.int64)
                               for b in mesh.blocks]
    return meshio.Mesh(points, cells, cell_data=cell_data)


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


_GRAD = {t: _gradient_table(_types.get(t)) for t in NODES_PER_CELL}


def _det(J: np.ndarray) -> np.ndarray:
    """Determinants of (..., d, d) with d = 2 or 3, written out (much faster than linalg)."""
    if J.shape[-1] == 2:
        return J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    return (J[..., 0, 0] * (J[..., 1, 1] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 1])
            - J[..., 0, 1] * (J[..., 1, 0] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 0])
            + J[..., 0, 2] * (J[..., 1, 0] * J[..., 2, 1] - J[..., 1, 1] * J[..., 2, 0]))


def _sample_dets(points: np.ndarray, block: CellBlock) -> np.ndarray:
    """det J at the corners and the centroid of every cell: (n, q).

    Cells of a lower topological dimension r < d have no orientation: their
    measure sqrt(det(J^T J)) (length, area) instead, never negative."""
    el = _types.get(block.type)
    X = points[block.cells]                                  # (n, k, d)
    J = np.einsum("nkd,qkr->nqdr", X, _gradient_table(el), optimize=True)
    if el.dim == points.shape[1]:
        return _det(J)
    G = np.einsum("nqdr,nqds->nqrs", J, J)
    gram = G[..., 0, 0] if el.dim == 1 else _det(G)
    return np.sqrt(np.maximum(gram, 0.0))


def _cell_size(points: np.ndarray, block: CellBlock) -> np.ndarray:
    X = points[block.cells[:, :_types.get(block.type).n_corners]]
    return np.linalg.norm(X.max(axis=1) - X.min(axis=1), axis=1)


# --------------------------------------------------------------------------- faces
#
# Faces (edges in 2D) in outward order for a positively oriented cell, corners
# only; quadratic midside nodes are looked up separately.

def _solid_blocks(mesh: Mesh) -> list:
    """(index, block, ElementType) of the blocks whose topological dimension is the space dimension."""
    out = []
    for bi, blk in enumerate(mesh.blocks):
        el = _types.get(blk.type)
        if el.dim == mesh.dim:
            out.append((bi, blk, el))
    return out


@dataclass
class _FaceTable:
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


def _group_rows(keys: np.ndarray):
    """Group equal rows: (order, group id per row, count per group)."""
    order = np.lexsort(keys.T[::-1])
    sk = keys[order]
    new = np.empty(len(keys), dtype=bool)
    new[:1] = True
    new[1:] = np.any(sk[1:] != sk[:-1], axis=1)
    gid = np.empty(len(keys), dtype=np.int64)
    gid[order] = np.cumsum(new) - 1
    return order, gid, np.bincount(gid)


def _face_table(mesh: Mesh) -> _FaceTable:
    width = 4 if mesh.dim == 3 else 2
    off = _offsets(mesh)
    parts = []
    for bi, blk, el in _solid_blocks(mesh):
        n = len(blk)
        for fi, f in enumerate(el.faces):
            face = f.corners
            rows = np.full((n, width), -1, dtype=np.int64)
            rows[:, :len(face)] = blk.cells[:, face]
            parts.append((rows, np.full(n, len(face)), off[bi] + np.arange(n), np.full(n, bi),
                          np.arange(n), np.full(n, fi), np.full(n, el.quadratic)))
    if not parts:
        e = np.zeros(0, np.int64)
        return _FaceTable(np.zeros((0, width), np.int64), e, e, e, e, e, e.astype(bool), e, e, e)
    cols = [np.concatenate(c) for c in zip(*parts)]
    nodes = cols[0]
    order, gid, count = _group_rows(np.sort(nodes, axis=1))
    return _FaceTable(nodes, cols[1], cols[2], cols[3], cols[4], cols[5], cols[6].astype(bool),
                      gid, count, order)


def _boundary_rows(ft: _FaceTable) -> np.ndarray:
    return np.flatnonzero(ft.count[ft.group] == 1)


def boundary_faces(mesh: Mesh) -> list:
    """Faces (edges in 2D) used by exactly one cell: (block index, cell index, nodes).

    Nodes are in outward order (right-hand normal, or edge direction with the
    cell on the left, points out of a positively oriented cell); quadratic
    cells give their midside nodes too (triangle6 / line3 order).
    """
    if mesh.n_cells == 0:
        return []
    ft = _face_table(mesh)
    out = []
    for r in _boundary_rows(ft):
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
    _check_structure(mesh)
    _check_jacobians(mesh)
    if not _solid_blocks(mesh):     # only lower-dimensional cells (bars in 3D, ...): no faces to match
        _check_midsides(mesh)
        return
    ft = _face_table(mesh)
    _check_shared_faces(mesh, ft)
    _check_midsides(mesh)
    _check_quad_against_triangles(ft)
    _check_overlapping_faces(mesh, ft)
    check_groups_on_surface(mesh, ft, _boundary_rows(ft), MeshError)


def _check_structure(mesh: Mesh) -> None:
    if mesh.n_cells == 0:
        raise MeshError("mesh has no cells")
    wrong = sorted({b.type for b in mesh.blocks if mesh.dim not in _types.get(b.type).space_dims})
    if wrong:
        raise MeshError(f"cell type(s) {', '.join(wrong)} do not fit a {mesh.dim}D mesh")
    check_coordinates(mesh.points)
    off = _offsets(mesh)
    out_of_range, repeated = [], []
    for bi, blk in enumerate(mesh.blocks):
        c = blk.cells
        out_of_range.append(off[bi] + np.flatnonzero(np.any((c < 0) | (c >= mesh.n_points), axis=1)))
        s = np.sort(c, axis=1)
        repeated.append(off[bi] + np.flatnonzero(np.any(s[:, 1:] == s[:, :-1], axis=1)))
    out_of_range, repeated = np.concatenate(out_of_range), np.concatenate(repeated)
    if out_of_range.size:
        raise MeshError(f"node index out of range 0..{mesh.n_points - 1} in cells {_fmt_ids(out_of_range)}")
    if repeated.size:
        raise MeshError(f"repeated node within a cell in cells {_fmt_ids(repeated)}")
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
    oriented when read (runtime.surfaces.orient_triangles); a mesh that still disagrees is refused."""
    from .surfaces import winding_conflicts
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
        raise MeshError(f"non-finite (NaN/Inf) coordinates at nodes {_fmt_ids(bad, noun='node')}: "
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
    off = _offsets(mesh)
    inverted, degenerate = [], []
    for bi, blk in enumerate(mesh.blocks):
        dets = _sample_dets(mesh.points, blk)
        tol = _DET_TOL * _cell_size(mesh.points, blk) ** _types.get(blk.type).dim
        lo = dets.min(axis=1)
        inverted.append(off[bi] + np.flatnonzero(lo < -tol))
        degenerate.append(off[bi] + np.flatnonzero((lo >= -tol) & (lo <= tol)))
    inverted, degenerate = np.concatenate(inverted), np.concatenate(degenerate)
    msgs = []
    if inverted.size:
        msgs.append(f"inverted cells (det J < 0 at a corner or the centroid) {_fmt_ids(inverted)}"
                    + _node_order_hint(mesh, inverted))
    if degenerate.size:
        msgs.append(f"degenerate cells (det J ~ 0, collapsed or flat) {_fmt_ids(degenerate)}")
    if msgs:
        raise MeshError("; ".join(msgs))


def _node_order_hint(mesh: Mesh, inverted: np.ndarray) -> str:
    """When every cell of a type is inverted, the file's node order (or orientation) is the likely cause."""
    off = _offsets(mesh)
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
            "runtime.mesh.orient_cells renumbers mirrored cells")


def _face_orientation(ft: _FaceTable, rows: np.ndarray):
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


def _check_shared_faces(mesh: Mesh, ft: _FaceTable) -> None:
    kind = "edge" if mesh.dim == 2 else "face"
    over = np.flatnonzero(ft.count[ft.group] > 2)
    if over.size:
        raise MeshError(f"{kind}s shared by more than two cells (overlapping cells) in cells {_fmt_ids(ft.cell[over])}")
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
    off = _offsets(mesh)
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


def _check_quad_against_triangles(ft: _FaceTable) -> None:
    """A boundary triangle whose three nodes all belong to one boundary quad splits that quad."""
    rows = _boundary_rows(ft)
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
    order, gid, count = _group_rows(keys)
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


def _check_overlapping_faces(mesh: Mesh, ft: _FaceTable) -> None:
    """Boundary faces that lie on top of other boundary faces mean a non-conforming interface.

    In a conforming mesh the boundary faces only meet along edges.  A hanging
    node, a quad against two triangles, mismatched diagonals or unmerged
    duplicate nodes all leave boundary faces on both sides of the interface
    that cover the same area.  Each face gets a test point at a generic interior
    position (so it does not fall on the other side's edges); it must not lie
    inside another boundary face (within _PLANE_TOL of its plane).
    """
    rows = _boundary_rows(ft)
    if rows.size < 2:
        return
    geo = _face_geometry_3d if mesh.dim == 3 else _face_geometry_2d
    centre, radius, normal, test = geo(mesh.points, ft.nodes[rows], ft.nvert[rows])
    from scipy.spatial import cKDTree

    tree = cKDTree(test)
    near = tree.query_ball_point(centre, radius * (1 + 1e-9) + 1e-300, workers=-1)
    lens = np.fromiter((len(x) for x in near), dtype=np.int64, count=len(near))
    j = np.repeat(np.arange(len(rows)), lens)              # face that might contain ...
    i = np.fromiter((v for x in near for v in x), dtype=np.int64, count=int(lens.sum()))  # ... this test point
    keep = ft.cell[rows[i]] != ft.cell[rows[j]]
    keep &= np.abs(np.einsum("nd,nd->n", normal[i], normal[j])) > 0.5
    i, j = i[keep], j[keep]
    off_plane = np.abs(np.einsum("nd,nd->n", test[i] - centre[j], normal[j]))
    keep = off_plane <= _PLANE_TOL * radius[j]
    i, j = i[keep], j[keep]
    inside = _inside_3d if mesh.dim == 3 else _inside_2d
    hit = inside(mesh.points, ft.nodes[rows[j]], ft.nvert[rows[j]], test[i], normal[j])
    if np.any(hit):
        raise MeshError("non-conforming interface (hanging node, split or mismatched faces, "
                        "or unmerged duplicate nodes): faces of "
                        + _fmt_pairs(ft.cell[rows[i[hit]]], ft.cell[rows[j[hit]]]))


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
    e = _INSIDE_TOL
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
    return (s > _INSIDE_TOL) & (s < 1 - _INSIDE_TOL)


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
        flip = np.all(_sample_dets(mesh.points, blk) < 0, axis=1)
        cells[flip] = cells[flip][:, list(_types.get(blk.type).flip)]
        blocks.append(CellBlock(blk.type, cells, None if blk.tags is None else blk.tags.copy()))
    return Mesh(mesh.points.copy(), blocks, list(mesh.groups))    # same nodes and cell ids: same groups


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
