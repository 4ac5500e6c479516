"""The history of viscous parts (laws/viscous.py): Prony branches per integration point.

Per point of a viscous part the runtime keeps, from the last accepted step, the non-equilibrium
stresses Q_i of the branches and the law's own stress S (second Piola-Kirchhoff, 6 components in
the order of laws.viscous.PAIRS). Before a step of length h, prepare(h) writes the step energy's
numbers g and H into the point inputs of the part's constants D; the kernels then give the total
stress g S(C) + H and its consistent tangent. Once the step is accepted, commit(u) reads the total
stress at the new state from the stress kernel, recovers S = (S_total - H) / g and updates

    Q_i <- xi_i^2 Q_i + beta_i xi_i (S - S_previous),   xi_i = exp(-h / (2 tau_i)).

A step that is refused (a halved dt, a line-search retry, Newton failing) never commits: the next
prepare starts again from the last accepted state. Nothing depends on wall-clock time.

The dissipation (the `viscous_dissipation` field): branch i is a spring of tangent beta_i C0 in
series with a dashpot (the standard linear solid the update integrates), C0 the law's tangent at
rest (by central differences of the stress kernel, per cell).  Its stored energy is
psi_i = Q_i : (beta_i C0)^-1 : Q_i / 2, and a step dissipates what the branch took in and did not
store:

    dD = sum_i (Q_i,n + Q_i,n+1) / 2 : (E_n+1 - E_n)  -  (psi_i,n+1 - psi_i,n)

(exact while the strain is held: everything a branch releases is dissipated).  It accumulates per
point from the start of the run, per unit rest volume.
"""
from __future__ import annotations

import numpy as np

from ...laws.viscous import PAIRS
from ..base.errors import TensormassError


