"""The co-rotational shell: the generated linear CST-DKT kernel applied in the current element frame.

    k = CorotationalShell(load_kernel("shell", "cst_dkt", "exact"))   # the model does this
    D = k.constants(X, E=..., nu=..., thickness=...)                 # (n, 1 + 324 + 9 + 9)
    f, K = k.forces_and_stiffness(D, u)                              # u (n, 3, 6): d, psi per node

Unknowns per node: the displacement d and the total rotation vector psi (R = exp(psi), Rodrigues).
Per element and step (thesis chapter 6, with the frame made right-handed):
  frame       R_e = [e0 e1 e2] of the current triangle, built like the rest frame R_0 (e0 along the
              edge 0 -> 1, e2 the normal, e1 = e2 x e0)
  local dofs  translations u_bar_i = R_e^T (x_i - x_0) - X_bar_i (X_bar_i: rest local coordinates);
              rotations theta_bar_i = log(R_e^T R_i R_0) (the node's rotation relative to the frame)
  energy      W = 1/2 u_bar^T K_bar u_bar with K_bar = T_0^T K T_0 the generated kernel's stiffness
              read back into its rest frame (hoisted once by constants())
  forces      f = -B^T K_bar u_bar, B = d u_bar / d u exact: the translations' derivative includes
              the frame's spin (Omega = G dx: e1.(dx1 - dx0) / l, -e2.(dx1 - dx0) / l and
              e2.(dx2 - dx0) / q - p e2.(dx1 - dx0) / (l q) about e2, e1, e0), the rotations'
              J^-1(theta_bar) (R_e^T J(psi_i) dpsi_i - Omega) with J the left Jacobian of exp on SO(3).
              So f is the gradient of W (tests: central differences at rotations of ~2 rad), the
              moments are conjugate to the rotation vectors, and a rigid motion costs nothing.
              (The printed formulation rotates the local forces twice.)
  tangent     K = B^T K_bar B (symmetric, positive semi-definite): the derivative of B itself
              (stress times geometry) is left out, so Newton converges linearly, not quadratically,
              where rotations are large and the element is loaded (the strip rolled into half a
              circle: ~27 Newton iterations per load step of 9 degrees).
Rotation vectors are added by the solvers (psi + delta): fine below |psi| = 2 pi (exp's singularity);
a strip rolled into a full circle is out of reach, half a circle is not.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..base.errors import DegenerateElementError, TensormassError

__all__ = ["CorotationalShell", "rest_frames", "rotation_matrices"]

N, P, NDOF = 3, 6, 18
KB, R0, XB = 1, 1 + NDOF * NDOF, 1 + NDOF * NDOF + 9        # offsets in D: v, K_bar, R_0, X_bar
N_CONSTANTS = XB + 9


def rest_frames(X: np.ndarray) -> np.ndarray:
    """(n, 3, 3) frames of triangles X (n, 3, 3): columns e0, e1, e2 (laws/cst_dkt.rest_frame)."""
    d1, d2 = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
    e0 = d1 / np.linalg.norm(d1, axis=1)[:, None]
    n = np.cross(d1, d2)
    e2 = n / np.linalg.norm(n, axis=1)[:, None]
    return np.stack([e0, np.cross(e2, e0), e2], axis=2)


@njit(cache=True)
def _exp(psi):
    """Rodrigues: exp of the skew matrix of psi."""
    a = np.sqrt(psi[0] ** 2 + psi[1] ** 2 + psi[2] ** 2)
    if a < 1e-8:                       # series: 1 - a^2/6, 1/2 - a^2/24 (exact to rounding here)
        s, c = 1.0 - a * a / 6.0, 0.5 - a * a / 24.0
    else:
        s, c = np.sin(a) / a, (1.0 - np.cos(a)) / (a * a)
    x, y, z = psi[0], psi[1], psi[2]
    R = np.empty((3, 3))
    R[0, 0] = 1.0 - c * (y * y + z * z)
    R[1, 1] = 1.0 - c * (x * x + z * z)
    R[2, 2] = 1.0 - c * (x * x + y * y)
    R[0, 1], R[1, 0] = -s * z + c * x * y, s * z + c * x * y
    R[0, 2], R[2, 0] = s * y + c * x * z, -s * y + c * x * z
    R[1, 2], R[2, 1] = -s * x + c * y * z, s * x + c * y * z
    return R


@njit(cache=True)
def _log(R):
    """The rotation vector of R (angle below pi: the relative rotations of a shell node)."""
    v0, v1, v2 = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
    s = 0.5 * np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)            # sin(angle)
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)              # cos(angle)
    a = np.arctan2(s, c)
    k = 0.5 if s < 1e-12 else 0.5 * a / s
    out = np.empty(3)
    out[0], out[1], out[2] = k * v0, k * v1, k * v2
    return out


@njit(cache=True)
def _frame(x):
    """Current frame (columns e0, e1, e2) of the triangle x (3, 3); zero where it is degenerate."""
    F = np.zeros((3, 3))
    d1, d2 = x[1] - x[0], x[2] - x[0]
    l1 = np.sqrt(d1[0] ** 2 + d1[1] ** 2 + d1[2] ** 2)
    n = np.array([d1[1] * d2[2] - d1[2] * d2[1], d1[2] * d2[0] - d1[0] * d2[2], d1[0] * d2[1] - d1[1] * d2[0]])
    ln = np.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2)
    if l1 == 0.0 or ln == 0.0:
        return F, False
    e0, e2 = d1 / l1, n / ln
    e1 = np.array([e2[1] * e0[2] - e2[2] * e0[1], e2[2] * e0[0] - e2[0] * e0[2], e2[0] * e0[1] - e2[1] * e0[0]])
    for k in range(3):
        F[k, 0], F[k, 1], F[k, 2] = e0[k], e1[k], e2[k]
    return F, True


@njit(cache=True)
def _element(De, Xe, ue, ub, Re):
    """u_bar (18,) and R_e (3, 3) of one element into ub, Re: rest X (3, 3), dofs u (3, 6); False
    when the current triangle is degenerate.  Explicit 3 x 3 loops: numba's @ on tiny matrices
    calls BLAS, whose overhead would dominate."""
    x = Xe + ue[:, :3]
    F, ok = _frame(x)
    if not ok:
        return False
    Re[:, :] = F
    rel = np.empty((3, 3))
    for i in range(N):
        for a in range(3):
            s = 0.0
            for k in range(3):
                s += Re[k, a] * (x[i, k] - x[0, k])
            ub[i * P + a] = s - De[XB + 3 * i + a]
        Ri = _exp(ue[i, 3:].copy())
        # rel = R_e^T R_i R_0
        for a in range(3):
            for b in range(3):
                s = 0.0
                for k in range(3):
                    t = 0.0
                    for m in range(3):
                        t += Ri[k, m] * De[R0 + 3 * m + b]
                    s += Re[k, a] * t
                rel[a, b] = s
        th = _log(rel)
        for a in range(3):
            ub[i * P + 3 + a] = th[a]
    return True


@njit(cache=True)
def _skew_sq(v, c1, c2, out):
    """out = I + c1 [v]x + c2 [v]x^2."""
    x, y, z = v[0], v[1], v[2]
    S = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    for r in range(3):
        for c in range(3):
            s2 = 0.0
            for k in range(3):
                s2 += S[r, k] * S[k, c]
            out[r, c] = (1.0 if r == c else 0.0) + c1 * S[r, c] + c2 * s2


@njit(cache=True)
def _jacobian(psi, out):
    """Left Jacobian of exp on SO(3): exp(psi + d) = exp(J d) exp(psi) to first order."""
    a = np.sqrt(psi[0] ** 2 + psi[1] ** 2 + psi[2] ** 2)
    if a < 1e-6:
        _skew_sq(psi, 0.5 - a * a / 24.0, 1.0 / 6.0 - a * a / 120.0, out)
    else:
        _skew_sq(psi, (1.0 - np.cos(a)) / (a * a), (a - np.sin(a)) / (a ** 3), out)


@njit(cache=True)
def _inverse_jacobian(theta, out):
    """Inverse left Jacobian: log(exp(phi) R) = log(R) + J^-1 phi to first order."""
    a = np.sqrt(theta[0] ** 2 + theta[1] ** 2 + theta[2] ** 2)
    if a < 1e-6:
        c2 = 1.0 / 12.0 + a * a / 720.0
    else:
        c2 = 1.0 / (a * a) - (1.0 + np.cos(a)) / (2.0 * a * np.sin(a))
    _skew_sq(theta, -0.5, c2, out)


@njit(cache=True)
def _strain_map(x, Re, ub, psi, B):
    """B = d u_bar / d(u) (18 x 18): the exact derivative of the local dofs with respect to the
    nodal displacements and rotation vectors, the frame's spin included (so f = -B^T K_bar u_bar
    is the gradient of W)."""
    for r in range(NDOF):
        for c in range(NDOF):
            B[r, c] = 0.0
    d1 = x[1] - x[0]
    d2 = x[2] - x[0]
    e0, e1, e2 = Re[:, 0], Re[:, 1], Re[:, 2]
    l = d1[0] * e0[0] + d1[1] * e0[1] + d1[2] * e0[2]
    p = d2[0] * e0[0] + d2[1] * e0[1] + d2[2] * e0[2]
    q = d2[0] * e1[0] + d2[1] * e1[1] + d2[2] * e1[2]
    # G: the frame's spin in its own axes, Omega = G (dx_0, dx_1, dx_2) (3 x 9)
    G = np.zeros((3, 9))
    for k in range(3):
        G[0, 6 + k] = e2[k] / q
        G[0, 3 + k] = -p * e2[k] / (l * q)
        G[0, k] = -(G[0, 6 + k] + G[0, 3 + k])
        G[1, 3 + k] = -e2[k] / l
        G[1, k] = e2[k] / l
        G[2, 3 + k] = e1[k] / l
        G[2, k] = -e1[k] / l
    Jinv = np.empty((3, 3))
    Jl = np.empty((3, 3))
    for i in range(N):
        # translations: R_e^T (dx_i - dx_0) + [y_i]x Omega, y_i the current local coordinates
        y = np.zeros(3)
        if i == 1:
            y[0] = l
        elif i == 2:
            y[0], y[1] = p, q
        for a in range(3):
            for k in range(3):
                if i != 0:
                    B[i * P + a, i * P + k] += Re[k, a]
                    B[i * P + a, k] -= Re[k, a]
        Y = np.array([[0.0, -y[2], y[1]], [y[2], 0.0, -y[0]], [-y[1], y[0], 0.0]])
        for a in range(3):
            for j in range(N):
                for k in range(3):
                    s = 0.0
                    for m in range(3):
                        s += Y[a, m] * G[m, 3 * j + k]
                    B[i * P + a, j * P + k] += s
        # rotations: J^-1(theta_bar) (R_e^T J(psi_i) dpsi_i - Omega)
        _inverse_jacobian(ub[i * P + 3:i * P + 6].copy(), Jinv)
        _jacobian(psi[i].copy(), Jl)
        for a in range(3):
            for k in range(3):
                s = 0.0
                for m in range(3):
                    t = 0.0
                    for n in range(3):
                        t += Re[n, m] * Jl[n, k]
                    s += Jinv[a, m] * t
                B[i * P + 3 + a, i * P + 3 + k] = s
            for j in range(N):
                for k in range(3):
                    s = 0.0
                    for m in range(3):
                        s += Jinv[a, m] * G[m, 3 * j + k]
                    B[i * P + 3 + a, j * P + k] -= s


@njit(cache=True, parallel=True)
def _evaluate(D, X, u, want_f, want_K, f, K, W, flags):
    # elements in parallel (runtime.base.parallel's thread count): each writes only its own rows, so
    # the results are the same bits whatever the count; the assembler scatters them in order
    for e in prange(D.shape[0]):
        ub, Re = np.zeros(NDOF), np.zeros((3, 3))
        if not _element(D[e], X[e], u[e], ub, Re):
            flags[e] = 1
            continue
        fb = np.zeros(NDOF)
        for r in range(NDOF):
            s = 0.0
            for c in range(NDOF):
                s += D[e, KB + r * NDOF + c] * ub[c]
            fb[r] = s
        w = 0.0
        for r in range(NDOF):
            w += ub[r] * fb[r]
        W[e] = 0.5 * w
        if not (want_f or want_K):
            continue
        B = np.empty((NDOF, NDOF))
        _strain_map(X[e] + u[e, :, :3], Re, ub, u[e, :, 3:], B)
        if want_f:
            for c in range(NDOF):
                s = 0.0
                for r in range(NDOF):
                    s += B[r, c] * fb[r]
                f[e, c] = -s
        if want_K:
            # B^T K_bar B: the terms of the derivative of B itself (stress times geometry) are left out
            KB_ = np.empty((NDOF, NDOF))
            for r in range(NDOF):
                for c in range(NDOF):
                    s = 0.0
                    for m in range(NDOF):
                        s += D[e, KB + r * NDOF + m] * B[m, c]
                    KB_[r, c] = s
            for r in range(NDOF):
                for c in range(r, NDOF):
                    s = 0.0
                    for m in range(NDOF):
                        s += B[m, r] * KB_[m, c]
                    K[e, r, c] = s
                    K[e, c, r] = s


class CorotationalShell:
    """A kernel (runtime.kernels.custom_kernels.Kernel protocol) wrapping a linear shell kernel."""

    def __init__(self, linear):
        self.linear = linear
        self.element, self.law, self.quadrature = linear.element, linear.law, linear.quadrature
        self.backend = linear.backend
        self.n_nodes, self.n_points, self.dim = N, 1, 3
        self.n_dofs, self.dofs_per_node = NDOF, P
        self.parameters = linear.parameters
        self.n_constants = N_CONSTANTS

    def __repr__(self):
        return f"<CorotationalShell {self.element}/{self.law} around {self.linear!r}>"

    def constants(self, X, **native):
        """v, K_bar (rest frame), R_0 and the rest local coordinates of each element. The rest
        coordinates themselves are kept by the wrapper (set_rest) to rebuild current positions."""
        X = np.ascontiguousarray(X, dtype=np.float64)
        Dl = self.linear.constants(X, **native)
        n = len(X)
        Kw = self.linear.stiffness(Dl, np.zeros((n, N, P)))
        frames = rest_frames(X)
        T = np.zeros((n, NDOF, NDOF))
        for b in range(2 * N):
            T[:, 3 * b:3 * b + 3, 3 * b:3 * b + 3] = frames
        Kb = np.einsum("nji,njk,nkl->nil", T, Kw, T)
        Xb = np.einsum("nka,nik->nia", frames, X - X[:, :1])
        D = np.concatenate([Dl[:, :1], Kb.reshape(n, -1), frames.reshape(n, 9), Xb.reshape(n, 9)], axis=1)
        return np.ascontiguousarray(D)

    def point_volumes(self, D):
        return np.asarray(D)[:, :1].copy()

    # The current positions need the rest ones: D keeps the local rest coordinates, and the
    # frame R_0; x_i - x_0 in the rest frame is all the element needs, so X is rebuilt from them.
    def _rest(self, D):
        Xb = D[:, XB:XB + 9].reshape(-1, 3, 3)
        frames = D[:, R0:R0 + 9].reshape(-1, 3, 3)
        return np.ascontiguousarray(np.einsum("nka,nia->nik", frames, Xb))

    def _run(self, D, u, want_f, want_K):
        D = np.ascontiguousarray(D, dtype=np.float64)
        u = np.ascontiguousarray(u, dtype=np.float64).reshape(len(D), N, P)
        if not np.all(np.isfinite(u)):
            raise TensormassError(f"{self}: displacements contain NaN or Inf")
        n = len(D)
        f = np.zeros((n, NDOF)) if want_f else np.zeros((1, NDOF))
        K = np.zeros((n, NDOF, NDOF)) if want_K else np.zeros((1, NDOF, NDOF))
        W, flags = np.zeros(n), np.zeros(n, dtype=np.int32)
        _evaluate(D, self._rest(D), u, want_f, want_K, f, K, W, flags)
        if flags.any():
            bad = np.flatnonzero(flags)
            raise DegenerateElementError(f"shell: {bad.size} element(s) collapsed to a line or a point "
                                         f"(first: element {int(bad[0])})")
        return f, K, W

    def energy(self, D, u):
        return self._run(D, u, False, False)[2]

    def forces(self, D, u):
        return self._run(D, u, True, False)[0]

    def stiffness(self, D, u):
        return self._run(D, u, False, True)[1]

    def forces_and_stiffness(self, D, u):
        f, K, _ = self._run(D, u, True, True)
        return f, K


def rotation_matrices(psi: np.ndarray) -> np.ndarray:
    """(n, 3, 3) exp of the rotation vectors psi (n, 3) (for outputs and tests)."""
    return np.stack([_exp(np.ascontiguousarray(p, dtype=np.float64)) for p in np.asarray(psi, float)])
