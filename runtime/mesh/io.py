"""Reading meshes with meshio (gmsh files checked first: runtime.mesh.msh_check) and writing them
back: the solid cells of the mesh's dimension, and its groups of every dimension."""
from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
from .container import CellBlock, Mesh, MeshError, topological_dim
from .mesh_groups import FACE_CORNERS, read_groups
from .msh_check import check_msh

from ... import elements as _types

# hexahedron20/27 and pyramid13 itself): gmsh's prism has its base triangle (0, 1, 2) wound the
# other way round (counterclockwise seen from the top face), VTK's wedge clockwise.  The other
# types tensormass supports (tetra, tetra10, hexahedron, pyramid, triangle, triangle6, quad) are
# read from gmsh files with positive volume as they are (tests/runtime/mesh/test_msh_node_order.py).
GMSH_TO_VTK = {"wedge": [0, 2, 1, 3, 5, 4]}

# Cell data names that carry integer region tags, most specific first.
_TAG_KEYS = ("gmsh:physical", "cell_tags", "medit:ref")

# --------------------------------------------------------------------------- reading / writing



def _int_tags(values, name: str) -> np.ndarray:
    tags = np.asarray(values).reshape(-1)
    if tags.dtype.kind == "f":
        if not np.all(np.isfinite(tags)) or np.any(tags != np.round(tags)):
            raise MeshError(f"cell data {name!r} holds non-integer tags")
    return tags.astype(np.int64)


def read_mesh(path, read=None) -> Mesh:
    """Read a mesh with meshio: the solid cells of its dimension, and its groups.

    Tags come from cell data 'gmsh:physical', 'cell_tags' or 'medit:ref'; the
    blocks are one per (type, tag), in order of first appearance, with the
    file's cell order kept within each block.  A 2D mesh stored with z == 0 is
    returned with 2 coordinates.  Physical groups, cell sets and tags of every
    dimension become Mesh.groups (runtime.mesh.mesh_groups): lower-dimensional cells
    (boundary triangles/quads/lines/vertices) are kept there, in the groups they
    belong to; those in no group are dropped.  gmsh files (first line
    $MeshFormat) get their node order converted to VTK's where it differs
    (GMSH_TO_VTK: the prism; meshio converts the quadratic types itself).  read: the file's
    read_meshio(path) when the caller has it already.
    """
    path = Path(path)
    m = read_meshio(path) if read is None else read
    dims = {cb.type: topological_dim(cb.type) for cb in m.cells}
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
    return Mesh(points, blocks, read_groups(m, all_tags, solid_ids, lower), cell_data=_cell_data(m, solid_ids))


def _cell_data(m, solid_ids) -> dict:
    """The file's numeric cell data on its solid cells, per cell in block order: name -> (n, k) with
    k columns (a vector field has 2 or 3); data that some solid block lacks, or of mixed widths, or
    not numbers, is left out (a scene that names it is told which the mesh has)."""
    n_cells = 1 + max((int(ids.max()) for ids in solid_ids if ids is not None and ids.size), default=-1)
    out = {}
    for name, per_block in m.cell_data.items():
        if name in _TAG_KEYS or name.startswith("gmsh:"):
            continue
        values, width = np.full((n_cells, 3), np.nan), None
        try:
            for block, ids in zip(per_block, solid_ids):
                if ids is None:
                    continue
                data = np.asarray(block, dtype=np.float64).reshape(len(ids), -1)
                if width not in (None, data.shape[1]) or data.shape[1] > 3:
                    raise ValueError(name)
                width = data.shape[1]
                values[ids, :width] = data
        except (TypeError, ValueError):
            continue
        if width is not None:
            out[name] = np.ascontiguousarray(values[:, :width])
    return out


def read_meshio(path):
    """meshio.read(path), every failure a MeshError naming the file: a gmsh .msh file's sections and
    counts are checked first (runtime.mesh.msh_check: a truncated or inconsistent file is refused naming
    the broken part, where meshio would read part of it or fail with an array error)."""
    import meshio

    path = Path(path)
    if not path.is_file():
        raise MeshError(f"mesh file not found: {path}")
    if path.stat().st_size == 0:
        raise MeshError(f"mesh file {path} is empty")
    if _is_gmsh(path):
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


