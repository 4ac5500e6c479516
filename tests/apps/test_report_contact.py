"""`tensormass report contact`: the rows against their closed forms on small meshes (the quick pool's
kernels: hexahedron neohookean gauss2, tetra10 hooke gauss2)."""
import json
import math

import pytest

import numpy as np

from tensormass.apps.reports.contact import BOUNDS, R, hertz, impact, incline, octant10, run_contact, verdicts
from tensormass.runtime.mesh.solids import tetra_volumes


def test_block_slides_with_the_closed_form_acceleration():
    # one hexahedron, dt = 0.01 s, 20 steps: measured a = 3.2066 against g (sin 30 - 0.2 cos 30) = 3.2059
    row = incline(0.2, 30.0, cells=(1, 1, 1), dt=0.01, steps=20)
    assert row["status"] == "ok"
    assert abs(row["acceleration_error"]) < BOUNDS["slide"]


def test_block_sticks_with_the_smoothed_frictions_creep():
    # mu = 0.7 > tan 30 = 0.577: the mean speed is the mollifier's creep eps_v (1 - sqrt(1 - tan t / mu))
    # (measured 5.864e-4 against 5.82e-4 m/s), below eps_v and far below sliding (3.2 m/s^2 x 0.2 s)
    row = incline(0.7, 30.0, cells=(1, 1, 1), dt=0.01, steps=20)
    assert row["status"] == "ok"
    assert abs(row["mean_speed"]) < row["eps_v"]
    assert row["mean_speed"] == pytest.approx(row["creep_theory"], rel=0.05)
    assert abs(row["x_end"]) < 1e-3


def test_impact_keeps_the_momentum_and_the_bodies_separate():
    row = impact(cells=1, dt=0.005, steps=20)
    assert row["status"] == "ok"
    assert row["contact_steps"] > 0                            # they did touch
    assert row["momentum_drift"] < BOUNDS["momentum"]          # measured 7e-16 of m V
    assert row["gap_end"] > 0 and row["velocity_left"] < 0 < row["velocity_right"]


def test_octant10_puts_the_middles_of_sphere_edges_on_the_sphere():
    points, cells = octant10(2)
    assert cells.shape[1] == 10
    assert (tetra_volumes(points, cells[:, :4]) > 0).all()
    r = np.linalg.norm(points, axis=1)
    corners = np.unique(cells[:, :4])
    on_sphere = np.abs(r[corners] - R) < 1e-12
    middles = np.unique(cells[:, 4:])
    # every middle of an edge between two sphere corners is on the sphere; no other middle is
    edges = [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]
    sphere_corner = np.zeros(len(points), dtype=bool)
    sphere_corner[corners[on_sphere]] = True
    for k, (i, j) in enumerate(edges):
        both = sphere_corner[cells[:, i]] & sphere_corner[cells[:, j]]
        assert np.allclose(r[cells[both, 4 + k]], R, atol=1e-12)
        assert (r[cells[~both, 4 + k]] < R - 1e-6).all()
    assert len(middles) > 0
    # the symmetry planes keep their nodes (graded mesh)
    assert (points >= 0.0).all() and (np.abs(points) < 1e-14).any(axis=0).all()


@pytest.mark.heavy          # tetra10 octant at n = 4 (491 nodes), about 3 s warm
def test_hertz_force_on_a_coarse_quadratic_octant():
    row = hertz(4)
    assert row["status"] == "ok" and row["element"] == "tetra10"
    assert 0 < row["indentation"] <= 0.01
    # measured (grade 2.5, delta = 0.01 R, dhat = 1e-5): force error n = 4: +13.0 %, n = 6: +11.9 %,
    # n = 8: +8.2 %, n = 10: +4.4 %, n = 12: +6.6 % (linear tetra, graded n = 12: +24 %); the coarse
    # bound is 20 %
    assert abs(row["force_error"]) < 0.2
    assert abs(row["radius_error"]) < 0.25        # n = 4: -16 %, n = 6: +2.4 %


@pytest.mark.heavy          # the whole quick report, 6 s warm
def test_quick_report_writes_its_json(tmp_path):
    rows = run_contact(tmp_path, quick=True, progress=None)
    data = json.loads((tmp_path / "contact.json").read_text())
    assert [r["row"] for r in data["rows"]] == ["hertz", "friction_slide", "friction_stick", "impact"]
    assert len(data["checks"]) == len(verdicts(rows)) == 6
    assert all(math.isfinite(c["measured"]) for c in data["checks"])