class ViscousHistory:
    """The Prony state of every viscous part of a model (Part.branches)."""

    def __init__(self, model, asm):
        self.model = model
        self.parts = [(i, p) for i, p in enumerate(model.parts) if p.branches is not None]
        for i, part in self.parts:
            plan = asm.plans[i]
            if plan.D is not part.D:       # the point inputs are written into the part's D in place
                raise TensormassError(f"viscous part {part.law}: its constants are copied by the assembly "
                                      "(inactive cells?); viscous materials cannot switch laws")
        # per part: Q (cells, points, branches, 6) and S (cells, points, 6), zero at rest
        self.Q = {i: np.zeros((len(p.cells), p.kernel.n_points, p.branches[0].shape[1], 6)) for i, p in self.parts}
        self.S = {i: np.zeros((len(p.cells), p.kernel.n_points, 6)) for i, p in self.parts}
        self.E = {i: np.zeros((len(p.cells), p.kernel.n_points, 6)) for i, p in self.parts}   # Green-Lagrange
        self.dissipated = {i: np.zeros((len(p.cells), p.kernel.n_points)) for i, p in self.parts}
        self._compliance = {}              # part index -> (n, 6, 6) Mandel inverse of the tangent at rest
        self._h = None                     # the step length the point inputs hold now (None: stale)

    # -- one step ---------------------------------------------------------------------------------
    def prepare(self, h: float) -> None:
        """g and H of a step of length h from the accepted state, into every viscous part's D."""
        if h == self._h:
            return
        for i, part in self.parts:
            tau, beta = part.branches
            xi = np.exp(-h / (2.0 * tau))                                   # (n, branches)
            g = 1.0 + np.sum(beta * xi, axis=1)                              # (n,)
            H = np.einsum("nb,nqbk->nqk", xi * xi, self.Q[i]) - np.einsum("nb,nqk->nqk", beta * xi, self.S[i])
            g_col, H_cols = self._columns(part)
            part.D[:, g_col] = g[:, None]
            part.D[:, H_cols] = H.reshape(len(part.cells), -1) if H.size else H
        self._h = h

    def commit(self, u: np.ndarray) -> None:
        """The accepted step's new state (the point inputs must be those prepare(h) wrote)."""
        if self._h is None:
            raise TensormassError("viscous history: commit without prepare")
        h = self._h
        for i, part in self.parts:
            tau, beta = part.branches
            xi = np.exp(-h / (2.0 * tau))
            S_total, E = self._total_stress(part, u, strain=True)
            g_col, H_cols = self._columns(part)
            g = part.D[:, g_col][:, :1, None]                                # (n, 1, 1)
            H = part.D[:, H_cols].reshape(S_total.shape)
            S = (S_total - H) / g
            dS = S - self.S[i]
            step = np.einsum("nb,nqk->nqbk", beta * xi, dS)
            Q = np.einsum("nb,nqbk->nqbk", xi * xi, self.Q[i]) + step
            self.dissipated[i] += self._dissipation(i, part, self.Q[i], Q, E - self.E[i])
            self.Q[i], self.S[i], self.E[i] = Q, S, E
        self._h = None                     # H changed: the next prepare rewrites the inputs

    # -- pieces -----------------------------------------------------------------------------------
    @staticmethod
    def _inputs(part) -> np.ndarray:
        """(points, 7) the D columns of each point's inputs: g, then H's 6 components."""
        k = part.kernel
        return np.arange(k.n_points)[:, None] * k.point_stride + k.point_fields["inputs"] + np.arange(7)

    @classmethod
    def _columns(cls, part):
        """(the D columns of g at every point, of H's 6 components at every point (point-major))."""
        columns = cls._inputs(part)
        return columns[:, 0], columns[:, 1:].ravel()

    # -- dissipation ------------------------------------------------------------------------------
    def _dissipation(self, i, part, Q0, Q1, dE):
        """(n, points) energy density the branches dissipate over a step (module docstring)."""
        c = self._compliance.get(i)
        if c is None:
            X = np.asarray(self.model.mesh.points)[part.cells][..., :part.kernel.dim]
            c = self._compliance[i] = _rest_compliance(part, X)
        beta = part.branches[1]                                              # (n, branches)
        m0, m1, de = _mandel(Q0), _mandel(Q1), _mandel(dE)
        taken = 0.5 * np.einsum("nqbk,nqk->nq", m0 + m1, de)
        # a branch with beta = 0 has no spring: its Q stays 0 and it stores nothing
        inverse = np.divide(1.0, beta, out=np.zeros_like(beta, dtype=float), where=beta > 0)[:, None, :]
        stored = lambda m: 0.5 * np.einsum("nqbk,nkl,nqbl->nqb", m, c, m) * inverse
        return taken - (stored(m1) - stored(m0)).sum(axis=2)

    def dissipation_field(self, n_cells: int) -> np.ndarray:
        """Per cell (global order), the energy per unit rest volume dissipated since the start: the
        volume-weighted mean over its points (0 in cells without branches)."""
        out = np.zeros(n_cells)
        for i, part in self.parts:
            v = part.kernel.point_volumes(part.D)
            out[part.cell_ids] = (v * self.dissipated[i]).sum(axis=1) / v.sum(axis=1)
        return out

    def dissipated_energy(self) -> float:
        """The energy (J) dissipated since the start, every viscous part summed."""
        return float(sum((part.kernel.point_volumes(part.D) * self.dissipated[i]).sum() for i, part in self.parts))

    @staticmethod
    def _total_stress(part, u, strain=False):
        """The second Piola-Kirchhoff stress (n, points, 6) at u, from the part's stress kernel
        (plane strain: F33 = 1, S33 = P33); strain: also the Green-Lagrange strain, same layout."""
        k = part.kernel
        return _stress(k, part.D, u[part.dofs].reshape(len(part.cells), k.n_nodes, k.dofs_per_node), strain)

    def carry(self, old: "ViscousHistory") -> None:
        """Take over the accepted state of `old`, the history of the model before a cut, a removal or
        a refinement (Part.origin_rows: each cell's row before, the same part index).  A cut changes
        nodes, not cells: each cell keeps its points' state.  The children of a split hexahedron
        (Part.origin_split) each take their parent's mean over its points at every point: copied,
        not interpolated."""
        for i, part in self.parts:
            if part.origin_rows is None or i not in old.Q or np.any(part.origin_rows < 0):
                raise TensormassError("viscous history: the changed model's parts do not descend from the old ones")
            rows, split = part.origin_rows, part.origin_split
            for mine, theirs in ((self.Q, old.Q), (self.S, old.S), (self.E, old.E),
                                 (self.dissipated, old.dissipated)):
                mine[i] = theirs[i][rows].copy()
                if split is not None and split.any():
                    mine[i][split] = mine[i][split].mean(axis=1, keepdims=True)
            # the point inputs (g, H) of the step that led to the state: its reactions and energy use them
            columns = self._inputs(part)                                    # (points, 7)
            inputs = dict(old.parts)[i].D[rows][:, self._inputs(dict(old.parts)[i])]   # (n, points, 7)
            if split is not None and split.any():
                inputs[split] = inputs[split].mean(axis=1, keepdims=True)
            part.D[:, columns] = inputs
        self._h = old._h

    def viscous_stress(self) -> dict:
        """{part index: sum_i Q_i (n, points, 6)}: the non-equilibrium stress of the accepted state."""
        return {i: self.Q[i].sum(axis=2) for i, _ in self.parts}


