"""Fibre-reinforced tissue (laws/hgo.py) through a scene: uniaxial tension of a cube along and across
its fibres against the principal-stretch solution of the same W written by hand in numpy (not the
generator's), and the fibres key (vectors, functions of the centroids, and what is refused)."""
import math

import numpy as np
import pytest
from scipy.optimize import brentq, fsolve

from tensormass.runtime.base.errors import SceneError, TensormassError
from tensormass.runtime.mesh import fibres
from tensormass.runtime.run.simulation import Simulation
from tensormass.runtime.scene.scene import Scene

from helpers import ROLLERS_TOML, UNIT_CUBE_TOML

E, NU, K1, K2 = 3000.0, 0.45, 2000.0, 1.5
MU, KAPPA = E / (2 * (1 + NU)), E / (3 * (1 - 2 * NU))


def principal_stress(stretches, dispersion, fibre_axis=0):
    """dW/d(lambda_i) of HGO for F = diag(stretches), fibres along axis fibre_axis (nominal stresses)."""
    lam = np.asarray(stretches, dtype=float)
    J, I1 = lam.prod(), (lam**2).sum()
    I4 = lam[fibre_axis] ** 2
    Ef = dispersion * (I1 - 3) + (1 - 3 * dispersion) * (I4 - 1)
    matrix = MU / 2 * (-2 / 3 * J ** (-2 / 3) * I1 / lam + 2 * J ** (-2 / 3) * lam) + KAPPA / 2 * (J - 1 / J) * J / lam
    dE = 2 * dispersion * lam
    dE[fibre_axis] += 2 * (1 - 3 * dispersion) * lam[fibre_axis]
    fibre = K1 * max(Ef, 0.0) * math.exp(K2 * max(Ef, 0.0) ** 2) * dE
    return matrix + fibre


def along(stretch, dispersion):
    """Pulled along the fibres (x): y and z stretch alike (transverse isotropy), stress-free."""
    t = brentq(lambda s: principal_stress([stretch, s, s], dispersion)[1], 0.3, 1.5, xtol=1e-15)
    return principal_stress([stretch, t, t], dispersion)[0]


def across(stretch, dispersion):
    """Pulled along y, fibres along x: x and z stretch differently, both stress-free."""
    def free(s):
        p = principal_stress([s[0], stretch, s[1]], dispersion)
        return [p[0], p[2]]
    sx, sz = fsolve(free, [1.0, 1.0], xtol=1e-12)
    assert np.abs(free([sx, sz])).max() < 1e-9 * MU
    return principal_stress([sx, stretch, sz], dispersion)[1]


def cube_text(pull_axis, fibre="[1, 0, 0]", dispersion=0.0):
    box = [[-1, -1, -1], [2, 2, 2]]
    box[0][pull_axis], box[1][pull_axis] = 0.99, 1.01
    displacement = [0.0, 0.0, 0.0]
    displacement[pull_axis] = 0.25
    return f"""{UNIT_CUBE_TOML}
[[material]]
law = "hgo"
quadrature = "gauss1"
E = {E}
nu = {NU}
k1 = {K1}
k2 = {K2}
dispersion = {dispersion}
fibres = {fibre}
{ROLLERS_TOML}
[[fixed]]
name = "pulled"
box = {box}
components = [{pull_axis}]
displacement = {displacement}
[solver]
kind = "static"
steps = 4
"""


@pytest.mark.parametrize("pull_axis, dispersion", [(0, 0.0), (0, 0.1), (1, 0.1)],
                         ids=["along", "along-dispersed", "across-dispersed"])
def test_uniaxial_tension_matches_the_principal_stretch_solution(pull_axis, dispersion):
    sim = Simulation(Scene.from_string(cube_text(pull_axis, dispersion=dispersion)))
    summary = sim.run()
    assert summary.status == "ok"
    force = sim.reactions()["pulled"]["force"][pull_axis]       # what pulls a unit face: the nominal stress
    expected = (along if pull_axis == 0 else across)(1.25, dispersion)
    assert force == pytest.approx(expected, rel=1e-6)           # homogeneous: exact up to Newton's tolerance


def test_fibres_stiffen_tension_along_them_only():
    """Along the fibres the stress is far above the matrix's; across aligned fibres (no dispersion)
    the fibres are compressed and carry nothing: the matrix alone."""
    assert along(1.25, 0.0) > 2 * across(1.25, 0.0)
    sim = Simulation(Scene.from_string(cube_text(1)))
    sim.run()
    assert sim.reactions()["pulled"]["force"][1] == pytest.approx(across(1.25, 0.0), rel=1e-6)


