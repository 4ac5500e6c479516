"""Cook's membrane benchmark (apps/reports/cook.py): the meshes, and locking measured as it is."""
from __future__ import annotations

import numpy as np
import pytest

from tensormass.apps.reports.accuracy import BENCHMARK_NAMES
from tensormass.apps.reports.cook import cook, cook_mesh

PANEL_AREA = 1440.0      # shoelace area of (0,0)-(48,44)-(48,60)-(0,44)


@pytest.mark.parametrize("element", ["quad", "triangle", "triangle6"])
def test_meshes_cover_the_panel_counter_clockwise(element):
    m = cook_mesh(element, 3)
    cells = m.cells[0].data
    p = m.points[:, :2]
    corners = cells[:, :3] if element != "quad" else cells
    area = 0.0
    for k in range(corners.shape[1]):            # shoelace of every cell at once
        a, b = p[corners[:, k]], p[corners[:, (k + 1) % corners.shape[1]]]
        area_k = 0.5 * (a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1])
        area = area + area_k
    assert np.all(area > 0) and area.sum() == pytest.approx(PANEL_AREA, rel=1e-12)
    if element == "triangle6":                    # midside nodes halfway along straight edges
        for (i, j), mid in zip(((0, 1), (1, 2), (2, 0)), (3, 4, 5)):
            assert np.allclose(p[cells[:, mid]], 0.5 * (p[cells[:, i]] + p[cells[:, j]]))
    assert np.allclose(np.sort(p[:, 0])[[0, -1]], [0.0, 48.0]) and np.isclose(p[:, 1].max(), 60.0)


@pytest.mark.heavy          # the report's quick run, 10 to 45 s cold: CI's heavy step
def test_linear_elements_lock_and_the_locking_free_formulations_do_not():
    assert "cook" in BENCHMARK_NAMES
    res = cook(True, lambda *_: None, {"levels": [4], "reference": 8, "nus": [1.0 / 3.0, 0.4999]})
    refs = res["references"]
    err = {(r["case"], r["element"], r["formulation"]): (r["value"] - refs[r["case"].split()[0]]) / refs[r["case"].split()[0]]
           for r in res["rows"]}
    assert all(r["value"] > 0 for r in res["rows"])           # the load bends the panel upwards
    for element, free in (("quad", "mean_dilatation"), ("triangle", "nodal_pressure")):
        assert err[("nu=0.4999", element, "displacement")] < -0.5                   # locked: far too stiff
        assert err[("nu=0.3333", element, "displacement")] > err[("nu=0.4999", element, "displacement")] + 0.1
        # the locking-free formulation loses (almost) nothing as nu -> 1/2
        assert err[("nu=0.4999", element, free)] > err[("nu=0.4999", element, "displacement")] + 0.1
    assert abs(err[("nu=0.4999", "triangle6", "mean_dilatation")]) < 0.02
    assert err[("nu=0.4999", "triangle6", "displacement")] < err[("nu=0.4999", "triangle6", "mean_dilatation")] - 0.1
    assert ("nu=0.4999 alternating", "triangle", "nodal_pressure") in err
    assert refs["nu=0.4999"] < refs["nu=0.3333"]
    # the reference converges: its change from half the resolution is small, Richardson lies beyond it
    for case, c in res["reference_checks"].items():
        assert abs(c["value"] - c["half"]) < 0.02 * c["value"]
        assert c["richardson"] is not None and c["richardson"] >= c["value"] > c["half"]
