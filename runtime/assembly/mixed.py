"""The mixed u-p formulation: the pressure as an unknown, for exact incompressibility (nu = 0.5).

A material with formulation "mixed" (runtime.physics.formulations) replaces its law's volumetric
energy U(theta) by a pressure field p_h = sum_a N_a p_a and the perturbed Lagrangian

    L(u, p) = integral of W_dev(F) + p_h (theta(F) - 1) dV  -  1/2 p^T C p,

    C = sum_g V_g / kappa_g (one entry per pressure unknown; 0 at nu = 0.5)  +  C_stab

with kappa = U''(1), the law's bulk stiffness at rest (inf at nu = 0.5), theta its volume measure
(laws.measures) and W_dev the law with the bulk parameter set to 0.  Stationarity in p is the
volume constraint integral of N_a (theta - 1) dV = (C p)_a; at nu < 0.5 eliminating p gives back a
volumetric energy kappa/2 (theta - 1)^2 in the mean, the law's own at small strain.  The Newton
matrix of (u, p) is symmetric and indefinite (runtime.physics.saddle solves it):

    [ K_dev + sum_e integral p_h d2theta/du2   B^T ]       B_ai = d/du_i integral N_a theta dV
    [ B                                        -C  ]

Pressure spaces, each a stable or stabilised pair with the element's displacements:
- tetra10: P2-P1 (Taylor-Hood): continuous linear pressure at the corner nodes;
- tetra:   P1-P1 stabilised by MINI's bubble condensed at rest (Arnold, Brezzi & Fortin 1984):
  the bubble b = 256 l1 l2 l3 l4 with the shear stiffness mu at rest contributes
  C_stab = sum_e tau_e V_e grad(l_a) . grad(l_b),  tau_e = (integral b)^2 / (mu V_e integral |grad b|^2)
  = (3/140) / (mu sum_i |grad l_i|^2), derived in docs/guide/materials.md (Brezzi-Pitkaranta's form);
- hexahedron: Q1-P0, one pressure per cell.
The integrals of N_a theta are the measure kernel's (generated, like every kernel) with each
point's weight v_q scaled by N_a(xi_q): its constants hold v_q and the shape gradients only.

The pressures are the coupling's state (`pressure`): Newton on (u, p) writes them, and they are
what the energy, the forces and the stress of this cell group use between solves.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..base.errors import TensormassError
from ..kernels import kernels as _kernels
from .assembly import project_psd, scatter_matrix, scatter_vector
from .volumetric import VolumetricCoupling, volumetric_functions

__all__ = ["MixedCoupling", "PAIRS", "MINI_TAU"]

# element -> (pressure space, the pair's name)
PAIRS = {"tetra10": ("P1", "P2-P1 (Taylor-Hood)"), "tetra": ("P1", "P1-P1 with MINI's condensed bubble"),
         "hexahedron": ("P0", "Q1-P0")}
# tau_e mu sum_i |grad l_i|^2 of a linear tetrahedron: (32/105)^2 / (65536/15120)
MINI_TAU = 3.0 / 140.0


# gradients of the barycentric coordinates on the reference tetrahedron (0,0,0), (1,0,0), (0,1,0), (0,0,1)
_GRAD_L = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def pressure_shapes(kernel) -> np.ndarray:
    """(n_pressure_shapes, n_points) values of the pressure shape functions at the points of the
    measure kernel's rule, read from the kernel itself (no quadrature tables, no sympy):
    - hexahedron (P0): 1;
    - tetra (P1 on a linear cell): 1/4 at every point. theta is constant in the cell, so every
      integral of N_a theta is theta V / 4 whatever the points;
    - tetra10: on the reference cell a corner's shape gradient is (4 l_a - 1) grad l_a, which
      gives l_a at each point exactly."""
    q = kernel.n_points
    if PAIRS[kernel.element][0] == "P0":
        return np.ones((1, q))
    if kernel.element == "tetra":
        return np.full((4, q), 0.25)
    from ... import elements
    X = np.array(elements.get(kernel.element).nodes, dtype=float)[None]
    G = kernel.point_gradients(kernel.constants(X))[0, :, :4]          # (q, 4 corners, 3)
    return ((np.einsum("qai,ai->qa", G, _GRAD_L) / (_GRAD_L ** 2).sum(axis=1) + 1.0) / 4.0).T


def shear_modulus(params: dict, n: int) -> np.ndarray:
    """mu at rest per cell from a law's native parameters (the MINI stabilisation needs it)."""
    if "mu" in params:
        return np.broadcast_to(np.asarray(params["mu"], dtype=float), (n,))
    if "C10" in params and "C01" in params:
        return 2.0 * (np.broadcast_to(params["C10"], (n,)) + np.broadcast_to(params["C01"], (n,)))
    if "E" in params and "nu" in params:
        return np.broadcast_to(params["E"] / (2.0 * (1.0 + np.asarray(params["nu"], dtype=float))), (n,))
    return None


