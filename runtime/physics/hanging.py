"""Hanging nodes: the multi-point constraints that keep a locally refined hexahedral mesh conforming.

    hanging = HangingNodes.of(mesh, dofs_per_node, fixed_dofs)   # None when the mesh has none
    u = hanging.expand(u)          # slave dofs set from their masters: u = P u
    g = hanging.reduce(g)          # forces / gradients onto the masters: P^T g
    A = hanging.reduce_matrix(A)   # P^T A P

A hexahedron split 1:8 (runtime.mesh.topology.refine_hexahedra) puts nodes at the midpoints of its
edges and the centres of its faces.  Where a neighbour is not split, such a node lies on the
neighbour's edge or face without being one of its nodes: it hangs.  Its displacement must then be
what the neighbour's trilinear field gives there, the mean of the edge's 2 or the face's 4 corner
nodes (the constraint is exact for trilinear hexahedra: on an edge or face the field is bilinear
in the corners), or the mesh tears along the interface.  The mesh records every created node's
parents (Mesh.midpoints: the node, then its 2 or 4 parents).  Nested refinement puts nodes on
edges and faces whose corners hang themselves, so a node hangs when it lies on some cell without
being one of its nodes, "lies on" decided recursively through the parents (hanging_nodes).

The constraints are eliminated: u = P u with P the identity except on the slave dofs, whose rows
average their masters' (the same component); a master that hangs itself is substituted until no
slave is left among the masters (any depth of nesting).  Solvers work on the reduced system
P^T A P, P^T b over the free dofs (slaves are neither free nor fixed), and gradients are reduced
by P^T, so Newton's residual, the line search and the reactions see the constrained problem.  A
slave's prescribed components stay prescribed (its masters lie on the same boundary and get the
same values from a linear field); its other components are constrained.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..base.errors import TensormassError
from ..mesh.topology import cells_around, incidence

__all__ = ["HangingNodes", "hanging_nodes"]


def hanging_nodes(mesh) -> tuple:
    """(slaves, masters (m, 4) -1 padded, weights (m, 4)) of the mesh's hanging nodes (empty arrays
    when Mesh.midpoints records none, or none of them hangs).

    A node created by refinement lies on a cell K's edge or face when each of its parents is a node
    of K or, recursively, lies there itself (the parents span the edge or face it was made on; in
    the parameter space of the original cell every refined cell is a dyadic box, so a sub-edge or
    sub-face whose corners are on K's boundary lies in one edge or face of K).  It hangs when it
    lies on some cell K without being one of K's nodes.  Its constraint is the mean of its own
    parents: on K's edge or face the trilinear field is bilinear, and a bilinear field's value at
    the centre of a parametric sub-square (or a sub-edge) is the mean of its corners; parents that
    hang are substituted by HangingNodes (nested levels, any depth)."""
    rows = getattr(mesh, "midpoints", None)
    empty = (np.zeros(0, np.int64), np.zeros((0, 4), np.int64), np.zeros((0, 4)))
    if rows is None or not len(rows):
        return empty
    rows = np.asarray(rows, dtype=np.int64)
    rows = rows[rows[:, 0] < mesh.n_points]
    hangs = _lies_on_a_cell_without_being_its_node(mesh, rows)
    rows = rows[hangs]
    masters = rows[:, 1:5]
    weights = np.where(masters >= 0, 1.0, 0.0)
    weights /= weights.sum(axis=1, keepdims=True).clip(min=1.0)
    return rows[:, 0].copy(), masters.copy(), weights


def _lies_on_a_cell_without_being_its_node(mesh, rows) -> np.ndarray:
    """Boolean per midpoint row: its node lies on the closure of some cell that does not hold it."""
    n_rows = len(rows)
    row_of = np.full(mesh.n_points, -1, dtype=np.int64)
    row_of[rows[:, 0]] = np.arange(n_rows)
    # candidate cells: a cell the node lies on holds some node of the chain of first parents (the
    # recursion that decides it ends in the cell's nodes along every branch, the first one too)
    chain_row, chain_node = [], []
    at, node = np.arange(n_rows), rows[:, 1].copy()
    for _ in range(_MAX_DEPTH):
        ok = node >= 0
        at, node = at[ok], node[ok]
        if not at.size:
            break
        chain_row.append(at), chain_node.append(node)
        nxt = row_of[node]
        at, node = at[nxt >= 0], rows[nxt[nxt >= 0], 1]
    else:
        raise TensormassError("hanging nodes: the recorded midpoints refer to each other in a loop")
    chain_row, chain_node = np.concatenate(chain_row), np.concatenate(chain_node)
    inc = incidence(mesh)
    which, cells, nodes = cells_around(mesh, inc, chain_node)
    pair_row, pair_cell = chain_row[which], cells
    # a cell's closure lies in its corners' bounding box (a cell's map is a convex combination of its
    # nodes): pairs whose node is outside it are dropped before the exact test
    X = mesh.points[np.where(nodes >= 0, nodes, nodes[:, :1])]
    lo, hi = X.min(axis=1), X.max(axis=1)
    tol = 1e-9 * (hi - lo).max(axis=1, keepdims=True)
    x = mesh.points[rows[pair_row, 0]]
    near = ((x >= lo - tol) & (x <= hi + tol)).all(axis=1)
    pair_row, pair_cell, nodes = pair_row[near], pair_cell[near], nodes[near]
    key = np.unique(pair_row * (mesh.n_cells + 1) + pair_cell, return_index=True)[1]
    pair_row, pair_cell, pair_nodes = pair_row[key], pair_cell[key], nodes[key]
    # a cell holding the node itself is not one it hangs on
    holds = (pair_nodes == rows[pair_row, 0][:, None]).any(axis=1)
    pair_row, pair_cell, pair_nodes = pair_row[~holds], pair_cell[~holds], pair_nodes[~holds]
    n_pairs = pair_row.size
    failed = np.zeros(n_pairs, dtype=bool)
    # frontier: (pair, node) entries still to be found on the pair's cell, from the node's parents
    par = rows[pair_row, 1:5]
    f_pair = np.repeat(np.arange(n_pairs), 4)
    f_node = par.ravel()
    for _ in range(_MAX_DEPTH):
        keep = f_node >= 0
        f_pair, f_node = f_pair[keep], f_node[keep]
        on = (pair_nodes[f_pair] == f_node[:, None]).any(axis=1)
        f_pair, f_node = f_pair[~on], f_node[~on]
        r = row_of[f_node]
        failed[f_pair[r < 0]] = True                 # an original node that is not the cell's
        alive = (r >= 0) & ~failed[f_pair]
        f_pair, r = f_pair[alive], r[alive]
        if not f_pair.size:
            break
        f_pair = np.repeat(f_pair, 4)
        f_node = rows[r, 1:5].ravel()
        u = np.unique(f_pair * (mesh.n_points + 1) + f_node + 1)
        f_pair, f_node = u // (mesh.n_points + 1), u % (mesh.n_points + 1) - 1
    else:
        raise TensormassError("hanging nodes: the recorded midpoints refer to each other in a loop")
    return np.bincount(pair_row[~failed], minlength=n_rows) > 0


# refinement levels a node's parents may go back through (each level adds at most 2 to the depth)
_MAX_DEPTH = 256


class HangingNodes:
    """The projector P of a mesh's hanging-node constraints on node-major dofs.

    Per dof: a slave's prescribed components stay prescribed (their masters lie on the same
    boundary and get the same values from a linear field), its other components follow their
    masters (a node on a symmetry plane with only its normal component held still hangs in the
    plane)."""

    def __init__(self, slaves, masters, weights, n_points: int, dofs_per_node: int, fixed_dofs=()):
        slaves = np.asarray(slaves, dtype=np.int64)
        self.n_points, self.dpn = n_points, dofs_per_node
        fixed = np.zeros(n_points * dofs_per_node, dtype=bool)
        fixed[np.asarray(fixed_dofs, dtype=np.int64)] = True
        fixed = fixed.reshape(n_points, dofs_per_node)
        parts, slave_dofs = [], []
        for c in range(dofs_per_node):
            keep = ~fixed[slaves, c]
            P_c = self._node_projector(slaves[keep], masters[keep], weights[keep], n_points).tocoo()
            parts.append((P_c.row * dofs_per_node + c, P_c.col * dofs_per_node + c, P_c.data))
            slave_dofs.append(slaves[keep] * dofs_per_node + c)
        r, cc, v = (np.concatenate(x) for x in zip(*parts))
        n = n_points * dofs_per_node
        self.P = sp.csr_matrix((v, (r, cc)), shape=(n, n))
        self.PT = self.P.T.tocsr()
        self.slave_dofs = np.sort(np.concatenate(slave_dofs))
        self.slaves = np.unique(self.slave_dofs // dofs_per_node)    # nodes with a constrained dof

    @classmethod
    def of(cls, mesh, dofs_per_node: int, fixed_dofs=()) -> "HangingNodes | None":
        slaves, masters, weights = hanging_nodes(mesh)
        if not slaves.size:
            return None
        fixed = np.asarray(fixed_dofs, dtype=np.int64)
        held = np.zeros(mesh.n_points * dofs_per_node, dtype=bool)
        held[fixed] = True
        if held.reshape(-1, dofs_per_node)[slaves].all():
            return None                         # every slave dof prescribed: nothing to constrain
        return cls(slaves, masters, weights, mesh.n_points, dofs_per_node, fixed)

    @staticmethod
    def _node_projector(slaves, masters, weights, n):
        """P on nodes: identity off the slaves, their rows the weights on masters that are not slaves."""
        is_slave = np.zeros(n, dtype=bool)
        is_slave[slaves] = True
        rows = {int(s): {int(m): float(w) for m, w in zip(ms, ws) if m >= 0} for s, ms, ws in zip(slaves, masters, weights)}
        for _ in range(_MAX_DEPTH):              # substitute slaves among the masters (nested levels)
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
