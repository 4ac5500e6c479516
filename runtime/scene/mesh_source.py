"""A scene on its mesh: the mesh is generated or read (after the memory estimate) and the
scene is checked against it.

    mesh = load_mesh(scene)                 # what Scene.load_mesh() does (cached on the scene)
    check_against_mesh(scene, mesh)         # what Scene.validate() does
    mesh = build_mesh(spec)                 # a MeshSpec alone (no scene): generated or read, checked

The scene itself (runtime.scene.scene) is schema and parsing; boxes, regions and the material of
each cell come from runtime.mesh.regions.  Errors name the scene key (SceneError).
"""
from __future__ import annotations

import time

from types import SimpleNamespace

import numpy as np

from ... import elements as _element_types
from ..kernels import catalogue
from . import resources
from ..base.dofs import dofs_per_node as _dofs_per_node
from ..base.errors import SceneError, TensormassError
# module attribute lookups, so that tests can stand in for read_mesh and generate_bar
from ..mesh import bars, checks, file_cache, io as mesh_io
from ..mesh.container import CellBlock, Mesh
from ..mesh.container import MeshError
from ..mesh.checks import check_coordinates
from ..mesh.probes import PROBE_CELL_FRACTION, ProbeError, locate_point
from ..mesh.refine import REFINABLE_TYPES
from .formulation_check import check_element as check_formulation_element
from ..mesh.regions import (assign_materials, box_contains, box_tolerance, check_unused_materials,
    prescribed_values, reachable_laws, region_faces, selection_nodes, switch_parameters)
from ..mesh import surfaces
from ..mesh.shells_and_solids import has_volume_cells, read_shells_and_solids
from ..mesh.solids import ball_tetrahedra
from ... import laws as _laws

__all__ = ["load_mesh", "scene_mesh", "build_mesh", "check_against_mesh", "catalogue_check", "PROBE_TOLERANCE"]

# A probe reports the displacement interpolated at its point; outside the body by more than
# this share of the nearest cell's size it is refused (runtime.mesh.probes: the rule and its reasons).
PROBE_TOLERANCE = PROBE_CELL_FRACTION


# ============================================================================== building the mesh


def load_mesh(scene):
    """The scene's mesh (generated or read once, then cached); MeshError-based problems become SceneError.

    The run's memory is estimated and checked against the limit (scene.max_memory) first: for
    a generated bar before it is built, for a file right after it is read (ResourceError).
    """
    mesh = getattr(scene, "_mesh", None)
    if mesh is None:
        start = time.perf_counter()
        spec = scene.mesh
        key = "mesh.file" if spec.file is not None else "mesh"
        try:
            if spec.file is None:                 # generated: estimated before anything is built
                _check_resources(scene, resources.MeshCounts.of_generated(spec))
            if spec.generate == "ball":
                mesh = ball_mesh(spec)
                _check_resources(scene, resources.MeshCounts.of_mesh(mesh))
            elif spec.file is not None or spec.generate in SURFACES:
                if spec.element == "shell":
                    mesh = shell_mesh(spec)
                else:               # read and checked before from the same bytes, or read now
                    mesh = file_cache.load(spec.file)
                    if mesh is None:
                        mesh = mesh_io.read_mesh(spec.file)
                        mesh.read_from = (spec.file, file_cache.fingerprint(mesh))
                check_coordinates(mesh.points)
                _check_resources(scene, resources.MeshCounts.of_mesh(mesh))
            else:
                mesh = bars.generate_bar(spec.size, spec.cells, spec.element, spec.origin)
                check_coordinates(mesh.points)
        except MeshError as exc:
            raise SceneError(f"{key}: {exc}") from None
        scene._mesh = mesh
        scene._mesh_seconds = time.perf_counter() - start        # reported with the run's setup
    return mesh


def _check_resources(scene, counts) -> None:
    est = resources.estimate(counts, materials=scene.materials, solver=scene.solver, adapt=scene.adapt)
    resources.check(est, scene.max_memory, what=f"scene {scene.name!r}")
    scene._estimate = est


