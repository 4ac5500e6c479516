"""Where things apply: boxes, regions, and which material (and law) models each cell.

The one place that evaluates a scene's boxes and regions on a mesh; the scene checks
(runtime.scene_mesh) and the model (runtime.model) both call it.

    tol = box_tolerance(mesh.points)                   # 1e-8 of the bounding-box diagonal
    inside = box_contains(box, mesh.points, tol)       # closed box, +- tol
    which = assign_materials(mesh, materials)          # per block: material index of each cell (-1: none)
    value, owner = prescribed_values(fixed, mesh.points, tol)   # [[fixed]] that disagree are refused

Materials are matched in order, first match wins: a material selects the cells of its
region ("all", an element type, or an integer cell tag) whose centroid is inside its box
(when it has one).  Materials and [[fixed]] entries are read by attribute (region, box,
law, quadrature; box, displacement, components, and rotation / translation when present),
so the scene's dataclasses and any object with those fields work.
"""
from __future__ import annotations

import numpy as np

from .. import laws
from .errors import SceneError, TensormassError
from .mesh import NODES_PER_CELL

__all__ = ["BOX_TOLERANCE", "box_tolerance", "box_bounds", "box_contains", "region_mask", "material_mask",
           "may_cover", "assign_materials", "material_groups", "check_unused_materials", "prescribed_values",
           "switch_applies", "reachable_laws", "switch_parameters"]

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


def material_mask(material, block, cell_centroids, tol: float) -> np.ndarray:
    """Cells of a block that a material's region (and box) select, ignoring earlier materials."""
    hit = region_mask(block, material.region)
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
    out = []
    for block in mesh.blocks:
        which = np.full(len(block), -1, dtype=np.int64)
        middle = centroids(mesh, block)
        for i, mat in enumerate(materials):
            free = which < 0
            if not free.any():
                break
            which[free & material_mask(mat, block, middle, tol)] = i
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
    for blk, w in zip(mesh.blocks, which):
        hit = material_mask(materials[i], blk, centroids(mesh, blk), tol)
        earlier.update(int(j) for j in np.unique(w[hit]))
    mat = materials[i]
    if earlier:
        names = ", ".join(f"material[{j}]" for j in sorted(earlier))
        return f"every cell it matches is taken by {names} (first match wins)"
    what = f"region {mat.region!r}" + ("" if mat.box is None else " and box")
    types = ", ".join(mesh.cell_types())
    tags = sorted({int(t) for b in mesh.blocks if b.tags is not None for t in np.unique(b.tags)})
    return f"no cell matches its {what} (the mesh has {types} cells" + (f", tags {tags})" if tags else ", no tags)")


# ============================================================================== [[fixed]]


def prescribed_values(fixed, points, tol: float, components: int | None = None):
    """(value, owner) per node and component: the prescribed displacement (NaN: free) and the
    index of the [[fixed]] entry that prescribes it.  components: dofs per node (default: the
    points' dimension; runtime.dofs).

    Two entries prescribing different values for the same dof are refused (SceneError
    naming both and a node): which one wins would otherwise depend on their order.
    """
    points = np.asarray(points, dtype=float)
    n, dim = points.shape
    dim = dim if components is None else int(components)
    value = np.full((n, dim), np.nan)
    owner = np.full((n, dim), -1, dtype=np.int64)
    # a rigid motion (runtime.motion) gives every node its own value: it may share no dof with another entry
    moves = np.array([getattr(f, "rotation", None) is not None or getattr(f, "translation", None) is not None
                      for f in fixed] + [False])
    for i, f in enumerate(fixed):
        nodes = np.flatnonzero(box_contains(f.box, points, tol))
        disp = np.zeros(dim) if f.displacement is None else np.asarray(f.displacement, dtype=float)[:dim]
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
