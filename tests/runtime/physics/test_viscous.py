"""Viscoelasticity with Prony branches (laws/viscous.py, runtime.physics.viscous): the step kernel
against finite differences and objectivity, relaxation and creep of a cube against the closed
forms of the linear Prony model, the history's prepare/commit rules, and the scene's checks."""
import numpy as np
import pytest

import tensormass as tm
from tensormass.runtime.base.errors import SceneError
from tensormass.runtime.run.simulation import Simulation
from tensormass.runtime.scene.scene import Scene

from helpers import ROLLERS_TOML, UNIT_CUBE_TOML, fd_gradient, random_elements, relative_error

E, NU = 3000.0, 0.3
BRANCHES = [(0.5, 2.0), (0.05, 1.0)]          # (tau s, beta): long-term E, instantaneous 4 E
H, STEPS = 0.02, 50                            # s per step, steps (1 s)


def test_the_step_kernel_is_the_derivative_of_its_energy_and_objective():
    k = tm.load_kernel("tetra", "neohookean_viscous", "gauss1")
    assert k.point_fields["inputs"] == 1 + 4 * 3
    X = random_elements("tetra", 5, seed=2)
    D = k.constants(X, E=3.0, nu=0.3)
    start = k.point_fields["inputs"]
    assert np.all(D[:, start] == 1.0) and np.all(D[:, start + 1:start + 7] == 0.0)     # at rest: g = 1, H = 0
    base = tm.load_kernel("tetra", "neohookean", "gauss1")
    u = 0.1 * np.random.default_rng(0).standard_normal((5, 12))
    assert relative_error(k.forces(D, u), base.forces(base.constants(X, E=3.0, nu=0.3), u)) < 1e-13
    rng = np.random.default_rng(1)
    D[:, start] = 1.7
    D[:, start + 1:start + 7] = rng.standard_normal((5, 6))
    f, K = k.forces_and_stiffness(D, u)
    assert relative_error(f, -fd_gradient(lambda v: k.energy(D, v), u, 1e-6)) < 1e-6
    assert relative_error(K, -fd_gradient(lambda v: k.forces(D, v), u, 1e-6)) < 1e-6
    # a rigid rotation of a deformed state: the same energy, forces turned with it
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    x = X + u.reshape(5, 4, 3)
    turned = (x @ R.T - X).reshape(5, 12)
    assert relative_error(k.energy(D, turned), k.energy(D, u)) < 1e-12
    assert relative_error(k.forces(D, turned).reshape(5, 4, 3), f.reshape(5, 4, 3) @ R.T) < 1e-11


@pytest.mark.heavy           # a numba compile of two generated modules (tens of seconds cold)
@pytest.mark.parametrize("law", ["neohookean_viscous", "hgo_viscous"])
def test_c_and_numba_agree_on_viscous_kernels(law):
    """The step kernels of a viscous law, fibres included: C = numba on random g, H and u."""
    from helpers import law_inputs
    c, nb = (tm.load_kernel("tetra", law, "gauss1", backend=b) for b in ("c", "numba"))
    X = random_elements("tetra", 6, seed=5)
    D = nb.constants(X, E=3.0, nu=0.3, **law_inputs(law))
    assert np.array_equal(D, c.constants(X, E=3.0, nu=0.3, **law_inputs(law)))
    start = c.point_fields["inputs"]
    rng = np.random.default_rng(3)
    D[:, start] = 1.4
    D[:, start + 1:start + 7] = rng.standard_normal((6, 6))
    u = 0.1 * rng.standard_normal((6, 12))
    for name in ("energy", "forces", "stiffness", "stress"):
        a, b = getattr(c, name)(D, u), getattr(nb, name)(D, u)
        assert relative_error(a, b) < 1e-12, name


def cube(viscous, pulled, amplitude_end=0.02, steps=STEPS):
    return Scene.from_string(cube_text(viscous, pulled, amplitude_end, steps))


def cube_text(viscous, pulled, amplitude_end=0.02, steps=STEPS):
    """A unit cube of tetrahedra in uniaxial stress: rollers on three faces, `pulled` on x = 1 (a
    prescribed displacement or a traction), reached at the load factor amplitude_end and held."""
    branches = ", ".join(f"{{tau = {t}, beta = {b}}}" for t, b in viscous)
    return f"""{UNIT_CUBE_TOML}
[[material]]
law = "neohookean"
quadrature = "gauss1"
E = {E}
nu = {NU}
{"viscous = [" + branches + "]" if viscous else ""}
[[amplitude]]
name = "step"
factor = [0.0, {amplitude_end}, 1.0]
value = [0.0, 1.0, 1.0]
{ROLLERS_TOML}
{pulled}
[solver]
kind = "static"
steps = {steps}
dt = {H}
"""


