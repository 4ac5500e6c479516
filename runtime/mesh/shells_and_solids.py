"""A file that holds shells beside solids: its volume cells are solids, its free triangles are shells.

    read = read_meshio(path)                       # runtime.mesh.io
    if has_volume_cells(read):                     # [mesh] file = ... with element = "shell"
        mesh, notes = read_shells_and_solids(path, read)

With element = "shell", a file's triangles are shells.  When the file also has volume cells (a
gmsh file with a volume group and surface groups), those are solids of the same mesh, and a
triangle group is read by where it lies:

    every triangle a face of a volume cell     a boundary group of the solid (fixed, pressure)
    no triangle a face of a volume cell        shells (a group of shell cells: materials, loads)
    some of each                               refused, naming the group

The shells go into one "shell" block after the solid blocks; each surface of them is wound
consistently (outward when closed: runtime.mesh.surfaces.orient_triangles).  A triangle in two
shell groups is one shell cell in both.  The nodes then carry 6 dofs (runtime.base.dofs).
"""
from __future__ import annotations

import numpy as np

from . import io as mesh_io
from .container import CellBlock, Mesh, MeshError, topological_dim
from .faces import boundary_faces
from .mesh_groups import Group
from .surfaces import orient_triangles

__all__ = ["read_shells_and_solids", "has_volume_cells"]


def has_volume_cells(read) -> bool:
    """Whether a file, as runtime.mesh.io.read_meshio read it, has 3D cells."""
    return any(topological_dim(cb.type) == 3 for cb in read.cells)


def read_shells_and_solids(path, read=None) -> tuple[Mesh, list]:
    """(mesh, notes): the file's solids, its boundary groups, and its free triangles as shells
    (read: the file's read_meshio(path) when the caller has it)."""
    solids = mesh_io.read_mesh(path, read)
    if solids.dim != 3:
        raise MeshError(f"{path}: shells beside solids need a 3D mesh")
    on_boundary = {tuple(sorted(nodes[:3])) for _, _, nodes in boundary_faces(solids)}
    keys: dict = {}                       # sorted corners -> shell cell index
    triangles, kept, shell_groups = [], [], []
    for g in solids.groups:
        tris = np.asarray(g.cells.get("triangle", np.zeros((0, 3), np.int64)), dtype=np.int64)
        if g.dim != 2 or not len(tris):
            kept.append(g)
            continue
        faces = np.array([tuple(sorted(t)) in on_boundary for t in tris.tolist()])
        if faces.all():
            kept.append(g)
            continue
        if faces.any():
            raise MeshError(f"{path}: surface group {g.label} has {int(faces.sum())} triangles on the solid's "
                            f"boundary and {int((~faces).sum())} off it; a group is either a boundary region of "
                            "the solid or shells: split it")
        ids = []
        for t in tris.tolist():
            key = tuple(sorted(t))
            if key not in keys:
                keys[key] = len(triangles)
                triangles.append(t)
            ids.append(keys[key])
        shell_groups.append((g, np.unique(ids)))
    if not triangles:
        raise MeshError(f"{path}: element = \"shell\" found no shell triangles: every triangle group lies on the "
                        "solid's boundary (put the shells' triangles in surface groups of their own)")
    points = solids.points
    try:
        triangles, notes = orient_triangles(points, np.asarray(triangles, dtype=np.int64), what=str(path))
    except ValueError as exc:
        raise MeshError(str(exc)) from None
    start = solids.n_cells
    tags = np.full(len(triangles), -1, dtype=np.int64)
    for g, ids in shell_groups:
        if g.id is not None:
            tags[ids] = np.where(tags[ids] < 0, g.id, tags[ids])
    groups = kept + [Group(g.name, g.id, 2, start + ids) for g, ids in shell_groups]
    blocks = list(solids.blocks) + [CellBlock("shell", triangles, tags if (tags >= 0).all() else None)]
    return Mesh(points, blocks, groups), notes
