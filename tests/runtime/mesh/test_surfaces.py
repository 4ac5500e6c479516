"""Surface generators (runtime/mesh/surfaces.py): counts, winding (every triangle's normal checked
against the analytic outward normal), areas against the analytic ones, no duplicated nodes, and
the argument checks."""
from __future__ import annotations

import numpy as np
import pytest

from tensormass.runtime.mesh import surfaces as S


def normals(points, triangles):
    p = points[triangles]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


def area(points, triangles):
    return 0.5 * np.linalg.norm(normals(points, triangles), axis=1).sum()


def centroids(points, triangles):
    return points[triangles].mean(axis=1)


def check_types(points, triangles):
    assert points.dtype == np.float64 and points.ndim == 2 and points.shape[1] == 3
    assert triangles.dtype == np.int64 and triangles.ndim == 2 and triangles.shape[1] == 3
    assert triangles.min() >= 0 and triangles.max() == len(points) - 1
    assert len(np.unique(triangles)) == len(points)          # every node used
    # no duplicated nodes (a seam or a subdivision numbering the same point twice)
    assert len(np.unique(np.round(points, 12), axis=0)) == len(points)
    n = np.linalg.norm(normals(points, triangles), axis=1)
    assert n.min() > 0


@pytest.mark.parametrize("pattern", ["right", "cross"])
def test_plate_counts_area_winding_order(pattern):
    p, t = S.plate(2.0, 0.5, 4, 3, pattern=pattern)
    check_types(p, t)
    assert p.shape == (20, 3) and t.shape == (24, 3)
    assert np.isclose(area(p, t), 1.0)
    assert (normals(p, t)[:, 2] > 0).all() and np.allclose(normals(p, t)[:, :2], 0)
    assert np.allclose(p[:5, 1], 0) and np.allclose(p[:5, 0], [0, 0.5, 1.0, 1.5, 2.0])   # row by row
    assert np.allclose(p[5], [0, 0.5 / 3, 0]) and np.allclose(p[:, 2], 0)


def test_plate_patterns_differ_in_diagonals():
    """"right": all diagonals the same way; "cross": the neighbouring cells' diagonals alternate."""
    def diagonals(t, p):
        d = []
        for tri in t:
            for i in range(3):
                e = p[tri[(i + 1) % 3]] - p[tri[i]]
                if abs(e[0]) > 1e-12 and abs(e[1]) > 1e-12:
                    d.append(np.sign(e[0] * e[1]))
        return np.array(d)
    p, t = S.plate(1.0, 1.0, 2, 2, "right")
    assert len(set(diagonals(t, p))) == 1
    p, t = S.plate(1.0, 1.0, 2, 2, "cross")
    assert set(diagonals(t, p)) == {-1.0, 1.0}


def test_strip_is_a_plate():
    p1, t1 = S.strip(10.0, 1.0, 20, 2)
    p2, t2 = S.plate(10.0, 1.0, 20, 2)
    assert np.array_equal(p1, p2) and np.array_equal(t1, t2)


@pytest.mark.parametrize("s", [0, 1, 3])
def test_icosphere_counts_radius_outward(s):
    p, t = S.icosphere(2.5, s)
    check_types(p, t)
    assert len(t) == 20 * 4 ** s and len(p) == 10 * 4 ** s + 2
    assert np.allclose(np.linalg.norm(p, axis=1), 2.5)
    assert (np.einsum("ij,ij->i", normals(p, t), centroids(p, t)) > 0).all()


def test_icosphere_area_converges_from_below():
    errors = [4 * np.pi - area(*S.icosphere(1.0, s)) for s in range(5)]
    assert all(e > 0 for e in errors)
    assert all(b < a / 3 for a, b in zip(errors, errors[1:]))   # O(h^2): / 4 per subdivision
    assert errors[-1] < 2e-3 * 4 * np.pi