PULL = """
[[fixed]]
name = "pulled"
box = [[0.99, -1, -1], [1.01, 2, 2]]
components = [0]
displacement = [0.001, 0, 0]
amplitude = "step"
"""
PROBE = """
[[probe]]
name = "corner"
point = [1.0, 0.0, 0.0]
"""
TRACTION = """
[[loads.traction]]
box = [[0.99, -1, -1], [1.01, 2, 2]]
value = [3.0, 0, 0]
amplitude = "step"
"""


def relaxation(t, strain=1e-3):
    """Uniaxial stress of the linear Prony model for a strain ramp over the first step, then held."""
    rate = strain / H
    if t <= H * (1 + 1e-9):
        return E * rate * (t + sum(b * tau * (1 - np.exp(-t / tau)) for tau, b in BRANCHES))
    return E * strain + E * rate * sum(b * tau * (np.exp(-(t - H) / tau) - np.exp(-t / tau)) for tau, b in BRANCHES)


def history(scene, what):
    summary = Simulation(scene).run()
    assert summary.status == "ok"
    rows = summary.per_step
    return np.array(rows["time"]), what(rows)


def test_relaxation_follows_the_prony_closed_form():
    """Held strain: the force decays from 4 E to E (1 + sum beta exp(-t / tau)); normalised by the
    elastic run's force at the same strain, within 0.3 % (the exponential update's first step)."""
    force = lambda rows: np.array(rows["reactions"]["pulled"]["force"])[:, 0]
    t, F = history(cube(BRANCHES, PULL), force)
    _, F_elastic = history(cube((), PULL), force)
    measured = F / F_elastic[-1]
    expected = np.array([relaxation(x) for x in t]) / (E * 1e-3)
    assert t[-1] == pytest.approx(1.0)
    assert np.abs(measured / expected - 1).max() < 3e-3
    assert measured[0] > 3.4 and measured[-1] < 1.35                 # it does relax


def test_creep_follows_the_standard_linear_solid():
    """One branch (tau, beta) under a held traction: the strain creeps from sigma / (E (1 + beta)) to
    sigma / E with the time tau (1 + beta) (the load ramps over the first step); normalised by the
    elastic run's strain, within 0.3 %."""
    tau, beta = 0.2, 1.5
    strain = lambda rows: np.array(rows["probes"]["corner"])[:, 0]        # the x = 1 face: uniform strain
    t, eps = history(cube([(tau, beta)], TRACTION + PROBE), strain)
    _, eps_elastic = history(cube((), TRACTION + PROBE), strain)
    tc = tau * (1 + beta)
    expected = np.array([(H - beta / (1 + beta) * tc * np.exp(-x / tc) * (np.exp(H / tc) - 1)) / H for x in t])
    measured = eps / eps_elastic[-1]
    assert np.abs(measured / expected - 1).max() < 3e-3
    assert measured[0] < 0.45 and measured[-1] > 0.9             # it does creep


def test_prepare_without_commit_keeps_the_accepted_state():
    """A refused step (a halved dt, a retry) prepares again from the last accepted state: the point
    inputs depend on (state, h) only."""
    sim = Simulation(cube(BRANCHES, PULL, steps=3))
    sim.run()
    history_ = sim.ctx.history
    part = sim.model.parts[0]
    history_.prepare(0.01)
    first = part.D.copy()
    history_.prepare(0.005)
    history_.prepare(0.01)
    assert np.array_equal(part.D, first)


@pytest.mark.parametrize("change, message", [
    (("viscous = [", "viscous = [{tau = 0.0, beta = 1.0}, "), r"viscous\[0\]\.tau: .*> 0"),
    (("viscous = [", "viscous = [{tau = 1.0, beta = -1.0}, "), r"viscous\[0\]\.beta: must be >= 0"),
    (("viscous = [", "viscous = [{tau = 1.0}, "), r"viscous\[0\]\.beta: missing"),
    (("viscous = [", "viscous = [{tau = 1.0, beta = 1.0, eta = 2.0}, "), r"viscous\[0\]\.eta: unknown key"),
    (('kind = "static"', 'kind = "explicit"'), r"material\[0\]\.viscous: viscous materials run with"),
    (('law = "neohookean"\nquadrature = "gauss1"', 'law = "mss"'), r"material\[0\]\.viscous: law 'mss' has no energy"),
    (("[solver]", '[[adapt]]\naction = "refine"\ncriterion = "R_S"\nthreshold = 1.0\n[solver]'),
     r"material\[0\]\.viscous: viscous materials cannot be combined with \[\[adapt\]\] yet"),
])
def test_scene_errors_name_the_key(change, message):
    text = cube_text(BRANCHES, PULL).replace(*change)
    with pytest.raises(SceneError, match=message):
        Scene.from_string(text)


