"""The contact surface of a body, taken from its mesh: triangles over the nodes that can touch.

    surface = contact_surface(model)
    surface.nodes          # (m,) mesh node of each surface vertex
    surface.triangles      # (t, 3) into surface.nodes, wound outward
    surface.body           # (m,) connected body of each vertex (0, 1, ...)
    surface.offset         # the distance kept between mid-surfaces and obstacles: shells' half thickness

Boundary faces of solids (runtime.mesh.faces.boundary_faces) are triangulated: a quadrilateral
(hexahedra, wedges, pyramids) into two triangles; the 6-node face of a tetra10 into its four
sub-triangles through the mid-edge nodes.  The sub-triangles, not the corner triangle, because a
tetra10's mid-edge nodes move on their own: a corner triangle would let a bulging edge pass
through an obstacle unseen, while the sub-triangles keep every node of the face outside.  Shell
triangles are the surface itself, with half their thickness as the offset: contact is reached
when the mid-surface is that far from an obstacle.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ... import laws
from ..base.errors import TensormassError
from ..mesh.faces import boundary_faces

__all__ = ["ContactSurface", "contact_surface", "triangulate_face"]

# sub-triangles of the 6-node triangle (corners 0 1 2, mid-edge 3 (01), 4 (12), 5 (20))
_TRIANGLE6 = ((0, 3, 5), (3, 1, 4), (5, 4, 2), (3, 4, 5))


@dataclass
class ContactSurface:
    nodes: np.ndarray                     # (m,) mesh node ids
    triangles: np.ndarray                 # (t, 3) indices into nodes
    body: np.ndarray                      # (m,) connected body of each vertex
    offset: float                         # kept distance (shells: half the thickness), 0 for solids
    n_bodies: int
    kind: str                             # what the triangles are, for messages and the summary

    @property
    def size(self) -> int:
        return len(self.nodes)


def triangulate_face(nodes) -> list:
    """Triangles of a boundary face given in outward order (3, 4 or 6 nodes)."""
    n = len(nodes)
    if n == 3:
        return [tuple(nodes)]
    if n == 4:
        return [(nodes[0], nodes[1], nodes[2]), (nodes[0], nodes[2], nodes[3])]
    if n == 6:
        return [tuple(nodes[i] for i in t) for t in _TRIANGLE6]
    raise TensormassError(f"contact: a boundary face with {n} nodes has no triangulation here")


def contact_surface(model) -> ContactSurface:
    """The triangles of the model's mesh that take part in contact (see the module doc)."""
    mesh = model.mesh
    if mesh.dim != 3:
        raise TensormassError("contact: needs a 3D mesh (solids or shells); this mesh is 2D")
    shells = [b for b in mesh.blocks if b.type == "shell"]
    tris = []
    for _, _, nodes in boundary_faces(mesh):
        tris.extend(triangulate_face(nodes))
    for b in shells:
        tris.extend(map(tuple, np.asarray(b.cells)[:, :3]))
    if not tris:
        kinds = sorted({b.type for b in mesh.blocks})
        raise TensormassError(f"contact: the mesh has no surface to touch with (cell types {', '.join(kinds)}); "
                              "contact takes solids (tetra, tetra10, hexahedron, wedge, pyramid) and shells")
    tris = np.asarray(tris, dtype=np.int64)
    nodes, local = np.unique(tris, return_inverse=True)
    triangles = local.reshape(-1, 3)
    body_of_node = _bodies(mesh)
    body = body_of_node[nodes]
    _, body = np.unique(body, return_inverse=True)
    offset = 0.5 * _shell_thickness(model) if shells else 0.0
    kind = " and ".join(k for k, on in (("solid boundary faces", len(tris) > sum(len(b) for b in shells)),
                                        ("shell triangles", bool(shells))) if on)
    return ContactSurface(nodes, triangles, body.astype(np.int64), float(offset), int(body.max()) + 1, kind)


def _bodies(mesh) -> np.ndarray:
    """The connected body of every mesh node (nodes joined by any cell)."""
    rows, cols = [], []
    for b in mesh.blocks:
        cells = np.asarray(b.cells)
        for k in range(1, cells.shape[1]):
            rows.append(cells[:, 0])
            cols.append(cells[:, k])
    n = len(mesh.points)
    if not rows:
        return np.arange(n)
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = sp.coo_matrix((np.ones(r.size), (r, c)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _shell_thickness(model) -> float:
    """The largest shell thickness of the model's materials (the offset is one value per scene)."""
    values = [float(dict(m.params).get("thickness", 0.0)) for m in model.materials if laws.is_shell(m.law)]
    return max(values, default=0.0)
