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


def test_linear_elements_lock_and_triangle6_does_not():
    assert "cook" in BENCHMARK_NAMES
    res = cook(True, lambda *_: None, {"levels": [4], "reference": 8, "nus": [1.0 / 3.0, 0.4999]})
    err = {(r["case"], r["element"]): (r["value"] - res["references"][r["case"]]) / res["references"][r["case"]]
           for r in res["rows"]}
    assert all(r["value"] > 0 for r in res["rows"])           # the load bends the panel upwards
    for element in ("quad", "triangle"):
        assert err[("nu=0.4999", element)] < -0.5                   # locked: far too stiff
        assert err[("nu=0.3333", element)] > err[("nu=0.4999", element)] + 0.1
    assert abs(err[("nu=0.4999", "triangle6")]) < 0.25
    assert res["references"]["nu=0.4999"] < res["references"]["nu=0.3333"]
