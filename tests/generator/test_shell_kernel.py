"""The flat CST-DKT shell triangle kernel (shell_cst_dkt_exact): finite differences, rigid motions,
the law's symbolic energy, the membrane and constant-curvature patch tests on a tilted irregular
patch, the degenerate-triangle flag, C = numba, and a cantilever strip against beam theory.

Dofs per node: (u, v, w, theta_x, theta_y, theta_z) in world axes.  The kernel is linear (small
rotations), so f = -K u and W = u.K.u / 2 exactly.  The C backend is used except in the C = numba
test (the numba kernel compiles once into $TENSORMASS_CACHE, ~1 min the first time).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sps
import scipy.sparse.linalg as spla
import sympy as sp

import tensormass as tm
from tensormass import laws
from tensormass.runtime.base.errors import DegenerateElementError

from helpers import relative_error

E, NU, H = 1.0e4, 0.3, 0.05


@pytest.fixture(scope="module")
def k():
    return tm.load_kernel("shell", "cst_dkt", "exact", backend="c")


def random_rotation(rng):
    Q, R = np.linalg.qr(rng.standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def min_angle(P):
    """The smallest corner angle (radians) of a triangle given by 2D or 3D corners."""
    out = []
    for i in range(3):
        a, b = P[(i + 1) % 3] - P[i], P[(i + 2) % 3] - P[i]
        out.append(math.acos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))
    return min(out)


def random_triangles(n, seed=0):
    """(n, 3, 3) well-shaped triangles (smallest angle > 20 degrees, size 0.5-2) in random 3D
    orientations and positions: a flat 2D triangle rotated at random and moved."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        P = rng.uniform(-1, 1, (3, 2))
        if min_angle(P) < math.radians(20):
            continue
        P *= rng.uniform(0.5, 2.0) / np.abs(P - P.mean(axis=0)).max()
        flat = np.column_stack([P, np.zeros(3)])
        out.append(flat @ random_rotation(rng).T + rng.standard_normal(3))
    return np.array(out)


def random_dofs(X, seed, amplitude=0.05):
    """Displacements ~ amplitude x element size and rotations ~ amplitude (radians)."""
    rng = np.random.default_rng(seed)
    u = amplitude * rng.standard_normal((len(X), 3, 6))
    u[:, :, :3] *= np.abs(X - X.mean(axis=1, keepdims=True)).max()
    return u


def plane_stress(E, nu):
    return E / (1 - nu**2) * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])


# ---------------------------------------------------------------- one element


def test_forces_and_stiffness_match_finite_differences(k):
    X = random_triangles(3, seed=1)
    D = k.constants(X, E=E, nu=NU, thickness=H)
    u = random_dofs(X, seed=2)
    f, K = k.forces_and_stiffness(D, u)
    assert f.shape == (3, 18) and K.shape == (3, 18, 18)
    step = 1e-4            # the energy is quadratic: central differences have no truncation error
    f_fd, K_fd = np.zeros_like(f), np.zeros_like(K)
    for r in range(18):
        du = np.zeros(18)
        du[r] = step
        du = np.broadcast_to(du.reshape(3, 6), u.shape)
        f_fd[:, r] = -(k.energy(D, u + du) - k.energy(D, u - du)) / (2 * step)
        K_fd[:, :, r] = -(k.forces(D, u + du) - k.forces(D, u - du)) / (2 * step)
    assert relative_error(f, f_fd) < 1e-7
    assert relative_error(K, K_fd) < 1e-7
    assert np.abs(K - np.swapaxes(K, 1, 2)).max() < 1e-12 * np.abs(K).max()
    assert relative_error(k.forces(D, u), f) < 1e-14 and relative_error(k.stiffness(D, u), K) < 1e-14
    # linear kernel: f = -K u, W = u.K.u / 2 = -f.u / 2, K independent of u
    flat = u.reshape(3, 18)
    assert relative_error(f, -np.einsum("erc,ec->er", K, flat)) < 1e-13
    W = k.energy(D, u)
    assert relative_error(W, 0.5 * np.einsum("er,erc,ec->e", flat, K, flat)) < 1e-13
    assert relative_error(W, -0.5 * np.einsum("er,er->e", f, flat)) < 1e-13
    assert np.all(W > 0)
    assert relative_error(k.stiffness(D, np.zeros_like(u)), K) < 1e-14


def test_stiffness_rotates_with_the_element(k):
    """K of the triangle rotated by R is T K T^T (T = R on every translation and rotation block)."""
    X = random_triangles(2, seed=3)
    R = random_rotation(np.random.default_rng(7))
    K0 = k.stiffness(k.constants(X, E=E, nu=NU, thickness=H), np.zeros((2, 3, 6)))
    K1 = k.stiffness(k.constants(X @ R.T + 1.5, E=E, nu=NU, thickness=H), np.zeros((2, 3, 6)))
    T = np.kron(np.eye(6), R)
    assert relative_error(K1, T @ K0 @ T.T) < 1e-12


