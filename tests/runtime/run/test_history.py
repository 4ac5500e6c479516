"""Per-step histories (runtime.run.history): bounded and aligned, every key, CSV, explicit energies."""
import csv

import numpy as np
import pytest

from tensormass.runtime.run import simulation as simulation_module
from tensormass.runtime.run.history import History, write_history_csv
from tensormass.runtime.scene.types import Fixed, Loads, Material, MeshSpec, Probe, Solver
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.run.simulation import Simulation

L, B, H = 1.2, 0.2, 0.2
RHO, G = 800.0, 9.81


def cantilever(law="hooke", cells=(6, 2, 2), **solver):
    return Scene(mesh=MeshSpec(generate="bar", size=(L, B, H), cells=cells, element="hexahedron"),
                 materials=[Material(law=law, quadrature="gauss2", E=1e6, nu=0.3, density=RHO)],
                 fixed=[Fixed(box=((-1, -1, -1), (1e-9, 1, 1)), name="clamp")],
                 loads=Loads(gravity=(0.0, 0.0, -G)), solver=Solver(**solver),
                 probes=[Probe("tip", (L, B / 2, H / 2)), Probe("mid", (L / 2, B / 2, H / 2))])


def test_decimated_rows_stay_aligned_with_their_steps(monkeypatch):
    monkeypatch.setattr(simulation_module, "HISTORY_MAX", 8)
    steps = 50
    s = Simulation(cantilever(steps=steps)).run()
    h = s.per_step
    n = len(h["step"])
    assert 4 <= n <= 8 and h["stride"] > 1 and all(k % h["stride"] == 0 for k in h["step"])
    for key in ("time", "newton", "linear", "wall", "elastic", "kinetic", "external_work"):
        assert len(h[key]) == n
    # a linear law under ramped gravity: every value is (its step / steps) x the final one
    lam = np.array(h["step"]) / steps
    weight = RHO * G * L * B * H
    force = np.array(h["reactions"]["clamp"]["force"])
    np.testing.assert_allclose(force[:, 2], lam * weight, rtol=1e-8)
    tip = np.array(h["probes"]["tip"])
    np.testing.assert_allclose(tip, np.outer(lam, s.probes["tip"]), rtol=0, atol=1e-10 * np.abs(tip).max())
    np.testing.assert_allclose(np.array(h["probes"]["mid"])[-1], lam[-1] * np.array(s.probes["mid"]), rtol=1e-8,
                               atol=1e-10 * abs(s.probes["mid"][2]))
    assert len(h["reactions"]["clamp"]["moment"]) == n and len(h["reactions"]["clamp"]["moment"][0]) == 3
    np.testing.assert_allclose(h["elastic"], lam**2 * s.energy, rtol=1e-8)


def test_every_key_and_unit_of_a_dynamic_history():
    s = Simulation(cantilever(law="stvk", cells=(4, 1, 1), kind="generalized_alpha", dt=1e-3, steps=4)).run()
    h = s.per_step
    assert h["step"] == [1, 2, 3, 4] and h["stride"] == 1
    assert h["time"] == pytest.approx([1e-3, 2e-3, 3e-3, 4e-3])
    assert sum(h["newton"]) == s.iterations["newton"] and sum(h["linear"]) == s.iterations["linear"]
    assert all(x > 0 for x in h["linear"]) and all(w > 0 for w in h["wall"])
    assert all(e is not None for key in ("elastic", "kinetic", "external_work") for e in h[key])
    assert set(h["probes"]) == {"tip", "mid"} and set(h["reactions"]) == {"clamp"}
    assert s.units == {"step": "1", "time": "s", "newton": "1", "linear": "1", "wall": "s", "elastic": "J",
                       "kinetic": "J", "external_work": "J", "probes": "m", "reactions.force": "N",
                       "reactions.moment": "N m"}
    assert np.isfinite(h["reactions"]["clamp"]["force"]).all()


