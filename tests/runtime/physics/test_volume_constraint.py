"""Volume constraint (runtime/physics/volume_constraint.py): the volume of icospheres against 4/3 pi r^3,
the closed/oriented surface checks, the exact gradient against central differences, the cubic's
coefficients against the volume at four lam values, the projection after deformations (with held
nodes and held components bit for bit unchanged), its analytic case (radial directions on a
sphere), its errors, and the penalty forces against the energy's derivative."""
from __future__ import annotations

import re

import numpy as np
import pytest

from tensormass.runtime.mesh import surfaces as S
from tensormass.runtime.physics.volume_constraint import (VolumeConstraint, VolumeConstraintError,
    check_closed_surface)

# unit tetrahedron 0, e1, e2, e3, wound outward
TET_POINTS = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
TET = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def sphere(s=2, r=1.0):
    p, t = S.icosphere(r, s)
    return p, t, VolumeConstraint(t, p)


def rel_error(c, x):
    return abs(c.volume(x) - c.rest_volume) / c.rest_volume


def test_tetrahedron_volume():
    c = VolumeConstraint(TET, TET_POINTS)
    assert np.isclose(c.rest_volume, 1 / 6)
    assert np.isclose(c.volume(TET_POINTS + [3.0, -2.0, 5.0]), 1 / 6)     # closed: translation-free


def test_icosphere_volume_converges_from_below():
    r = 1.7
    exact = 4 / 3 * np.pi * r ** 3
    errors = []
    for s in range(5):
        p, t = S.icosphere(r, s)
        errors.append(exact - VolumeConstraint(t, p).rest_volume)
    assert all(e > 0 for e in errors)
    assert all(b < a / 3 for a, b in zip(errors, errors[1:]))
    assert errors[-1] < 3e-3 * exact


def test_flipped_triangle_named():
    p, t = S.icosphere(1.0, 1)
    k = 17
    bad = t.copy()
    bad[k] = bad[k, ::-1]
    with pytest.raises(ValueError, match="edge") as info:
        VolumeConstraint(bad, p)
    a, b, tri = map(int, re.search(r"edge \((\d+), (\d+)\) of triangle (\d+)", str(info.value)).groups())
    assert {a, b} <= set(t[k])                       # an edge of the flipped triangle
    assert {a, b} <= set(bad[tri]) and "wound oppositely" in str(info.value)


def test_open_surfaces_refused():
    p, t = S.icosphere(1.0, 1)
    with pytest.raises(ValueError, match="boundary"):
        VolumeConstraint(t[1:], p)
    with pytest.raises(ValueError, match="not a closed"):
        VolumeConstraint(*reversed(S.cylinder(1.0, 2.0, 8, 2)))
    with pytest.raises(ValueError, match="not a closed"):
        VolumeConstraint(*reversed(S.hemisphere(1.0, 3, 8)))
    # two spheres glued along nothing but sharing a triangle's edge set twice -> same-direction edges
    with pytest.raises(ValueError, match="wound oppositely|more than two"):
        check_closed_surface(np.concatenate([t, t]))


def test_degenerate_and_inward_refused():
    with pytest.raises(ValueError, match="repeats a node"):
        check_closed_surface(np.array([[0, 1, 1], [0, 1, 2]]))
    with pytest.raises(ValueError, match="inward-oriented"):
        VolumeConstraint(TET[:, ::-1], TET_POINTS)
    with pytest.raises(ValueError, match="outside"):
        VolumeConstraint(TET, TET_POINTS[:3])
    with pytest.raises(ValueError, match="integer"):
        VolumeConstraint(TET.astype(float), TET_POINTS)


def deformed(p, seed=0, scale=1.1, noise=0.05):
    rng = np.random.default_rng(seed)
    return scale * p + noise * rng.standard_normal(p.shape)


def test_gradient_against_central_differences():
    p, t, c = sphere(1)
    x = deformed(p)
    g = c.vertex_normals(x)
    h = 1e-6
    fd = np.zeros_like(x)
    for i in range(len(x)):
        for k in range(3):
            e = np.zeros_like(x)
            e[i, k] = h
            fd[i, k] = (c.volume(x + e) - c.volume(x - e)) / (2 * h)
    assert np.allclose(g, fd, rtol=0, atol=1e-8 * np.abs(g).max())
    # sum of the gradients = 0 (translation) and sum x_i . g_i = 3 V (homogeneous of degree 3)
    assert np.allclose(g.sum(axis=0), 0, atol=1e-12)
    assert np.isclose(np.einsum("ij,ij->", x, g), 3 * c.volume(x))


def test_cubic_coefficients_against_volume_at_four_lams():
    p, t, c = sphere(2)
    rng = np.random.default_rng(3)
    x, d = deformed(p), rng.standard_normal(p.shape)
    coefficients = c.cubic_coefficients(x, d)
    lams = np.array([-0.7, -0.2, 0.3, 1.1])
    volumes = [c.volume(x + lam * d) for lam in lams]
    fitted = np.linalg.solve(np.vander(lams, 4, increasing=True), volumes)
    assert np.allclose(coefficients, fitted, rtol=1e-9, atol=1e-10 * np.abs(fitted).max())
    assert np.isclose(coefficients[0], c.volume(x))
    assert np.isclose(coefficients[1], np.einsum("ij,ij->", c.vertex_normals(x), d))


@pytest.mark.parametrize("seed, scale", [(0, 1.1), (1, 0.85), (2, 1.0)])
def test_project_restores_volume_after_noise(seed, scale):
    p, t, c = sphere(3)
    x = deformed(p, seed, scale, noise=0.03)
    x_new, lam = c.project(x)
    assert rel_error(c, x_new) <= 1e-12
    assert np.allclose(x_new, x + lam * c.vertex_normals(x), atol=1e-14)
    assert (lam < 0) == (c.volume(x) > c.rest_volume)