def rigid_motions(X):
    """(6, 3, 6) dofs of the three translations and the three infinitesimal rotations
    (u_i = omega x X_i, theta_i = omega) of a triangle X (3, 3)."""
    out = []
    for a in range(3):
        u = np.zeros((3, 6))
        u[:, a] = 1.0
        out.append(u)
    for a in range(3):
        omega = np.eye(3)[a]
        u = np.zeros((3, 6))
        u[:, :3] = np.cross(omega, X)
        u[:, 3:] = omega
        out.append(u)
    return np.array(out)


def test_exactly_the_six_rigid_motions_are_free(k):
    X = random_triangles(6, seed=5)
    D = k.constants(X, E=E, nu=NU, thickness=H)
    K = k.stiffness(D, np.zeros((6, 3, 6)))
    for e in range(len(X)):
        lam = np.linalg.eigvalsh(K[e])
        top = lam.max()
        assert np.abs(lam[:6]).max() < 1e-10 * top, lam / top
        assert lam[6] > 1e-7 * top, lam / top
        size = np.abs(X[e]).max()
        for u in rigid_motions(X[e]):
            f = k.forces(D[e:e + 1], u[None])
            assert np.abs(f).max() < 1e-12 * top * size
            assert abs(k.energy(D[e:e + 1], u[None])[0]) < 1e-12 * top * size**2


def test_energy_is_the_laws_symbolic_element_energy(k):
    """The law's element_energy (world dofs, through its frame) evaluated exactly with sympy."""
    X = random_triangles(1, seed=11)[0]
    u = random_dofs(X[None], seed=12)[0]
    law = laws.get("cst_dkt")
    Xs = sp.Matrix(3, 3, lambda i, j: sp.Rational(X[i, j]))
    us = sp.Matrix(3, 6, lambda i, j: sp.Rational(u[i, j]))
    W = law.element_energy("shell", us, Xs, sp.Rational(E), sp.Rational(NU).limit_denominator(100),
                           sp.Rational(H).limit_denominator(100))
    expected = float(sp.N(W, 30))
    D = k.constants(X[None], E=E, nu=NU, thickness=H)
    assert k.energy(D, u[None])[0] == pytest.approx(expected, rel=1e-12)


def test_exactly_degenerate_triangles_are_flagged(k):
    """Collinear or coincident corners whose cross product is exactly 0 (axis-aligned): flag 1."""
    X = random_triangles(3, seed=13)
    X[1] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.5, 0.0, 0.0]]
    with pytest.raises(DegenerateElementError, match="degenerate") as err:
        k.constants(X, E=E, nu=NU, thickness=H)
    assert list(err.value.elements) == [1]
    X[1] = [[0.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 2.0, 0.0]]
    with pytest.raises(DegenerateElementError):
        k.constants(X, E=E, nu=NU, thickness=H)


# constants() also flags corners collinear up to rounding (twice the area / l^2 below 1e-12): the
# rounding residue of |d1 x d2| in a general 3D position is ~1e-16 l^2, far from zero otherwise
def test_collinear_triangles_in_general_position_are_flagged(k):
    X = random_triangles(8, seed=13)
    for e, s in enumerate(np.linspace(-0.5, 1.5, 8)):
        X[e, 2] = X[e, 0] + s * (X[e, 1] - X[e, 0])       # collinear up to rounding
    with pytest.raises(DegenerateElementError) as err:
        k.constants(X, E=E, nu=NU, thickness=H)
    assert list(err.value.elements) == list(range(8))
    X = random_triangles(3, seed=14)
    X[1, 2] = X[1, 1]                                       # two coincident corners
    with pytest.raises(DegenerateElementError):
        k.constants(X, E=E, nu=NU, thickness=H)


@pytest.mark.heavy                  # numba compiles the shell kernel's functions for about 50 s cold
def test_c_equals_numba():
    c = tm.load_kernel("shell", "cst_dkt", "exact", backend="c")
    nb = tm.load_kernel("shell", "cst_dkt", "exact", backend="numba")
    X = random_triangles(5, seed=17)
    u = random_dofs(X, seed=18)
    Dc, Dn = c.constants(X, E=E, nu=NU, thickness=H), nb.constants(X, E=E, nu=NU, thickness=H)
    assert relative_error(Dn, Dc) < 1e-12
    fc, Kc = c.forces_and_stiffness(Dc, u)
    fn, Kn = nb.forces_and_stiffness(Dn, u)
    assert relative_error(fn, fc) < 1e-12 and relative_error(Kn, Kc) < 1e-12
    assert relative_error(nb.energy(Dn, u), c.energy(Dc, u)) < 1e-12


