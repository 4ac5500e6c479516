"""`tensormass report squeeze --quick`: it runs, writes its files, and the models keep the order measured."""
import csv
import json
import math

import pytest

from tensormass.apps.reports.squeeze import COLUMNS, MODELS, run_squeeze


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("squeeze")
    return out, {r["model"]: r for r in run_squeeze(out, quick=True, progress=None)}


@pytest.mark.heavy          # the report's quick run, 10 to 45 s cold: CI's heavy step
def test_quick_report_writes_its_csv_and_json(quick):
    out, rows = quick
    with open(out / "squeeze.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert [r["model"] for r in table] == [m[0] for m in MODELS]
    assert list(table[0].keys()) == list(COLUMNS)
    data = json.loads((out / "squeeze.json").read_text())
    assert data["thesis_percent"] == {"shell_constraint": 0.0, "fem_hooke": 1.9, "mss": 12.5}
    assert [r["model"] for r in data["rows"]] == [m[0] for m in MODELS]
    assert all(r["steps"] == data["case"]["ramp"] / data["case"]["dt"] + data["case"]["hold"] / data["case"]["dt"]
               for r in data["rows"])


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_the_constraint_keeps_the_volume_and_the_others_lose_some(quick):
    _, rows = quick
    assert abs(rows["shell_constraint"]["volume_loss_percent"]) < 1e-6          # |1 - V/V0| < 1e-8
    assert abs(rows["shell_constraint"]["max_volume_loss_percent"]) < 1e-6
    # the velocities are projected too, so the constraint pumps no kinetic energy in: measured on the
    # quick case, 4.2 J against 0.63 J without the constraint (a stiffer, bulging ball still ringing
    # after its short hold); positions-only projection gave 21 J (100 J at dt = 0.02)
    assert rows["shell_constraint"]["kinetic_end"] < 10 * rows["shell"]["kinetic_end"]
    for name in ("shell", "fem_hooke", "fem_neohookean", "fem_neohookean_contact", "mss"):
        assert rows[name]["volume_loss_percent"] > 0.1, name
    for name, row in rows.items():
        assert row["status"] in ("ok", "warnings") or name == "mss", (name, row["message"])
        assert math.isfinite(row["volume_end"]) and row["steps"] > 0


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_ordering_measured_on_the_quick_meshes(quick):
    """The full run's order holds on the quick meshes: neo-Hookean loses least, linear FEM more
    (the linear strain misses the quadratic terms of the volume change), MSS and the unconstrained
    shell most; the linear FEM's own volume measure tr(grad u) sees far less than it loses."""
    _, rows = quick
    loss = {k: r["volume_loss_percent"] for k, r in rows.items()}
    assert loss["fem_neohookean"] < loss["fem_hooke"] < loss["mss"]
    assert loss["fem_hooke"] < loss["shell"]
    assert abs(rows["fem_hooke"]["linear_dv_percent"]) < 0.5 * loss["fem_hooke"]
    assert rows["fem_neohookean"]["equator_bulge"] > 0 and rows["fem_hooke"]["equator_bulge"] > 0
    assert rows["mss"]["equator_bulge"] < rows["fem_hooke"]["equator_bulge"]


@pytest.mark.heavy          # the report's quick run (its module fixture)
def test_plates_in_contact_squeeze_the_ball_as_glued_ones_do(quick):
    """Frictionless plates in contact instead of glued caps: about the same volume lost and plate
    force (quick meshes, measured: 0.433 % against 0.437 %, -1 159 N against -1 107 N)."""
    _, rows = quick
    glued, contact = rows["fem_neohookean"], rows["fem_neohookean_contact"]
    assert contact["status"] == "ok"
    assert abs(contact["volume_loss_percent"] / glued["volume_loss_percent"] - 1.0) < 0.1
    assert contact["top_force"] < 0 and abs(contact["top_force"] / glued["top_force"] - 1.0) < 0.15
