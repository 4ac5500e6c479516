"""Locking-free formulations: a law's volumetric energy at averaged volume measures.

For the cells a material models with formulation "mean_dilatation" or "nodal_pressure"
(runtime.physics.formulations), the law's split W = W_dev + U(theta) (generator.volumetric) is integrated as

    Pi(u) = sum_q v_q W_dev(F_q)  +  sum_g V_g U(J_g),     J_g = Theta_g / V_g,  Theta_g = sum_e S_ge Theta_e(u)

- W_dev is the part's own generated kernel with the bulk parameter set to 0 (runtime.model.model does so);
- Theta_e = sum_q v_q theta(F_q) is the element energy of the measure's generated kernel, V_e its
  value at rest (theta = 1 there) and V_g = sum_e S_ge V_e;
- groups g: every cell (mean dilatation: S = I, Q1-P0 / P2-P0 with the pressure condensed per cell),
  or every node with S_ge = 1/k for the k-node cells around it (nodal pressure, Bonet & Burton 1998).

Pi is an energy, so forces and the (symmetric) Jacobian follow exactly:

    f_int = sum_e p_e f_e,               p_e = sum_g S_ge U'(J_g),    f_e = -dTheta_e/du
    K     = sum_e p_e K_e + sum_g U''(J_g) / V_g  b_g b_g^T,          b_g = sum_e S_ge f_e

The rank-one terms couple the cells of one group: inside one cell for mean dilatation; for nodal
pressure the nodes of the cells around a node, so the Assembler adds those patches to the sparsity
pattern (`patch_tables`).  The pressure of a group is U'(J_g); runtime.physics.fields adds p_e dtheta/dF to
the stress (`cell_terms`).

"edge_smoothed" (linear triangles) is nodal pressure plus edge-based strain smoothing of the rest
of the law (ES-FEM, Liu, Nguyen-Thoi & Lam 2009; with the node-based volumetric part: the
selective ES/NS-FEM of Nguyen-Thoi et al. 2009):

    Pi_dev = sum_k A_k W_dev(F_k),   A_k = sum_{e at edge k} A_e / 3,   F_k = sum_e (A_e / 3) F_e / A_k

over the edges k whose cells share a material (an edge with one such cell takes A_e / 3 W_dev(F_e)).
F_k is linear in the four nodes of the two triangles, so the generated one-point quad kernel of the
law evaluates it: its constants D hold the weight and the shape gradients of the point, which are
set to A_k and the smoothed gradients.  The part's own kernel still integrates A_e W_dev(F_e) per
cell (its stress is what runtime.physics.fields shows); this coupling adds the difference,
sum_k A_k W_dev(F_k) - sum_e w_e A_e W_dev(F_e) with w_e = 1 - (edges of e counted alone) / 3.
Under a homogeneous deformation every F_k is F: the patch test holds exactly.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.sparse as sp
from numba import njit

from ... import laws
from ...laws.viscous import base_name
from ...generated import volumetric as committed_splits
from ..base.errors import InvertedElementError, TensormassError
from ..kernels import kernels as _kernels
from .assembly import project_psd, scatter_matrix, scatter_vector

__all__ = ["VolumetricCoupling", "volumetric_functions"]


@lru_cache(maxsize=None)
def volumetric_functions(law_name: str):
    """(bulk parameter, measure law, function(theta, **params) -> (U, U', U'')) of a law.

    From the committed generated/volumetric.py while the law file is unchanged; a new or edited
    law is split now (sympy) and the same expressions are compiled in memory.  A viscous law's
    (laws/viscous.py) is its base law's: under a formulation the volumetric part stays elastic and
    the Prony branches act on the deviatoric part (Simo's split)."""
    law_name = base_name(law_name) or law_name
    law = laws.get(law_name)
    table = committed_splits
    if law_name in table.SPLITS and table.SPLITS[law_name][2] == laws.source_hash(law):
        parameter, measure, _ = table.SPLITS[law_name]
        return parameter, measure, table.FUNCTIONS[law_name]
    return _derived(law_name)


def _derived(law_name: str):
    # deferred: the generator loads sympy (0.65 s), needed only for a law without a committed split
    from ...generator import volumetric as gen
    text = gen.module_text([law_name])
    namespace: dict = {}
    exec(compile(text, f"<volumetric split of {law_name}>", "exec"), namespace)   # our own generated code
    parameter, measure, _ = namespace["SPLITS"][law_name]
    return parameter, measure, namespace["FUNCTIONS"][law_name]


class VolumetricCoupling:
    """The volumetric energy of the cells `rows` of one part under one locking-free formulation."""

    def __init__(self, model, part_index: int, rows: np.ndarray, formulation: str, params: dict,
                 materials: np.ndarray):
        part = model.parts[part_index]
        self.part_index, self.formulation, self.law = part_index, formulation, part.law
        self.parameter, self.measure, self.function = volumetric_functions(part.law)
        self.rows = np.asarray(rows, dtype=np.int64)
        self.cells = np.ascontiguousarray(part.cells[self.rows], dtype=np.int64)
        self.dofs = np.ascontiguousarray(part.dofs[self.rows], dtype=np.int64)
        self.cell_ids = part.cell_ids[self.rows]
        self.kernel = _kernels.load_kernel(part.element, self.measure, part.quadrature, backend=model.solver.backend)
        self.D = self.kernel.constants(model.mesh.points[self.cells])
        self.cell_volume = self.kernel.point_volumes(self.D).sum(axis=1)
        self.dpn = model.dofs_per_node
        n, k = self.cells.shape
        self.S = self._groups(np.asarray(materials), n, k)
        self.V = self.S @ self.cell_volume
        first = self.S.indices[self.S.indptr[:-1]]           # a cell of each group (one material per group)
        self.params = {p: np.ascontiguousarray(np.broadcast_to(v, (len(part.cells),))[self.rows][first])
                       for p, v in params.items()}
        self.ST = self.S.T.tocsr()
        self.positions = None              # (n, nd, nd) CSR positions of the cells; set by the Assembler
        self.patch_positions = []          # per patch table (nodal pressure); set by the Assembler
        self.needs_positive = law_needs_positive(self.function, self.params)
        self.edges = None
        if formulation == "edge_smoothed":
            self.edges = _EdgeSmoothing(model, part, self.rows, np.asarray(materials), params, self.parameter)
            self.patch_tables.append(self.edges.dofs)

    # -- groups ----------------------------------------------------------------------------------
    def _groups(self, materials, n, k):
        """S (groups x cells): the identity for mean dilatation; 1/k per (material, node) for nodal pressure."""
        self.patch_tables, self._patch_index = [], []
        if self.formulation == "mean_dilatation":
            return sp.identity(n, format="csr")
        mat = np.repeat(materials, k)
        node = self.cells.ravel()
        keys = np.stack([mat, node], axis=1)
        groups, group_of = np.unique(keys, axis=0, return_inverse=True)
        group_of = group_of.reshape(n, k)
        cell = np.repeat(np.arange(n), k)
        S = sp.csr_matrix((np.full(n * k, 1.0 / k), (group_of.ravel(), cell)), shape=(len(groups), n))
        S.sum_duplicates()
        self._build_patches(group_of, len(groups))
        return S

    def _build_patches(self, group_of, n_groups):
        """The nodes around each node group, their dof tables by size, and the map B: cell forces -> b_g."""
        n, k = self.cells.shape
        dpn = self.dpn
        # (group, neighbour node) for every cell of the group and every node of that cell
        g = np.repeat(group_of, k, axis=1).ravel()                 # (n k k): group of (e, i), repeated over j
        nb = np.tile(self.cells, (1, k)).ravel()                    # node j of cell e
        pairs = np.unique(np.stack([g, nb], axis=1), axis=0)        # sorted by group, then node
        size = np.bincount(pairs[:, 0], minlength=n_groups)
        start = np.concatenate([[0], np.cumsum(size)])
        # slot of (group, node) in the flat b vector: (start[g] + position of node) * dpn + c
        key = pairs[:, 0] * (self.cells.max() + 1) + pairs[:, 1]
        where = np.searchsorted(key, g * (self.cells.max() + 1) + nb)
        comp = np.arange(dpn)
        rows = (where[:, None] * dpn + comp).ravel()
        e = np.repeat(np.arange(n), k * k)
        j = np.tile(np.repeat(np.arange(k)[None, :], k, axis=0).ravel(), n)
        cols = ((e * k + j)[:, None] * dpn + comp).ravel()
        self.B = sp.csr_matrix((np.full(rows.size, 1.0 / k), (rows, cols)), shape=(len(pairs) * dpn, n * k * dpn))
        self.B.sum_duplicates()
        for s in np.unique(size):
            members = np.flatnonzero(size == s)
            nodes = pairs[:, 1][start[members][:, None] + np.arange(s)]
            self.patch_tables.append((nodes[:, :, None] * dpn + comp).reshape(len(members), s * dpn))
            slots = (start[members][:, None] * dpn + np.arange(s * dpn))
            self._patch_index.append((members, slots))

    # -- evaluation ------------------------------------------------------------------------------
    def evaluate(self, U: np.ndarray, f: np.ndarray | None, data: np.ndarray | None, project: bool = False) -> float:
        """Add this coupling's forces into f and Jacobian into the CSR data (either may be None);
        returns its energy sum_g V_g U(J_g)."""
        ue = np.ascontiguousarray(U[self.cells])
        theta = self.kernel.energy(self.D, ue)
        fe = Ke = None
        if data is not None:
            fe, Ke = self.kernel.forces_and_stiffness(self.D, ue)
        elif f is not None:
            fe = self.kernel.forces(self.D, ue)
        J = (self.S @ theta) / self.V
        if self.needs_positive and not np.all(J > 0):
            bad = np.unique(self.S[np.flatnonzero(~(J > 0))].indices)
            raise InvertedElementError(f"{self.formulation}: mean volume ratio <= 0 (inverted cells) where law "
                                       f"{self.law!r} is undefined", self.cell_ids[bad])
        with np.errstate(all="ignore"):
            Ug, dU, d2U = (np.broadcast_to(np.asarray(x, dtype=float), J.shape) for x in self.function(J, **self.params))
        p = self.ST @ dU
        if f is not None:
            scatter_vector(f, np.ascontiguousarray(p[:, None] * fe), self.dofs)
        if data is not None:
            c = d2U / self.V
            cell_c = c if self.formulation == "mean_dilatation" else np.zeros(len(p))
            if project:
                # PSD-projected Newton matrices: the cell terms projected per cell, rank-one terms kept >= 0
                c, cell_c = np.maximum(c, 0.0), np.maximum(cell_c, 0.0)
                Ke *= p[:, None, None]
                Ke += cell_c[:, None, None] * fe[:, :, None] * fe[:, None, :]
                project_psd(Ke, out=Ke)
                scatter_matrix(data, Ke, self.positions, 1.0)
            else:
                _scatter_cells(data, Ke, fe, p, cell_c, self.positions)
            if self.formulation != "mean_dilatation":
                b = self.B @ fe.ravel()
                for (members, slots), pos in zip(self._patch_index, self.patch_positions):
                    _scatter_patches(data, b, slots, members, c, pos)
        energy = float(np.dot(self.V, Ug))
        if self.edges is not None:
            energy += self.edges.evaluate(U, f, data, project, self.positions, self.patch_positions[-1])
        return energy

    def cell_terms(self, U: np.ndarray) -> tuple:
        """(p_e, u_e) per cell at nodal displacements U: the factor of the measure's stress in the
        cell's stress (P = P_dev + p_e dtheta/dF at every point) and its volumetric energy density
        (sum_e V_e u_e = sum_g V_g U(J_g)); runtime.physics.fields adds them to the part's records."""
        theta = self.kernel.energy(self.D, np.ascontiguousarray(U[self.cells]))
        J = (self.S @ theta) / self.V
        with np.errstate(all="ignore"):
            Ug, dU, _ = (np.broadcast_to(np.asarray(x, dtype=float), J.shape) for x in self.function(J, **self.params))
        return self.ST @ dU, self.ST @ Ug

    def part_rows(self, n_part_cells: int) -> np.ndarray:
        """For every cell of the part, its row in this coupling (-1: not formulated)."""
        index = np.full(n_part_cells, -1, dtype=np.int64)
        index[self.rows] = np.arange(len(self.rows))
        return index


class _EdgeSmoothing:
    """The edge-smoothed deviatoric energy of formulation "edge_smoothed", as the difference it makes
    to the part's cell-wise integration (module docstring)."""

    def __init__(self, model, part, rows, materials, params, bulk):
        self.part = part
        cells = part.cells[rows]
        n = len(cells)
        G = part.kernel.point_gradients(part.D[rows])[:, 0]           # (n, 3, dim): constant on a triangle
        area = part.kernel.point_volumes(part.D[rows]).sum(axis=1)
        dim = G.shape[2]
        # every (material, edge) with the cells that hold it: 2 cells = a smoothing domain of 4 nodes
        local = np.array([[0, 1], [1, 2], [2, 0]])
        ends = np.sort(cells[:, local], axis=2).reshape(-1, 2)                 # (3n, 2)
        cell = np.repeat(np.arange(n), 3)
        keys = np.column_stack([np.repeat(materials, 3), ends])
        _, edge_of, count = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        edge_of = edge_of.ravel()
        if count.max(initial=0) > 2:
            raise TensormassError("edge_smoothed: an edge is shared by more than two triangles of one material "
                                  "(a non-manifold mesh)")
        shared = count[edge_of] == 2
        order = np.argsort(edge_of[shared], kind="stable")
        pair = cell[shared][order].reshape(-1, 2)                              # the two cells of each interior edge
        opposite = (np.arange(3 * n)[shared][order] % 3 + 2) % 3               # the vertex opposite the edge
        opposite = opposite.reshape(-1, 2)
        e0, e1 = pair[:, 0], pair[:, 1]
        a_, b_ = cells[e0, (opposite[:, 0] + 1) % 3], cells[e0, (opposite[:, 0] + 2) % 3]
        nodes = np.column_stack([a_, b_, cells[e0, opposite[:, 0]], cells[e1, opposite[:, 1]]])
        # smoothed gradients: sum_e (A_e / 3) G_e[node] / A_k on the patch's four nodes
        Ak = (area[e0] + area[e1]) / 3.0
        Gk = np.zeros((len(nodes), 4, dim))
        for e in (e0, e1):
            for i in range(3):
                node = cells[e, i]
                slot = np.argmax(nodes == node[:, None], axis=1)
                np.add.at(Gk, (np.arange(len(nodes)), slot), (area[e] / 3.0)[:, None] * G[e, i])
        Gk /= Ak[:, None, None]
        # cells' own weight left after the edges they share: 1 - (edges counted alone) / 3
        alone = np.bincount(cell[~shared], minlength=n)
        self.weight = 1.0 - alone / 3.0
        self.cells, self.rows, self.nodes = cells, rows, nodes
        self.cell_dofs = np.ascontiguousarray(part.dofs[rows], dtype=np.int64)
        dpn = model.dofs_per_node
        self.dofs = np.ascontiguousarray((nodes[:, :, None] * dpn + np.arange(dpn)).reshape(len(nodes), 4 * dpn))
        self.D_cells = np.ascontiguousarray(part.D[rows])                      # W_dev: the bulk parameter is 0 there
        self.kernel = _kernels.load_kernel("quad", part.law, "gauss1", backend=model.solver.backend)
        k = self.kernel
        if k.G_offset is None or k.n_points != 1:
            raise TensormassError(f"edge_smoothed: the one-point quad kernel of law {part.law!r} has no shape "
                                  "gradients in its constants")
        dev = {p: np.array(np.broadcast_to(v, (len(part.cells),))[rows][e0], dtype=float)
               for p, v in params.items()}
        dev[bulk] = np.zeros(len(nodes))
        square = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])[:, :dim]
        D = k.constants(np.broadcast_to(square, (len(nodes), 4, dim)), **dev)
        D[:, k.v_offset] = Ak
        D[:, k.G_offset:k.G_offset + 4 * dim] = Gk.reshape(len(nodes), 4 * dim)
        self.D = np.ascontiguousarray(D)

    def evaluate(self, U, f, data, project, cell_positions, edge_positions) -> float:
        """Add sum_k A_k W_dev(F_k) - sum_e w_e A_e W_dev(F_e) to f and data; return it."""
        part = self.part
        uc = np.ascontiguousarray(U[self.cells])
        ue = np.ascontiguousarray(U[self.nodes])
        energy = float(self.kernel.energy(self.D, ue).sum() - np.dot(self.weight, part.kernel.energy(self.D_cells, uc)))
        if data is not None:
            fk, Kk = self.kernel.forces_and_stiffness(self.D, ue)
            fc, Kc = part.kernel.forces_and_stiffness(self.D_cells, uc)
            if project:
                # the part adds its cells projected; taking w_e of the same projection off keeps the sum >= 0
                project_psd(Kk, out=Kk)
                project_psd(Kc, out=Kc)
            Kc *= -self.weight[:, None, None]
            scatter_matrix(data, Kk, edge_positions, 1.0)
            scatter_matrix(data, Kc, cell_positions, 1.0)
        elif f is not None:
            fk, fc = self.kernel.forces(self.D, ue), part.kernel.forces(self.D_cells, uc)
        if f is not None:
            scatter_vector(f, fk, self.dofs)
            scatter_vector(f, np.ascontiguousarray(-self.weight[:, None] * fc), self.cell_dofs)
        return energy


@njit(cache=True)
def _scatter_cells(data, Ke, fe, p, c, pos):
    """data += p_e K_e + c_e f_e f_e^T for every cell, with no (n, nd, nd) temporaries."""
    for e in range(Ke.shape[0]):
        for r in range(Ke.shape[1]):
            cr = c[e] * fe[e, r]
            for s in range(Ke.shape[2]):
                data[pos[e, r, s]] += p[e] * Ke[e, r, s] + cr * fe[e, s]


@njit(cache=True)
def _scatter_patches(data, b, slots, members, c, pos):
    """data += c_g b_g b_g^T for the node groups of one patch size (b_g = b[slots[g]])."""
    for g in range(slots.shape[0]):
        cg = c[members[g]]
        for r in range(slots.shape[1]):
            cr = cg * b[slots[g, r]]
            for s in range(slots.shape[1]):
                data[pos[g, r, s]] += cr * b[slots[g, s]]


def law_needs_positive(function, params) -> bool:
    """True when U is undefined for theta <= 0 (ln theta): NaN at theta = -1 says so."""
    with np.errstate(all="ignore"):
        values = function(np.array([-1.0]), **{p: v[:1] if np.ndim(v) else v for p, v in params.items()})
    return not all(np.all(np.isfinite(np.asarray(x, dtype=float))) for x in values)