def test_an_implicit_euler_run_with_viscous_branches():
    """A dynamic run: the history commits once per accepted step, the run ends ok, and the branches
    damp the motion the elastic run keeps (implicit Euler damps both; the viscous one more)."""
    def swing(viscous):
        text = cube_text(viscous, PROBE, steps=40).replace('kind = "static"', 'kind = "implicit_euler"')
        text = text.replace("[[material]]", "[loads]\ngravity = [-2.0, 0, 0]\ngravity_amplitude = \"step\"\n[[material]]")
        summary = Simulation(Scene.from_string(text)).run()
        assert summary.status == "ok"
        x = np.array(summary.per_step["probes"]["corner"])[:, 0]
        return x
    elastic, viscous = swing(()), swing([(0.05, 3.0)])
    assert np.abs(np.diff(viscous[-10:])).max() < np.abs(np.diff(elastic[-10:])).max()


def test_the_liver_example_relaxes(tmp_path):
    """examples/tissue/liver_relaxation.toml through the CLI: the tool's force peaks when the press
    ends (0.1 s) and relaxes monotonically while it is held, towards the relaxed modulus' force."""
    import json
    from pathlib import Path
    from tensormass.apps.cli import main
    example = Path(__file__).resolve().parents[3] / "examples" / "tissue" / "liver_relaxation.toml"
    out = tmp_path / "summary.json"
    assert main(["run", str(example), "--quiet", "--json", str(out)]) == 0
    summary = json.loads(out.read_text())
    assert summary["status"] == "ok"
    force = -np.array(summary["per_step"]["reactions"]["tool"]["force"])[:, 2]
    t = np.array(summary["per_step"]["time"])
    peak = int(np.argmax(force))
    assert t[peak] == pytest.approx(0.1)
    assert np.all(np.diff(force[peak:]) < 0) and force[-1] < 0.75 * force[peak]


def test_advice_names_branches_the_run_cannot_see():
    from tensormass.runtime.scene import advice
    scene = cube(((1e-5, 1.0), (0.5, 2.0), (1e4, 1.0)), PULL)
    lines = [a for a in advice.scene_advice(scene) if "viscous" in a]
    assert len(lines) == 1
    assert "tau = 1e-05 s relax within a step of 0.02 s" in lines[0]
    assert "tau = 10000 s do not relax within the run's 1 s" in lines[0]
    assert not [a for a in advice.scene_advice(cube(BRANCHES, PULL)) if "viscous" in a]


def test_constant_strain_patch_of_the_step_energy():
    """A linear displacement on affine elements: the step energy is (g W(F) + H : E) x volume, with W
    the base law's energy density (by the base kernel) and H : E by hand."""
    k = tm.load_kernel("tetra", "neohookean_viscous", "gauss1")
    base = tm.load_kernel("tetra", "neohookean", "gauss1")
    rng = np.random.default_rng(4)
    X = random_elements("tetra", 3, seed=9)
    A = np.eye(3) + 0.1 * rng.standard_normal((3, 3))
    u = np.einsum("ab,enb->ena", A - np.eye(3), X)
    D, Db = k.constants(X, E=3.0, nu=0.3), base.constants(X, E=3.0, nu=0.3)
    start = k.point_fields["inputs"]
    g, h = 1.6, rng.standard_normal(6)
    D[:, start], D[:, start + 1:start + 7] = g, h
    E_ = 0.5 * (A.T @ A - np.eye(3))
    pairs = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
    HE = sum((1 if a == b else 2) * h[k_] * E_[a, b] for k_, (a, b) in enumerate(pairs))
    volume = base.point_volumes(Db).sum(axis=1)
    assert relative_error(k.energy(D, u), g * base.energy(Db, u) + HE * volume) < 1e-12


