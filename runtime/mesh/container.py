"""The mesh container: cell blocks of one type, their points, groups and tags, and the
facts every mesh module shares (node counts, tolerances, the MeshError that names bad cells).

Node ordering is meshio's (= VTK's) everywhere. Cell ids in error messages are global: blocks
are numbered in order and the cells of block b follow those of blocks 0..b-1.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ... import elements as _types
from ..base.errors import TensormassError

# Built-in types, read from the element table (types registered later: elements.get).
NODES_PER_CELL = {name: _types.get(name).n_nodes for name in _types.builtin()}
SOLID_TYPES_3D = tuple(n for n in _types.builtin() if _types.get(n).dim == 3 and _types.get(n).solid)
SOLID_TYPES_2D = tuple(n for n in _types.builtin() if _types.get(n).dim == 2 and _types.get(n).solid)

# Relative tolerances.  DET_TOL: det J below this times h^dim is "degenerate"
# (h = cell bounding-box diagonal); PLANE_TOL: how far (relative to the face
# size) a point may sit off a face's plane and still count as lying on it.
DET_TOL = 1e-10
PLANE_TOL = 1e-4
INSIDE_TOL = 1e-8
# Kernels and checks raise coordinates to powers up to 6 (h^dim tolerances, squared
# Jacobian determinants, energies of E h^3 strain^2): beyond 1e50 (1e50^6 = 1e300) they
# overflow float64's 1.8e308, and a body smaller than 1e-50 underflows the same way.
COORD_MAX = 1e50
SIZE_MIN = 1e-50


class MeshError(TensormassError):
    """Bad mesh input; the message names the problem and the cell ids involved."""


def format_ids(ids, first: int = 8, noun: str = "cell") -> str:
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
    groups: list = field(default_factory=list)          # runtime.mesh.mesh_groups.Group: named regions of the file
    # nodes created by refinement at edge midpoints / face centres: rows (node, 2 or 4 parents, -1
    # padded); runtime.physics.hanging finds those that hang on an unrefined neighbour.  None: no such node
    midpoints: np.ndarray | None = None
    # numeric cell data of the file (not its tags), per cell in block order: name -> (n_cells, k)
    # (a fibre field: [[material]] fibres = "NAME"); a mesh made from another (refined, cut) has none
    cell_data: dict = field(default_factory=dict)

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


def block_offsets(mesh: Mesh) -> np.ndarray:
    """Global id of the first cell of each block."""
    return np.concatenate([[0], np.cumsum([len(b) for b in mesh.blocks])]).astype(np.int64)




def topological_dim(cell_type: str) -> int | None:
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

