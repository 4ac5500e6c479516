"""Follower pressure: a load normal to the current (deformed) surface, with its Newton stiffness.

    P = FollowerPressure(points, [(faces, p), ...], dim)   # faces {face type: (n, k)}, p in Pa
    f = P.forces(u)                  # f_a = -p sum_q w_q N_a n dA  on x = X + u (p > 0 pushes inward)
    Ke = P.element_stiffness(u)      # per face: -df/du (k d, k d), not symmetric in general
    P.add_stiffness(data, pattern, u, scale)   # its symmetric part added to the CSR data
    W = P.work(u0, u1)               # work done along the straight path u0 -> u1 (exact: Simpson)

n dA is t1 x t2 (3D faces) or (t_y, -t_x) (2D edges): a polynomial in the nodal positions (degree
2 in 3D, 1 in 2D), so f is exact with the shape tables' rules and Simpson's rule is exact for the
work along a straight segment.  Conservativeness: on a closed surface the pressure has the
potential p V(x) (V the enclosed volume) and its stiffness is symmetric after assembly; on an open
surface it has none.  The runtime treats both alike for energies: the line search and the health
monitor use the work of the pressure along the path actually taken (Newton steps, time steps),
which is the potential's change (-p dV) on a closed surface.  Stiffness: closed surfaces add the
symmetric part (exact after assembly: the symmetric solvers, band Cholesky and CG, keep working);
open surfaces add the full non-symmetric K_p and their Newton systems are solved by LU
(runtime.physics.newton.Context), so Newton stays quadratic.  With solver.linear = "cg" an open
surface adds the symmetric part only: a quasi-Newton step that converges linearly, and may not
converge at all when the pressure stiffness is not small against the elastic one.
"""
from __future__ import annotations

import numpy as np

from ... import elements as _types
from ...elements._faces import FACE_ONLY
from ..base.errors import TensormassError
from .loads import normal_areas, shape_table

__all__ = ["FollowerPressure"]


def _skew(v):
    """(..., 3, 3) matrices [v]_x with [v]_x w = v x w."""
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


