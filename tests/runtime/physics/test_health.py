"""The run health monitor: every run ends trusted, with warnings, or stopped (issue #10, items 1-4).

Each scene here reproduces a run that used to end with exit 0 and a meaningless result.
"""
from __future__ import annotations

import numpy as np
import pytest

import tensormass as tm
from tensormass.runtime.run import simulation as simulation_module
from tensormass.runtime.base.errors import RunInterrupted, RunStopped, TensormassError
from tensormass.runtime.physics.health import min_det_F, safe_norm
from tensormass.runtime.physics.newton import Context
from tensormass.runtime.physics.integrators import stable_time_step
from tensormass.runtime.model.model import Model


def bar(law="stvk", kind="implicit_euler", gravity=-9.81, E=1e6, steps=10, dt=0.01, cells=(6, 1, 1),
        element="hexahedron", quadrature="gauss2", extra="", fixed=True, every=1):
    clamp = '[[fixed]]\nbox = [[-1e-9, -1, -1], [1e-9, 1, 1]]\n' if fixed else ""
    return tm.Scene.from_string(f"""
[mesh]
generate = "bar"
size = [1.0, 0.1, 0.1]
cells = {list(cells)}
element = "{element}"
[[material]]
law = "{law}"
quadrature = "{quadrature}"
E = {E}
nu = 0.3
density = 1000.0
{clamp}
[loads]
gravity = [0.0, 0.0, {gravity}]
[solver]
kind = "{kind}"
dt = {dt}
steps = {steps}
{extra}
[[probe]]
name = "tip"
point = [1.0, 0.05, 0.05]
[output]
every = {every}
""")


class Recorder:
    """A writer that keeps what the Simulation gives it, flags and stop marks included."""

    def __init__(self):
        self.frames, self.stopped = [], None

    def write_frame(self, step, time, points, displacement, fields, flag=None, **_):
        self.frames.append((step, np.array(displacement), flag))

    def mark_stopped(self, step, message):
        self.stopped = (step, message)

    def close(self):
        pass


def run_stopped(scene, **kw) -> RunStopped:
    with pytest.raises(RunStopped) as info:
        tm.Simulation(scene, **kw).run()
    return info.value


# --------------------------------------------------------------------------- item 1: blow-ups


@pytest.mark.parametrize("law", ["stvk", "stable_neohookean", "hooke"])
def test_soft_bar_under_huge_gravity_is_never_a_success(law):
    # the 1 m hexahedral bar, E = 1e3 Pa, 1000 g: energies of 1e12..1e22 J with exit 0
    stop = run_stopped(bar(law=law, E=1e3, gravity=-9810.0, steps=100))
    assert stop.status in ("diverged", "invalid") and stop.exit_code == 3
    s = stop.summary
    assert s.status == stop.status and s.message == str(stop) and s.steps_done < 100
    assert s.exit_code == 3 and s.to_dict()["exit_code"] == 3


def test_energy_growth_stops_an_explicit_blow_up():
    model = Model.from_scene(bar(law="hooke", kind="explicit", steps=1))
    dt = stable_time_step(Context(model))
    # displacement check out of the way: the energy balance alone must catch it
    stop = run_stopped(bar(law="hooke", kind="explicit", dt=2.5 * dt, steps=400,
                           extra="max_displacement = 1e9"))
    assert stop.status == "diverged"
    assert "energy balance" in str(stop) or "unstable" in str(stop)
    assert stop.summary.health["max_energy_growth"] > 0


def test_energy_check_alone_stops_growth_beyond_the_threshold():
    # the explicit integrator has its own blow-up test; this one guards the balance by itself
    from tensormass.runtime.physics.health import HealthMonitor
    model = Model.from_scene(bar(law="hooke", steps=1, extra="max_energy_growth = 10.0"))
    ctx = Context(model)
    monitor = HealthMonitor(ctx, dynamic=True, duration=1.0)
    scale = monitor.energy_scale
    assert scale > 0
    monitor.start(ctx, {"elastic": 0.0, "kinetic": 0.0, "external_work": 0.0})
    calm = monitor.check(ctx, 1, {"elastic": 9.0 * scale, "kinetic": 0.0, "external_work": 0.0})
    assert calm.stop is None and monitor.max_growth == pytest.approx(9.0)
    # work done by the loads pays for the energy: no growth of the balance
    paid = monitor.check(ctx, 2, {"elastic": 50.0 * scale, "kinetic": 0.0, "external_work": 50.0 * scale})
    assert paid.stop is None
    blown = monitor.check(ctx, 3, {"elastic": 5.0 * scale, "kinetic": 6.0 * scale, "external_work": 0.0})
    assert blown.stop is not None and "energy balance" in blown.stop