def test_a_fibre_function_of_the_centroids(tmp_path):
    """"FILE.py:FUNCTION" in the scene: a function of the rest centroids; a rotated field gives the
    same stress as the equivalent constant vector."""
    (tmp_path / "field.py").write_text("import numpy as np\n"
                                       "def along_x(centroids):\n"
                                       "    return np.tile([2.0, 0.0, 0.0], (len(centroids), 1))\n")
    text = cube_text(0).replace("fibres = [1, 0, 0]", 'fibres = "field.py:along_x"')
    scene = Scene.from_string(text, base_dir=tmp_path)
    sim = Simulation(scene)
    sim.run()
    assert sim.reactions()["pulled"]["force"][0] == pytest.approx(along(1.25, 0.0), rel=1e-6)


def test_directions_are_normalised_and_checked():
    centroids = np.zeros((3, 3))
    a = fibres.directions((0.0, 3.0, 4.0), centroids, "x")
    np.testing.assert_allclose(a, [[0.0, 0.6, 0.8]] * 3)
    with pytest.raises(TensormassError, match=r"zero or not finite in cell\(s\) 1"):
        fibres.directions(lambda c: np.array([[1.0, 0, 0], [0, 0, 0], [0, 1.0, 0]]), centroids, "x")
    with pytest.raises(TensormassError, match="shape"):
        fibres.directions(lambda c: np.ones((2, 3)), centroids, "x")
    with pytest.raises(TensormassError, match="in-plane"):
        fibres.directions((1.0, 0.0, 1.0), np.zeros((2, 2)), "x")


@pytest.mark.parametrize("change, message", [
    ("fibres = [1, 0, 0]", "fibres: missing; law 'hgo' needs 1 fibre direction"),
    ("fibres = [0, 0, 0]", "non-zero vector"),
    ("fibres = [[1, 0, 0], [0, 1, 0]]", "has 1 fibre direction"),
    ("fibres = \"nowhere.py:f\"", "cannot read"),
    ("k1 = 2000.0", "needs parameter k1"),
    ("k2 = 1.5", "needs parameter k2"),
    ("dispersion = 0.0", None),
])
def test_scene_errors_name_the_key(change, message):
    text = cube_text(0)
    replacement = {"fibres = [1, 0, 0]": "", "k1 = 2000.0": "", "k2 = 1.5": "", "dispersion = 0.0": "dispersion = 0.5"}
    if change in replacement:
        text = text.replace(change, replacement[change])
    else:
        text = text.replace("fibres = [1, 0, 0]", change)
    with pytest.raises(SceneError, match=message or "dispersion must be a number in"):
        Scene.from_string(text)


def test_fibres_on_a_law_without_directions_are_refused():
    text = cube_text(0).replace('law = "hgo"', 'law = "neohookean"')
    for key in ("k1 = 2000.0", "k2 = 1.5", "dispersion = 0.0"):
        text = text.replace(key, "")
    with pytest.raises(SceneError, match="has no fibre directions"):
        Scene.from_string(text)


def test_the_myocardium_example_twists_under_tension(tmp_path):
    """examples/tissue/myocardium_strip.toml through the CLI: fibres turning through the thickness
    (a function of the centroids) couple the pull with a twist about x, which aligned fibres do not;
    the exponential fibres do not trip the energy-scale check."""
    import json
    import shutil
    from pathlib import Path
    from tensormass.apps.cli import main
    example = Path(__file__).resolve().parents[3] / "examples" / "tissue"
    for name in ("myocardium_strip.toml", "fibres.py"):
        shutil.copy(example / name, tmp_path / name)
    moments = {}
    for variant, fibre in (("helical", None), ("aligned", "[1, 0, 0]")):
        scene = tmp_path / f"{variant}.toml"
        text = (tmp_path / "myocardium_strip.toml").read_text()
        scene.write_text(text if fibre is None else text.replace('"fibres.py:helical"', fibre))
        assert main(["run", str(scene), "--quiet", "--json", str(tmp_path / f"{variant}.json")]) == 0
        summary = json.loads((tmp_path / f"{variant}.json").read_text())
        assert summary["status"] == "ok"
        reaction = summary["reactions"]["pulled"]
        moments[variant] = abs(reaction["moment"][0]) / (reaction["force"][0] * 0.01)   # per force x thickness
    assert moments["helical"] > 1e-3 > 1e3 * moments["aligned"]


def test_the_fibre_stretch_field():
    """fibre_stretch = |F a|: the imposed 1.25 pulled along the fibres; across them, the lateral
    stretch of the principal-stretch solution; 0 in cells whose law has no fibres."""
    from tensormass.runtime.physics import fields
    sim = Simulation(Scene.from_string(cube_text(0)))
    sim.run()
    _, cells = fields.evaluate(sim.model, sim.displacement, ["fibre_stretch"])
    np.testing.assert_allclose(cells["fibre_stretch"], 1.25, rtol=1e-12)
    sim = Simulation(Scene.from_string(cube_text(1, dispersion=0.1)))
    sim.run()
    _, cells = fields.evaluate(sim.model, sim.displacement, ["fibre_stretch"])

    def free(s):
        p = principal_stress([s[0], 1.25, s[1]], 0.1)
        return [p[0], p[2]]
    lateral = fsolve(free, [1.0, 1.0], xtol=1e-12)[0]
    np.testing.assert_allclose(cells["fibre_stretch"], lateral, rtol=1e-6)
    elastic = cube_text(0).replace('law = "hgo"', 'law = "neohookean"').replace("fibres = [1, 0, 0]", "")
    for key in ("k1 = 2000.0", "k2 = 1.5", "dispersion = 0.0"):
        elastic = elastic.replace(key, "")
    sim = Simulation(Scene.from_string(elastic))
    sim.run()
    assert np.all(fields.evaluate(sim.model, sim.displacement, ["fibre_stretch"])[1]["fibre_stretch"] == 0)