class FollowerPressure:
    """Pressure loads on sets of faces; values may differ per set (Pa, positive pushes inward)."""

    def __init__(self, points: np.ndarray, loads, dim: int, dofs_per_node: int | None = None):
        self.X = np.asarray(points, float)
        self.dim = dim
        # nodes may carry more dofs than their displacement (a shell's rotations follow it)
        self.dofs_per_node = dofs_per_node or dim
        self.n_dofs = self.X.shape[0] * self.dofs_per_node
        groups: dict = {}
        # loads: (faces, p) or (faces, p, amplitude name): an amplitude scales that load over time
        self.amplitude_names = sorted({entry[2] for entry in loads if len(entry) > 2 and entry[2] is not None})
        for entry in loads:
            faces, p = entry[0], entry[1]
            which = self.amplitude_names.index(entry[2]) + 1 if len(entry) > 2 and entry[2] is not None else 0
            for name, f in faces.items():
                f = np.asarray(f, dtype=np.int64)
                if f.size:
                    groups.setdefault(name, []).append((f, np.full(len(f), float(p)), np.full(len(f), which)))
        # {face type: (faces (n, k), p (n,))}; p = the base value x its amplitude's factor now
        self.groups = {name: (np.vstack([f for f, _, _ in v]), np.concatenate([p for _, p, _ in v]))
                       for name, v in sorted(groups.items())}
        self._base = {name: (g[1].copy(), np.concatenate([w for _, _, w in groups[name]]))
                      for name, g in self.groups.items()}
        if not self.groups:
            raise TensormassError("pressure: no faces")
        self._positions = {}
        self.closed = self._is_closed()
        # Newton's pressure stiffness: symmetric (closed surfaces: exact; symmetric solvers) or full
        # (open surfaces: the solver must accept a non-symmetric matrix, see runtime.model.model)
        self.symmetric = self.closed

    def _is_closed(self) -> bool:
        """Every corner edge (3D) or corner vertex (2D) of the loaded faces is shared by exactly two."""
        keys = []
        for name, (faces, _) in self.groups.items():
            t = FACE_ONLY.get(name) or _types.get(name)
            if self.dim == 3:
                for a, b in t.edges:
                    keys.append(np.sort(faces[:, [a, b]], axis=1))
            else:
                keys.append(faces[:, :t.n_corners].reshape(-1, 1))
        keys = np.vstack(keys)
        _, counts = np.unique(keys, axis=0, return_counts=True)
        return bool(np.all(counts == 2))

    def __bool__(self):
        return True

    def set_factors(self, factors: dict) -> None:
        """Scale each load by its amplitude's value now ({amplitude name: factor}; loads without
        one keep their value): the integrators call it with the step's time (runtime.physics.integrators)."""
        scale = np.array([1.0] + [float(factors[n]) for n in self.amplitude_names])
        for name, (faces, p) in self.groups.items():
            base, which = self._base[name]
            p[:] = base * scale[which]

    def _x(self, u, faces):
        return self.X[faces] + np.asarray(u, float).reshape(-1, self.dofs_per_node)[:, :self.dim][faces]

    def forces(self, u: np.ndarray) -> np.ndarray:
        """Global nodal forces (n_dofs,) at displacement u."""
        f = np.zeros((self.X.shape[0], self.dim))
        for name, (faces, p) in self.groups.items():
            t = shape_table(name)
            nA = normal_areas(self._x(u, faces), t)                          # (n, q, d)
            fe = -np.einsum("n,q,qa,nqd->nad", p, t.weights, t.N, nA)
            np.add.at(f, faces, fe)
        if self.dofs_per_node != self.dim:
            f = np.concatenate([f, np.zeros((len(f), self.dofs_per_node - self.dim))], axis=1)
        return f.ravel()

    def element_stiffness(self, u: np.ndarray) -> dict:
        """{face type: (n, k d, k d)} K_p = -df/du per face (node-major local dofs)."""
        out = {}
        d = self.dim
        for name, (faces, p) in self.groups.items():
            t = shape_table(name)
            x = self._x(u, faces)
            J = np.einsum("nkd,qkr->nqdr", x, t.dN)
            k = faces.shape[1]
            if d == 3:
                # d(t1 x t2)/dx_b = dN_b,1 (-[t2]_x) + dN_b,2 [t1]_x
                S1, S2 = _skew(J[..., 0]), _skew(J[..., 1])                   # (n, q, 3, 3)
                dnA = (-np.einsum("qb,nqij->nqbij", t.dN[:, :, 0], S2)
                       + np.einsum("qb,nqij->nqbij", t.dN[:, :, 1], S1))
            else:
                R = np.array([[0.0, 1.0], [-1.0, 0.0]])                       # (t_y, -t_x) = R t
                dnA = np.einsum("qb,ij->qbij", t.dN[:, :, 0], R)[None].repeat(len(faces), 0)
            # f_a = -p sum_q w N_a nA  =>  K_ab = -df_a/dx_b = p sum_q w N_a dnA/dx_b
            K = np.einsum("n,q,qa,nqbij->naibj", p, t.weights, t.N, dnA)
            out[name] = K.reshape(len(faces), k * d, k * d)
        return out

    def _face_positions(self, pattern, name, faces):
        key = (id(pattern), name)
        if key not in self._positions:
            d, n = self.dim, pattern.n_dofs
            dofs = (faces[:, :, None] * self.dofs_per_node + np.arange(d)).reshape(len(faces), -1)
            keys = (dofs[:, :, None] * n + dofs[:, None, :]).ravel()
            csr_keys = pattern._rows.astype(np.int64) * n + pattern.indices.astype(np.int64)
            pos = np.searchsorted(csr_keys, keys)
            if np.any(pos >= csr_keys.size) or np.any(csr_keys[np.minimum(pos, csr_keys.size - 1)] != keys):
                raise TensormassError("pressure: a loaded face is not part of a cell (its nodes are not coupled)")
            self._positions[key] = pos
        return self._positions[key]

    def add_stiffness(self, data: np.ndarray, pattern, u: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """data += scale * K_p (its symmetric part when self.symmetric) on the assembler's CSR
        pattern (structurally symmetric: a face's nodes belong to one cell); returns data."""
        for name, K in self.element_stiffness(u).items():
            if self.symmetric:
                K = 0.5 * (K + np.swapaxes(K, 1, 2))
            np.add.at(data, self._face_positions(pattern, name, self.groups[name][0]), scale * K.ravel())
        return data

    def work(self, u0: np.ndarray, u1: np.ndarray) -> float:
        """Work of the pressure forces along the straight path u0 -> u1 (Simpson: exact)."""
        du = u1 - u0
        if not np.any(du):
            return 0.0
        f0, fm, f1 = self.forces(u0), self.forces(0.5 * (u0 + u1)), self.forces(u1)
        return float((f0 + 4.0 * fm + f1) @ du) / 6.0

    def volume(self, u: np.ndarray) -> float:
        """(1/d) int x.n dA over the loaded faces: the enclosed volume (area in 2D) of a closed surface."""
        total = 0.0
        for name, (faces, _) in self.groups.items():
            t = shape_table(name)
            x = self._x(u, faces)
            nA = normal_areas(x, t)
            xq = np.einsum("qk,nkd->nqd", t.N, x)
            total += float(np.einsum("q,nqd,nqd->", t.weights, xq, nA))
        return total / self.dim
