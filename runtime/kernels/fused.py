"""The fused evaluation and scatter: element-to-nonzero maps blocked by node.

    pos = node_block_positions(pattern, dofs_per_node)[i]     # part i of a SparsePattern, once
    k.forces_and_stiffness_scatter(D, U, cells, pos, f, data)   # f += f_e, data += K_e, every call

The generated kernels' forces_and_stiffness_scatter reads each element's displacements from
the global (n_points, dofs_per_node) array through cells and adds its forces into the global
vector and its stiffness into the CSR values; no (n_elem, n_dofs, n_dofs) element buffer is
written. Dofs are node-major (runtime.base.dofs), so the dofs of one node are consecutive columns
of every CSR row that holds them: one index per (row dof, node) says where the node's
dofs_per_node entries start, pos[e, r, j] = SparsePattern.positions[e, r, j * dofs_per_node]
(int32: a fifth of the int64 per-entry map in memory).
"""
from __future__ import annotations

import numpy as np

from ..base.errors import TensormassError

__all__ = ["node_block_positions", "block_positions"]

INDEX_LIMIT = 2**31 - 1       # pos is int32 (the generated C code reads int)


def block_positions(positions: np.ndarray, dofs_per_node: int) -> np.ndarray:
    """(n_elem, n_dofs, n_nodes) int32 CSR index of (row dof r, first dof of node j) from the
    per-entry map (n_elem, n_dofs, n_dofs) of SparsePattern.positions; checked: every node
    block must be dofs_per_node consecutive CSR entries (node-major dofs)."""
    positions = np.asarray(positions)
    if positions.ndim != 3 or positions.shape[1] != positions.shape[2]:
        raise TensormassError(f"positions must have shape (n_elem, n_dofs, n_dofs), got {positions.shape}")
    n, nd, _ = positions.shape
    d = int(dofs_per_node)
    if d < 1 or nd % d:
        raise TensormassError(f"{nd} element dofs are not a whole number of nodes of {d} dofs")
    blocks = positions.reshape(n, nd, nd // d, d)
    first = blocks[..., 0]
    if not np.array_equal(blocks, first[..., None] + np.arange(d)):
        raise TensormassError("the element dofs are not node-major consecutive CSR entries "
                              "(dof = node * dofs_per_node + component): no node-blocked map")
    if positions.size and positions.max() > INDEX_LIMIT:
        raise TensormassError(f"the matrix has more than {INDEX_LIMIT} nonzeros: the fused path indexes them with int32")
    return np.ascontiguousarray(first, dtype=np.int32)


def node_block_positions(pattern, dofs_per_node: int) -> list:
    """block_positions of every part of a runtime.assembly.assembly.SparsePattern, in its part order
    (parts that share a per-entry map share the array); dofs_per_node: the model's (runtime.base.dofs)."""
    done: dict = {}
    out = []
    for positions in pattern.positions:
        key = id(positions)
        if key not in done:
            done[key] = block_positions(positions, dofs_per_node)
        out.append(done[key])
    return out