def test_sphere_with_triangles_picks_smallest():
    assert len(S.sphere_with_triangles(1.0, 1280)[1]) == 1280
    assert len(S.sphere_with_triangles(1.0, 1281)[1]) == 5120
    assert len(S.sphere_with_triangles(1.0, 1)[1]) == 20


def test_sphere_with_triangles_10000_benchmark():
    p, t = S.sphere_with_triangles(1.0, 10_000)
    assert len(t) == 20480 and len(p) == 10242


def test_cylinder_area_outward():
    r, length = 0.7, 3.0
    p, t = S.cylinder(r, length, 48, 10)
    check_types(p, t)
    assert len(p) == 48 * 11 and len(t) == 2 * 48 * 10
    assert np.allclose(np.hypot(p[:, 1], p[:, 2]), r) and np.isclose(p[:, 0].max(), length)
    radial = centroids(p, t) * [0.0, 1.0, 1.0]
    assert (np.einsum("ij,ij->i", normals(p, t), radial) > 0).all()
    exact = 2 * np.pi * r * length
    assert 0 < exact - area(p, t) < 2e-2 * exact                # inscribed polygon: from below
    assert exact - area(*S.cylinder(r, length, 96, 10)) < (exact - area(p, t)) / 3


@pytest.mark.parametrize("hole", [None, 18.0])
def test_hemisphere_area_outward(hole):
    r = 10.0
    p, t = S.hemisphere(r, 16, 64, hole_degrees=hole)
    check_types(p, t)
    assert np.allclose(np.linalg.norm(p, axis=1), r) and p[:, 2].min() >= -1e-12
    assert np.isclose(p[:, 2].min(), 0.0, atol=1e-12)            # the equator is there
    assert (np.einsum("ij,ij->i", normals(p, t), centroids(p, t)) > 0).all()
    if hole is None:
        exact = 2 * np.pi * r ** 2
        assert np.allclose(p[0], [0, 0, r]) and len(p) == 1 + 16 * 64
    else:
        exact = 2 * np.pi * r ** 2 * np.cos(np.radians(hole))
        assert np.isclose(p[:, 2].max(), r * np.cos(np.radians(hole))) and len(p) == 17 * 64
    assert 0 < exact - area(p, t) < 5e-3 * exact


def test_hemisphere_hole_edge_is_a_circle_at_18_degrees():
    p, t = S.hemisphere(1.0, 4, 12, hole_degrees=18.0)
    top = p[:12]
    assert np.allclose(np.degrees(np.arccos(top[:, 2])), 18.0)


@pytest.mark.parametrize("call, word", [
    (lambda: S.plate(0.0, 1.0, 2, 2), "a"),
    (lambda: S.plate(1.0, float("nan"), 2, 2), "b"),
    (lambda: S.plate(1.0, 1.0, 0, 2), "nx"),
    (lambda: S.plate(1.0, 1.0, 2, 2.0), "ny"),
    (lambda: S.plate(1.0, 1.0, 2, 2, pattern="diag"), "pattern"),
    (lambda: S.icosphere(-1.0, 2), "radius"),
    (lambda: S.icosphere(1.0, -1), "subdivisions"),
    (lambda: S.icosphere(1.0, 9), "subdivisions"),
    (lambda: S.sphere_with_triangles(1.0, 0), "n_min"),
    (lambda: S.cylinder(1.0, 1.0, 2, 3), "n_around"),
    (lambda: S.cylinder(1.0, 0.0, 8, 3), "length"),
    (lambda: S.hemisphere(1.0, 0, 8), "n_rings"),
    (lambda: S.hemisphere(1.0, 2, 8, hole_degrees=90.0), "hole_degrees"),
    (lambda: S.hemisphere(1.0, 2, 8, hole_degrees=-5.0), "hole_degrees"),
    (lambda: S.strip(1.0, 1.0, True, 2), "nx"),
])
def test_bad_arguments_named(call, word):
    with pytest.raises(ValueError, match=rf"^{word} "):
        call()
