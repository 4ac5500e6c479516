"""Named groups of a mesh file: gmsh physical groups, meshio cell sets, integer cell tags.

    groups = read_groups(m, dim, solid_ids)    # from a meshio.Mesh (read_mesh does this)
    check_groups_on_surface(mesh, face_table)  # boundary groups must lie on the body's surface

A Group is what a scene's `region = "<name or id>"` selects:

    name      the physical name (gmsh $PhysicalNames, meshio field_data / cell_sets), or None
    id        the physical id / integer tag, or None (a named cell set without one)
    dim       topological dimension of its cells (3: volume, 2: surface, 1: curve, 0: point)
    cell_ids  sorted global ids of the solid cells (blocks in order) it holds: volume groups
    cells     {cell type: (n, k) node ids} of its lower-dimensional cells (boundary triangles,
              quads, lines, vertices): surface / curve / point groups

Sources, merged by name when a tag's (id, dim) has a physical name: cell data
"gmsh:physical" (else "cell_tags", "medit:ref"), the physical names in field_data
({name: [id, dim]}), and meshio cell_sets (gmsh 4.1 files list every group an entity belongs
to there; the tag holds only the first).  gmsh numbers physical groups per dimension: a
surface 1 and a volume 1 are different groups.

Lower-dimensional cells that belong to no group are dropped (nothing could select them).
Boundary groups are checked against the volume cells by check_groups_on_surface (check_mesh
calls it): every face cell must be a boundary face of the volume cells, every curve cell an
edge of one, every point a node of one.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ... import elements as _types
from ..base.errors import TensormassError
from .faces import boundary_rows, face_table

__all__ = ["Group", "read_groups", "check_groups_on_surface", "carry_groups", "group_label", "FACE_CORNERS", "cell_dim"]

# Lower-dimensional cell types a group may hold, with their corner counts (meshio names).
FACE_CORNERS = {"vertex": 1, "line": 2, "line3": 2, "triangle": 3, "triangle6": 3, "quad": 4, "quad8": 4,
                "quad9": 4}
_FACE_DIM = {"vertex": 0, "line": 1, "line3": 1, "triangle": 2, "triangle6": 2, "quad": 2, "quad8": 2, "quad9": 2}


def cell_dim(cell_type: str) -> int | None:
    """Topological dimension of a registered element type or a face type (None: unknown)."""
    if cell_type in _FACE_DIM:
        return _FACE_DIM[cell_type]
    try:
        return _types.get(cell_type).dim
    except ValueError:
        return None


@dataclass
class Group:
    name: str | None
    id: int | None
    dim: int
    cell_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    cells: dict = field(default_factory=dict)

    @property
    def label(self) -> str:
        return group_label(self)

    def n_cells(self) -> int:
        return int(self.cell_ids.size) + sum(len(c) for c in self.cells.values())


_KIND = {3: "volume", 2: "surface", 1: "curve", 0: "point"}


def group_label(g: Group) -> str:
    """'"attached" (id 2, surface)' / 'id 7 (volume)' / '"tool" (curve)'."""
    kind = _KIND.get(g.dim, f"{g.dim}D")
    if g.name is not None:
        return f"{g.name!r} (" + (f"id {g.id}, " if g.id is not None else "") + f"{kind})"
    return f"id {g.id} ({kind})"


class _Builder:
    """Accumulates cells per group key: a name, or ("id", dim, id) for an unnamed tag."""

    def __init__(self, names_by_tag: dict, ids_by_name: dict):
        self.names_by_tag = names_by_tag       # (id, dim) -> name
        self.ids_by_name = ids_by_name         # name -> (id, dim)
        self.solid: dict = {}
        self.lower: dict = {}
        self.dims: dict = {}
        self.order: list = []

    def _key(self, key, dim):
        if key not in self.dims:
            self.order.append(key)
            self.dims[key] = dim
        else:
            self.dims[key] = max(self.dims[key], dim)
        return key

    def tag(self, tag: int, dim: int):
        name = self.names_by_tag.get((tag, dim))
        return self._key(name if name is not None else ("id", dim, tag), dim)

    def named(self, name: str, dim: int):
        return self._key(name, dim)

    def add_solid(self, key, ids):
        self.solid.setdefault(key, []).append(np.asarray(ids, np.int64))

    def add_lower(self, key, ctype, rows):
        self.lower.setdefault(key, {}).setdefault(ctype, []).append(np.asarray(rows, np.int64))

    def groups(self) -> list:
        out = []
        for key in self.order:
            if isinstance(key, tuple):
                name, (_, dim, gid) = None, key
            else:
                name, dim = key, self.dims[key]
                gid = self.ids_by_name.get(key, (None, None))[0]
            ids = np.unique(np.concatenate(self.solid[key])) if key in self.solid else np.zeros(0, np.int64)
            cells = {}
            for ctype, parts in self.lower.get(key, {}).items():
                rows = np.concatenate(parts)
                # the same cell listed twice (a tag and a cell set): keep it once, file order
                _, first = np.unique(np.sort(rows, axis=1), axis=0, return_index=True)
                cells[ctype] = rows[np.sort(first)]
            out.append(Group(name, None if gid is None else int(gid), int(dim), ids, cells))
        return out


def _physical_names(field_data) -> tuple:
    """(name by (id, dim), (id, dim) by name) from meshio field_data entries [id, dim]."""
    by_tag, by_name = {}, {}
    for name, value in (field_data or {}).items():
        v = np.asarray(value).reshape(-1)
        if v.size != 2 or v.dtype.kind not in "iuf" or not np.all(v == np.round(v)):
            continue
        gid, dim = int(v[0]), int(v[1])
        by_tag[(gid, dim)] = str(name)
        by_name[str(name)] = (gid, dim)
    return by_tag, by_name


def read_groups(m, tags_per_block, solid_ids, keep) -> list:
    """Groups of a meshio mesh.

    tags_per_block  integer tags of every meshio block (None: the file has no tags)
    solid_ids       global cell id of each cell of every meshio block that became a solid block
                    (None for the other blocks)
    keep            per meshio block: the (converted) node ids of its cells, for lower-dimensional
                    blocks of a FACE_CORNERS type (None for the others)
    """
    by_tag, by_name = _physical_names(getattr(m, "field_data", None))
    b = _Builder(by_tag, by_name)
    for i, cb in enumerate(m.cells):
        dim = cell_dim(cb.type)
        if dim is None or (solid_ids[i] is None and keep[i] is None):
            continue
        tags = tags_per_block[i]
        if tags is None:
            continue
        uniq, first = np.unique(tags, return_index=True)
        for t in uniq[np.argsort(first)]:
            sel = tags == t
            key = b.tag(int(t), dim)
            if solid_ids[i] is not None:
                b.add_solid(key, solid_ids[i][sel])
            else:
                b.add_lower(key, cb.type, keep[i][sel])
    for name, per_block in (getattr(m, "cell_sets", None) or {}).items():
        if str(name).startswith("gmsh:") or per_block is None:
            continue
        for i, idx in enumerate(per_block):
            if i >= len(m.cells) or idx is None:
                continue
            idx = np.asarray(idx).reshape(-1)
            if idx.size == 0 or idx.dtype.kind not in "iu":
                continue
            dim = cell_dim(m.cells[i].type)
            if dim is None or (solid_ids[i] is None and keep[i] is None):
                continue
            n = len(m.cells[i].data)
            idx = idx[(idx >= 0) & (idx < n)]
            key = b.named(str(name), dim)
            if solid_ids[i] is not None:
                b.add_solid(key, solid_ids[i][idx])
            else:
                b.add_lower(key, m.cells[i].type, keep[i][idx])
    return [g for g in b.groups() if g.n_cells()]


# ------------------------------------------------------------------------------ on the surface


def boundary_keys(mesh, ft, rows):
    """Sorted corner tuples of the boundary faces (rows of the face table) -> row, as a dict."""
    return {tuple(sorted(int(v) for v in ft.nodes[r] if v >= 0)): int(r) for r in rows}


def _corner_key(row, ctype) -> tuple:
    return tuple(sorted(int(v) for v in row[:FACE_CORNERS[ctype]]))


def check_groups_on_surface(mesh, ft, boundary_rows, error=TensormassError) -> None:
    """Every cell of a lower-dimensional group must lie on the boundary of the volume cells."""
    lower = [g for g in getattr(mesh, "groups", ()) if g.cells]
    if not lower:
        return
    keys = boundary_keys(mesh, ft, boundary_rows)
    nodes = set(int(v) for v in ft.nodes[boundary_rows].ravel() if v >= 0)
    edges = set()
    F, nv = ft.nodes[boundary_rows], ft.nvert[boundary_rows]
    for v in np.unique(nv):
        R = F[nv == v][:, :v]
        if v == 2:
            continue
        for a in range(v):
            e = np.sort(np.column_stack([R[:, a], R[:, (a + 1) % v]]), axis=1)
            edges.update(map(tuple, e.tolist()))
    facet = mesh.dim - 1
    for g in lower:
        for ctype, rows in g.cells.items():
            d = _FACE_DIM[ctype]
            if d == facet:
                ok = np.array([_corner_key(r, ctype) in keys for r in rows], bool)
                what = "a boundary face of the volume cells"
            elif d == 1:                                  # curves in 3D
                ok = np.array([tuple(sorted((int(r[0]), int(r[1])))) in edges for r in rows], bool)
                what = "an edge of a boundary face"
            elif d == 0:
                ok = np.array([int(r[0]) in nodes for r in rows], bool)
                what = "a node of a boundary face"
            else:
                raise error(f"region {g.label}: {len(rows)} {ctype} cell(s) of dimension {d} in a "
                            f"{mesh.dim}D mesh: a boundary group holds faces, curves or points of the body")
            bad = np.flatnonzero(~ok)
            if bad.size:
                first = ", ".join(str(int(v)) for v in rows[bad[0]])
                raise error(f"region {g.label}: {bad.size} of its {len(rows)} {ctype} cell(s) are not on the "
                            f"body's surface (each must be {what}; e.g. the cell with nodes [{first}]): a "
                            "boundary group must lie on the boundary of the volume cells (an interface "
                            "inside the body, or cells that do not share the volume's nodes)")


# ------------------------------------------------------------------------------ through refinement


def carry_groups(old, new, parents, cell_parent) -> list:
    """The groups of `old` on its refinement `new` (runtime.mesh.refine: new point n_old + i is the
    midpoint of parents[i]; new cell c descends from old cell cell_parent[c]).

    Volume groups keep the descendants of their cells.  A new point lies on an old face (edge)
    exactly when all the old points it descends from (its support, through the midpoints) are
    corners of that face: a refined boundary face belongs to a surface group when its corners'
    support is one of the group's old faces; a curve's segment is cut at the midpoints whose
    support is its two ends; points stay.
    """
    groups = list(getattr(old, "groups", ()))
    if not groups:
        return []
    n_old = old.n_points
    supp = [frozenset((v,)) for v in range(n_old)]
    for a, b in np.asarray(parents, dtype=np.int64).tolist():
        supp.append(supp[a] | supp[b])
    cell_parent = np.asarray(cell_parent, dtype=np.int64)
    faces = None
    out = []
    for g in groups:
        cells = {}
        for ctype, rows in g.cells.items():
            d = _FACE_DIM[ctype]
            k = FACE_CORNERS[ctype]
            if d == new.dim - 1 and d > 0:
                if faces is None:
                    faces = _new_boundary(new, supp)
                want = {tuple(sorted(int(v) for v in r[:k])) for r in rows}
                for ftype, nodes, key in faces:
                    if key in want:
                        cells.setdefault(ftype, []).append(nodes)
            elif d == 1:
                cells.setdefault("line", []).extend(_split_segments(new, supp, rows, n_old))
            else:
                cells.setdefault(ctype, []).extend(np.asarray(rows).tolist())
        cells = {t: np.asarray(v, dtype=np.int64) for t, v in cells.items() if len(v)}
        ids = np.flatnonzero(np.isin(cell_parent, g.cell_ids)) if g.cell_ids.size else np.zeros(0, np.int64)
        out.append(Group(g.name, g.id, g.dim, ids.astype(np.int64), cells))
    return out


def _new_boundary(mesh, supp) -> list:
    """(face type, nodes, sorted support of its corners) of every boundary face of a refined mesh."""
    ft = face_table(mesh)
    out = []
    for r in boundary_rows(ft):
        blk = mesh.blocks[ft.block[r]]
        face = _types.get(blk.type).faces[ft.lface[r]]
        nodes = blk.cells[ft.local[r], list(face.nodes)]
        support = frozenset().union(*(supp[int(v)] for v in nodes[:len(face.corners)]))
        out.append((face.type, nodes.tolist(), tuple(sorted(support))))
    return out


def _split_segments(mesh, supp, rows, n_old) -> list:
    """Curve cells (a, b) cut at the new points on them (support {a, b}), in order along the segment."""
    on: dict = {}
    for v in range(n_old, len(supp)):
        if len(supp[v]) == 2:
            on.setdefault(supp[v], []).append(v)
    out = []
    for r in np.asarray(rows).tolist():
        a, b = int(r[0]), int(r[1])
        inner = on.get(frozenset((a, b)), [])
        if not inner:
            out.append([a, b])
            continue
        d = mesh.points[b] - mesh.points[a]
        t = [(float(np.dot(mesh.points[v] - mesh.points[a], d)), v) for v in inner]
        chain = [a] + [v for _, v in sorted(t)] + [b]
        out.extend([p, q] for p, q in zip(chain[:-1], chain[1:]))
    return out
