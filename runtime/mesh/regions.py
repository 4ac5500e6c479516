"""Where things apply: boxes, regions, and which material (and law) models each cell.

The one place that evaluates a scene's boxes and regions on a mesh; the scene checks
(runtime.scene.mesh_source) and the model (runtime.model.model) both call it.

    tol = box_tolerance(mesh.points)                   # 1e-8 of the bounding-box diagonal
    inside = box_contains(box, mesh.points, tol)       # closed box, +- tol
    which = assign_materials(mesh, materials)          # per block: material index of each cell (-1: none)
    value, owner = prescribed_values(fixed, mesh.points, tol)   # [[fixed]] that disagree are refused

Materials are matched in order, first match wins: a material selects the cells of its
region ("all", an element type, an integer cell tag or volume group id, or a group name)
whose centroid is inside its box (when it has one).  Materials and [[fixed]] entries are
read by attribute (region, box, law, quadrature; region, box, displacement, components, and rotation / translation when present),
so the scene's dataclasses and any object with those fields work.

Regions are the mesh file's groups (Mesh.groups, runtime.mesh.mesh_groups: gmsh physical groups,
meshio cell sets, tags), named by name or id.  Boundary conditions, loads and probes select
nodes or boundary faces by a region, a box, or both (the intersection):

    group = find_group(mesh, "attached", key="fixed[0].region")     # unknown: SceneError listing the known
    nodes = region_nodes(mesh, region="attached", box=None)          # sorted node ids
    faces = region_faces(mesh, region="loaded")                      # {face type: (n, k) node ids}, outward

region_faces gives boundary faces of the volume cells with their nodes in the face type's
order of the element table (Face.nodes: corners first, then midsides), oriented outward.
"""
from __future__ import annotations

import numpy as np

from ... import laws
from ... import elements as _types
from ..base.errors import SceneError, TensormassError
from .container import NODES_PER_CELL
from .faces import boundary_rows, face_table
from .mesh_groups import FACE_CORNERS, cell_dim, group_label

__all__ = ["material_dims", "BOX_TOLERANCE", "box_tolerance", "box_bounds", "box_contains", "region_mask", "material_mask",
           "may_cover", "assign_materials", "material_groups", "check_unused_materials", "prescribed_values",
           "switch_applies", "reachable_laws", "switch_parameters", "find_group", "known_regions",
           "region_cell_masks", "region_nodes", "region_faces", "selection_nodes"]

# Relative tolerance for "inside a box" (times the mesh's bounding-box diagonal): nodes on a face count.
BOX_TOLERANCE = 1e-8


# ============================================================================== boxes


def box_tolerance(points) -> float:
    """Slack for box tests: BOX_TOLERANCE of the bounding-box diagonal (0 for no points)."""
    points = np.asarray(points, dtype=float)
    if points.size == 0:
        return 0.0
    return BOX_TOLERANCE * float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def box_bounds(box, dim: int, tol: float = 0.0) -> tuple:
    """(lo, hi) of a box given as two corner points (in any order, extra coordinates dropped), widened by tol."""
    try:
        a, b = (np.asarray(c, dtype=float).reshape(-1) for c in box)
    except (TypeError, ValueError):
        raise TensormassError(f"a box must be two corner points, got {box!r}") from None
    if a.size < dim or b.size < dim:
        raise TensormassError(f"box corners need {dim} coordinates, got {box!r}")
    a, b = a[:dim], b[:dim]
    return np.minimum(a, b) - tol, np.maximum(a, b) + tol


def box_contains(box, points, tol: float = 0.0) -> np.ndarray:
    """Boolean mask of the points (n, dim) inside the closed box ((lo...), (hi...)), +- tol."""
    points = np.asarray(points, dtype=float)
    lo, hi = box_bounds(box, points.shape[1], tol)
    return np.all((points >= lo) & (points <= hi), axis=1)


# ============================================================================== regions of the mesh (groups)