def principal_stress_families(stretches, fibres, dispersion=0.0):
    """dW/d(lambda_i) of HGO with any fibre families (unit vectors) for F = diag(stretches), whose
    fibres keep F diagonal (families symmetric about the axes)."""
    lam = np.asarray(stretches, dtype=float)
    J, I1 = lam.prod(), (lam**2).sum()
    out = MU / 2 * (-2 / 3 * J ** (-2 / 3) * I1 / lam + 2 * J ** (-2 / 3) * lam) + KAPPA / 2 * (J - 1 / J) * J / lam
    for a in fibres:
        a = np.asarray(a, dtype=float)
        Ef = dispersion * (I1 - 3) + (1 - 3 * dispersion) * ((lam * a) ** 2).sum() - (1 - 3 * dispersion)
        dE = 2 * dispersion * lam + (1 - 3 * dispersion) * 2 * lam * a**2
        out = out + K1 * max(Ef, 0.0) * math.exp(K2 * max(Ef, 0.0) ** 2) * dE
    return out


def test_two_fibre_families_pulled_between_them():
    """hgo2 with families at +-30 degrees from x in the x-y plane, pulled along x: the principal-stretch
    solution with both families (y and z stretch differently, both stress-free)."""
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    families = [(c, s, 0.0), (c, -s, 0.0)]
    text = cube_text(0).replace('law = "hgo"', 'law = "hgo2"').replace(
        "fibres = [1, 0, 0]", f"fibres = [{list(families[0])}, {list(families[1])}]")
    sim = Simulation(Scene.from_string(text))
    assert sim.run().status == "ok"

    def free(lateral):
        p = principal_stress_families([1.25, *lateral], families)
        return [p[1], p[2]]
    lateral = fsolve(free, [0.9, 0.9], xtol=1e-12)
    expected = principal_stress_families([1.25, *lateral], families)[0]
    assert sim.reactions()["pulled"]["force"][0] == pytest.approx(expected, rel=1e-6)
    assert expected > 1.2 * principal_stress_families([1.25, *lateral], [])[0]     # the fibres carry load


def test_fibres_from_the_mesh_files_cell_data(tmp_path):
    """fibres = "NAME": the mesh file's cell data, a vector per cell (here +x and -x alternately:
    the same fibres) gives the constant vector's stress; the mesh cache keeps the field; a name the
    file lacks is refused, naming those it has."""
    import meshio
    from tensormass.runtime.mesh.bars import generate_bar
    mesh = generate_bar((1.0, 1.0, 1.0), (1, 1, 1), "tetra")
    n = len(mesh.blocks[0])
    sign = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    vectors = np.column_stack([2.0 * sign, np.zeros(n), np.zeros(n)])
    meshio.write(tmp_path / "cube.vtu", meshio.Mesh(mesh.points, [("tetra", mesh.blocks[0].cells)],
                                                    cell_data={"fibres": [vectors], "other": [np.ones(n)]}))
    text = cube_text(0).replace('generate = "bar"\nsize = [1.0, 1.0, 1.0]\ncells = [1, 1, 1]\nelement = "tetra"',
                                'file = "cube.vtu"').replace("fibres = [1, 0, 0]", 'fibres = "fibres"')
    for attempt in range(2):                       # the second read comes from the mesh cache
        scene = Scene.from_string(text, base_dir=tmp_path)
        sim = Simulation(scene)
        sim.run()
        assert sim.reactions()["pulled"]["force"][0] == pytest.approx(along(1.25, 0.0), rel=1e-6)
        np.testing.assert_array_equal(sim.model.mesh.cell_data["fibres"], vectors)
    with pytest.raises(TensormassError, match=r"no cell data 'fibre' \(it has: fibres, other\)"):
        Simulation(Scene.from_string(text.replace('fibres = "fibres"', 'fibres = "fibre"'), base_dir=tmp_path))


def test_cell_data_fibres_with_refinement_are_refused():
    text = cube_text(0).replace("fibres = [1, 0, 0]", 'fibres = "fibres"') + """
[[refine]]
step = 2
box = [[-1, -1, -1], [2, 2, 2]]
"""
    with pytest.raises(SceneError, match=r"fibres from the mesh file's cell data cannot be combined with \[\[refine\]\]"):
        Scene.from_string(text)
