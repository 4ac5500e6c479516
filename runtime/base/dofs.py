"""The dof layout: how many unknowns a node carries, and which of them are its displacement.

    n = dofs_per_node(mesh)                 # mesh.dim for solids; the element table's count otherwise
    table = node_dofs(cells, n)             # (n_cells, k * n) global dofs, node-major
    table = node_dofs(cells, n, used=3)     # a solid's cells in a mesh whose nodes carry 6: their first 3
    disp, extra = split_nodal(U, mesh.dim)  # U: (n_points, n) -> displacement and extra point fields

Dofs are node-major: dof = node * dofs_per_node + component.  Where a node carries at
least `dim` dofs, the first `dim` are its displacement (a shell's rotations follow);
with fewer (a scalar-dof element: a spring chain in one direction, a potential) the
nodal values are not a displacement at all and are written as their own field.

A mesh may mix shells (6 dofs: displacement and rotation) with solids (3: displacement).  Every
node then carries 6 dofs; a solid's cells use the first 3 of each of their nodes, and the rotations
that no shell cell uses are held (the model fixes every dof no cell uses).  One count per node
keeps dof = node * dofs_per_node + component, which the outputs, the loads and contact read.
"""
from __future__ import annotations

import numpy as np

from ... import elements as _types
from .errors import TensormassError

__all__ = ["dofs_per_node", "node_dofs", "split_nodal", "EXTRA_FIELD", "SCALAR_FIELD"]

# Output field names: dofs past the displacement ("dofs_extra": a shell's rotations, ...), and
# the nodal values of an element whose dofs are no displacement ("dofs").
EXTRA_FIELD = "dofs_extra"
SCALAR_FIELD = "dofs"


def dofs_per_node(mesh) -> int:
    """Dofs per node of a mesh: its cells' count, or the largest where every count holds the
    displacement (shells beside solids); counts below the dimension do not mix with others."""
    counts: dict = {}
    for block in mesh.blocks:
        el = _types.get(block.type)
        n = mesh.dim if el.dofs_per_node is None else int(el.dofs_per_node)
        counts.setdefault(n, []).append(block.type)
    if not counts:
        return int(mesh.dim)
    if len(counts) > 1 and min(counts) < mesh.dim:
        which = "; ".join(f"{', '.join(dict.fromkeys(t))}: {n}" for n, t in sorted(counts.items()))
        raise TensormassError(f"the mesh mixes element types with different dofs per node ({which}); "
                              "scalar dofs mix with no other count")
    return max(counts)


def node_dofs(cells: np.ndarray, n: int, used: int | None = None) -> np.ndarray:
    """(n_cells, k * used) global dofs of the cells' nodes, node-major: the first `used` (default
    all n) of each node's n dofs."""
    cells = np.asarray(cells)
    used = n if used is None else int(used)
    return (cells[:, :, None] * n + np.arange(used)).reshape(len(cells), cells.shape[1] * used)


def split_nodal(U: np.ndarray, dim: int) -> tuple:
    """(displacement (n_points, dim), {field name: (n_points, m)}) of nodal values U (n_points, n).

    n == dim: U itself; n > dim: the first dim columns, the rest as EXTRA_FIELD; n < dim: the
    nodes do not move (zeros) and U is SCALAR_FIELD."""
    n = U.shape[1]
    if n == dim:
        return U, {}
    if n > dim:
        return U[:, :dim], {EXTRA_FIELD: U[:, dim:]}
    return np.zeros((U.shape[0], dim)), {SCALAR_FIELD: U}