def test_energy_balance_is_recorded_for_explicit_runs():
    model = Model.from_scene(bar(law="hooke", kind="explicit", steps=1))
    dt = stable_time_step(Context(model))
    s = tm.Simulation(bar(law="hooke", kind="explicit", dt=0.5 * dt, steps=40)).run()
    assert s.status == "ok" and s.energy is not None          # explicit runs used to report None
    elastic = [e for e in s.per_step["elastic"] if e is not None]
    assert len(elastic) >= 4 and all(np.isfinite(elastic))
    assert s.health["max_energy_growth"] < 1.0


def test_growth_threshold_comes_from_the_scene():
    s = tm.Simulation(bar(steps=3)).run()
    assert s.health["limits"] == {"max_energy_growth": 100.0, "max_displacement": 10.0, "on_inversion": "warn"}
    s = tm.Simulation(bar(steps=3, extra='max_energy_growth = 5.0\nmax_displacement = 2.0\non_inversion = "stop"')).run()
    assert s.health["limits"] == {"max_energy_growth": 5.0, "max_displacement": 2.0, "on_inversion": "stop"}
    with pytest.raises(TensormassError, match="on_inversion"):
        bar(extra='on_inversion = "ignore"')
    with pytest.raises(TensormassError, match="max_displacement"):
        bar(extra="max_displacement = -1.0")


# --------------------------------------------------------------------------- item 2: invalid final states


def test_hooke_absurd_tip_displacement_is_stopped():
    # Hooke under a load far beyond its range reported a 326 km tip on a 1 m bar
    stop = run_stopped(bar(law="hooke", kind="static", E=1e3, gravity=-9.81, steps=1))
    assert stop.status == "diverged" and "body sizes" in str(stop)
    assert stop.summary.health["max_relative_displacement"] > 10


def test_inverted_final_state_is_invalid_and_frames_are_flagged():
    rec = Recorder()
    stop = run_stopped(bar(law="stvk", E=1e3, gravity=-98.1, steps=100), writer=rec)
    assert stop.status == "invalid" and "inverted" in str(stop)
    s = stop.summary
    assert s.health["inverted_final"] > 0 and s.health["min_det_F_final"] <= 0
    first = next(w for w in s.warnings if w["kind"] == "inverted")
    # frames after the first inversion carry the warning; none before it does
    for step, u, flag in rec.frames:
        assert (flag is not None) == (step >= first["step"]), (step, flag)
    assert rec.stopped is not None and "inverted" in rec.stopped[1]


def test_on_inversion_stop_stops_at_the_first_inverted_step():
    stop = run_stopped(bar(law="stvk", E=1e3, gravity=-98.1, steps=100, extra='on_inversion = "stop"'))
    assert stop.status == "diverged" and "on_inversion" in str(stop)
    assert stop.summary.steps_done < 100


def test_recovered_inversion_is_a_warning_not_a_failure():
    # a scrambled stable neo-Hookean cube inverts, then recovers: warnings, exit code 0
    from tensormass.apps.reports.stability_runs import scene_dict as _scene_dict
    scene = tm.Scene.from_dict(_scene_dict("stable_neohookean", "backward_euler", 0.05, 40, E=1e5, size=(1, 1, 1),
                                           cells=(2, 2, 2), gravity=False, fixed="bottom", rayleigh=(2.0, 0.0)))
    X = Model.from_scene(scene).mesh.points
    u0 = np.random.default_rng(1234).uniform(-0.5, 0.5, size=X.shape)
    u0[X[:, 2] <= 1e-12] = 0.0
    s = tm.Simulation(scene, u0=u0).run()
    assert s.status == "warnings" and s.exit_code == 0
    kinds = [w["kind"] for w in s.warnings]
    assert kinds[:2] == ["inverted", "recovered"] and s.health["inverted_final"] == 0