_KINDS = {3: "volume", 2: "surface", 1: "curve", 0: "point"}


def _as_id(region):
    """An integer region (or a string of digits) as int, else None."""
    if isinstance(region, (int, np.integer)) and not isinstance(region, bool):
        return int(region)
    if isinstance(region, str) and region.lstrip("-").isdigit():
        return int(region)
    return None


def known_regions(mesh, dims=None) -> str:
    """The mesh's groups for a message: '"organ" (id 1, volume), "attached" (id 2, surface)'."""
    groups = [g for g in getattr(mesh, "groups", ()) if dims is None or g.dim in dims]
    groups = sorted(groups, key=lambda g: (-g.dim, g.id if g.id is not None else 1 << 62, g.name or ""))
    text = ", ".join(group_label(g) for g in groups)
    if dims is None or set(material_dims(mesh)) & set(dims):
        tags = sorted({int(t) for b in mesh.blocks if b.tags is not None for t in np.unique(b.tags)}
                      - {g.id for g in getattr(mesh, "groups", ()) if g.dim in material_dims(mesh)})
        if tags:
            text += (", " if text else "") + "cell tags " + ", ".join(map(str, tags))
    return text or "none (the mesh has no groups or tags)"


def find_group(mesh, region, key: str = "region", dims=None, what: str = "region"):
    """The group a scene's region names (a name, or an id; dims: the dimensions it may have).

    SceneError naming the key when no group matches (listing the known ones), when the group has
    another dimension than `dims` allows, or when an id names groups of several dimensions."""
    groups = list(getattr(mesh, "groups", ()))
    gid = _as_id(region)
    if gid is not None:
        hits = [g for g in groups if g.id == gid]
    else:
        hits = [g for g in groups if g.name == region]
    if dims is not None and len(hits) > 1:
        fitting = [g for g in hits if g.dim in dims]
        hits = fitting or hits
    if not hits:
        raise SceneError(f"{key}: unknown region {region!r}; the mesh's regions: {known_regions(mesh)}")
    if len(hits) > 1:
        raise SceneError(f"{key}: id {gid} names groups of several dimensions "
                         f"({', '.join(group_label(g) for g in hits)}); use the group's name")
    group = hits[0]
    if dims is not None and group.dim not in dims:
        want = " or ".join(_KINDS.get(d, f"{d}D") for d in sorted(dims, reverse=True))
        raise SceneError(f"{key}: region {group_label(group)} is not a {want} group, which {what} needs; "
                         f"the mesh's {want} groups: {known_regions(mesh, dims)}")
    return group


def material_dims(mesh) -> tuple:
    """The dimensions of the groups that select the cells materials model: the mesh's for solids,
    2 for shells (their groups of triangles select materials as volume groups do for solids), both
    for shells beside solids (runtime.mesh.shells_and_solids)."""
    shells = any(b.type == "shell" for b in mesh.blocks)
    others = any(b.type != "shell" for b in mesh.blocks)
    return (mesh.dim, 2) if shells and others else (2,) if shells else (mesh.dim,)


def region_cell_masks(mesh, region, key: str = "region") -> list:
    """Per block, the solid cells a material's region selects: "all", an element type, an integer
    (a volume group's id, else a cell tag), or the name of a volume group (of shells: of triangles)."""
    gid = _as_id(region)
    dims = material_dims(mesh)
    if region == "all" or (isinstance(region, str) and region in NODES_PER_CELL) or \
            (gid is not None and not any(g.id == gid and g.dim in dims for g in getattr(mesh, "groups", ()))):
        return [region_mask(b, region) for b in mesh.blocks]
    group = find_group(mesh, region, key, dims=dims, what="a material (it selects cells)")
    if not group.cell_ids.size:
        raise SceneError(f"{key}: region {group_label(group)} holds no cells (a boundary group); a material "
                         f"needs a group of cells: {known_regions(mesh, dims)}")
    out, start = [], 0
    for b in mesh.blocks:
        ids = group.cell_ids[(group.cell_ids >= start) & (group.cell_ids < start + len(b))] - start
        mask = np.zeros(len(b), bool)
        mask[ids] = True
        out.append(mask)
        start += len(b)
    return out