def test_explicit_runs_report_their_elastic_energy_on_every_kept_row(monkeypatch):
    steps = 23                                      # not a multiple of EXPLICIT_ENERGY_EVERY
    scene = cantilever(law="stvk", cells=(4, 1, 1), kind="explicit", dt=2e-4, steps=steps)
    scene.output.every = 1000
    sim = Simulation(scene)
    s = sim.run()
    assert all(e is not None for e in s.per_step["elastic"]) and len(s.per_step["elastic"]) == steps
    assert s.per_step["elastic"][-1] == s.energy == sim.ctx.asm.energy(sim.ctx.u)
    # past the bound, the rows kept are still complete
    monkeypatch.setattr(simulation_module, "HISTORY_MAX", 4)
    s = Simulation(scene).run()
    assert s.per_step["stride"] > 1 and all(e is not None for e in s.per_step["elastic"])


def test_history_csv_round_trips(tmp_path):
    h = History(limit=100)
    for k in (1, 2):
        h.add({"step": k, "time": 0.1 * k, "newton": 2, "linear": 5 * k, "wall": 1e-3, "elastic": 1.0 / 3 * k,
               "kinetic": None, "external_work": 2.0 * k, "probes": {"tip": [0.1 * k, -0.2, 1e-17]},
               "reactions": {"clamp, left": {"force": [1.0, 2.0, 3.0 * k], "moment": [0.5, 0.25, 0.125]}}})
    per_step = h.to_dict()
    units = {"step": "1", "time": "s", "newton": "1", "linear": "1", "wall": "s", "elastic": "J", "kinetic": "J",
             "external_work": "J", "probes": "m", "reactions.force": "N", "reactions.moment": "N m"}
    path = tmp_path / "history.csv"
    write_history_csv(path, per_step, units)
    text = path.read_text()
    rows = list(csv.reader(text.splitlines()))
    assert rows[0] == ["step", "time [s]", "newton", "linear", "wall [s]", "elastic [J]", "kinetic [J]",
                       "external_work [J]", "probe.tip.ux [m]", "probe.tip.uy [m]", "probe.tip.uz [m]",
                       "reaction.clamp, left.Fx [N]", "reaction.clamp, left.Fy [N]", "reaction.clamp, left.Fz [N]",
                       "reaction.clamp, left.Mx [N m]", "reaction.clamp, left.My [N m]",
                       "reaction.clamp, left.Mz [N m]"]
    assert len(rows) == 3 and rows[1][0] == "1" and rows[2][3] == "10" and rows[1][6] == ""
    assert float(rows[2][5]) == 2.0 / 3 and float(rows[1][10]) == 1e-17 and float(rows[2][13]) == 6.0
    write_history_csv(tmp_path / "again.csv", per_step, units)
    assert (tmp_path / "again.csv").read_text() == text          # deterministic


def test_two_dimensional_csv_has_one_moment_column(tmp_path):
    h = History()
    h.add({"step": 1, "time": 1.0, "newton": 1, "linear": 1, "wall": 0.0, "elastic": 1.0, "kinetic": None,
           "external_work": 1.0, "probes": {}, "reactions": {"fixed[0]": {"force": [1.0, 2.0], "moment": 3.5}}})
    write_history_csv(tmp_path / "h.csv", h.to_dict(), {"reactions.moment": "N m/m"})
    header, row = (tmp_path / "h.csv").read_text().splitlines()
    assert header.endswith("reaction.fixed[0].Fx,reaction.fixed[0].Fy,reaction.fixed[0].Mz [N m/m]")
    assert row.endswith("1.0,2.0,3.5")


def test_an_interrupted_add_drops_the_row_whole():
    """Ctrl-C between two columns' appends: every column keeps the same length (the row is dropped),
    so the interrupted run's summary and CSV stay consistent."""
    from tensormass.runtime.run.history import History

    class Interrupting(list):
        def append(self, value):
            raise KeyboardInterrupt

    h = History()
    row = {"step": 1, "time": 0.1, "newton": 1, "linear": 1, "wall": 0.01, "elastic": 1.0}
    h.add(row)
    keys = list(h.columns)
    h.columns[keys[3]] = Interrupting(h.columns[keys[3]])
    with pytest.raises(KeyboardInterrupt):
        h.add({**row, "step": 2})
    assert {len(v) for v in h.columns.values()} == {1}