def test_min_det_F_agrees_with_the_kernels_inverted_flag():
    scene = bar(law="stvk", cells=(3, 1, 1), steps=1)
    model = Model.from_scene(scene)
    u = 0.4 * np.random.default_rng(0).standard_normal(model.n_dofs)
    low, cells = min_det_F(model, u)
    part = model.parts[0]
    flagged = part.kernel.inverted(part.D_active, model.element_displacements(part, u))
    assert np.array_equal(np.sort(part.cell_ids[flagged]), cells)
    assert (low <= 0) == bool(flagged.any())
    # an independent evaluation: F = I + sum_i u_i (x) G_qi with numpy, det per point, min per element
    k, ue = part.kernel, model.element_displacements(part, u)
    stride = 1 + k.n_dofs
    dets = [np.linalg.det(np.eye(3) + np.einsum("eia,eib->eab", ue,
                                                part.D[:, q * stride + 1:(q + 1) * stride].reshape(-1, k.n_nodes, 3)))
            for q in range(k.n_points)]
    reference = np.min(dets, axis=0)
    np.testing.assert_allclose(k.min_det_F(part.D, ue), reference, rtol=1e-12, atol=1e-12)
    assert low == pytest.approx(reference.min(), rel=1e-12)


# --------------------------------------------------------------------------- item 3: infinite residual


def test_gravity_beyond_float_range_is_refused_not_converged():
    # gravity 1e160: the residual and the load norm overflow to inf and inf <= tol * inf "converged"
    with pytest.raises(TensormassError, match="beyond what double precision"):
        tm.Simulation(bar(law="hooke", kind="static", gravity=-1e160, steps=1)).run()


def test_safe_norm_does_not_overflow():
    x = np.full(10, 1e200)
    assert safe_norm(x) == pytest.approx(1e200 * np.sqrt(10))
    assert np.isinf(safe_norm(np.array([1.0, np.inf]))) and np.isnan(safe_norm(np.array([np.nan])))
    assert safe_norm(np.zeros(3)) == 0.0


# --------------------------------------------------------------------------- item 4: explicit divergence


def test_explicit_divergence_never_writes_unflagged_absurd_frames():
    model = Model.from_scene(bar(law="hooke", kind="explicit", steps=1))
    dt = stable_time_step(Context(model))
    rec = Recorder()
    stop = run_stopped(bar(law="hooke", kind="explicit", dt=2.0 * dt, steps=400), writer=rec)
    assert stop.status == "diverged" and rec.stopped is not None
    size = model.size
    for step, u, flag in rec.frames:
        assert np.all(np.isfinite(u))
        spread = np.linalg.norm(u - u.mean(axis=0), axis=1).max()
        assert spread <= 10 * size                      # nothing beyond the monitor's limit was written
        low, cells = min_det_F(model, u.ravel())
        assert flag is not None or cells.size == 0      # inverted frames are flagged
    assert max(step for step, _, _ in rec.frames) <= stop.summary.steps_done


# --------------------------------------------------------------------------- interruption, history, off switch


def test_ctrl_c_during_the_steps_gives_the_summary_so_far():
    calls = []

    def progress(k, n):
        calls.append(k)
        if k == 3:
            raise KeyboardInterrupt

    with pytest.raises(RunInterrupted) as info:
        tm.Simulation(bar(steps=10), progress=progress).run()
    s = info.value.summary
    assert s.status == "interrupted" and s.exit_code == 130 and info.value.exit_code == 130
    assert s.steps_done == 3 and len(s.per_step["step"]) == 3


def test_history_is_bounded(monkeypatch):
    monkeypatch.setattr(simulation_module, "HISTORY_MAX", 8)
    s = tm.Simulation(bar(law="hooke", steps=50)).run()
    rows = s.per_step
    assert 4 <= len(rows["step"]) <= 8 and rows["stride"] > 1
    assert all(k % rows["stride"] == 0 for k in rows["step"])
    assert s.steps_done == 50 and s.energy is not None       # final values kept apart from the rows


def test_monitor_off_is_said_in_the_summary():
    s = tm.Simulation(bar(law="stvk", E=1e3, gravity=-98.1, steps=30, extra="health_monitor = false")).run()
    assert s.status == "warnings" and s.health["monitor"] is False
    assert s.warnings[0]["kind"] == "unchecked"


def test_a_healthy_run_is_ok_and_reports_its_health():
    s = tm.Simulation(bar(steps=5)).run()
    assert s.status == "ok" and s.message is None and s.warnings == [] and s.exit_code == 0
    h = s.health
    assert h["steps_checked"] == 5 and 0.9 < h["min_det_F"] <= 1.1 and h["inverted_final"] == 0
    assert 0 <= h["max_relative_displacement"] < 0.1 and h["energy_scale"] > 0
