"""runtime.run.curves: history panels of a run summary, and the PNG they make.

Summaries in the session-6 format (probes, reactions, units) are built here; the summaries
of today's runtime (step/time/newton/wall/elastic/kinetic/external_work only) are real ones,
saved from runs of examples/cantilever_hexahedron.toml and examples/cantilever_swinging.toml
(40 steps) in tests/apps/data."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from tensormass.runtime.run.curves import history_groups, history_panels, plot_history
from tensormass.runtime.base.errors import TensormassError

DATA = Path(__file__).resolve().parents[2] / "apps" / "data"
PIL = pytest.importorskip("PIL.Image")


def full_summary(n=12, solver="generalized_alpha", dim=3):
    t = [0.01 * (i + 1) for i in range(n)]
    comp = 3 if dim == 3 else 2
    return {
        "format": "tensormass-summary/1", "name": "swing", "solver": solver,
        "units": {"step": "1", "time": "s", "newton": "1", "linear": "1", "wall": "s", "elastic": "J/m" if dim == 2 else "J",
                  "kinetic": "J", "external_work": "J", "probes": "m", "reactions.force": "N",
                  "reactions.moment": "N m"},
        "per_step": {
            "step": list(range(1, n + 1)), "time": t, "newton": [2 + i % 3 for i in range(n)],
            "linear": [5 + i % 4 for i in range(n)], "wall": [0.01] * n,
            "elastic": [math.sin(10 * x) ** 2 for x in t], "kinetic": [None] * n,
            "external_work": [None if i % 4 == 1 else 1.0 + i for i in range(n)],
            "probes": {"tip": [[0.001 * x, -0.01 * x, 0.02 * x][:comp] for x in t],
                       "mid": [None if i == 0 else [0.5, 0.25, 0.125][:comp] for i in range(n)]},
            "reactions": {"clamp": {"force": [[0.0, 1.0, 15.0 + x][:comp] for x in t],
                                    "moment": [[0.0, -9 * x, 1.0] if dim == 3 else [-9 * x] for x in t]}},
            "stride": 1}}


def test_panels_of_a_full_summary():
    x, xlabel, panels = history_panels(full_summary())
    assert xlabel == "time [s]" and np.allclose(x, [0.01 * (i + 1) for i in range(12)])
    assert [p["title"] for p in panels] == ["probe displacements", "energies", "reaction forces",
                                            "reaction moments", "solver"]
    by = {p["title"]: p for p in panels}
    assert by["probe displacements"]["ylabel"] == "displacement [m]"
    assert [c[0] for c in by["probe displacements"]["curves"]] == ["tip ux", "tip uy", "tip uz",
                                                                   "mid ux", "mid uy", "mid uz"]
    assert [c[0] for c in by["reaction forces"]["curves"]] == ["clamp Fx", "clamp Fy", "clamp Fz"]
    assert by["reaction moments"]["ylabel"] == "moment [N m]"
    assert np.allclose(dict(by["reaction forces"]["curves"])["clamp Fz"], 15.0 + x)
    # kinetic is None throughout: no curve; external work's None entries are gaps, not zeros
    energy = dict(by["energies"]["curves"])
    assert list(energy) == ["elastic", "external work"]
    work = energy["external work"]
    assert np.isnan(work[1::4]).all() and np.allclose(np.delete(work, np.s_[1::4]), 1.0 + np.delete(np.arange(12), np.s_[1::4]))
    mid = dict(by["probe displacements"]["curves"])["mid ux"]
    assert np.isnan(mid[0]) and np.allclose(mid[1:], 0.5)
    assert [c[0] for c in by["solver"]["curves"]] == ["Newton iterations", "linear iterations"]


def test_static_runs_plot_against_the_load_step_and_2d_moments_are_mz():
    s = full_summary(n=4, solver="static", dim=2)
    s["per_step"]["time"] = [0.25, 0.5, 0.75, 1.0]         # statics: the load factor
    x, xlabel, panels = history_panels(s, what="probes,reactions")
    assert xlabel == "load step" and list(x) == [1, 2, 3, 4]
    assert [c[0] for c in panels[0]["curves"]] == ["tip ux", "tip uy", "mid ux", "mid uy"]
    assert [c[0] for c in panels[2]["curves"]] == ["clamp Mz"]


def _check_png(path, width=1000):
    with PIL.open(path) as im:
        assert im.format == "PNG" and im.size[0] == width
        rgb = np.asarray(im.convert("RGB"))
    colours = np.unique(rgb.reshape(-1, 3), axis=0)
    assert len(colours) > 50, "a nearly blank plot"
    return im.size


def test_plot_writes_one_png_with_a_panel_per_group(tmp_path):
    path = tmp_path / "h.png"
    assert len(plot_history(full_summary(), path)) == 5
    w, h = _check_png(path)
    assert h == 115 + 5 * 250
    assert plot_history(full_summary(), path, what=["energy"]) == ["energies"]
    assert _check_png(path)[1] == 115 + 250
    assert sorted(os.listdir(tmp_path)) == ["h.png"]


@pytest.mark.parametrize("name,groups", [("summary_static_s5.json", ["energy", "solver"]),
                                         ("summary_dynamic_s5.json", ["energy", "solver"])])
def test_summaries_of_todays_runtime_still_plot(tmp_path, name, groups):
    summary = json.loads((DATA / name).read_text())
    assert history_groups(summary) == groups
    x, xlabel, panels = history_panels(summary)
    assert xlabel == ("load step" if summary["solver"] == "static" else "time [s]")
    assert len(x) == summary["steps_done"]
    assert dict(panels[0]["curves"])["elastic"][-1] == pytest.approx(summary["energy"])
    plot_history(summary, tmp_path / "old.png")
    _check_png(tmp_path / "old.png")


def test_bad_summaries_are_refused(tmp_path):
    path = tmp_path / "h.png"

    def refused(summary, match, **kw):
        with pytest.raises(TensormassError, match=match):
            plot_history(summary, kw.pop("path", path), **kw)
        assert not path.exists()

    refused({"format": "tensormass-summary/1", "per_step": None}, "no per-step history")
    refused([1, 2], "not a run summary")
    s = full_summary()
    s["per_step"]["elastic"] = s["per_step"]["elastic"][:-1]
    refused(s, r"per_step.elastic: 11 entries for 12 steps")
    s = full_summary()
    s["per_step"]["probes"]["tip"][3] = [1.0]
    refused(s, r"per_step.probes.tip\[3\]: expected a list of 3 numbers")
    refused(full_summary(), "unknown plot group\\(s\\) stress; known: probes, energy, reactions, solver",
            what="energy,stress")
    old = json.loads((DATA / "summary_static_s5.json").read_text())
    refused(old, "nothing to plot: the summary's per-step history has no probes, reactions data "
                 "\\(it has: energy, solver\\)", what="probes,reactions")
    refused(full_summary(), "must end in .png", path=tmp_path / "h.svg")
