"""The dof layout: how many unknowns a node carries, and which of them are its displacement.

    n = dofs_per_node(mesh)                 # mesh.dim for solids; the element table's count otherwise
    table = node_dofs(cells, n)             # (n_cells, k * n) global dofs, node-major
    disp, extra = split_nodal(U, mesh.dim)  # U: (n_points, n) -> displacement and extra point fields

Dofs are node-major: dof = node * dofs_per_node + component.  Where a node carries at
least `dim` dofs, the first `dim` are its displacement (a shell's rotations follow);
with fewer (a scalar-dof element: a spring chain in one direction, a potential) the
nodal values are not a displacement at all and are written as their own field.
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
    """Dofs per node of a mesh: one count for the whole mesh (a mixed count is refused for now)."""
    counts: dict = {}
    for block in mesh.blocks:
        el = _types.get(block.type)
        n = mesh.dim if el.dofs_per_node is None else int(el.dofs_per_node)
        counts.setdefault(n, []).append(block.type)
    if not counts:
        return int(mesh.dim)
    if len(counts) > 1:
        which = "; ".join(f"{', '.join(dict.fromkeys(t))}: {n}" for n, t in sorted(counts.items()))
        raise TensormassError(f"the mesh mixes element types with different dofs per node ({which}); "
                              "one count per mesh is supported")
    return next(iter(counts))


def node_dofs(cells: np.ndarray, n: int) -> np.ndarray:
    """(n_cells, k * n) global dofs of the cells' nodes, node-major."""
    cells = np.asarray(cells)
    return (cells[:, :, None] * n + np.arange(n)).reshape(len(cells), cells.shape[1] * n)


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