@pytest.mark.heavy           # hgo_viscous is generated on first use (seconds of sympy, cold)
def test_viscous_fibres_take_the_laws_own_parameters():
    """A viscous hgo material: its kernel (hgo_viscous) gets the material's k1, k2 and fibres, and
    with beta = 0 it gives the elastic hgo run's force."""
    def force(viscous):
        text = cube_text((), PULL).replace('law = "neohookean"', 'law = "hgo"').replace(
            "nu = 0.3", "nu = 0.3\nk1 = 2000.0\nk2 = 1.5\nfibres = [1, 0, 0]" + (
                "\nviscous = [{tau = 0.5, beta = 0.0}]" if viscous else ""))
        sim = Simulation(Scene.from_string(text))
        assert sim.run().status == "ok"
        return sim.reactions()["pulled"]["force"][0]
    assert force(True) == pytest.approx(force(False), rel=1e-9)


@pytest.mark.parametrize("event, share", [
    ('[[cut]]\nname = "slit"\nstep = 25\nplane = [[0.0, 0.5, 0.0], [0.0, 1.0, 0.0]]\n', 1.0),
    ('[[remove]]\nname = "half"\nstep = 25\nbox = [[-1.0, 0.5, -1.0], [2.0, 2.0, 2.0]]\n', 0.5)])
def test_the_history_follows_cuts_and_removals(event, share):
    """A cube relaxing in uniaxial stress, cut along the pull (the state stays homogeneous) or with
    half its cells removed mid-run: the force goes on relaxing as the untouched cube's, times the
    share of the section left; a history reset at the change would jump to the instantaneous modulus."""
    force = lambda rows: np.array(rows["reactions"]["pulled"]["force"])[:, 0]
    text = cube_text(BRANCHES, PULL).replace("cells = [1, 1, 1]", "cells = [2, 2, 2]")
    assert "cells = [2, 2, 2]" in text
    t, F = history(Scene.from_string(text), force)
    t_changed, F_changed = history(Scene.from_string(text + event), force)
    assert np.array_equal(t, t_changed)
    after = t > 0.5 - 1e-9                    # the row of the change's step is written after it
    assert after.any() and (~after).any()
    assert np.allclose(F_changed[after], share * F[after], rtol=1e-6)
    assert np.allclose(F_changed[~after], F[~after], rtol=1e-12)


def test_the_dissipation_matches_the_standard_linear_solids():
    """Uniaxial stress ramped over 0.1 s and held to 1 s: each branch is a spring beta E in series
    with a dashpot tau beta E, whose dissipation is q^2 / (tau beta E) integrated in closed form;
    the field (uniform here) and the total agree within 1 %."""
    from scipy.integrate import quad
    ramp, strain = 0.1, 1e-3
    sim = Simulation(cube(BRANCHES, PULL, amplitude_end=ramp))
    summary = sim.run()
    assert summary.status == "ok"
    assert summary.viscous["dissipated"] == sim.ctx.history.dissipated_energy()
    expected = 0.0
    for tau, beta in BRANCHES:
        q = lambda t: beta * E * strain / ramp * tau * (1 - np.exp(-t / tau))
        expected += quad(lambda t: q(t) ** 2 / (tau * beta * E), 0, ramp)[0]
        expected += q(ramp) ** 2 / (2 * beta * E) * (1 - np.exp(-2 * (1.0 - ramp) / tau))
    assert sim.ctx.history.dissipated_energy() == pytest.approx(expected, rel=0.01)     # the unit cube: J = J/m^3
    _, cells = sim.fields(["viscous_dissipation"])
    assert np.allclose(cells["viscous_dissipation"], expected, rtol=0.01)
    elastic = Simulation(cube((), PULL))
    with pytest.raises(Exception, match="viscous_dissipation.*runtime.physics.viscous"):
        elastic.fields(["viscous_dissipation"])


@pytest.mark.heavy           # generates the hexahedron's viscous step kernel (about 30 s cold)
@pytest.mark.parametrize("box", ["[[-1, -1, -1], [2, 2, 2]]", "[[-1, -1, -1], [0.5, 2, 2]]"])
def test_the_history_follows_a_refinement(box):
    """A hexahedral cube relaxing in uniaxial stress, refined 1:8 mid-run (all cells, or half with
    hanging nodes): the state is homogeneous, so the children's copies of their parents' state are
    exact and the force goes on relaxing as the unrefined cube's."""
    force = lambda rows: np.array(rows["reactions"]["pulled"]["force"])[:, 0]
    text = (cube_text(BRANCHES, PULL).replace('element = "tetra"', 'element = "hexahedron"')
            .replace('quadrature = "gauss1"', 'quadrature = "gauss2"').replace("cells = [1, 1, 1]", "cells = [2, 2, 2]"))
    t, F = history(Scene.from_string(text), force)
    _, F_refined = history(Scene.from_string(text + f"[[refine]]\nstep = 25\nbox = {box}\n"), force)
    assert np.allclose(F_refined, F, rtol=1e-6)
