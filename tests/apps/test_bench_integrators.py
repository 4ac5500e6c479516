"""`tensormass bench integrators --quick`: runs through the CLI, writes JSON, and its numbers tell the schemes apart."""
import json

import pytest

from tensormass.apps.cli import main


@pytest.mark.heavy          # the benchmark's quick run, 10 to 35 s cold: CI's heavy step
def test_quick_integrator_bench_writes_json(tmp_path, capsys):
    out = tmp_path / "integrators.json"
    assert main(["bench", "integrators", "--quick", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "generalized_alpha rho_inf=1" in printed and "energy lost" in printed
    report = json.loads(out.read_text())
    assert report["quick"] is True and report["case"]["first_period"] > 0
    rows = {(r["label"], r["dt"]): r for r in report["results"]}
    assert {r["kind"] for r in report["results"]} == {"implicit_euler", "backward_euler", "generalized_alpha",
                                                      "explicit"}
    assert all(r["status"] == "ok" for r in report["results"])
    conserving = rows[("generalized_alpha rho_inf=1", 0.01)]
    assert abs(conserving["loss"]) < 1e-3
    assert rows[("implicit_euler", 0.01)]["loss"] > 0.2
    # more numerical damping as rho_inf goes down, all far below implicit Euler's
    losses = [rows[(f"generalized_alpha rho_inf={r}", 0.01)]["loss"] for r in ("1", "0.5", "0")]
    assert losses[0] < losses[1] < losses[2] < 0.1 * rows[("implicit_euler", 0.01)]["loss"]
    order = {r["label"]: r for r in report["order"]["results"]}
    assert len(order["backward_euler"]["errors"]) == 2 and order["backward_euler"]["ratios"][0] < 2.5
    for r in report["results"]:
        assert abs(r["loss_per_period"]) < 1 and r["steps_per_period"] > 0 and r["max_deviation"] >= abs(r["loss"])