def scene_mesh(scene):
    """The scene's mesh (its cached load_mesh() when it has one), checked (check_mesh)."""
    if hasattr(scene, "load_mesh"):
        mesh = scene.load_mesh()
        if not getattr(mesh, "checked", False):         # (file_cache: these bytes passed already)
            checks.check_mesh(mesh)
            if _as_read(scene.mesh, mesh):
                file_cache.store(scene.mesh.file, mesh)
        return mesh
    return build_mesh(scene.mesh)


SURFACES = ("plate", "sphere")         # shell generators (runtime.mesh.surfaces)


def _as_read(spec, mesh) -> bool:
    """Whether the mesh is still the file's cells as read_mesh gave them (what file_cache keeps): not a
    shell's triangles, nor a mesh a caller put in its place or changed since (a report refining it)."""
    read = getattr(mesh, "read_from", None)
    return (spec.element != "shell" and read is not None and read[0] == spec.file
            and read[1] == file_cache.fingerprint(mesh))


def shell_mesh(spec):
    """The shell triangles of a MeshSpec with element = "shell": a generated plate (at z = 0) or
    icosphere, or a file's triangles (3D points; other cells refused, unused points dropped)."""
    if spec.generate == "plate":
        points, triangles = surfaces.plate(spec.size[0], spec.size[1], spec.cells[0], spec.cells[1])
    elif spec.generate == "sphere":
        points, triangles = surfaces.icosphere(spec.radius, spec.subdivisions)
    tags, groups = None, []
    if spec.file is not None:
        read = mesh_io.read_meshio(spec.file)
        if has_volume_cells(read):                 # shells beside the file's solids
            mesh, notes = read_shells_and_solids(spec.file, read)
            mesh.notes = [f"mesh.file: {note}" for note in notes]
            return mesh
        # windings made to agree across shared edges; the notes say what was turned
        points, triangles, notes, (tags, groups) = surfaces.read_shell_triangles(spec.file, with_groups=True, read=read)
    points = np.asarray(points, float) + np.asarray(spec.origin, float)[:3] if spec.file is None else points
    mesh = Mesh(points, [CellBlock("shell", np.asarray(triangles, dtype=np.int64), tags)], groups)
    mesh.notes = [f"mesh.file: {note}" for note in notes] if spec.file is not None else []
    return mesh


def ball_mesh(spec):
    """The tetrahedral solid ball of a MeshSpec with generate = "ball" (runtime.mesh.solids), at its origin."""
    points, tetra = ball_tetrahedra(spec.radius, spec.divisions)
    points = points + np.asarray(spec.origin, float)[:3]
    check_coordinates(points)
    return Mesh(points, [CellBlock("tetra", tetra)])


def build_mesh(spec):
    """Generate or read the mesh of a MeshSpec and check it."""
    if spec.file is None and spec.generate in SURFACES + ("ball",):
        resources.check(resources.estimate(resources.MeshCounts.of_generated(spec)), what=f"the generated {spec.generate}")
    if getattr(spec, "element", None) == "shell":
        mesh = shell_mesh(spec)
    elif spec.generate == "ball":
        mesh = ball_mesh(spec)
    elif spec.file:
        mesh = mesh_io.read_mesh(spec.file)
    elif spec.generate in (None, "bar"):
        dim = 2 if spec.element in _element_types.names(dim=2) or len(spec.cells) == 2 else 3
        bar = SimpleNamespace(size=tuple(spec.size)[:dim], cells=tuple(spec.cells)[:dim], element=spec.element)
        resources.check(resources.estimate(resources.MeshCounts.of_bar(bar)), what="the generated bar")
        mesh = bars.generate_bar(tuple(spec.size)[:dim], tuple(spec.cells)[:dim], spec.element,
                            tuple(spec.origin)[:dim])
    else:
        raise TensormassError(f"mesh.generate: unknown generator {spec.generate!r} (known: bar)")
    checks.check_mesh(mesh)
    return mesh


# ============================================================================== checking the scene against it


