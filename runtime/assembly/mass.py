"""Masses: consistent element masses, their lumping, and the mass operator the integrators use.

    Me = element_mass(points, "tetra10", cells, density)    # (n, k, k) int rho N_a N_b dV
    m = lump(Me, "tetra10")                                  # (n, k) nodal masses of each element
    M = MassMatrix.build(model, kind="lumped")               # M @ v, M.diagonal, M.matrix(), M.add_to(...)

Lumping: linear elements by row sums (sum_b Me_ab = int rho N_a dV: the equal split on
simplices, positive for every linear element); quadratic elements by HRZ (the diagonal of Me
scaled so that the element's mass is conserved: positive, where the row sums of tetra10 and
triangle6 put negative or zero masses on the corners).  The consistent mass (solver.mass =
"consistent") is the assembled Me (x the identity over the components).  The rule of
shape_tables.json is exact for Me of every isoparametric element (runtime/assembly/loads.py).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ... import elements as _types
from ..base.errors import TensormassError
from .loads import has_table, measure_weights, shape_table

__all__ = ["element_mass", "lump", "MassMatrix", "MASS_KINDS"]

MASS_KINDS = ("lumped", "consistent")


def element_mass(points: np.ndarray, cell_type: str, cells: np.ndarray, density) -> np.ndarray:
    """(n, k, k) consistent scalar element masses: sum_q w_q rho N_a N_b det J."""
    table = shape_table(cell_type)
    cells = np.asarray(cells, dtype=np.int64)
    if cells.size == 0:
        return np.zeros((0, table.N.shape[1], table.N.shape[1]))
    dV = measure_weights(points[cells], table)                       # (n, q)
    Me = np.einsum("nq,qa,qb->nab", dV, table.N, table.N)
    return Me * np.broadcast_to(np.asarray(density, float), (len(cells),))[:, None, None]


def lump(Me: np.ndarray, cell_type: str) -> np.ndarray:
    """(n, k) lumped nodal masses: row sums (linear elements) or HRZ (quadratic ones)."""
    if not _types.get(cell_type).quadratic and _types.get(cell_type).order == 1:
        return Me.sum(axis=2)
    diag = np.einsum("naa->na", Me)
    total = Me.sum(axis=(1, 2))
    scale = np.divide(total, diag.sum(axis=1), out=np.zeros_like(total), where=diag.sum(axis=1) != 0)
    return diag * scale[:, None]


class MassMatrix:
    """The global mass, per dof (node-major): lumped (diagonal) or consistent (element masses).

    M @ x (or M.matvec(x)), M.diagonal (per dof), M.lumped (the lumped masses, whatever the kind),
    M.matrix() (CSR), M.energy(v) = v.M v / 2, M.add_to(data, pattern, scale): data += scale M on
    the assembler's CSR pattern (the element masses share the stiffness pattern).
    """
    __array_ufunc__ = None            # `vector * M` is an error, not an elementwise product: use M @ x

    def __init__(self, kind: str, dim: int, n_dofs: int, lumped: np.ndarray, blocks=()):
        if kind not in MASS_KINDS:
            raise TensormassError(f"solver.mass must be one of {', '.join(MASS_KINDS)}, got {kind!r}")
        self.kind, self.dim, self.n_dofs = kind, dim, n_dofs
        self.lumped = lumped
        self.blocks = list(blocks)        # (part index, cell rows, cells (n, k), Me (n, k, k))
        self._csr = None
        self._pattern_data = {}
        self.diagonal = lumped if kind == "lumped" else self.matrix().diagonal()

    # -- building ------------------------------------------------------------------------------
    @classmethod
    def build(cls, points: np.ndarray, parts, dim: int, kind: str = "lumped") -> "MassMatrix":
        """From the model's parts: each cell counted once (in the part whose law models it now)."""
        n_points = points.shape[0]
        node_mass = np.zeros(n_points)
        node_rotary = np.zeros(n_points)           # sum of m_a x (rotary inertia per unit mass)
        blocks = []
        for i, part in enumerate(parts):
            rows = np.flatnonzero(part.active)
            if rows.size == 0:
                continue
            if np.any(part.density[rows] < 0):
                raise TensormassError("negative density gives negative nodal masses")
            cells = part.cells[rows]
            if has_table(part.element, points.shape[1]):
                Me = element_mass(points, part.element, cells, part.density[rows])
            else:   # a registered element without shape tables: its measure split equally (diagonal)
                share = part.density[rows] * part.volume[rows] / cells.shape[1]
                Me = share[:, None, None] * np.eye(cells.shape[1])
            lumped = lump(Me, part.element)
            np.add.at(node_mass, cells, lumped)
            if hasattr(part, "cell_masses"):          # kept for local updates (runtime.change.cutting)
                part.cell_masses = np.zeros(part.cells.shape)
                part.cell_masses[rows] = lumped
            if getattr(part, "rotary", None) is not None:
                np.add.at(node_rotary, cells, lumped * np.asarray(part.rotary, float)[rows, None])
            blocks.append((i, rows, cells, Me))
        if np.any(node_mass < 0):
            raise TensormassError("negative density gives negative nodal masses")
        space = points.shape[1]
        if dim > space and any(getattr(p, "rotary", None) is not None for p in parts):
            # nodes with rotations (shells): translations, then rotary inertia
            if kind != "lumped":
                raise TensormassError("solver.mass = \"consistent\" is not available for shells (nodes with "
                                      "rotations); use the default lumped mass")
            per_dof = np.concatenate([np.repeat(node_mass[:, None], space, axis=1),
                                      np.repeat(node_rotary[:, None], dim - space, axis=1)], axis=1)
            return cls(kind, dim, n_points * dim, per_dof.ravel(), blocks)
        return cls(kind, dim, n_points * dim, np.repeat(node_mass, dim), blocks)

    # -- use -------------------------------------------------------------------------------------
    def matrix(self) -> sp.csr_matrix:
        if self._csr is None:
            if self.kind == "lumped":
                self._csr = sp.diags(self.lumped).tocsr()
            else:
                d = self.dim
                rows, cols, vals = [], [], []
                for _, _, cells, Me in self.blocks:
                    k = cells.shape[1]
                    for c in range(d):
                        dofs = cells * d + c
                        rows.append(np.repeat(dofs, k, axis=1).ravel())
                        cols.append(np.tile(dofs, (1, k)).ravel())
                        vals.append(Me.reshape(len(cells), k * k).ravel())
                if rows:
                    r, c_, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
                else:
                    r = c_ = np.zeros(0, np.int64)
                    v = np.zeros(0)
                self._csr = sp.csr_matrix((v, (r, c_)), shape=(self.n_dofs, self.n_dofs))
                self._csr.sum_duplicates()
        return self._csr

    def matvec(self, x: np.ndarray) -> np.ndarray:
        if self.kind == "lumped":
            return self.lumped * x
        return self.matrix() @ x

    def __matmul__(self, x):
        return self.matvec(np.asarray(x, float))

    def energy(self, v: np.ndarray) -> float:
        return 0.5 * float(v @ self.matvec(v))

    def add_to(self, data: np.ndarray, pattern, scale: float = 1.0) -> np.ndarray:
        """data += scale M on `pattern` (runtime.assembly.assembly.SparsePattern); returns data."""
        if self.kind == "lumped":
            data[pattern.diagonal] += scale * self.lumped
            return data
        data += scale * self._on_pattern(pattern)
        return data

    def _on_pattern(self, pattern) -> np.ndarray:
        key = id(pattern)
        if key not in self._pattern_data:
            out = np.zeros(pattern.nnz)
            d = self.dim
            for i, rows, cells, Me in self.blocks:
                pos = pattern.positions[i][rows]                       # (n, k d, k d)
                k = cells.shape[1]
                full = np.einsum("nab,cd->nacbd", Me, np.eye(d)).reshape(len(cells), k * d, k * d)
                np.add.at(out, pos.ravel(), full.ravel())
            self._pattern_data = {key: out}
        return self._pattern_data[key]
