"""The "usual approach" baseline: a hand-written, generic finite-element kernel.

This is what a competent FEM code does without code generation (Picinbono
2003 style, total Lagrangian): at setup, per element and per integration
point, the rest Jacobian gives the shape-function gradients G (dN_i/dX) and
the weighted volume v = w det J; every step, per point,

    F = I + sum_i u_i (x) G_i,
    P = dW/dF (first Piola-Kirchhoff stress),   A = dP/dF (3x3x3x3 tangent),
    f_i -= v P G_i,     K_ij[a, c] += v sum_bd G_i[b] A[a, b, c, d] G_j[d],

with generic loops over nodes and dimensions (only the node blocks j >= i of
the symmetric K are accumulated, then mirrored, as any careful code does).
It exists to be benchmarked against the generated kernels
(apps/bench.py), and is checked against them in tests/test_bench.py.

    k = load_classic("hexahedron", "stvk", "gauss2")
    state = k.constants(X, E=1e6, nu=0.3)            # G, v, material, once
    f, K = k.forces_and_stiffness(state, u)

Laws: hooke, stvk, neohookean; any 3D element of the catalogue (tetra,
hexahedron, wedge, pyramid, tetra10) with any Gauss rule.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import sympy as sp
from numba import njit

from .. import laws
from ..generator.elements import element as reference
from ..generator.quadrature import rule
from ..runtime.base.errors import DegenerateElementError, InvertedElementError, TensormassError

LAWS = {"hooke": 0, "stvk": 1, "neohookean": 2}
HOOKE, STVK, NEOHOOKEAN = 0, 1, 2

_JIT = dict(cache=True, fastmath=False, error_model="numpy")


# -- reference element tables (Python, once per element x rule) ------------------------------
@lru_cache(maxsize=None)
def reference_tables(element: str, quadrature: str):
    """(dN (n_points, n_nodes, 3) reference gradients at the points, weights (n_points,))."""
    ref = reference(element)
    if ref.dim != 3:
        raise TensormassError(f"classic baseline: 3D elements only, {element!r} is {ref.dim}D")
    q = rule(element, quadrature)
    grad = sp.lambdify(ref.xi, ref.gradients(), "numpy")
    dN = np.empty((q.n_points, ref.n_nodes, 3))
    for k, point in enumerate(q.points):
        dN[k] = np.array(grad(*[float(x) for x in point]), dtype=float)
    w = np.array([float(x) for x in q.weights])
    return dN, w


# -- setup: G and v per element and point ------------------------------------------------------
@njit(**_JIT)
def _setup(X, dN, w, G, v, flags):
    n_elem, n_nodes = X.shape[0], X.shape[1]
    n_points = dN.shape[0]
    J = np.empty((3, 3))
    Ji = np.empty((3, 3))
    for e in range(n_elem):
        flags[e] = 0
        for q in range(n_points):
            for a in range(3):
                for k in range(3):
                    s = 0.0
                    for i in range(n_nodes):
                        s += X[e, i, a] * dN[q, i, k]
                    J[a, k] = s
            det = _inverse(J, Ji)
            if not (det > 0.0):
                flags[e] = 1
            v[e, q] = w[q] * det
            # G_i[b] = dN_i/dX_b = sum_k dN_i/dxi_k dxi_k/dX_b, dxi/dX = J^-1
            for i in range(n_nodes):
                for b in range(3):
                    s = 0.0
                    for k in range(3):
                        s += dN[q, i, k] * Ji[k, b]
                    G[e, q, i, b] = s


@njit(**_JIT)
def _inverse(M, Mi):
    """Mi = M^-1 (3x3, cofactors); returns det M."""
    c00 = M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]
    c01 = M[1, 2] * M[2, 0] - M[1, 0] * M[2, 2]
    c02 = M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]
    det = M[0, 0] * c00 + M[0, 1] * c01 + M[0, 2] * c02
    r = 1.0 / det
    Mi[0, 0] = c00 * r
    Mi[1, 0] = c01 * r
    Mi[2, 0] = c02 * r
    Mi[0, 1] = (M[0, 2] * M[2, 1] - M[0, 1] * M[2, 2]) * r
    Mi[1, 1] = (M[0, 0] * M[2, 2] - M[0, 2] * M[2, 0]) * r
    Mi[2, 1] = (M[0, 1] * M[2, 0] - M[0, 0] * M[2, 1]) * r
    Mi[0, 2] = (M[0, 1] * M[1, 2] - M[0, 2] * M[1, 1]) * r
    Mi[1, 2] = (M[0, 2] * M[1, 0] - M[0, 0] * M[1, 2]) * r
    Mi[2, 2] = (M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]) * r
    return det


# -- per point: F, P, dP/dF ---------------------------------------------------------------------
@njit(**_JIT)
def _deformation_gradient(G, u, e, q, F):
    for a in range(3):
        for b in range(3):
            F[a, b] = 1.0 if a == b else 0.0
    for i in range(G.shape[2]):
        g0 = G[e, q, i, 0]
        g1 = G[e, q, i, 1]
        g2 = G[e, q, i, 2]
        for a in range(3):
            ua = u[e, i, a]
            F[a, 0] += ua * g0
            F[a, 1] += ua * g1
            F[a, 2] += ua * g2


@njit(**_JIT)
def _stress(law, F, lam, mu, P, S, Fi):
    """P = dW/dF; returns False where the law is undefined (det F <= 0)."""
    if law == HOOKE:
        # eps = sym(F) - I, P = lam tr(eps) I + 2 mu eps
        tr = F[0, 0] + F[1, 1] + F[2, 2] - 3.0
        for a in range(3):
            for b in range(3):
                P[a, b] = mu * (F[a, b] + F[b, a])
            P[a, a] += lam * tr - 2.0 * mu
    elif law == STVK:
        # E = (F^T F - I)/2, S = lam tr(E) I + 2 mu E, P = F S
        for a in range(3):
            for b in range(3):
                s = 0.0
                for k in range(3):
                    s += F[k, a] * F[k, b]
                S[a, b] = s
        trE = 0.5 * (S[0, 0] + S[1, 1] + S[2, 2]) - 1.5
        for a in range(3):
            for b in range(3):
                S[a, b] *= mu
        for a in range(3):
            S[a, a] += lam * trE - mu
        for a in range(3):
            for b in range(3):
                s = 0.0
                for k in range(3):
                    s += F[a, k] * S[k, b]
                P[a, b] = s
    else:
        # P = mu (F - F^-T) + lam ln J F^-T
        J = _inverse(F, Fi)
        if not (J > 0.0):
            return False
        c = lam * np.log(J) - mu
        for a in range(3):
            for b in range(3):
                P[a, b] = mu * F[a, b] + c * Fi[b, a]
    return True


@njit(**_JIT)
def _stress_tangent(law, F, lam, mu, P, A, S, B, Fi):
    """P and A[a, b, c, d] = dP_ab/dF_cd; returns False where det F <= 0 (neo-Hookean)."""
    if law == NEOHOOKEAN:
        # P = mu F + (lam ln J - mu) F^-T
        # A = mu delta_ac delta_bd + (mu - lam ln J) Fi_bc Fi_da + lam Fi_ba Fi_dc
        J = _inverse(F, Fi)
        if not (J > 0.0):
            return False
        lnJ = np.log(J)
        c0 = lam * lnJ - mu
        for a in range(3):
            for b in range(3):
                P[a, b] = mu * F[a, b] + c0 * Fi[b, a]
        c1 = -c0
        for a in range(3):
            for b in range(3):
                for c in range(3):
                    for d in range(3):
                        t = c1 * Fi[b, c] * Fi[d, a] + lam * Fi[b, a] * Fi[d, c]
                        if a == c and b == d:
                            t += mu
                        A[a, b, c, d] = t
        return True
    _stress(law, F, lam, mu, P, S, Fi)
    if law == HOOKE:
        for a in range(3):
            for b in range(3):
                for c in range(3):
                    for d in range(3):
                        A[a, b, c, d] = ((lam if (a == b and c == d) else 0.0)
                                         + (mu if (a == c and b == d) else 0.0)
                                         + (mu if (a == d and b == c) else 0.0))
    elif law == STVK:
        # A = delta_ac S_bd + F_ae C_ebgd F_cg with C = lam I(x)I + 2 mu I_sym:
        #   = delta_ac S_bd + lam F_ab F_cd + mu (B_ac delta_bd + F_ad F_cb),  B = F F^T
        for a in range(3):
            for c in range(3):
                s = 0.0
                for k in range(3):
                    s += F[a, k] * F[c, k]
                B[a, c] = mu * s
        for a in range(3):
            for b in range(3):
                for c in range(3):
                    for d in range(3):
                        t = lam * F[a, b] * F[c, d] + mu * F[a, d] * F[c, b]
                        if a == c:
                            t += S[b, d]
                        if b == d:
                            t += B[a, c]
                        A[a, b, c, d] = t
    return True


# -- element loops ------------------------------------------------------------------------------
@njit(inline="always", **_JIT)
def _forces(G, v, mat, u, f, flags, law):
    """f (n, n_nodes*3) = -dW/du. G (n, Q, N, 3), v (n, Q), mat (n, 2) = lam, mu, u (n, N, 3)."""
    n_elem, n_points, n_nodes = G.shape[0], G.shape[1], G.shape[2]
    F = np.empty((3, 3))
    P = np.empty((3, 3))
    S = np.empty((3, 3))
    Fi = np.empty((3, 3))
    for e in range(n_elem):
        flags[e] = 0
        for r in range(3 * n_nodes):
            f[e, r] = 0.0
        lam = mat[e, 0]
        mu = mat[e, 1]
        for q in range(n_points):
            _deformation_gradient(G, u, e, q, F)
            if not _stress(law, F, lam, mu, P, S, Fi):
                flags[e] = 1
                break
            w = v[e, q]
            for i in range(n_nodes):
                g0 = w * G[e, q, i, 0]
                g1 = w * G[e, q, i, 1]
                g2 = w * G[e, q, i, 2]
                for a in range(3):
                    f[e, 3 * i + a] -= P[a, 0] * g0 + P[a, 1] * g1 + P[a, 2] * g2


@njit(inline="always", **_JIT)
def _forces_and_stiffness(G, v, mat, u, f, K, flags, law):
    """f as _forces and K (n, N*3, N*3) = d2W/du2."""
    n_elem, n_points, n_nodes = G.shape[0], G.shape[1], G.shape[2]
    n_dofs = 3 * n_nodes
    F = np.empty((3, 3))
    P = np.empty((3, 3))
    S = np.empty((3, 3))
    B = np.empty((3, 3))
    Fi = np.empty((3, 3))
    A = np.empty((3, 3, 3, 3))
    H = np.empty((3, 3, 3))
    for e in range(n_elem):
        flags[e] = 0
        for r in range(n_dofs):
            f[e, r] = 0.0
            for s_ in range(n_dofs):
                K[e, r, s_] = 0.0
        lam = mat[e, 0]
        mu = mat[e, 1]
        for q in range(n_points):
            _deformation_gradient(G, u, e, q, F)
            if not _stress_tangent(law, F, lam, mu, P, A, S, B, Fi):
                flags[e] = 1
                break
            w = v[e, q]
            for i in range(n_nodes):
                g0 = w * G[e, q, i, 0]
                g1 = w * G[e, q, i, 1]
                g2 = w * G[e, q, i, 2]
                for a in range(3):
                    f[e, 3 * i + a] -= P[a, 0] * g0 + P[a, 1] * g1 + P[a, 2] * g2
            for i in range(n_nodes):
                # H[a, c, d] = v sum_b G_i[b] A[a, b, c, d]
                g0 = w * G[e, q, i, 0]
                g1 = w * G[e, q, i, 1]
                g2 = w * G[e, q, i, 2]
                for a in range(3):
                    for c in range(3):
                        for d in range(3):
                            H[a, c, d] = g0 * A[a, 0, c, d] + g1 * A[a, 1, c, d] + g2 * A[a, 2, c, d]
                # K_ij[a, c] += sum_d H[a, c, d] G_j[d]   (node blocks j >= i)
                for j in range(i, n_nodes):
                    h0 = G[e, q, j, 0]
                    h1 = G[e, q, j, 1]
                    h2 = G[e, q, j, 2]
                    for a in range(3):
                        for c in range(3):
                            K[e, 3 * i + a, 3 * j + c] += H[a, c, 0] * h0 + H[a, c, 1] * h1 + H[a, c, 2] * h2
        # K is symmetric: only node blocks j >= i were accumulated.
        for r in range(n_dofs):
            for s_ in range((r // 3) * 3):
                K[e, r, s_] = K[e, s_, r]


# One compiled loop per law (the law is a compile-time constant, as a C++ template would make
# it): the generic body above is inlined with `law` fixed, so the branches fold away.
@njit(**_JIT)
def forces_hooke(G, v, mat, u, f, flags):
    _forces(G, v, mat, u, f, flags, HOOKE)


@njit(**_JIT)
def forces_stvk(G, v, mat, u, f, flags):
    _forces(G, v, mat, u, f, flags, STVK)


@njit(**_JIT)
def forces_neohookean(G, v, mat, u, f, flags):
    _forces(G, v, mat, u, f, flags, NEOHOOKEAN)


@njit(**_JIT)
def forces_and_stiffness_hooke(G, v, mat, u, f, K, flags):
    _forces_and_stiffness(G, v, mat, u, f, K, flags, HOOKE)


@njit(**_JIT)
def forces_and_stiffness_stvk(G, v, mat, u, f, K, flags):
    _forces_and_stiffness(G, v, mat, u, f, K, flags, STVK)


@njit(**_JIT)
def forces_and_stiffness_neohookean(G, v, mat, u, f, K, flags):
    _forces_and_stiffness(G, v, mat, u, f, K, flags, NEOHOOKEAN)


FORCES = {"hooke": forces_hooke, "stvk": forces_stvk, "neohookean": forces_neohookean}
FORCES_AND_STIFFNESS = {"hooke": forces_and_stiffness_hooke, "stvk": forces_and_stiffness_stvk,
                        "neohookean": forces_and_stiffness_neohookean}


# -- friendly wrapper ---------------------------------------------------------------------------
@dataclass
class ClassicState:
    """Per-element data of the classic kernel: G (n, Q, N, 3), v (n, Q), mat (n, 2) = lam, mu."""
    G: np.ndarray
    v: np.ndarray
    mat: np.ndarray

    def __len__(self):
        return len(self.v)

    @property
    def nbytes_per_element(self) -> int:
        return (self.G[0].size + self.v[0].size + self.mat[0].size) * 8


class ClassicKernel:
    """Hand-written generic kernel for one element x law x quadrature (3D)."""

    def __init__(self, element: str, law: str, quadrature: str):
        if law not in LAWS:
            raise TensormassError(f"classic baseline: no law {law!r}; it implements {', '.join(LAWS)}")
        self.element, self.law, self.quadrature = element, law, quadrature
        self.law_id = LAWS[law]
        self._forces = FORCES[law]
        self._forces_and_stiffness = FORCES_AND_STIFFNESS[law]
        self.dN, self.weights = reference_tables(element, quadrature)
        self.n_points, self.n_nodes = self.dN.shape[0], self.dN.shape[1]
        self.dim = 3
        self.n_dofs = 3 * self.n_nodes

    def __repr__(self):
        return f"<ClassicKernel {self.element}/{self.law}/{self.quadrature}>"

    @property
    def n_constants(self) -> int:
        """Doubles stored per element (G, v and the two Lamé parameters)."""
        return self.n_points * (self.n_nodes * 3 + 1) + 2

    def constants(self, X, E=None, nu=None, **native) -> ClassicState:
        X = np.ascontiguousarray(X, dtype=np.float64)
        if X.ndim == 2:
            X = X[None]
        if X.shape[1:] != (self.n_nodes, 3):
            raise TensormassError(f"{self.element}: rest coordinates must have shape (n_elem, {self.n_nodes}, 3)")
        n = len(X)
        values = laws.get(self.law).native_parameters(E=E, nu=nu, **native)
        mat = np.empty((n, 2))
        mat[:, 0] = np.broadcast_to(values["lam"], (n,))
        mat[:, 1] = np.broadcast_to(values["mu"], (n,))
        G = np.empty((n, self.n_points, self.n_nodes, 3))
        v = np.empty((n, self.n_points))
        flags = np.zeros(n, dtype=np.int32)
        _setup(X, self.dN, self.weights, G, v, flags)
        if flags.any():
            raise DegenerateElementError(f"{self.element}: det J <= 0 in the rest configuration",
                                         np.flatnonzero(flags))
        return ClassicState(G, v, mat)

    def _u(self, state, u):
        return np.ascontiguousarray(u, dtype=np.float64).reshape(len(state), self.n_nodes, 3)

    def _check(self, flags):
        if flags.any():
            raise InvertedElementError(f"classic {self.law}: det F <= 0 (inverted element)", np.flatnonzero(flags))

    # preallocated-output entry points (what the benchmark times)
    def forces_into(self, state: ClassicState, u, f, flags):
        self._forces(state.G, state.v, state.mat, u, f, flags)

    def forces_and_stiffness_into(self, state: ClassicState, u, f, K, flags):
        self._forces_and_stiffness(state.G, state.v, state.mat, u, f, K, flags)

    def forces(self, state: ClassicState, u) -> np.ndarray:
        u = self._u(state, u)
        n = len(state)
        f, flags = np.empty((n, self.n_dofs)), np.zeros(n, dtype=np.int32)
        self.forces_into(state, u, f, flags)
        self._check(flags)
        return f

    def forces_and_stiffness(self, state: ClassicState, u):
        u = self._u(state, u)
        n = len(state)
        f, K = np.empty((n, self.n_dofs)), np.empty((n, self.n_dofs, self.n_dofs))
        flags = np.zeros(n, dtype=np.int32)
        self.forces_and_stiffness_into(state, u, f, K, flags)
        self._check(flags)
        return f, K


@lru_cache(maxsize=None)
def load_classic(element: str, law: str, quadrature: str) -> ClassicKernel:
    return ClassicKernel(element, law, quadrature)
