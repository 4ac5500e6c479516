"""`tensormass report contact`: the rows against their closed forms on small meshes (the quick pool's
kernels: hexahedron neohookean gauss2, tetra hooke gauss1)."""
import json
import math

import pytest

from tensormass.apps.reports.contact import BOUNDS, hertz, impact, incline, run_contact, verdicts


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


@pytest.mark.heavy          # the octant at n = 8 (430 nodes), 3 s warm
def test_hertz_force_on_a_coarse_octant():
    row = hertz(8)
    assert row["status"] == "ok"
    assert 0 < row["indentation"] <= 0.02
    # n = 8: force 0.92 x Hertz (n = 12: 1.15, n = 16: 1.14): the coarse bound is 20 %
    assert abs(row["force_error"]) < 0.2


@pytest.mark.heavy          # the whole quick report, 6 s warm
def test_quick_report_writes_its_json(tmp_path):
    rows = run_contact(tmp_path, quick=True, progress=None)
    data = json.loads((tmp_path / "contact.json").read_text())
    assert [r["row"] for r in data["rows"]] == ["hertz", "friction_slide", "friction_stick", "impact"]
    assert len(data["checks"]) == len(verdicts(rows)) == 6
    assert all(math.isfinite(c["measured"]) for c in data["checks"])
