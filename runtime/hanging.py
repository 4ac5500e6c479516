"""Hanging nodes: the multi-point constraints that keep a locally refined hexahedral mesh conforming.

    hanging = HangingNodes.of(mesh, dofs_per_node, fixed_dofs)   # None when the mesh has none
    u = hanging.expand(u)          # slave dofs set from their masters: u = P u
    g = hanging.reduce(g)          # forces / gradients onto the masters: P^T g
    A = hanging.reduce_matrix(A)   # P^T A P

A hexahedron split 1:8 (runtime.topology.refine_hexahedra) puts nodes at the midpoints of its
edges and the centres of its faces.  Where a neighbour is not split, such a node lies on the
neighbour's edge or face without being one of its nodes: it hangs.  Its displacement must then be
what the neighbour's trilinear field gives there, the mean of the edge's 2 or the face's 4 corner
nodes (the constraint is exact for trilinear hexahedra: on an edge or face the field is bilinear
in the corners), or the mesh tears along the interface.  The mesh records every created node's
parents (Mesh.midpoints: the node, then its 2 or 4 parents); a node hangs when some cell holds
all its parents but not the node.

The constraints are eliminated: u = P u with P the identity except on the slave dofs, whose rows
average their masters' (the same component); a master that hangs itself is substituted until no
slave is left among the masters (refinement levels that differ by more than one).  Solvers work on
the reduced system P^T A P, P^T b over the free dofs (slaves are neither free nor fixed), and
gradients are reduced by P^T, so Newton's residual, the line search and the reactions see the
constrained problem.  A slave whose dofs are prescribed stays prescribed (its masters lie on the
same boundary and get the same values from a linear field).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .errors import TensormassError

__all__ = ["HangingNodes", "hanging_nodes"]


def hanging_nodes(mesh) -> tuple:
    """(slaves, masters (m, 4) -1 padded, weights (m, 4)) of the mesh's hanging nodes (empty arrays
    when Mesh.midpoints records none, or none of them hangs)."""
    rows = getattr(mesh, "midpoints", None)
    empty = (np.zeros(0, np.int64), np.zeros((0, 4), np.int64), np.zeros((0, 4)))
    if rows is None or not len(rows):
        return empty
    from .topology import cells_around, incidence
    rows = np.asarray(rows, dtype=np.int64)
    # candidate cells: those around each node's first parent
    which, _, nodes = cells_around(mesh, incidence(mesh), rows[:, 1])
    parents = rows[which, 1:5]
    holds = ((parents[:, :, None] == nodes[:, None, :]).any(axis=2) | (parents < 0)).all(axis=1)
    has_node = (rows[which, 0][:, None] == nodes).any(axis=1)
    hangs = np.bincount(which[holds & ~has_node], minlength=len(rows)) > 0
    rows = rows[hangs]
    masters = rows[:, 1:5]
    weights = np.where(masters >= 0, 1.0, 0.0)
    weights /= weights.sum(axis=1, keepdims=True).clip(min=1.0)
    return rows[:, 0].copy(), masters.copy(), weights


class HangingNodes:
    """The projector P of a mesh's hanging-node constraints on node-major dofs."""

    def __init__(self, slaves, masters, weights, n_points: int, dofs_per_node: int):
        self.slaves = np.asarray(slaves, dtype=np.int64)
        self.n_points, self.dpn = n_points, dofs_per_node
        node_P = self._node_projector(self.slaves, masters, weights, n_points)
        self.P = sp.kron(node_P, sp.identity(dofs_per_node, format="csr"), format="csr")
        self.PT = self.P.T.tocsr()
        self.slave_dofs = (self.slaves[:, None] * dofs_per_node + np.arange(dofs_per_node)).ravel()

    @classmethod
    def of(cls, mesh, dofs_per_node: int, fixed_dofs=()) -> "HangingNodes | None":
        slaves, masters, weights = hanging_nodes(mesh)
        if not slaves.size:
            return None
        held = np.zeros(mesh.n_points, dtype=bool)
        fixed = np.asarray(fixed_dofs, dtype=np.int64)
        held[fixed // dofs_per_node] = True
        keep = ~held[slaves]                    # a prescribed node stays prescribed
        if not keep.any():
            return None
        return cls(slaves[keep], masters[keep], weights[keep], mesh.n_points, dofs_per_node)

    @staticmethod
    def _node_projector(slaves, masters, weights, n):
        """P on nodes: identity off the slaves, their rows the weights on masters that are not slaves."""
        is_slave = np.zeros(n, dtype=bool)
        is_slave[slaves] = True
        rows = {int(s): {int(m): float(w) for m, w in zip(ms, ws) if m >= 0} for s, ms, ws in zip(slaves, masters, weights)}
        for _ in range(64):                      # substitute slaves among the masters (nested levels)
            changed = False
            for s, row in rows.items():
                nested = [m for m in row if is_slave[m]]
                for m in nested:
                    w = row.pop(m)
                    for mm, ww in rows[m].items():
                        row[mm] = row.get(mm, 0.0) + w * ww
                    changed = True
            if not changed:
                break
        else:
            raise TensormassError("hanging nodes: the constraints refer to each other in a loop")
        r, c, v = [], [], []
        for node in np.flatnonzero(~is_slave):
            r.append(int(node)); c.append(int(node)); v.append(1.0)
        for s in sorted(rows):
            for m in sorted(rows[s]):
                r.append(s); c.append(m); v.append(rows[s][m])
        return sp.csr_matrix((v, (r, c)), shape=(n, n))

    def expand(self, x: np.ndarray) -> np.ndarray:
        """x with every slave dof set from its masters."""
        return self.P @ x

    def reduce(self, g: np.ndarray) -> np.ndarray:
        """P^T g: a force on a slave goes to its masters; slave rows become 0."""
        return self.PT @ g

    def reduce_matrix(self, A) -> sp.csr_matrix:
        """P^T A P, CSR."""
        return (self.PT @ A @ self.P).tocsr()
