"""The discrete laws' kernels (springs, lattice cubes): finite differences, rigid motions, the
small-strain stiffness of the HybMSS cube against the isotropic tensor, Baudet's values, the
stiffness rules against the thesis' numbers, the volume force's sign and the homogenised record.

The C backend is used (the numba compilation of the 28-spring cube takes 20-40 s); C = numba
is checked for every entry by CI's backend step (test_backends_agree.py). The quick suite checks the
tetrahedron and triangle kernels; the cube kernels (gcc takes 12 s for mss, 34 s for hybmss) are
heavy: CI's catalogue step runs them.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import tensormass as tm
from tensormass import elements, laws
from tensormass.generator.catalogue import entries
from tensormass.laws import springs
from tensormass.runtime.base.errors import DegenerateElementError

from helpers import random_cubes, random_elements, relative_error

DISCRETE = entries(law_names=laws.discrete_names())
CUBE = pytest.mark.heavy          # needs a hexahedron_*_discrete kernel
DISCRETE_PARAMS = [pytest.param(e, id=e.name, marks=CUBE if e.element == "hexahedron" else ()) for e in DISCRETE]
E = 1.0e4


def kernel(element, law):
    return tm.load_kernel(element, law, "discrete", backend="c")


def sample(element, n, seed):
    if element == "hexahedron":
        return random_cubes(n, seed)
    return random_elements(element, n, seed=seed)


def rotation(angle=1.1, axis=(1.0, 2.0, 2.0), dim=3):
    if dim == 2:
        c, s = math.cos(angle), math.sin(angle)
        return np.array([[c, -s], [s, c]])
    n = np.asarray(axis) / np.linalg.norm(axis)
    K = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def unit_cube(edge=0.5):
    return np.array(elements.get("hexahedron").nodes, dtype=float) * edge / 2


def test_the_catalogue_has_the_spring_entries():
    assert [e.name for e in DISCRETE] == ["hexahedron_hybmss_discrete", "hexahedron_mss_discrete",
                                          "tetra_mss_discrete", "triangle_mss_discrete"]


@pytest.mark.parametrize("entry", DISCRETE_PARAMS)
def test_forces_and_stiffness_match_finite_differences(entry):
    k = kernel(entry.element, entry.law)
    X = sample(entry.element, 2, seed=4)
    D = k.constants(X, E=E, nu=0.3)
    u = 0.08 * np.random.default_rng(1).standard_normal((2, k.n_nodes, k.dim)) * np.abs(X).max()
    f, K = k.forces_and_stiffness(D, u)
    h = 1e-6 * np.abs(X).max()
    f_fd, K_fd = np.zeros_like(f), np.zeros_like(K)
    for r in range(k.n_dofs):
        step = np.zeros(k.n_dofs)
        step[r] = h
        step = np.broadcast_to(step.reshape(k.n_nodes, k.dim), u.shape)
        f_fd[:, r] = -(k.energy(D, u + step) - k.energy(D, u - step)) / (2 * h)
        K_fd[:, :, r] = -(k.forces(D, u + step) - k.forces(D, u - step)) / (2 * h)
    assert relative_error(f, f_fd) < 1e-7
    assert relative_error(K, K_fd) < 1e-7
    assert np.abs(K - np.swapaxes(K, 1, 2)).max() < 1e-12 * np.abs(K).max()
    assert relative_error(k.forces(D, u), f) < 1e-14 and relative_error(k.stiffness(D, u), K) < 1e-14


@pytest.mark.parametrize("entry", DISCRETE_PARAMS)
def test_rigid_motions_cost_nothing(entry):
    """Springs and the cube volume are invariant under any rotation, not only small ones."""
    k = kernel(entry.element, entry.law)
    X = sample(entry.element, 3, seed=2)
    D = k.constants(X, E=E, nu=0.45)
    scale = np.abs(k.stiffness(D, np.zeros(X.shape))).max() * np.abs(X).max()
    R = rotation(dim=k.dim)
    for u in (np.broadcast_to(np.arange(1.0, k.dim + 1), X.shape), X @ R.T - X + 0.3):
        assert np.abs(k.forces(D, u)).max() < 1e-11 * scale
        assert np.abs(k.energy(D, u)).max() < 1e-11 * scale * np.abs(X).max()


@CUBE
@pytest.mark.parametrize("A", [0.0, 1.0, 3.0])
@pytest.mark.parametrize("nu", [0.0, 0.25, 0.3, 0.45, 0.499])
def test_hybmss_cube_is_the_isotropic_material(nu, A):
    """At small strain the cube's energy under any affine motion is V (lam/2 tr(eps)^2 + mu eps:eps)
    with the E and nu it was given: the lattice shares (k_e/4, k_f/2, k_c) and the volume term."""
    k = kernel("hexahedron", "hybmss")
    X = random_cubes(1, seed=int(100 * nu + A))[0]
    D = k.constants(X, E=E, nu=nu, A=A)
    K = k.stiffness(D, np.zeros((1, 8, 3)))[0]
    lam, mu = laws.lame_from_E_nu(E, nu)
    V = k.point_volumes(D)[0, 0]
    rng = np.random.default_rng(3)
    for _ in range(4):
        H = rng.standard_normal((3, 3))
        u = (X - X.mean(axis=0)) @ H.T
        eps = (H + H.T) / 2
        expected = V * (lam / 2 * np.trace(eps) ** 2 + mu * np.sum(eps * eps))
        assert abs(0.5 * u.ravel() @ K @ u.ravel() / expected - 1) < 1e-10


def affine_tensor(k, D, X):
    """C_xxxx, C_xxyy, C_xyxy of a cube kernel from its energy under small affine motions."""
    K = k.stiffness(D, np.zeros((1, 8, 3)))[0]
    V = k.point_volumes(D)[0, 0]

    def W(H):
        u = ((X - X.mean(axis=0)) @ np.asarray(H, float).T).ravel()
        return 0.5 * u @ K @ u / V
    xx = W([[1, 0, 0], [0, 0, 0], [0, 0, 0]]) * 2                   # 1/2 C_xxxx
    xy = W([[0, 0.5, 0], [0.5, 0, 0], [0, 0, 0]])                    # 2 C_xyxy eps_xy^2 (eps_xy = 1/2)
    xxyy = W([[1, 0, 0], [0, 1, 0], [0, 0, 0]]) - xx                  # C_xxxx + C_xxyy - C_xxxx
    return xx, xxyy, xy / 0.5


@CUBE
@pytest.mark.parametrize("nu", [0.0, 0.25, 0.45])
def test_baudet_lattice_obeys_the_cauchy_relation(nu):
    """Central springs: C_xxyy = C_xyxy whatever nu is given, so the lattice is isotropic only at
    nu = 1/4 (thesis section 3.4); at nu = 1/4 it is the isotropic material of E."""
    k = kernel("hexahedron", "mss")
    X = unit_cube()
    xxxx, xxyy, xyxy = affine_tensor(k, k.constants(X, E=E, nu=nu), X)
    assert abs(xxyy / xyxy - 1) < 1e-12
    isotropic = abs(xxxx / (xxyy + 2 * xyxy) - 1) < 1e-12
    assert isotropic == (nu == 0.25)
    if nu == 0.25:
        lam, mu = laws.lame_from_E_nu(E, nu)
        assert abs(xxyy / lam - 1) < 1e-12 and abs(xyxy / mu - 1) < 1e-12


@CUBE
def test_baudet_equals_hybmss_without_face_diagonals_at_nu_one_quarter():
    """Baudet's cube values (0.2 E l per edge, 0.3 E l per inner diagonal at nu = 1/4) are HybMSS-FD's."""
    X = random_cubes(3, seed=9)
    mss, hyb = kernel("hexahedron", "mss"), kernel("hexahedron", "hybmss")
    u = 0.05 * np.random.default_rng(0).standard_normal(X.shape)
    Km = mss.stiffness(mss.constants(X, E=E, nu=0.25), u)
    Kh = hyb.stiffness(hyb.constants(X, E=E, nu=0.25, A=0.0), u)
    assert relative_error(Kh, Km) < 1e-13
    k = springs.baudet(E, 0.25, 0.5)
    assert math.isclose(k["edge"], 0.2 * E * 0.5) and math.isclose(k["inner_diagonal"], 0.3 * E * 0.5)


@pytest.mark.parametrize("A, nu, k_c, k_f, k_e", [
    (0, 0.25, 1500.0, 0.0, 4000.0), (1, 0.25, 857.14, 857.14, 3142.86),
    (1, 0.0, 1071.43, 1071.43, 3928.57), (1, 0.499, 714.76, 714.76, 2620.79)])
def test_stiffness_rule_matches_the_thesis_table(A, nu, k_c, k_f, k_e):
    """SEED_DIGEST 5.2: lattice stiffnesses for l_e = 0.5 m, E = 10 kPa."""
    k = springs.hybmss_lattice(E, nu, A, 0.5)
    assert k["inner_diagonal"] == pytest.approx(k_c, abs=0.01)
    assert k["face_diagonal"] == pytest.approx(k_f, abs=0.01)
    assert k["edge"] == pytest.approx(k_e, abs=0.01)


@pytest.mark.parametrize("nu, kappa", [(0.0, -5000.0), (0.25, 0.0), (0.45, 27586.2), (0.49, 161073.8), (0.499, 1.661e6)])
def test_volume_modulus_matches_the_thesis(nu, kappa):
    assert springs.volume_modulus(E, nu) == pytest.approx(kappa, rel=1e-3, abs=1e-9)


@CUBE
def test_the_volume_force_restores():
    """The printed eq. 7.12 pushes an expanded cube further out; -grad W pulls it back: at nu = 0.499
    (kappa = 1.7 MPa against springs of ~1 kN/m) the wrong sign would win."""
    k = kernel("hexahedron", "hybmss")
    X = unit_cube()
    D = k.constants(X, E=E, nu=0.499, A=1.0)
    for s in (0.01, -0.01):
        u = (s * (X - X.mean(axis=0)))[None]
        assert float(np.sum(k.forces(D, u) * u.reshape(1, -1))) < 0
    # the volume term alone: the difference from the same cube at nu = 1/4 is kappa's energy
    V0 = k.point_volumes(D)[0, 0]
    u = (0.01 * (X - X.mean(axis=0)))[None]
    D_quarter = k.constants(X, E=E, nu=0.25, A=1.0)
    G = springs.shear_modulus(E, 0.499) / springs.shear_modulus(E, 0.25)    # the springs scale with G
    W_vol = k.energy(D, u)[0] - G * k.energy(D_quarter, u)[0]
    assert W_vol == pytest.approx(springs.volume_modulus(E, 0.499) / 2 * (1.01 ** 3 * V0 - V0) ** 2 / V0, rel=1e-12)


def test_van_gelder_edge_springs_on_a_triangle():
    """One triangle: each edge a spring of stiffness E A / l^2 (independent numpy sum)."""
    k = kernel("triangle", "mss")
    X = np.array([[0.0, 0.0], [2.0, 0.0], [0.5, 1.5]])
    x = X + np.array([[0.1, 0.0], [-0.05, 0.2], [0.0, -0.1]])
    (ax, ay), (bx, by) = X[1] - X[0], X[2] - X[0]
    area = 0.5 * abs(ax * by - ay * bx)
    expected = sum(0.5 * E * area / np.sum((X[j] - X[i]) ** 2)
                   * (np.linalg.norm(x[j] - x[i]) - np.linalg.norm(X[j] - X[i])) ** 2
                   for i, j in ((0, 1), (1, 2), (2, 0)))
    D = k.constants(X, E=E, nu=0.3)
    assert k.energy(D, (x - X)[None])[0] == pytest.approx(expected, rel=1e-13)


@CUBE
def test_homogenised_record_of_an_affine_motion():
    """For an affine motion the record's F is exactly I + H, det F the volume ratio of the cube,
    and at small strain its P is Hooke's stress (the virial equals the average stress)."""
    k = kernel("hexahedron", "hybmss")
    X = random_cubes(1, seed=5)
    nu = 0.35
    D = k.constants(X, E=E, nu=nu, A=1.0)
    H = 1e-6 * np.random.default_rng(4).standard_normal((3, 3))
    u = (X[0] @ H.T)[None]
    S = k.stress(D, u)[0, 0]
    at = k.stress_record["offsets"]
    F = S[at["F"]:at["F"] + 9].reshape(3, 3)
    assert np.abs(F - np.eye(3) - H).max() < 1e-14
    lam, mu = laws.lame_from_E_nu(E, nu)
    eps = (H + H.T) / 2
    sigma = lam * np.trace(eps) * np.eye(3) + 2 * mu * eps
    assert relative_error(S[at["P"]:at["P"] + 9].reshape(3, 3), sigma) < 1e-5
    assert S[at["W"]] == pytest.approx(k.energy(D, u)[0] / S[at["v"]], rel=1e-14)
    big = (X[0] @ (0.2 * np.eye(3)).T)[None]
    assert k.min_det_F(D, big)[0] == pytest.approx(1.2 ** 3, rel=1e-12)


@CUBE
def test_cells_that_are_not_cubes_are_refused():
    k = kernel("hexahedron", "hybmss")
    X = random_cubes(3, seed=1)
    X[1, 6] += 0.01 * np.abs(X[1]).max()
    with pytest.raises(DegenerateElementError, match="cubes") as err:
        k.constants(X, E=E, nu=0.3)
    assert list(err.value.elements) == [1]
    brick = unit_cube() * np.array([1.0, 1.0, 2.0])
    with pytest.raises(DegenerateElementError, match="cubes"):
        k.constants(brick, E=E, nu=0.3)


def test_parameters_are_checked():
    law = laws.get("hybmss")
    with pytest.raises(laws.LawError, match="A must be"):
        law.native_parameters(E=E, nu=0.3, A=-1.0)
    with pytest.raises(laws.LawError, match="no parameter B"):
        law.native_parameters(E=E, nu=0.3, B=1.0)
    with pytest.raises(laws.LawError, match="needs E and nu"):
        law.native_parameters(E=E)
    with pytest.raises(laws.LawError, match="nu"):
        law.native_parameters(E=E, nu=0.5)
    assert float(law.native_parameters(E=E, nu=0.3)["A"]) == 1.0
