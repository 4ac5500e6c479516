"""Point probes (runtime/mesh/probes.py): interpolation in the containing cell, and the on-the-body rule."""
from __future__ import annotations

import numpy as np
import pytest

from tensormass.runtime.mesh.bars import BAR_ELEMENTS, generate_bar
from tensormass.runtime.mesh.probes import (PROBE_CELL_FRACTION, ProbeError, locate_point, shape_functions,
    surface_distance)
from tensormass import elements

SIZE = {3: (1.0, 0.3, 0.2), 2: (1.0, 0.3)}
CELLS = {3: (4, 2, 2), 2: (4, 2)}


def _bar(dim, element):
    mesh = generate_bar(SIZE[dim], CELLS[dim], element, (0.1,) * dim)
    # a non-affine but smooth map (straight edges stay straight for the linear types' nodes only)
    return mesh


def _points(dim, n=25, seed=0):
    rng = np.random.default_rng(seed)
    pts = 0.1 + rng.random((n, dim)) * np.array(SIZE[dim])
    corners = 0.1 + np.array(SIZE[dim]) * np.array([[1.0] * dim, [0.0] * dim])
    return np.vstack([pts, corners])            # on the surface too: the tip corner, the origin corner


@pytest.mark.parametrize("dim,element", [(d, e) for d in (3, 2) for e in BAR_ELEMENTS[d]])
def test_linear_fields_are_interpolated_exactly_in_every_element_type(dim, element):
    """Every element reproduces linear fields: the probe value equals the field at the point (a nearest
    node would miss it by a cell's gradient times the distance)."""
    mesh = _bar(dim, element)
    A = np.arange(1.0, dim * dim + 1).reshape(dim, dim)
    U = mesh.points @ A.T + 0.5
    for p in _points(dim):
        probe = locate_point(mesh, p, "p")
        np.testing.assert_allclose(probe.value(U), A @ p + 0.5, rtol=1e-10, atol=1e-12)
        assert probe.distance == 0.0 and probe.weights.sum() == pytest.approx(1.0)


@pytest.mark.parametrize("element,dim", [("tetra10", 3), ("triangle6", 2)])
def test_quadratic_fields_are_interpolated_exactly_by_quadratic_elements(element, dim):
    mesh = _bar(dim, element)
    f = lambda x: x[..., 0] ** 2 - 2.0 * x[..., 0] * x[..., 1] + 3.0 * x[..., -1] ** 2   # noqa: E731
    U = f(mesh.points)
    for p in _points(dim, seed=1):
        assert locate_point(mesh, p).value(U) == pytest.approx(float(f(p)), rel=1e-10, abs=1e-12)


def test_curved_quadratic_cells_are_inverted_by_newton():
    """A tetra10 with a bent midside node: the point mapped from known reference coordinates comes back."""
    el = elements.get("tetra10")
    ref = np.array([[float(c) for c in q] for q in el.nodes])
    X = ref * [2.0, 1.0, 1.5]
    X[4] += [0.0, -0.1, 0.05]                                           # midside node of edge 01, bent
    from tensormass.runtime.mesh.container import CellBlock, Mesh
    mesh = Mesh(X, [CellBlock("tetra10", np.arange(10)[None])])
    xi = np.array([0.3, 0.2, 0.25])
    N, _ = shape_functions("tetra10", xi[None])
    p = N[0] @ X
    probe = locate_point(mesh, p)
    np.testing.assert_allclose(probe.xi, xi, atol=1e-10)
    np.testing.assert_allclose(probe.weights, N[0], atol=1e-10)


def test_shape_function_gradients_match_finite_differences():
    rng = np.random.default_rng(3)
    for name in ("tetra", "tetra10", "hexahedron", "wedge", "pyramid", "triangle", "triangle6", "quad"):
        el = elements.get(name)
        xi = rng.random((4, el.dim)) * 0.3 + 0.1
        N, G = shape_functions(name, xi)
        assert np.allclose(N.sum(axis=1), 1.0), name
        h = 1e-6
        for r in range(el.dim):
            e = np.zeros(el.dim)
            e[r] = h
            fd = (shape_functions(name, xi + e)[0] - shape_functions(name, xi - e)[0]) / (2 * h)
            np.testing.assert_allclose(G[:, :, r], fd, atol=1e-7, err_msg=name)
        ref = np.array([[float(c) for c in q] for q in el.nodes])
        np.testing.assert_allclose(shape_functions(name, ref)[0], np.eye(el.n_nodes), atol=1e-12, err_msg=name)


def test_a_probe_off_the_body_is_refused_with_its_distance():
    mesh = generate_bar((1.0, 0.2, 0.2), (10, 2, 2), "hexahedron")
    with pytest.raises(ProbeError) as info:
        locate_point(mesh, (101.0, 0.1, 0.1), "tip")
    msg = str(info.value)
    assert msg.startswith("probe 'tip' at [101, 0.1, 0.1] is not on the body: it is 100 m outside it")
    assert "nearest node" in msg and "10% of the nearest cell's size" in msg
    # just outside the side face, farther than the tolerance (10 % of a 0.1 x 0.1 x 0.1 cell = 0.0173 m)
    with pytest.raises(ProbeError, match=r"is 0\.03 m outside"):
        locate_point(mesh, (0.55, 0.1, 0.23), "side")
    # 2D: a segment distance
    mesh2 = generate_bar((1.0, 0.2), (4, 2), "triangle")
    with pytest.raises(ProbeError, match=r"is 0\.5 m outside"):
        locate_point(mesh2, (0.5, 0.7), "up")
    assert surface_distance(mesh2, np.array([0.5, 0.1])) == pytest.approx(0.1)


def test_a_probe_within_the_tolerance_reads_the_nearest_point_of_the_body():
    mesh = generate_bar((1.0, 0.2, 0.2), (10, 2, 2), "tetra")
    U = mesh.points[:, [0]] * [0.0, 0.0, -1.0]                       # u_z = -x
    tol = PROBE_CELL_FRACTION * np.sqrt(3) * 0.1
    near = locate_point(mesh, (1.0 + 0.5 * tol, 0.1, 0.1), "near")
    assert 0 < near.distance <= tol
    assert near.value(U)[2] == pytest.approx(-1.0)                  # the value at the tip face
    with pytest.raises(ProbeError):
        locate_point(mesh, (1.0 + 1.5 * tol, 0.1, 0.1), "far")


def test_the_model_reports_interpolated_probes_and_refuses_points_off_the_body():
    from tensormass.runtime.model.model import Model
    from tensormass.runtime.scene.types import Material, Probe
    mesh = generate_bar((1.0, 0.2, 0.2), (4, 1, 1), "tetra10")
    mat = [Material(law="hooke", E=1e6, nu=0.3)]
    model = Model(mesh, mat, probes=[Probe("mid", (0.3, 0.05, 0.15))])
    u = (mesh.points ** 2 @ np.diag([1.0, 2.0, 3.0])).ravel()       # quadratic: exact in tetra10
    np.testing.assert_allclose(model.probe_values(u)["mid"], [0.09, 0.005, 0.0675], rtol=1e-10)
    with pytest.raises(ProbeError, match=r"^probe 'far' at \[5, 0\.1, 0\.1\] is not on the body: it is 4 m outside"):
        Model(mesh, mat, probes=[Probe("far", (5.0, 0.1, 0.1))])