class MixedCoupling:
    """The pressure unknowns and the volumetric terms of the cells `rows` of one part (module docstring)."""

    patch_tables: list = []                       # the pressure couples no displacement dofs beyond a cell

    def __init__(self, model, part_index: int, rows: np.ndarray, params: dict, materials: np.ndarray):
        part = model.parts[part_index]
        self.part_index, self.formulation, self.law = part_index, "mixed", part.law
        self.element = part.element
        self.pair = PAIRS[part.element][1]
        self.parameter, self.measure, self.function = volumetric_functions(part.law)
        self.rows = np.asarray(rows, dtype=np.int64)
        self.cells = np.ascontiguousarray(part.cells[self.rows], dtype=np.int64)
        self.dofs = np.ascontiguousarray(part.dofs[self.rows], dtype=np.int64)
        self.cell_ids = part.cell_ids[self.rows]
        self.kernel = k = _kernels.load_kernel(part.element, self.measure, part.quadrature, backend=model.solver.backend)
        if k.v_offset is None or k.G_offset is None:
            raise TensormassError(f"formulation 'mixed' on {part.element}: the measure kernel keeps no point weights")
        self.D = k.constants(model.mesh.points[self.cells])
        self.N = pressure_shapes(k)                                          # (a, q)
        v = k.point_volumes(self.D)                                          # (n, q)
        self.cell_volume = v.sum(axis=1)
        n = len(self.cells)
        materials = np.asarray(materials)
        if self.N.shape[0] == 1:                                             # P0: a pressure per cell
            self.group_of = np.arange(n)[:, None]
        else:                                                                # P1: per (material, corner node)
            corners = self.cells[:, :4]
            keys = np.stack([np.repeat(materials, 4), corners.ravel()], axis=1)
            _, inverse = np.unique(keys, axis=0, return_inverse=True)
            self.group_of = inverse.reshape(n, 4)
        self.n_groups = int(self.group_of.max()) + 1 if n else 0
        self.shares = v @ self.N.T                                          # (n, a) integral of N_a dV at rest
        self.V = np.bincount(self.group_of.ravel(), self.shares.ravel(), minlength=self.n_groups)
        full = {p: np.broadcast_to(np.asarray(val, dtype=float), (len(part.cells),))[self.rows]
                for p, val in params.items()}
        self.C = self._pressure_matrix(full, materials)
        self.pressure = np.zeros(self.n_groups)
        self.positions = None                                                # set by the Assembler
        self.patch_positions = []

    # -- the (p, p) block ---------------------------------------------------------------------
    def _pressure_matrix(self, params, materials) -> sp.csr_matrix:
        """C = diag(V_g / kappa_g) + C_stab (tetra), symmetric positive semi-definite."""
        n = len(self.cells)
        with np.errstate(all="ignore"):
            _, _, d2U = self.function(np.ones(n), **params)
        kappa = np.broadcast_to(np.asarray(d2U, dtype=float), (n,))
        if np.any(np.isnan(kappa)) or np.any(kappa <= 0):
            raise TensormassError(f"formulation 'mixed': law {self.law!r} has no positive bulk stiffness at rest")
        # 1 / kappa per group: cells of one group share a material
        inv = np.zeros(self.n_groups)
        inv[self.group_of.ravel()] = np.repeat(1.0 / kappa, self.group_of.shape[1])
        C = sp.diags(self.V * inv, format="csr")
        if self.element == "tetra":
            mu = shear_modulus(params, n)
            if mu is None:
                raise TensormassError(f"formulation 'mixed' on tetra: the shear modulus of law {self.law!r} is not "
                                      "known (its MINI stabilisation needs it); use tetra10 (P2-P1)")
            G = self.kernel.point_gradients(self.D)[:, 0]                   # (n, 4, 3): grad l_a, constant
            tau = MINI_TAU / (mu * np.einsum("eij,eij->e", G, G))
            Ce = (tau * self.cell_volume)[:, None, None] * np.einsum("eai,ebi->eab", G, G)
            r = np.repeat(self.group_of, 4, axis=1).ravel()
            c = np.tile(self.group_of, (1, 4)).ravel()
            C = C + sp.csr_matrix((Ce.ravel(), (r, c)), shape=(self.n_groups, self.n_groups))
            C.sum_duplicates()
        return C.tocsr()

    # -- constants with scaled weights --------------------------------------------------------
    def _weighted(self, weights: np.ndarray) -> np.ndarray:
        """The measure constants with v_q multiplied by weights (n, q)."""
        k = self.kernel
        D = self.D.copy()
        D[:, k.v_offset:k.n_points * k.point_stride:k.point_stride] *= weights
        return D

    def point_pressure(self, pressure=None) -> np.ndarray:
        """(n, q) p_h at the points of every cell."""
        p = self.pressure if pressure is None else pressure
        return p[self.group_of] @ self.N

    # -- evaluation ---------------------------------------------------------------------------
    def evaluate(self, U, f, data, project=False) -> float:
        """Add the pressure's forces (f) and d2/du2 of integral p_h theta (data); returns
        integral p_h (theta - 1) dV - 1/2 p^T C p at the current pressures."""
        ue = np.ascontiguousarray(U[self.cells])
        Dp = self._weighted(self.point_pressure())
        k = self.kernel
        energy = float(k.energy(Dp, ue).sum() - self.pressure @ self.V - 0.5 * self.pressure @ (self.C @ self.pressure))
        if data is not None:
            fe, Ke = k.forces_and_stiffness(Dp, ue)
            if project:
                project_psd(Ke, out=Ke)
            scatter_matrix(data, Ke, self.positions, 1.0)
        elif f is not None:
            fe = k.forces(Dp, ue)
        if f is not None:
            scatter_vector(f, fe, self.dofs)
        return energy

    def constraint(self, U, pressure=None) -> np.ndarray:
        """dL/dp: integral N_a (theta - 1) dV summed per group, minus C p."""
        ue = np.ascontiguousarray(U[self.cells])
        n = len(self.cells)
        theta = np.stack([self.kernel.energy(self._weighted(np.broadcast_to(Na, (n, len(Na)))), ue)
                          for Na in self.N], axis=1)                          # (n, a)
        Theta = np.bincount(self.group_of.ravel(), theta.ravel(), minlength=self.n_groups)
        p = self.pressure if pressure is None else pressure
        return Theta - self.V - self.C @ p

    def constraint_matrix(self, U, n_dofs: int) -> sp.csr_matrix:
        """B (groups x dofs): d/du of integral N_a theta dV per group."""
        ue = np.ascontiguousarray(U[self.cells])
        n, nd = self.dofs.shape
        rows, cols, vals = [], [], []
        for a, Na in enumerate(self.N):
            fe = self.kernel.forces(self._weighted(np.broadcast_to(Na, (n, len(Na)))), ue)
            rows.append(np.repeat(self.group_of[:, a], nd))
            cols.append(self.dofs.ravel())
            vals.append(-fe.ravel())
        B = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(self.n_groups, n_dofs))
        B.sum_duplicates()
        return B

    def volume_ratio(self, U) -> np.ndarray:
        """Per group, integral N_a theta dV / integral N_a dV: 1 where the constraint holds at nu = 0.5."""
        return (self.constraint(U, np.zeros(self.n_groups)) + self.V) / self.V

    def cell_terms(self, U) -> tuple:
        """(p_e, u_e) per cell for the output fields: the cell's mean pressure (its stress adds p_e
        dtheta/dF at every point) and the Lagrangian's volumetric density p_e (theta_e - 1) in the
        mean (without the -p^2 / (2 kappa) of nu < 0.5)."""
        p_cell = (self.pressure[self.group_of] * self.shares).sum(axis=1) / self.cell_volume
        theta = self.kernel.energy(self.D, np.ascontiguousarray(U[self.cells])) / self.cell_volume
        return p_cell, p_cell * (theta - 1.0)

    part_rows = VolumetricCoupling.part_rows
