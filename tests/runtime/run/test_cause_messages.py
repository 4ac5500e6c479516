"""Messages that name the cause: an explicit step above the stable step is printed before the run and
named when an element inverts."""
from __future__ import annotations

import json

from tensormass.apps.cli import main

EXPLICIT = """
name = "explicit_bar"
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [4, 1, 1]
element = "hexahedron"
[[material]]
law = "neohookean"
quadrature = "gauss2"
E = 1.0e5
nu = 0.3
density = 1000.0
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "explicit"
dt = {dt}
steps = 200
backend = "c"
max_energy_growth = 1e12
"""


def _run(tmp_path, dt, capsys):
    path = tmp_path / "explicit.toml"
    path.write_text(EXPLICIT.format(dt=dt))
    rc = main(["run", str(path), "--json", str(tmp_path / "s.json")])
    out = capsys.readouterr()
    return rc, out.out, out.err, json.loads((tmp_path / "s.json").read_text())


def test_an_inverted_element_of_an_explicit_run_above_the_stable_step_names_dt(tmp_path, capsys):
    # stable step at rest 14.3 ms; dt = 20 ms inverts elements at step 12
    rc, out, err, data = _run(tmp_path, 0.02, capsys)
    assert rc == 3 and data["status"] == "failed"
    crit = data["stable_dt"]
    assert 0.01 < crit < 0.02
    assert "det F <= 0 (inverted element)" in data["message"]
    assert f"dt = 0.02 s exceeds the estimated stable step {crit:.3g} s" in data["message"]
    assert f"dt = 20.0 ms is above the stable step estimated at rest, {crit * 1e3:.1f} ms" in out.split("scene")[0]
    assert "stable step" in out and f"{crit * 1e3:.1f} ms estimated at rest" in out


def test_the_stable_step_is_printed_before_a_good_explicit_run(tmp_path, capsys):
    rc, out, err, data = _run(tmp_path, 0.002, capsys)
    assert rc == 0
    before = out.split("scene")[0]
    assert f"dt = 2.0 ms, stable step estimated at rest {data['stable_dt'] * 1e3:.1f} ms" in before