def _boundary(mesh):
    """Boundary faces of the volume cells: (face type per row, full node rows, corner keys, cell ids).

    Kept on the mesh while its points and cell arrays are the same objects (a scene selects
    several regions on one mesh: the face table is built once)."""
    key = (id(mesh.points), mesh.points.shape) + tuple((id(b.cells), b.cells.shape) for b in mesh.blocks)
    cached = getattr(mesh, "_boundary_cache", None)
    if cached is not None and cached[0] == key:
        return cached[1]
    value = _boundary_faces_of(mesh)
    try:
        mesh._boundary_cache = (key, value)
    except AttributeError:                  # a mesh-like object without attributes: no cache
        pass
    return value


def _boundary_faces_of(mesh):
    ft = face_table(mesh)
    rows = boundary_rows(ft)
    types, nodes, keys = [None] * rows.size, [None] * rows.size, [None] * rows.size
    pair = ft.block[rows] * 64 + ft.lface[rows]             # (block, face of the cell): one gather each
    for p in np.unique(pair):
        at = np.flatnonzero(pair == p)
        blk = mesh.blocks[int(p) // 64]
        face = _types.get(blk.type).faces[int(p) % 64]
        full = blk.cells[ft.local[rows[at]]][:, list(face.nodes)]
        corner = np.sort(full[:, :len(face.corners)], axis=1).tolist()
        for j, i in enumerate(at.tolist()):
            types[i], nodes[i], keys[i] = face.type, full[j], tuple(corner[j])
    return types, nodes, keys, ft.cell[rows]


def _group_face_rows(mesh, group, boundary, key, what) -> np.ndarray:
    """Indices into the boundary faces that a group selects (a facet group, or a volume group's outside)."""
    types, _, keys, cells = boundary
    facet = mesh.dim - 1
    if group.dim == mesh.dim:
        return np.flatnonzero(np.isin(cells, group.cell_ids))
    if group.dim != facet:
        raise SceneError(f"{key}: region {group_label(group)} holds no faces; {what} needs a "
                         f"{_KINDS[facet]} group (or a volume group: its part of the body's surface); the mesh's "
                         f"regions: {known_regions(mesh, (facet, mesh.dim))}")
    want = set()
    for ctype, rows in group.cells.items():
        if cell_dim(ctype) == facet:
            k = FACE_CORNERS[ctype]
            want.update(tuple(sorted(int(v) for v in r[:k])) for r in rows)
    return np.array([i for i, k in enumerate(keys) if k in want], dtype=np.int64)


def region_faces(mesh, region=None, box=None, key: str = "region", tol: float | None = None,
                 what: str = "a surface load") -> dict:
    """Boundary faces of the volume cells that a region and/or a box select, outward.

    region: None or "all" (every boundary face), a surface group (a curve group in 2D), or a volume
    group (the faces of its cells on the body's surface).  box: faces whose nodes are all inside
    (closed, +- tol; default box_tolerance).  Both: the intersection.  Returns {face type:
    (n, k) int64 node ids} in the element table's face node order (Face.nodes: corners first,
    then midsides); the right-hand normal (3D) or the edge direction with the body on its left
    (2D) points out of the body.  Face types of the element table: "triangle", "triangle6",
    "quad", "line", "line3", ...
    """
    boundary = _boundary(mesh)
    types, nodes, _, _ = boundary
    pick = np.arange(len(types))
    if region is not None and region != "all":
        group = find_group(mesh, region, key, what=what)
        pick = _group_face_rows(mesh, group, boundary, key, what)
    if box is not None and pick.size:
        tol = box_tolerance(mesh.points) if tol is None else tol
        inside = box_contains(box, mesh.points, tol)
        pick = pick[np.fromiter((inside[nodes[i]].all() for i in pick), bool, pick.size)]
    out: dict = {}
    for i in pick:
        out.setdefault(types[i], []).append(nodes[i])
    return {t: np.asarray(v, dtype=np.int64) for t, v in out.items()}


def region_nodes(mesh, region=None, box=None, key: str = "region", tol: float | None = None) -> np.ndarray:
    """Sorted ids of the nodes a region and/or a box select (both: the intersection).

    region: "all", a group name or id of any dimension: the nodes of its cells (of a surface
    group, also the midside nodes of the matching faces of quadratic volume cells).  None:
    every node.  box: nodes inside (closed, +- tol; default box_tolerance).
    """
    sel = np.ones(mesh.n_points, bool)
    if region is not None and region != "all":
        group = find_group(mesh, region, key)
        mine = np.zeros(mesh.n_points, bool)
        for rows in group.cells.values():
            mine[np.asarray(rows).ravel()] = True
        if group.cell_ids.size:
            start = 0
            for b in mesh.blocks:
                ids = group.cell_ids[(group.cell_ids >= start) & (group.cell_ids < start + len(b))] - start
                mine[b.cells[ids].ravel()] = True
                start += len(b)
        if any(cell_dim(t) == mesh.dim - 1 for t in group.cells):
            boundary = _boundary(mesh)
            for i in _group_face_rows(mesh, group, boundary, key, "a region"):
                mine[boundary[1][i]] = True
        sel &= mine
    if box is not None:
        tol = box_tolerance(mesh.points) if tol is None else tol
        sel &= box_contains(box, mesh.points, tol)
    return np.flatnonzero(sel)


def selection_nodes(mesh, item, key: str, tol: float | None = None) -> np.ndarray:
    """Nodes of a [[fixed]], load or probe entry (its region and/or box; SceneError naming the key
    when they select no node)."""
    region, box = getattr(item, "region", None), getattr(item, "box", None)
    if region is None and box is None:
        raise SceneError(f"{key}: needs a region or a box (or both)")
    nodes = region_nodes(mesh, region, box, key=f"{key}.region", tol=tol)
    if nodes.size == 0:
        if region is None:
            lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
            raise SceneError(f"{key}.box: no mesh node inside (mesh bounds [{', '.join(f'{v:g}' for v in lo)}]"
                             f" .. [{', '.join(f'{v:g}' for v in hi)}])")
        where = "" if box is None else " inside its box"
        raise SceneError(f"{key}: region {region!r} has no node{where}")
    return nodes


# ============================================================================== regions and materials


def region_mask(block, region) -> np.ndarray:
    """Cells of a block that a region selects: "all", an element type, or an integer cell tag."""
    n = len(block)
    if isinstance(region, str) and region.lstrip("-").isdigit():
        region = int(region)
    if region == "all":
        return np.ones(n, bool)
    if isinstance(region, (int, np.integer)) and not isinstance(region, bool):
        return np.zeros(n, bool) if block.tags is None else block.tags == region
    if isinstance(region, str) and region in NODES_PER_CELL:
        return np.full(n, block.type == region)
    raise TensormassError(f"material region {region!r}: use 'all', an element type "
                          f"({', '.join(NODES_PER_CELL)}) or an integer cell tag")


def may_cover(material, cell_type: str) -> bool:
    """Whether a material may cover cells of a type, without a mesh (tags and boxes: maybe, so yes)."""
    region = getattr(material, "region", "all")
    return not isinstance(region, str) or region in ("all", cell_type)


def centroids(mesh, block) -> np.ndarray:
    """(n, dim) centroids of a block's cells."""
    return mesh.points[block.cells].mean(axis=1) if len(block) else np.zeros((0, mesh.dim))


def material_mask(material, block, cell_centroids, tol: float, region_hit=None) -> np.ndarray:
    """Cells of a block that a material's region (and box) select, ignoring earlier materials.

    region_hit: the region's cells of this block (region_cell_masks), when the region may be a group."""
    hit = region_mask(block, material.region) if region_hit is None else region_hit.copy()
    if material.box is not None and hit.any():
        hit &= box_contains(material.box, cell_centroids, tol)
    return hit


def assign_materials(mesh, materials, complete: bool = False) -> list:
    """Per block, the index of the first matching material of every cell (-1: none matches).

    complete: refuse (TensormassError) cells that no material matches, and an empty list.
    """
    materials = list(materials)
    if complete and not materials:
        raise TensormassError("the scene defines no material")
    tol = box_tolerance(mesh.points)
    hits = [region_cell_masks(mesh, m.region, f"material[{i}].region") for i, m in enumerate(materials)]
    out = []
    for b, block in enumerate(mesh.blocks):
        which = np.full(len(block), -1, dtype=np.int64)
        middle = centroids(mesh, block)
        for i, mat in enumerate(materials):
            free = which < 0
            if not free.any():
                break
            which[free & material_mask(mat, block, middle, tol, hits[i][b])] = i
        out.append(which)
    if complete:
        _refuse_orphans(mesh, out)
    return out


def _refuse_orphans(mesh, which) -> None:
    missing, first, offset = 0, [], 0
    for block, w in zip(mesh.blocks, which):
        lost = np.flatnonzero(w < 0)
        missing += lost.size
        first.extend((offset + lost[:5]).tolist())
        offset += len(block)
    if missing:
        raise TensormassError(f"{missing} cell(s) match no material (e.g. cells {first[:5]}); "
                              "add a material with region = 'all' or widen the regions")


def material_groups(mesh, materials, which) -> dict:
    """(element, law, quadrature) -> [(block, local cell ids, material index)], in order of appearance."""
    groups: dict = {}
    for b, (block, w) in enumerate(zip(mesh.blocks, which)):
        for i in np.unique(w):
            if i < 0:
                continue
            mat = materials[int(i)]
            groups.setdefault((block.type, mat.law, mat.quadrature), []).append((b, np.flatnonzero(w == i), int(i)))
    return groups


def check_unused_materials(materials, mesh, which) -> None:
    """Every [[material]] must model some cell: one that none does is a mistake in the scene (SceneError)."""
    used = set()
    for w in which:
        used.update(int(i) for i in np.unique(w))
    for i in range(len(materials)):
        if i not in used:
            raise SceneError(f"material[{i}]: no cell uses it: {_why_unused(materials, mesh, which, i)}; "
                             "remove it, or change its region or box")


def _why_unused(materials, mesh, which, i: int) -> str:
    """The region/box matches nothing, or every cell it matches went to earlier materials."""
    tol = box_tolerance(mesh.points)
    earlier = set()
    masks = region_cell_masks(mesh, materials[i].region, f"material[{i}].region")
    for blk, w, m in zip(mesh.blocks, which, masks):
        hit = material_mask(materials[i], blk, centroids(mesh, blk), tol, m)
        earlier.update(int(j) for j in np.unique(w[hit]))
    mat = materials[i]
    if earlier:
        names = ", ".join(f"material[{j}]" for j in sorted(earlier))
        return f"every cell it matches is taken by {names} (first match wins)"
    what = f"region {mat.region!r}" + ("" if mat.box is None else " and box")
    types = ", ".join(mesh.cell_types())
    tags = sorted({int(t) for b in mesh.blocks if b.tags is not None for t in np.unique(b.tags)})
    groups = [g for g in getattr(mesh, "groups", ()) if g.dim == mesh.dim]
    if groups:
        return f"no cell matches its {what} (the mesh has {types} cells, volume regions {known_regions(mesh, (mesh.dim,))})"
    return f"no cell matches its {what} (the mesh has {types} cells" + (f", tags {tags})" if tags else ", no tags)")


# ============================================================================== [[fixed]]


def prescribed_values(fixed, points, tol: float, components: int | None = None, mesh=None):
    """(value, owner) per node and component: the prescribed displacement (NaN: free) and the
    index of the [[fixed]] entry that prescribes it.  components: dofs per node (default: the
    points' dimension; runtime.base.dofs).

    Entries select nodes by box, or (with the mesh) by region and/or box (selection_nodes).

    Two entries prescribing different values for the same dof are refused (SceneError
    naming both and a node): which one wins would otherwise depend on their order.
    """
    points = np.asarray(points, dtype=float)
    n, dim = points.shape
    dim = dim if components is None else int(components)
    value = np.full((n, dim), np.nan)
    owner = np.full((n, dim), -1, dtype=np.int64)
    # a rigid motion (runtime.physics.motion) gives every node its own value: it may share no dof with another entry
    moves = np.array([getattr(f, "rotation", None) is not None or getattr(f, "translation", None) is not None
                      for f in fixed] + [False])
    for i, f in enumerate(fixed):
        if getattr(f, "region", None) is not None or f.box is None:
            if mesh is None:
                raise TensormassError(f"fixed[{i}]: selecting nodes by region needs the mesh")
            nodes = selection_nodes(mesh, f, f"fixed[{i}]", tol)
        else:
            nodes = np.flatnonzero(box_contains(f.box, points, tol))
        disp = np.zeros(dim)            # a shell's rotations (past the displacement) are held at zero
        if f.displacement is not None:
            given = np.asarray(f.displacement, dtype=float)[:dim]
            disp[:given.size] = given
        for c in range(dim) if f.components is None else f.components:
            c = int(c)
            old = value[nodes, c]
            clash = np.flatnonzero(~np.isnan(old) & ((old != disp[c]) | moves[i] | moves[owner[nodes, c]]))
            if clash.size:
                node = int(nodes[clash[0]])
                j = int(owner[node, c])
                where = ", ".join(f"{float(x):g}" for x in points[node])
                if moves[i] or moves[j]:
                    raise SceneError(f"fixed[{i}]: prescribes component {c} at node {node} ([{where}]) where "
                                     f"fixed[{j}] prescribes it too, and fixed[{i if moves[i] else j}] is a rigid "
                                     f"motion (rotation/translation) ({clash.size} node(s) in both); narrow one "
                                     "box, or use components = [...] so that each component is prescribed once")
                raise SceneError(f"fixed[{i}]: prescribes component {c} = {disp[c]:g} at node {node} ([{where}]) "
                                 f"where fixed[{j}] prescribes {old[clash[0]]:g} ({clash.size} node(s) in "
                                 "both boxes); the boxes overlap with different values: narrow one box, or "
                                 "use components = [...] so that each component is prescribed once")
            value[nodes, c] = disp[c]
            owner[nodes, c] = i
    return value, owner


# ============================================================================== laws a cell can be under


def switch_applies(rule, law: str) -> bool:
    """Whether a switch_law [[adapt]] rule moves elements that are under `law`."""
    return rule.action == "switch_law" and law != rule.law and rule.from_law in (None, law)


def reachable_laws(law: str, rules) -> list:
    """The material's law first, then every law switch_law rules can move its cells to (in rule order).

    Reachability is transitive (hooke -> stvk -> stable_neohookean)."""
    reach = [law]
    grew = True
    while grew:
        grew = False
        for rule in rules:
            if rule.action == "switch_law" and rule.law not in reach and any(switch_applies(rule, x) for x in reach):
                reach.append(rule.law)
                grew = True
    return reach


def switch_parameters(material, law_name: str) -> dict:
    """Native parameters of `law_name` for a material written for another law (from E, nu, or same names)."""
    law = laws.get(law_name)
    if material.E is not None and material.nu is not None:
        return law.native_parameters(E=material.E, nu=material.nu)
    missing = [p for p in law.parameters if p not in material.params]
    if missing:
        raise SceneError(f"material with law {material.law!r} gives no E, nu and no {', '.join(missing)} "
                         f"for law {law_name!r}; give E and nu")
    return law.native_parameters(**{p: material.params[p] for p in law.parameters})