def _stress(k, D, ue, strain=False):
    """_total_stress of the kernel k with constants D at element displacements ue (n, nodes, dofs)."""
    record = k.stress(D, ue)
    at, d = k.stress_record["offsets"], k.dim
    F = record[..., at["F"]:at["F"] + d * d].reshape(*record.shape[:2], d, d)
    P = record[..., at["P"]:at["P"] + d * d].reshape(*record.shape[:2], d, d)
    S2 = np.linalg.solve(F, P)                                            # F^-1 P
    S3 = np.zeros(record.shape[:2] + (3, 3))
    S3[..., :d, :d] = S2
    if d == 2:
        S3[..., 2, 2] = record[..., at["P33"]]
    S6 = np.stack([0.5 * (S3[..., a, b] + S3[..., b, a]) for a, b in PAIRS], axis=-1)
    if not strain:
        return S6
    F3 = np.broadcast_to(np.eye(3), S3.shape).copy()
    F3[..., :d, :d] = F
    E3 = 0.5 * (np.einsum("nqba,nqbc->nqac", F3, F3) - np.eye(3))
    return S6, np.stack([E3[..., a, b] for a, b in PAIRS], axis=-1)


_MANDEL = np.array([1.0, 1.0, 1.0, np.sqrt(2.0), np.sqrt(2.0), np.sqrt(2.0)])   # PAIRS: 3 normal, 3 shear


def _mandel(A6: np.ndarray) -> np.ndarray:
    """Symmetric tensors in PAIRS order to Mandel vectors (A : B = mandel(A) . mandel(B))."""
    return A6 * _MANDEL


def _rest_compliance(part, X, delta: float = 1e-6) -> np.ndarray:
    """(n, 6, 6) inverse of the law's tangent dS/dE at rest in Mandel form, the cell's mean over its
    points: central differences of the stress kernel under F = I +- delta T_k (X: the cells' rest
    coordinates (n, nodes, dim)), with the point inputs of the base law (g = 1, H = 0)."""
    k = part.kernel
    D = part.D.copy()
    g_col, H_cols = ViscousHistory._columns(part)
    D[:, g_col], D[:, H_cols] = 1.0, 0.0
    d = k.dim
    columns = []
    for a, b in PAIRS:
        T = np.zeros((3, 3))
        T[a, b] = T[b, a] = 1.0 if a == b else 1.0 / np.sqrt(2.0)        # unit Mandel basis tensor
        if d == 2 and (a == 2 or b == 2):
            columns.append(np.zeros((len(part.cells), 6)))                  # plane strain: no out-of-plane strain
            continue
        S = []
        for sign in (1.0, -1.0):
            ue = np.zeros((len(X), k.n_nodes, k.dofs_per_node))
            ue[..., :d] = np.einsum("ij,nkj->nki", sign * delta * T[:d, :d], X)
            S.append(_mandel(_stress(k, D, ue)).mean(axis=1))
        columns.append((S[0] - S[1]) / (2.0 * delta))
    C = np.stack(columns, axis=2)                                          # (n, 6, 6): column k = dS / dE_k
    C = 0.5 * (C + np.transpose(C, (0, 2, 1)))
    if d == 3:
        return np.linalg.inv(C)
    # plane strain: the in-plane block (11, 22, 12); the out-of-plane stress does no work (E33 = 0)
    plane = np.array([0, 1, 5])
    out = np.zeros_like(C)
    out[:, plane[:, None], plane] = np.linalg.inv(C[:, plane[:, None], plane])
    return out

