"""Generated kernels against finite differences, patch tests, rigid motions and Hooke at rest.

The kernels are the default backend's (C where a compiler is found; C = numba is
test_backends_agree.py's): a sample covering every element type, law and quadrature, and every
catalogue entry in CI's catalogue step (TENSORMASS_FULL_CATALOGUE=1, helpers.catalogue_selection).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

import tensormass as tm
from tensormass import laws
from tensormass.generator.catalogue import entries

from helpers import FULL_CATALOGUE, QUICK_KERNELS, QUICK_NUMBA_KERNELS, catalogue_selection, fd_gradient, law_inputs, random_elements, reference_nodes, relative_error

pytestmark = pytest.mark.catalogue

# discrete laws: test_discrete_kernels.py. The sample covers every element type, law and quadrature
# of the continuum catalogue with kernels of the quick pool (helpers.QUICK_KERNELS: compiled once for
# the suite); the Hooke kernels test_tangent_at_rest_equals_hooke compares with are in it too.
CONTINUUM = entries(law_names=laws.continuum_names(user=False))
SAMPLE = {"tetra_stable_neohookean_gauss1", "triangle_mooney_rivlin_gauss1", "tetra10_stvk_gauss2",
          "hexahedron_neohookean_gauss2", "wedge_hooke_gauss2", "pyramid_stvk_gauss2", "triangle6_stvk_exact",
          "quad_hooke_gauss3", "tetra_hgo_gauss1", "tetra_hgo2_gauss1"}
CATALOGUE = catalogue_selection(CONTINUUM, SAMPLE)
IDS = [e.name for e in CATALOGUE]
FINITE_STRAIN = ["stvk", "neohookean", "stable_neohookean", "mooney_rivlin", "hgo", "hgo2"]
E, NU = 3.0, 0.3


def test_the_sample_covers_every_element_law_and_quadrature():
    """The quick sample stands for the catalogue: every element type, law and quadrature of it, from
    the quick pool (CI's catalogue step runs every entry)."""
    for field in ("element", "law", "quadrature"):
        assert {getattr(e, field) for e in CATALOGUE} == {getattr(e, field) for e in CONTINUUM}, field
    if not FULL_CATALOGUE:
        assert SAMPLE <= QUICK_KERNELS, sorted(SAMPLE - QUICK_KERNELS)
        hooke = {f"{e.element}_hooke_{e.quadrature}" for e in CATALOGUE}
        assert hooke <= QUICK_KERNELS, sorted(hooke - QUICK_KERNELS)


def test_the_quick_pool_is_in_the_catalogue():
    from tensormass.generator.catalogue import catalogue
    names = {e.name for e in catalogue()}
    assert QUICK_KERNELS <= names, sorted(QUICK_KERNELS - names)
    assert QUICK_NUMBA_KERNELS <= QUICK_KERNELS


def kernel(entry):
    return tm.load_kernel(entry.element, entry.law, entry.quadrature)


def rotation(dim, angle=1.1, axis=(1.0, 2.0, 2.0)):
    if dim == 2:
        c, s = math.cos(angle), math.sin(angle)
        return np.array([[c, -s], [s, c]])
    n = np.asarray(axis) / np.linalg.norm(axis)
    Kx = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
    return np.eye(3) + math.sin(angle) * Kx + (1 - math.cos(angle)) * Kx @ Kx


def law_energy_density(law_name, dim):
    """W(F) of the law as a numpy function of a dim x dim F, by lambdify (independent of the kernels;
    W alone: its derivatives take sympy seconds on the fibre laws)."""
    from tensormass.generator.kinematics import F_symbols, embed_plane_strain
    law = laws.get(law_name)
    F = F_symbols(dim)
    flat = [s for row in F for s in row]
    symbols = law.symbols()
    W = law.W(embed_plane_strain(F), symbols)
    fn = sp.lambdify(flat + [symbols[p] for p in law.inputs], W, "math")
    params = laws.get(law_name).native_parameters(E=E, nu=NU, **law_inputs(law_name))
    return lambda F: fn(*np.ravel(F), *[float(params[p]) for p in laws.get(law_name).inputs])


@pytest.mark.parametrize("entry", CATALOGUE, ids=IDS)
def test_forces_and_stiffness_match_finite_differences(entry):
    k = kernel(entry)
    X = random_elements(entry.element, 4, seed=7, straight=entry.quadrature == "exact")
    D = k.constants(X, E=E, nu=NU, **law_inputs(entry.law))
    u = 0.04 * np.random.default_rng(3).standard_normal((len(X), k.n_dofs))
    f, K = k.forces_and_stiffness(D, u)
    h = 1e-6
    assert relative_error(f, -fd_gradient(lambda v: k.energy(D, v), u, h)) < 1e-6
    assert relative_error(K, -fd_gradient(lambda v: k.forces(D, v), u, h)) < 1e-6
    assert relative_error(K, np.swapaxes(K, 1, 2)) < 1e-14
    # The separate kernels compute exactly what the fused one does.
    assert relative_error(k.forces(D, u), f) < 1e-13
    assert relative_error(k.stiffness(D, u), K) < 1e-13


def affine_elements(name, n, seed):
    """Elements that are affine images of the reference: det J is constant, every rule integrates exactly."""
    rng = np.random.default_rng(seed)
    ref = reference_nodes(name)
    dim = ref.shape[1]
    out = []
    while len(out) < n:
        A = np.eye(dim) + 0.4 * rng.standard_normal((dim, dim))
        if np.linalg.det(A) > 0.3:
            out.append(ref @ A.T + rng.standard_normal(dim))
    return np.array(out)


def element_volume(name, X):
    """Volume of affine images of the reference element: |det A| x reference volume."""
    from tensormass.generator.elements import element
    ref = reference_nodes(name)
    dim = ref.shape[1]
    # Solve X = ref A^T + b for A from the first dim+1 affinely independent reference nodes.
    idx = {2: [0, 1, 3] if name == "quad" else [0, 1, 2],
           3: {"hexahedron": [0, 1, 3, 4], "wedge": [0, 1, 2, 3], "pyramid": [0, 1, 3, 4]}.get(name, [0, 1, 2, 3])}[dim]
    R = np.hstack([ref[idx], np.ones((dim + 1, 1))])
    vols = []
    for x in X:
        M = np.linalg.solve(R, x[idx])
        vols.append(abs(np.linalg.det(M[:dim].T)) * float(element(name).volume()))
    return np.array(vols)


@pytest.mark.parametrize("entry", CATALOGUE, ids=IDS)
def test_constant_strain_patch(entry):
    """A linear displacement field gives constant F: W_E = W(F) x volume, exactly."""
    k = kernel(entry)
    X = affine_elements(entry.element, 3, seed=11)
    D = k.constants(X, E=E, nu=NU, **law_inputs(entry.law))
    rng = np.random.default_rng(5)
    H = 0.05 * rng.standard_normal((k.dim, k.dim))
    u = np.einsum("ab,enb->ena", H, X) + rng.standard_normal(k.dim)
    expected = law_energy_density(entry.law, k.dim)(np.eye(k.dim) + H) * element_volume(entry.element, X)
    assert relative_error(k.energy(D, u), expected) < 1e-12
    if entry.law == "hooke":
        eps = (H + H.T) / 2
        lam, mu = laws.lame_from_E_nu(E, NU)
        sigma = lam * np.trace(eps) * np.eye(k.dim) + 2 * mu * eps   # plane strain: eps33 = 0
        assert relative_error(k.energy(D, u), 0.5 * np.sum(sigma * eps) * element_volume(entry.element, X)) < 1e-12


@pytest.mark.parametrize("entry", CATALOGUE, ids=IDS)
def test_rigid_motions(entry):
    k = kernel(entry)
    X = random_elements(entry.element, 3, seed=2, straight=entry.quadrature == "exact")
    D = k.constants(X, E=E, nu=NU, **law_inputs(entry.law))
    scale = np.abs(k.stiffness(D, np.zeros((len(X), k.n_dofs)))).max() * np.abs(X).max()
    translation = np.broadcast_to(np.arange(1.0, k.dim + 1), X.shape)
    assert np.abs(k.forces(D, translation)).max() < 1e-12 * scale
    R = rotation(k.dim)
    rotated = X @ R.T - X + 0.3
    f = k.forces(D, rotated)
    if entry.law in FINITE_STRAIN:
        assert np.abs(f).max() < 1e-11 * scale
    else:
        # Hooke's linear strain is not rotation invariant: a rotated body feels "ghost" forces.
        assert np.abs(f).max() > 1e-2 * scale


@pytest.mark.parametrize("entry", [e for e in CATALOGUE if e.law != "hooke"], ids=[e.name for e in CATALOGUE if e.law != "hooke"])
def test_tangent_at_rest_equals_hooke(entry):
    k = kernel(entry)
    hooke = tm.load_kernel(entry.element, "hooke", entry.quadrature)
    X = random_elements(entry.element, 3, seed=4, straight=entry.quadrature == "exact")
    zero = np.zeros((len(X), k.n_dofs))
    D = k.constants(X, E=E, nu=NU, **law_inputs(entry.law))
    f, K = k.forces_and_stiffness(D, zero)
    K_hooke = hooke.stiffness(hooke.constants(X, E=E, nu=NU), zero)
    assert np.abs(f).max() < 1e-12 * np.abs(K).max()      # stress free at rest
    assert relative_error(K, K_hooke) < 1e-12


@pytest.mark.parametrize("element,law", [("tetra", "neohookean"), ("triangle", "mooney_rivlin"),
                                         pytest.param("tetra", "mooney_rivlin", marks=pytest.mark.heavy)])
def test_inverted_elements_are_reported(element, law):
    k = tm.load_kernel(element, law, "gauss1")
    X = random_elements(element, 4, seed=1)
    D = k.constants(X, E=E, nu=NU)
    u = np.zeros_like(X)
    # element 2 turned inside out: F = -I in 3D, the mirror diag(1, -1) in 2D (where -I keeps det F = 1)
    mirror = -np.ones(k.dim) if k.dim == 3 else np.array([1.0, -1.0])
    u[2] = (X[2] - X[2].mean(axis=0)) * (mirror - 1.0)
    with pytest.raises(tm.InvertedElementError) as info:
        k.forces_and_stiffness(D, u)
    assert list(info.value.elements) == [2] and "element(s) 2" in str(info.value)
    for call in (k.energy, k.forces, k.stiffness):
        with pytest.raises(tm.InvertedElementError):
            call(D, u)
    assert list(k.inverted(D, u)) == [False, False, True, False]


def test_stable_neohookean_is_defined_for_inverted_elements():
    k = tm.load_kernel("tetra", "stable_neohookean", "gauss1")    # any element: the quick pool's
    X = random_elements("tetra", 2, seed=1)
    D = k.constants(X, E=E, nu=NU)
    u = -2.0 * (X - X.mean(axis=1, keepdims=True))
    f, K = k.forces_and_stiffness(D, u)
    assert np.all(np.isfinite(f)) and np.all(np.isfinite(K)) and np.all(np.isfinite(k.energy(D, u)))
    assert k.inverted(D, u).all()


def test_degenerate_and_inverted_rest_elements_are_refused():
    k = tm.load_kernel("tetra", "stvk", "gauss1")
    X = random_elements("tetra", 3, seed=1)
    X[1, 3] = X[1, 0]                                   # flat element
    X[2, [1, 2]] = X[2, [2, 1]]                         # inverted element
    with pytest.raises(tm.DegenerateElementError) as info:
        k.constants(X, E=E, nu=NU)
    assert list(info.value.elements) == [1, 2]


def test_bad_parameters_and_inputs_are_named():
    k = tm.load_kernel("tetra", "stvk", "gauss1")
    X = random_elements("tetra", 2, seed=1)
    with pytest.raises(laws.LawError, match="nu"):
        k.constants(X, E=1.0, nu=0.5)
    with pytest.raises(laws.LawError, match="E must be > 0"):
        k.constants(X, E=-1.0, nu=0.3)
    with pytest.raises(laws.LawError, match="NaN"):
        k.constants(X, E=float("nan"), nu=0.3)
    with pytest.raises(laws.LawError, match="kappa"):
        tm.load_kernel("triangle", "mooney_rivlin", "gauss1").constants(
            random_elements("triangle", 2, seed=1), C10=1.0, C01=1.0)
    with pytest.raises(tm.TensormassError, match="shape"):
        k.constants(X[:, :3], E=1.0, nu=0.3)
    D = k.constants(X, E=1.0, nu=0.3)
    with pytest.raises(tm.TensormassError, match="NaN"):
        k.forces(D, np.full((2, 12), np.nan))
    with pytest.raises(ValueError, match="unknown law"):
        tm.load_kernel("tetra", "rubber", "gauss1")
    with pytest.raises(ValueError, match="unknown element"):
        tm.load_kernel("tetra4", "stvk", "gauss1")


def test_native_parameters_and_per_element_values():
    k = tm.load_kernel("tetra", "neohookean", "gauss1")
    X = random_elements("tetra", 3, seed=1)
    lam, mu = laws.lame_from_E_nu(np.array([1.0, 2.0, 3.0]), 0.3)
    D1 = k.constants(X, E=[1.0, 2.0, 3.0], nu=0.3)
    D2 = k.constants(X, lam=lam, mu=mu)
    assert np.array_equal(D1, D2)
    u = 0.05 * np.random.default_rng(0).standard_normal((3, 12))
    W1 = k.energy(k.constants(X, E=1.0, nu=0.3), u)
    assert relative_error(k.energy(D1, u), W1 * np.array([1.0, 2.0, 3.0])) < 1e-13