def test_project_squeezed_between_planes_holds_clamped_nodes():
    r = 2.0
    p, t, c = sphere(3, r)
    x = deformed(p, 4, 1.0, noise=0.01 * r)
    clamped = np.abs(x[:, 2]) > 0.8 * r
    x[:, 2] = np.clip(x[:, 2], -0.8 * r, 0.8 * r)
    assert clamped.sum() > 20 and c.volume(x) < c.rest_volume
    x_new, lam = c.project(x, free=~clamped)
    assert rel_error(c, x_new) <= 1e-12 and lam > 0
    assert np.array_equal(x_new[clamped], x[clamped])             # bit for bit
    assert np.abs(x_new[clamped, 2]).max() <= 0.8 * r
    # the clamped nodes may slide on the planes: a component mask holding z only
    mask = np.ones_like(x)
    mask[clamped, 2] = 0.0
    x_slide, lam_slide = c.project(x, free=mask)
    assert rel_error(c, x_slide) <= 1e-12
    assert np.array_equal(x_slide[clamped, 2], x[clamped, 2])
    assert not np.array_equal(x_slide[clamped, :2], x[clamped, :2])
    assert 0 < lam_slide < lam                                    # more freedom, a smaller move


def test_project_with_given_directions_is_analytic_on_a_sphere():
    """D_i = x_i (radial): V(x + lam x) = (1 + lam)^3 V(x), one real root (V0 / V)^(1/3) - 1."""
    p, t, c = sphere(3)
    x = 1.3 * p
    x_new, lam = c.project(x, directions=x)
    assert np.isclose(lam, 1 / 1.3 - 1, rtol=1e-13)
    assert np.allclose(x_new, p, atol=1e-13)


def test_project_picks_smallest_real_root():
    """Directions with three real roots: the one of smallest magnitude is returned."""
    p, t, c = sphere(2)
    rng = np.random.default_rng(7)
    x, d = deformed(p, 5, 1.02, 0.01), rng.standard_normal(p.shape)
    coefficients = c.cubic_coefficients(x, d)
    coefficients[0] -= c.rest_volume
    roots = np.roots(coefficients[::-1])
    real = roots[np.abs(roots.imag) < 1e-9].real
    _, lam = c.project(x, directions=d)
    assert np.isclose(lam, real[np.argmin(np.abs(real))], rtol=1e-10)


def test_project_at_rest_and_large_mesh():
    p, t, c = sphere(5)          # 20 480 triangles: the 10 000-triangle benchmark size
    x_new, lam = c.project(p)
    assert lam == 0.0 and np.array_equal(x_new, p)
    x_new, lam = c.project(deformed(p, 6, 0.97, 0.002))
    assert rel_error(c, x_new) <= 1e-12


def test_project_errors():
    p, t, c = sphere(1)
    x = 1.1 * p
    with pytest.raises(VolumeConstraintError, match="all directions are zero"):
        c.project(x, free=np.zeros(len(p), dtype=bool))
    with pytest.raises(VolumeConstraintError, match="do not change the volume"):
        c.project(x, directions=np.tile([1.0, 2.0, -0.5], (len(p), 1)))   # a translation
    with pytest.raises(ValueError, match="0/1"):
        c.project(x, free=np.full(len(p), 0.5))
    with pytest.raises(ValueError, match="shape"):
        c.project(x, free=np.ones(3))
    with pytest.raises(ValueError, match="shape"):
        c.project(x[:-1])
    assert issubclass(VolumeConstraintError, RuntimeError)


def test_project_no_real_root():
    """Tetrahedron scaled by 2 (V = 8 V0); moving e1 by lam e2 and e2 by -lam e1 gives
    V = 8 (4 + lam^2) / 6 / 4 > V0 for every lam: a quadratic without a real root."""
    c = VolumeConstraint(TET, TET_POINTS)
    x = 2.0 * TET_POINTS
    d = np.zeros((4, 3))
    d[1], d[2] = [0, 1, 0], [-1, 0, 0]
    coefficients = c.cubic_coefficients(x, d)
    assert np.allclose(coefficients, [8 / 6, 0, 2 / 6, 0])
    with pytest.raises(VolumeConstraintError, match="no real lam"):
        c.project(x, directions=d)


def test_penalty_forces():
    p, t, c = sphere(1)
    k = 250.0
    at_rest = c.pressure_penalty_forces(p, k)
    assert np.allclose(at_rest.forces, 0) and at_rest.energy == 0.0
    assert np.isclose(at_rest.stiffness_scale, k / c.rest_volume)
    x = deformed(p, 8)
    pf = c.pressure_penalty_forces(x, k)
    rng = np.random.default_rng(9)
    v = rng.standard_normal(x.shape)
    h = 1e-6
    de = (c.pressure_penalty_forces(x + h * v, k).energy - c.pressure_penalty_forces(x - h * v, k).energy) / (2 * h)
    assert np.isclose(-np.einsum("ij,ij->", pf.forces, v), de, rtol=1e-7)
    # at V = V0 the stiffness is the rank-one term: -df/dx v = scale g (g . v)
    df = (c.pressure_penalty_forces(p + h * v, k).forces - c.pressure_penalty_forces(p - h * v, k).forces) / (2 * h)
    g = at_rest.gradient
    assert np.allclose(-df, at_rest.stiffness_scale * g * np.einsum("ij,ij->", g, v), rtol=1e-6, atol=1e-8)
    with pytest.raises(ValueError, match="k must be"):
        c.pressure_penalty_forces(x, -1.0)
