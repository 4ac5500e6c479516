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
            S_total = self._total_stress(part, u)
            g_col, H_cols = self._columns(part)
            g = part.D[:, g_col][:, :1, None]                                # (n, 1, 1)
            H = part.D[:, H_cols].reshape(S_total.shape)
            S = (S_total - H) / g
            dS = S - self.S[i]
            step = np.einsum("nb,nqk->nqbk", beta * xi, dS)
            self.Q[i] = np.einsum("nb,nqbk->nqbk", xi * xi, self.Q[i]) + step
            self.S[i] = S
        self._h = None                     # H changed: the next prepare rewrites the inputs

    # -- pieces -----------------------------------------------------------------------------------
    @staticmethod
    def _columns(part):
        """(the D columns of g at every point, of H's 6 components at every point (point-major))."""
        k = part.kernel
        start = k.point_fields["inputs"]
        points = np.arange(k.n_points) * k.point_stride + start
        return points, (points[:, None] + 1 + np.arange(6)).ravel()

    @staticmethod
    def _total_stress(part, u):
        """The second Piola-Kirchhoff stress (n, points, 6) at u, from the part's stress kernel
        (plane strain: F33 = 1, S33 = P33)."""
        k = part.kernel
        record = k.stress(part.D, u[part.dofs].reshape(len(part.cells), k.n_nodes, k.dofs_per_node))
        at, d = k.stress_record["offsets"], k.dim
        F = record[..., at["F"]:at["F"] + d * d].reshape(*record.shape[:2], d, d)
        P = record[..., at["P"]:at["P"] + d * d].reshape(*record.shape[:2], d, d)
        S2 = np.linalg.solve(F, P)                                            # F^-1 P
        S3 = np.zeros(record.shape[:2] + (3, 3))
        S3[..., :d, :d] = S2
        if d == 2:
            S3[..., 2, 2] = record[..., at["P33"]]
        return np.stack([0.5 * (S3[..., a, b] + S3[..., b, a]) for a, b in PAIRS], axis=-1)

    def carry(self, old: "ViscousHistory") -> None:
        """Take over the accepted state of `old`, the history of the model before a cut or a removal:
        each cell keeps its points' branches (Part.origin_rows: its row before; a cut changes nodes,
        not cells, so nothing is interpolated)."""
        for i, part in self.parts:
            if part.origin_rows is None or i not in old.Q:
                raise TensormassError("viscous history: the changed model's parts do not descend from the old ones")
            self.Q[i] = old.Q[i][part.origin_rows].copy()
            self.S[i] = old.S[i][part.origin_rows].copy()
        self._h = None

    def viscous_stress(self) -> dict:
        """{part index: sum_i Q_i (n, points, 6)}: the non-equilibrium stress of the accepted state."""
        return {i: self.Q[i].sum(axis=2) for i, _ in self.parts}
