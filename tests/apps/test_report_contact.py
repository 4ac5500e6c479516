"""`tensormass report contact`: the rows against their closed forms on small meshes (the quick pool's
kernels: hexahedron neohookean gauss2, tetra10 hooke gauss2) and the committed Hertz octant."""
import json
import math

import meshio
import pytest

import numpy as np

from tensormass.apps.reports.contact import (BOUNDS, DELTA, HERTZ_MESH, R, hertz, impact, incline, run_contact,
                                             verdicts)
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


def test_the_committed_hertz_octant_is_the_ball_octant_refined_at_the_pole():
    mesh = meshio.read(HERTZ_MESH)
    points, cells = mesh.points, mesh.get_cells_type("tetra10")
    assert len(cells) and (tetra_volumes(points, cells[:, :4]) > 0).all()
    r = np.linalg.norm(points, axis=1)
    assert (points >= -1e-12).all() and (r <= R * (1 + 1e-9)).all()
    assert np.isclose(points, [0.0, 0.0, R], atol=1e-12).all(axis=1).any()          # the pole is a node
    # quadratic on the sphere: the middle of every edge whose ends lie on the sphere lies on it too
    edges = [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]
    on = np.abs(r - R) < 1e-9
    for k, (i, j) in enumerate(edges):
        both = on[cells[:, i]] & on[cells[:, j]]
        assert both.any() and np.allclose(r[cells[both, 4 + k]], R, atol=1e-6)
    # edges of about 0.25 a near the pole (a = sqrt(R delta)), far longer far from it
    a = math.sqrt(R * DELTA)
    lengths = np.linalg.norm(points[cells[:, 0]] - points[cells[:, 1]], axis=1)
    near = np.linalg.norm(points[cells[:, 0]] - [0.0, 0.0, R], axis=1) < a
    assert lengths[near].mean() < 0.4 * a and lengths[~near].max() > 8 * a


@pytest.mark.heavy          # 2 922 nodes, tetra10, about 9 s warm
def test_hertz_on_the_committed_octant():
    row = hertz()
    assert row["status"] == "ok" and row["mesh"] == HERTZ_MESH.name
    # measured: force +2.82 %, radius +0.96 %, force against the radius -0.09 %
    assert abs(row["force_error"]) < BOUNDS["hertz_force"]
    assert abs(row["radius_error"]) < BOUNDS["hertz_radius"]
    assert abs(row["force_radius_error"]) < 0.01
    # what is left is the finite ball's, growing like sqrt(delta / R) over the load steps (measured
    # error / sqrt(delta / R): 0.591, 0.550, 0.548, 0.564)
    errors, ratios = np.array(row["step_force_errors"]), np.array(row["finite_ball"])
    assert (np.diff(errors) > 0).all() and ratios.max() < 1.2 * ratios.min()


@pytest.mark.heavy          # the whole quick report, 6 s warm
def test_quick_report_writes_its_json(tmp_path):
    rows = run_contact(tmp_path, quick=True, progress=None)
    data = json.loads((tmp_path / "contact.json").read_text())
    assert [r["row"] for r in data["rows"]] == ["hertz", "friction_slide", "friction_stick", "impact"]
    assert len(data["checks"]) == len(verdicts(rows)) == 7
    assert all(math.isfinite(c["measured"]) for c in data["checks"])