def catalogue_check(key, element, law, quadrature):
    """A SceneError unless (element, law, quadrature) is in the generator's catalogue."""
    if law in _laws.discrete_names() and element not in _laws.get(law).elements:
        raise SceneError(f"{key}: law {law!r} is a discrete model defined on {', '.join(_laws.get(law).elements)} "
                         f"cells, not {element}")
    try:
        catalogue.check(element, law, quadrature)
    except ValueError:
        try:
            available = ", ".join(catalogue.quadratures(element, law))
        except Exception:  # noqa: BLE001 - only for the message
            available = "?"
        raise SceneError(f"{key}: quadrature {quadrature!r} is not available for {element} with law "
                         f"{law!r}; available: {available}") from None


def check_against_mesh(scene, mesh) -> None:
    """Checks that need the mesh: vector sizes, boxes that hold no node, cells without a material,
    unused materials, conflicting [[fixed]], probes off the body, kernels that do not exist."""
    try:                                  # NaN would make every box test below fail
        check_coordinates(mesh.points)
    except MeshError as exc:
        raise SceneError(f"{'mesh.file' if scene.mesh.file is not None else 'mesh'}: {exc}") from None
    dim = mesh.dim

    def vec(value, key):
        if value is not None and len(value) != dim:
            raise SceneError(f"{key}: expected {dim} components, got {len(value)} (the mesh is {dim}D)")

    # vectors of file meshes could not be checked while parsing
    g = scene.loads.gravity
    if len(g) != dim:
        if not any(g) and scene.mesh.file is not None:
            scene.loads.gravity = (0.0,) * dim
        else:
            vec(g, "loads.gravity")
    tol = box_tolerance(mesh.points)
    lo, hi = (mesh.points.min(axis=0), mesh.points.max(axis=0)) if mesh.n_points else (None, None)
    bounds = "" if lo is None else (f" (mesh bounds [{', '.join(f'{v:g}' for v in lo)}] .. "
                                    f"[{', '.join(f'{v:g}' for v in hi)}])")
    for i, m in enumerate(scene.materials):
        if m.box is not None:
            vec(m.box[0], f"material[{i}].box")
    for i, f in enumerate(scene.fixed):
        if f.box is not None:
            vec(f.box[0], f"fixed[{i}].box")
        vec(f.displacement, f"fixed[{i}].displacement")
        if f.components is not None and max(f.components) >= _dofs_per_node(mesh):
            raise SceneError(f"fixed[{i}].components: component {max(f.components)} does not exist in {dim}D")
        if getattr(f, "region", None) is not None:          # a mesh group (and box): runtime.mesh.regions
            selection_nodes(mesh, f, f"fixed[{i}]", tol)
        elif not box_contains(f.box, mesh.points, tol).any():
            raise SceneError(f"fixed[{i}].box: no mesh node inside{bounds}")
    counters = {"force": 0, "traction": 0, "moment": 0}
    for load in scene.loads.nodal:
        key = f"loads.{load.kind}[{counters[load.kind]}]"
        counters[load.kind] += 1
        if load.box is not None:
            vec(load.box[0], f"{key}.box")
        vec(load.force, f"{key}.value")
        if getattr(load, "region", None) is not None:
            _check_region_load(mesh, load, key, tol)
        elif not box_contains(load.box, mesh.points, tol).any():
            raise SceneError(f"{key}.box: no mesh node inside{bounds}")
    for i, load in enumerate(getattr(scene.loads, "pressure", ())):
        key = f"loads.pressure[{i}]"
        if load.box is not None:
            vec(load.box[0], f"{key}.box")
        if any(b.type == "shell" for b in mesh.blocks):     # shell triangles: checked by the model
            continue
        if getattr(load, "region", None) is not None:       # boundary faces of a group (and box)
            if not region_faces(mesh, load.region, load.box, key=f"{key}.region", tol=tol, what="a pressure"):
                where = "" if load.box is None else " inside its box"
                raise SceneError(f"{key}: region {load.region!r} has no boundary face{where}")
        elif not box_contains(load.box, mesh.points, tol).any():
            raise SceneError(f"{key}.box: no mesh node inside{bounds}")
    for i, p in enumerate(scene.probes):
        if p.point is None:                                 # region and/or box: the mean over their nodes
            if getattr(p, "box", None) is not None:
                vec(p.box[0], f"probe[{i}].box")
            selection_nodes(mesh, p, f"probe[{i}]", tol)
            continue
        vec(p.point, f"probe[{i}].point")
    prescribed_values(scene.fixed, mesh.points, tol, _dofs_per_node(mesh), mesh=mesh)
    _check_probes(scene, mesh)

    # every cell needs a material, and every (cell type, law, quadrature) in use must exist
    which = assign_materials(mesh, scene.materials)
    offset = 0
    for blk, w in zip(mesh.blocks, which):
        orphans = np.flatnonzero(w < 0)
        if orphans.size:
            ids = ", ".join(str(int(offset + c)) for c in orphans[:8]) + (", ..." if orphans.size > 8 else "")
            where, fix = _orphan_groups(mesh, blk, offset + orphans, orphans)
            raise SceneError(f"material: {orphans.size} {blk.type} cell(s){where} match no [[material]]: "
                             f"cells [{ids}]; {fix}add a last [[material]] with region = \"all\"")
        for i in np.unique(w):
            m = scene.materials[int(i)]
            catalogue_check(f"material[{int(i)}].quadrature", blk.type, m.law, m.quadrature)
            check_formulation_element(f"material[{int(i)}].formulation",
                                      getattr(m, "formulation", "displacement"), blk.type)
        offset += len(blk)
    check_unused_materials(scene.materials, mesh, which)
    _check_adapt(scene, mesh, which)