# ---------------------------------------------------------------- patches and assembly


def patch():
    """An irregular planar mesh of the unit square: 4 corners, 2 boundary nodes off the edge
    midpoints, 2 interior off-centre nodes; 8 triangles wound counter-clockwise.  Returns the
    2D coordinates, the triangles and the interior node indices."""
    P = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.57, 0], [0, 0.62], [0.38, 0.41], [0.69, 0.58]])
    tri = np.array([[0, 4, 6], [4, 1, 7], [4, 7, 6], [1, 2, 7], [7, 2, 3], [6, 7, 3], [5, 6, 3],
                    [0, 6, 5]])
    (a, b), (c, d) = (P[tri[:, 1]] - P[tri[:, 0]]).T, (P[tri[:, 2]] - P[tri[:, 0]]).T
    twice = a * d - b * c
    assert np.all(twice > 0) and twice.sum() / 2 == pytest.approx(1.0)
    return P, tri, [6, 7]


def assemble(k, X, tri, u=None, E=E, nu=NU, thickness=H):
    """The global stiffness (scipy CSR, 6 dofs per node) of the triangles tri of the mesh X."""
    D = k.constants(X[tri], E=E, nu=nu, thickness=thickness)
    Ke = k.stiffness(D, np.zeros((len(tri), 3, 6)))
    dofs = (6 * tri[:, :, None] + np.arange(6)).reshape(len(tri), 18)
    rows = np.broadcast_to(dofs[:, :, None], Ke.shape).ravel()
    cols = np.broadcast_to(dofs[:, None, :], Ke.shape).ravel()
    n = 6 * len(X)
    return sps.csr_matrix((Ke.ravel(), (rows, cols)), shape=(n, n)), D


def tilted(P, seed):
    """The planar 2D mesh P placed in 3D: X = origin + x a0 + y a1; returns X and the axes R
    (columns a0, a1, normal)."""
    R = random_rotation(np.random.default_rng(seed))
    return np.array([0.3, -0.2, 0.7]) + P @ R[:, :2].T, R


def patch_forces(k, X, tri, U):
    """Assembled kernel forces (n_nodes, 6) and total energy of the nodal dofs U (n_nodes, 6)."""
    D = k.constants(X[tri], E=E, nu=NU, thickness=H)
    fe = k.forces(D, U[tri]).reshape(len(tri), 3, 6)
    F = np.zeros_like(U)
    np.add.at(F, tri, fe)
    return F, k.energy(D, U[tri]).sum(), D


def test_membrane_patch_test(k):
    """A linear in-plane field u = A x (any A: strain and rotation) with theta = omega n: the
    interior nodes are in equilibrium and the energy is h Area eps^T C eps / 2 exactly; the stress
    record's P is the plane-stress sigma in world axes."""
    P, tri, interior = patch()
    X, R = tilted(P, seed=21)
    A = np.array([[0.013, -0.021], [0.008, -0.006]])
    omega = (A[1, 0] - A[0, 1]) / 2
    U = np.zeros((len(P), 6))
    U[:, :3] = (P @ A.T) @ R[:, :2].T + np.array([0.01, 0.02, -0.03])     # plus a translation
    U[:, 3:] = omega * R[:, 2]
    F, W, D = patch_forces(k, X, tri, U)
    scale = np.abs(F).max()
    assert scale > 0
    assert np.abs(F[interior]).max() < 1e-10 * scale
    eps = np.array([A[0, 0], A[1, 1], A[0, 1] + A[1, 0]])
    C = plane_stress(E, NU)
    assert W == pytest.approx(0.5 * H * 1.0 * eps @ C @ eps, rel=1e-12)
    # the stress record: the membrane stress in world axes, the same in every element
    S = k.stress(D, U[tri])
    at = k.stress_record["offsets"]
    sxx, syy, sxy = C @ eps
    sigma = R[:, :2] @ np.array([[sxx, sxy], [sxy, syy]]) @ R[:, :2].T
    for e in range(len(tri)):
        assert relative_error(S[e, 0, at["P"]:at["P"] + 9].reshape(3, 3), sigma) < 1e-10
        F_rec = S[e, 0, at["F"]:at["F"] + 9].reshape(3, 3)
        assert relative_error(F_rec - np.eye(3), R[:, :2] @ A @ R[:, :2].T) < 1e-10


