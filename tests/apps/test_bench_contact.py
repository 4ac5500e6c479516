"""`tensormass bench contact --quick`: the pieces of a Newton iteration are timed with and without contact, the
whole steps against a glued tool, and the JSON holds them."""
from __future__ import annotations

import json

import pytest

from tensormass.apps.bench_contact import TARGET_RATIO, TARGET_SHARE, run_contact_bench


@pytest.mark.heavy          # the benchmark's quick run, ~10 s: CI's heavy step
def test_quick_bench_times_contact_against_no_contact(tmp_path):
    lines = []
    path = tmp_path / "contact.json"
    run_contact_bench(quick=True, json_path=path, repeats=1, progress=lines.append)
    report = json.loads(path.read_text())
    it = report["iteration"]
    assert 0 < it["active_vertices"] < it["surface_vertices"] and it["pairs"] > 0 and 0 < it["ccd_step"] <= 1
    ms = it["ms"]
    assert all(v > 0 for v in ms.values())
    assert abs(it["iteration_ms_without"] - (ms["assembly"] + ms["solve"] + ms["trial_energy"])) < 1e-9
    assert it["ratio"] == it["iteration_ms_with"] / it["iteration_ms_without"]
    # the broad phase counted at the run's rate: between none and one per Newton iteration
    contact = report["step"]["contact"]
    builds = contact["broad_phases"]["near"] + contact["broad_phases"]["swept"]
    assert 0 < builds and it["broad_phases_per_iteration"] == builds / contact["newton_iterations"] <= 1.5
    assert it["iteration_ms_with"] <= it["iteration_ms_with_broad_phase"] or it["broad_phases_per_iteration"] > 1
    assert 0 < contact["broad_phase_ccd_share"] < 1 and contact["broad_phase_s"] > 0
    step = report["step"]
    assert step["contact"]["status"] == step["glued_tool"]["status"] == "ok" and step["glued_nodes_in_box"] > 0
    assert step["glued_uz_m"] < 0 and step["ratio"] > 0
    assert report["targets"] == {"ratio": TARGET_RATIO, "broad_phase_ccd_share": TARGET_SHARE}
    assert any("ratio with / without" in line for line in lines) and any("glued tool" in line for line in lines)