def _orphan_groups(mesh, blk, global_ids, local) -> tuple:
    """(" in group 'tumour' (id 2, volume)", "add a [[material]] with region = \"tumour\", or ") for
    cells without a material: the mesh's volume groups that hold them, by name (their id when the
    file names none); the block's cell tag when no group holds them."""
    held = [g for g in getattr(mesh, "groups", ()) if g.cell_ids.size and np.isin(global_ids, g.cell_ids).any()]
    if held:
        labels = ", ".join(g.label for g in held[:4]) + (", ..." if len(held) > 4 else "")
        first = held[0]
        region = f'"{first.name}"' if first.name is not None else str(first.id)
        return f" in group{'s' if len(held) > 1 else ''} {labels}", f"give a [[material]] region = {region}, or "
    if blk.tags is not None:
        return f" (cell tag {int(blk.tags[local[0]])}, in no named group)", ""
    return "", ""


def _check_region_load(mesh, load, key, tol) -> None:
    """A load on a region selects nodes (force) or boundary faces (traction); none is an error."""
    if load.kind != "traction":
        selection_nodes(mesh, load, key, tol)
        return
    if not region_faces(mesh, load.region, load.box, key=f"{key}.region", tol=tol, what="a traction"):
        where = "" if load.box is None else " inside its box"
        raise SceneError(f"{key}: region {load.region!r} has no boundary face{where}")


def _check_probes(scene, mesh) -> None:
    """Every probe point must lie inside the body or on it within a tolerance (runtime.mesh.probes)."""
    for i, p in enumerate(scene.probes):
        if p.point is None:               # region / box probes: checked in check_against_mesh
            continue
        try:
            locate_point(mesh, p.point, p.name)
        except ProbeError as exc:
            raise SceneError(f"probe[{i}].point: {exc}") from None


def _check_adapt(scene, mesh, which) -> None:
    """Every law a switch_law rule can reach must exist for the cells it reaches; refine needs simplices."""
    for r, rule in enumerate(scene.adapt):
        key = f"adapt[{r}]"
        if rule.action == "refine":
            bad = sorted({b.type for b in mesh.blocks} - set(REFINABLE_TYPES))
            if bad:
                raise SceneError(f"{key}.action: refine splits triangle and tetra cells only; the mesh has {bad[0]}")
            continue
        for blk, w in zip(mesh.blocks, which):
            for i in np.unique(w):
                m = scene.materials[int(i)]
                # chains count: hooke -> stvk -> neohookean reaches neohookean through rule 1
                if rule.law not in reachable_laws(m.law, scene.adapt)[1:]:
                    continue
                catalogue_check(f"{key}.law", blk.type, rule.law, m.quadrature)
                try:
                    switch_parameters(m, rule.law)
                except SceneError as exc:
                    raise SceneError(f"{key}.law: {exc}") from None