def test_bending_patch_test(k):
    """Constant curvature: w = w0 + g.x + (a x^2 + 2 b x y + c y^2) / 2 along the normal with the
    Kirchhoff rotations beta = (theta_y, -theta_x) = -grad w (local axes), drilling 0.  DKT
    reproduces the linear beta exactly: energy (h^3/12) Area kappa^T C kappa / 2 with
    kappa = (w_xx, w_yy, 2 w_xy), and the interior nodes are in equilibrium."""
    P, tri, interior = patch()
    X, R = tilted(P, seed=22)
    a, b, c = 0.7, -0.4, 0.25
    w0, gx, gy = 0.01, 0.03, -0.02
    x, y = P[:, 0], P[:, 1]
    w = w0 + gx * x + gy * y + 0.5 * (a * x**2 + 2 * b * x * y + c * y**2)
    wx, wy = gx + a * x + b * y, gy + b * x + c * y
    theta_local = np.column_stack([wy, -wx, np.zeros_like(x)])     # theta_x = w_y, theta_y = -w_x
    U = np.zeros((len(P), 6))
    U[:, :3] = w[:, None] * R[:, 2]
    U[:, 3:] = theta_local @ R.T
    F, W, _ = patch_forces(k, X, tri, U)
    kappa = np.array([a, c, 2 * b])
    expected = 0.5 * H**3 / 12 * 1.0 * kappa @ plane_stress(E, NU) @ kappa
    assert W == pytest.approx(expected, rel=1e-12)
    assert np.abs(F[interior]).max() < 1e-10 * np.abs(F).max()


def strip(L, b, nx, ny):
    """A rectangular strip [0, L] x [0, b] in nx x ny cells, two triangles per cell."""
    xs, ys = np.linspace(0, L, nx + 1), np.linspace(0, b, ny + 1)
    P = np.array([[x, y] for x in xs for y in ys])
    node = lambda i, j: i * (ny + 1) + j
    tri = []
    for i in range(nx):
        for j in range(ny):
            a, b_, c, d = node(i, j), node(i + 1, j), node(i + 1, j + 1), node(i, j + 1)
            tri += [[a, b_, c], [a, c, d]]
    return P, np.array(tri)


def cantilever_ratio(k, nx, ny, direction, L=1.0, b=0.1, h=0.01, nu=NU, load=1e-3):
    """Tip deflection of the strip clamped at x = 0 under an end load along `direction`
    (2: out of plane, 1: in plane, across the width) divided by the beam's P L^3 / (3 E I).
    The strip is tilted in 3D (a fixed rotation) so that the world axes are exercised."""
    P, tri = strip(L, b, nx, ny)
    X, R = tilted(P, seed=31)
    K, _ = assemble(k, X, tri, nu=nu, thickness=h)
    n = len(P)
    clamped = np.flatnonzero(np.isclose(P[:, 0], 0.0))
    tip = np.flatnonzero(np.isclose(P[:, 0], L))
    tip = tip[np.argsort(P[tip, 1])]
    share = np.full(len(tip), 1.0 / (len(tip) - 1))          # consistent load of a linear edge
    share[[0, -1]] /= 2
    f = np.zeros((n, 6))
    f[tip, :3] = load * share[:, None] * R[:, direction]
    free = np.setdiff1d(np.arange(6 * n), (6 * clamped[:, None] + np.arange(6)).ravel())
    U = np.zeros(6 * n)
    U[free] = spla.spsolve(K[free][:, free].tocsc(), f.ravel()[free])
    deflection = (U.reshape(n, 6)[tip, :3] @ R[:, direction]).mean()
    I = b * h**3 / 12 if direction == 2 else h * b**3 / 12
    return deflection / (load * L**3 / (3 * E * I))


def test_cantilever_bending_matches_beam_theory(k):
    """Out-of-plane end shear on a 1 x 0.1 x 0.01 strip (20 x 2 cells): DKT bending vs
    P L^3 / (3 E I), I = b h^3 / 12.  Measured: 0.9880 at nu = 0.3 (the clamp stops the
    anticlastic curvature near the root: a little of the plate's 1 / (1 - nu^2)), 1.00005 at nu = 0."""
    assert abs(cantilever_ratio(k, 20, 2, direction=2) - 1) < 0.03
    assert abs(cantilever_ratio(k, 20, 2, direction=2, nu=0.0) - 1) < 2e-3


def test_cantilever_membrane_converges_to_beam_theory(k):
    """In-plane end load across the width, I = h b^3 / 12: the CST is stiff in bending, so the
    coarse strip is far too stiff (measured 0.541 at 20 x 2 cells, 0.827 at 40 x 4, 0.954 at 80 x 8);
    the error must shrink at least 2x per refinement and the finest be within 10 %
    (beam theory omits the shear deflection, ~ +0.8 % here)."""
    ratios = [cantilever_ratio(k, 20 * m, 2 * m, direction=1) for m in (1, 2, 4)]
    errors = [1 - r for r in ratios]
    assert 0 < ratios[0] < ratios[1] < ratios[2] < 1.02, ratios
    assert errors[1] < 0.5 * errors[0] and errors[2] < 0.5 * errors[1], ratios
    assert abs(ratios[2] - 1) < 0.10, ratios
