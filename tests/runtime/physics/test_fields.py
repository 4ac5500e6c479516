"""Output fields (runtime/physics/fields.py): analytic stresses for every law, von Mises, objectivity,
nodal averaging on a mixed mesh, law switching, the scene key and the VTU frames.

The analytic values come from the laws' closed forms written here with numpy (not from the
generator) and P = dW/dF by central differences; sigma = P F^T / J. Most tests run the generated
numba code as plain Python (py_func: the same generated source, no JIT compilation) through
registered kernels, to stay fast; the VTU test runs the compiled kernels. C = numba of the
stress kernel: tests/generator/test_stress_kernel.py."""
from __future__ import annotations

import meshio
import numpy as np
import pytest

from tensormass.apps.commands import run_scene
from tensormass.backends import KERNEL_FUNCTIONS
from tensormass.runtime.kernels import custom_kernels
from tensormass.runtime.physics import fields as fm
from tensormass.runtime.base.errors import SceneError, TensormassError
from tensormass.runtime.kernels.kernels import Kernel, load_kernel
from tensormass.runtime.mesh.container import CellBlock, Mesh
from tensormass.runtime.model.model import Model
from tensormass.runtime.scene.types import Adapt, Material
from tensormass.runtime.scene.scene import Scene

LAWS = ["hooke", "stvk", "neohookean", "stable_neohookean", "mooney_rivlin"]
YOUNG, NU = 1000.0, 0.3
TETRA = np.array([[0.1, 0.0, 0.0], [1.2, 0.1, 0.0], [0.2, 0.9, 0.1], [0.0, 0.3, 1.1]])
TRIANGLE = np.array([[0.1, 0.0], [1.2, 0.1], [0.2, 0.9]])


# -- the laws' energies, independently ------------------------------------------------------------
def lame(E=YOUNG, nu=NU):
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def energy(law: str, F: np.ndarray) -> float:
    """W(F) per rest volume of each law (laws/*.py docstrings), F 3x3."""
    lam, mu = lame()
    C, J, I = F.T @ F, np.linalg.det(F), np.eye(3)
    I1 = np.trace(C)
    if law == "hooke":
        eps = (F + F.T) / 2 - I
        return lam / 2 * np.trace(eps) ** 2 + mu * np.trace(eps @ eps)
    if law == "stvk":
        E = (C - I) / 2
        return lam / 2 * np.trace(E) ** 2 + mu * np.trace(E @ E)
    if law == "neohookean":
        return mu / 2 * (I1 - 3) - mu * np.log(J) + lam / 2 * np.log(J) ** 2
    if law == "stable_neohookean":
        ms, ls = 4 * mu / 3, lam + 5 * mu / 6
        alpha = 1 + 0.75 * ms / ls
        W = ms / 2 * (I1 - 3) + ls / 2 * (J - alpha) ** 2 - ms / 2 * np.log(I1 + 1)
        return W - (ls / 2 * (1 - alpha) ** 2 - ms / 2 * np.log(4))
    if law == "mooney_rivlin":
        C10 = C01 = mu / 4
        kappa = lam + 2 * mu / 3
        I2 = (I1 ** 2 - np.trace(C @ C)) / 2
        return C10 * (J ** (-2 / 3) * I1 - 3) + C01 * (J ** (-4 / 3) * I2 - 3) + kappa / 2 * (J - 1) ** 2
    raise ValueError(law)


def cauchy(law: str, F: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """sigma = P F^T / J with P = dW/dF by central differences over all 9 entries of F (2D plane
    strain: F is the embedded 3x3 one, F33 = 1, so P33 is the out-of-plane stress)."""
    P = np.zeros((3, 3))
    for a in range(3):
        for b in range(3):
            Fp, Fm = F.copy(), F.copy()
            Fp[a, b] += h
            Fm[a, b] -= h
            P[a, b] = (energy(law, Fp) - energy(law, Fm)) / (2 * h)
    return P @ F.T / np.linalg.det(F)


def embed(F2: np.ndarray) -> np.ndarray:
    F = np.eye(3)
    F[:2, :2] = F2
    return F


def rotation(axis, angle) -> np.ndarray:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


# -- kernels run as plain Python ------------------------------------------------------------------
class _Interpreted:
    """A generated numba module whose functions run as plain Python (numba's py_func)."""

    def __init__(self, module):
        self.METADATA = module.METADATA
        for name in KERNEL_FUNCTIONS:
            setattr(self, name, getattr(module, name).py_func)


def interpreted(element, law, quadrature) -> Kernel:
    return Kernel(_Interpreted(load_kernel(element, law, quadrature, "numba").module), "python")


@pytest.fixture
def python_kernels():
    """register(element, law, quadrature): models built in the test use the interpreted kernel."""
    keys = []

    def register(element, law, quadrature="gauss1"):
        custom_kernels.register_kernel(element, law, quadrature, interpreted(element, law, quadrature), replace=True)
        keys.append((element, law, quadrature))

    yield register
    for key in keys:
        custom_kernels.unregister_kernel(*key)


def one_cell(element, law, quadrature="gauss1") -> Model:
    X = TETRA if element == "tetra" else TRIANGLE
    mesh = Mesh(X, [CellBlock(element, np.arange(len(X))[None])])
    return Model(mesh, [Material(law=law, quadrature=quadrature, E=YOUNG, nu=NU)])


def homogeneous(model, F) -> np.ndarray:
    """u = (F - I) X at every node (F: dim x dim)."""
    X = model.mesh.points
    return (X @ (F - np.eye(len(F))).T).ravel()


def tensor(values) -> np.ndarray:
    return np.asarray(values).reshape(-1, 3, 3)


# every record field at every location it is offered at ("name@cell" / "name@point")
ALL = [f"{n}@{w}" for n in ("cauchy_stress", "von_mises", "pressure", "principal_stretches", "green_lagrange",
                            "det_F_min", "energy_density")
       for w in fm.FIELDS[n].where + ((fm.FIELDS[n].other,) if fm.FIELDS[n].other else ())]
F3D = np.array([[1.08, 0.05, -0.02], [0.03, 0.96, 0.04], [-0.01, 0.02, 1.03]])
F2D = np.array([[1.07, 0.06], [-0.03, 0.95]])


# -- analytic values ------------------------------------------------------------------------------
@pytest.mark.parametrize("element", ["tetra", "triangle"])
@pytest.mark.parametrize("law", LAWS)
def test_fields_of_a_homogeneous_deformation_are_analytic(law, element, python_kernels):
    python_kernels(element, law)
    model = one_cell(element, law)
    F_in = F3D if element == "tetra" else F2D
    F = F_in if element == "tetra" else embed(F_in)
    point, cell = fm.evaluate(model, homogeneous(model, F_in), ALL)
    sigma = cauchy(law, F)
    scale = np.abs(sigma).max()
    assert scale > 1.0                                       # a real stress state
    for values in (cell["cauchy_stress"], point["cauchy_stress"]):   # nodal = the cell's: homogeneous
        assert np.abs(tensor(values) - sigma).max() < 1e-7 * scale
    if element == "triangle":
        assert abs(sigma[2, 2]) > 0.05 * scale               # plane strain: sigma33 is not zero
    s = sigma - np.trace(sigma) / 3 * np.eye(3)
    assert cell["von_mises"][0] == pytest.approx(np.sqrt(1.5 * np.sum(s * s)), rel=1e-7)
    assert cell["pressure"][0] == pytest.approx(-np.trace(sigma) / 3, rel=1e-6, abs=1e-7 * scale)
    C = F.T @ F
    assert np.allclose(cell["principal_stretches"][0], np.sqrt(np.linalg.eigvalsh(C))[::-1], rtol=1e-13)
    assert np.allclose(tensor(cell["green_lagrange"])[0], (C - np.eye(3)) / 2, atol=1e-14)
    assert cell["det_F_min"][0] == pytest.approx(np.linalg.det(F), rel=1e-13)
    assert cell["energy_density"][0] == pytest.approx(energy(law, F), rel=1e-10)
    names = {a.split("@")[0] for a in ALL}
    assert set(point) == names - {"det_F_min"} and set(cell) == names


@pytest.mark.parametrize("strain", [0.01, -0.01])
def test_von_mises_of_uniaxial_stress_is_abs_sigma11(strain, python_kernels):
    """Hooke with F = diag(1 + e, 1 - nu e, 1 - nu e) is exactly uniaxial: P = diag(E e, 0, 0)."""
    python_kernels("tetra", "hooke")
    model = one_cell("tetra", "hooke")
    F = np.diag([1 + strain, 1 - NU * strain, 1 - NU * strain])
    _, cell = fm.evaluate(model, homogeneous(model, F), ["cauchy_stress", "von_mises@cell", "pressure@cell"])
    sigma = tensor(cell["cauchy_stress"])[0]
    s11 = YOUNG * strain * (1 + strain) / np.linalg.det(F)
    assert sigma[0, 0] == pytest.approx(s11, rel=1e-12)
    assert np.abs(sigma - np.diag([s11, 0, 0])).max() < 1e-12 * abs(s11)
    assert cell["von_mises"][0] == pytest.approx(abs(s11), rel=1e-12)
    assert cell["pressure"][0] == pytest.approx(-s11 / 3, rel=1e-12)


@pytest.mark.parametrize("law", [law for law in LAWS if law != "hooke"])   # Hooke is not objective
def test_a_rigid_rotation_rotates_the_cauchy_stress(law, python_kernels):
    python_kernels("tetra", law)
    model = one_cell("tetra", law)
    R = rotation([1.0, -2.0, 0.5], 0.7)
    names = ["cauchy_stress", "von_mises@cell", "principal_stretches", "green_lagrange", "energy_density"]
    _, before = fm.evaluate(model, homogeneous(model, F3D), names)
    _, after = fm.evaluate(model, homogeneous(model, R @ F3D), names)
    sigma = tensor(before["cauchy_stress"])[0]
    scale = np.abs(sigma).max()
    assert np.abs(tensor(after["cauchy_stress"])[0] - R @ sigma @ R.T).max() < 1e-10 * scale
    assert np.abs(tensor(after["cauchy_stress"])[0] - sigma).max() > 0.1 * scale      # it did rotate
    for name in (n.split("@")[0] for n in names[1:]):        # invariants stay
        assert np.allclose(after[name], before[name], rtol=1e-10, atol=1e-12)


# -- mixed meshes, averaging, ids, law switching --------------------------------------------------
MIXED = """
[mesh]
generate = "bar"
size = [4.0, 1.0, 1.0]
cells = [4, 1, 1]
element = "mixed"
[[material]]
region = "hexahedron"
law = "hooke"
quadrature = "gauss1"
E = 1000.0
nu = 0.3
[[material]]
region = "all"
law = "stvk"
quadrature = "gauss1"
E = 1000.0
nu = 0.3
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 2, 2]]
"""


def test_mixed_mesh_cell_values_ids_and_nodal_volume_average(python_kernels):
    scene = Scene.from_string(MIXED)
    mesh = scene.load_mesh()
    types = [b.type for b in mesh.blocks]
    assert len(set(types)) >= 3
    for t in set(types):
        python_kernels(t, "hooke" if t == "hexahedron" else "stvk")
    model = Model.from_scene(scene, mesh)
    F = np.array([[1.02, 0.01, 0.0], [0.0, 0.99, 0.01], [0.01, 0.0, 1.01]])
    point, cell = fm.evaluate(model, homogeneous(model, F), ["cauchy_stress", "cauchy_stress@point", "material", "law",
                                                                      "region"])
    ctype = np.concatenate([[b.type] * len(b) for b in mesh.blocks])
    hexa = ctype == "hexahedron"
    assert list(np.unique(cell["material"][hexa])) == [0] and list(np.unique(cell["material"][~hexa])) == [1]
    law_ids = model.law_names()                              # the summary's fields.law_ids
    assert [law_ids[i] for i in cell["law"][[np.flatnonzero(hexa)[0], np.flatnonzero(~hexa)[0]]]] == ["hooke", "stvk"]
    assert list(np.unique(cell["region"])) == [-1]           # a generated bar has no tags
    sigma = {"hooke": cauchy("hooke", F), "stvk": cauchy("stvk", F)}
    expected = np.where(hexa[:, None, None], sigma["hooke"], sigma["stvk"])
    scale = np.abs(expected).max()
    assert np.abs(tensor(cell["cauchy_stress"]) - expected).max() < 1e-7 * scale
    # nodal: sum_c V_c sigma_c / sum_c V_c over the cells around the node
    volume = np.zeros(mesh.n_cells)
    for part in model.parts:
        volume[part.cell_ids] = part.volume
    cells = [c for b in mesh.blocks for c in b.cells]
    for node in range(mesh.n_points):
        around = [i for i, c in enumerate(cells) if node in c]
        want = sum(volume[i] * expected[i] for i in around) / volume[around].sum()
        assert np.abs(tensor(point["cauchy_stress"])[node] - want).max() < 1e-7 * scale
    mixed_nodes = [n for n in range(mesh.n_points)
                   if len({hexa[i] for i, c in enumerate(cells) if n in c}) == 2]
    assert mixed_nodes                                       # some nodes average across the two laws


def test_law_switched_cells_use_their_current_law(python_kernels, monkeypatch):
    monkeypatch.setattr(fm, "CHUNK", 4)                      # parts of 10 and 2 cells: several chunks
    mesh = Scene.from_string(TINY).load_mesh()
    for law in ("stvk", "neohookean"):
        python_kernels("tetra", law)
    model = Model(mesh, [Material(law="stvk", quadrature="gauss1", E=YOUNG, nu=NU)],
                  adapt=[Adapt(criterion="R_L", threshold=0.1, law="neohookean")])
    names = np.array(["stvk"] * mesh.n_cells, dtype=object)
    names[[0, 2]] = "neohookean"
    model.set_cell_laws(names)
    point, cell = fm.evaluate(model, homogeneous(model, F3D), ["cauchy_stress", "law"])
    assert [model.law_names()[i] for i in cell["law"]] == list(names)
    for c in range(mesh.n_cells):
        want = cauchy(names[c], F3D)
        assert np.abs(tensor(cell["cauchy_stress"])[c] - want).max() < 1e-7 * np.abs(want).max()


def test_region_is_the_cell_tag():
    mesh = Mesh(np.vstack([TETRA, [[1.0, 1.0, 1.0]]]),
                [CellBlock("tetra", [[0, 1, 2, 3]], tags=[7]), CellBlock("tetra", [[1, 2, 3, 4]])])
    assert list(fm.cell_regions(mesh)) == [7, -1]


# -- scene key, refusals, kernels without stress --------------------------------------------------
TINY = """
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [2, 1, 1]
element = "tetra"
[[material]]
law = "hooke"
quadrature = "gauss1"
E = 1.0e6
nu = 0.3
density = 1000.0
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "static"
steps = 1
"""


@pytest.mark.parametrize("value, message", [
    ('["von_mises", "vonmises"]', "output.fields[1]: unknown field 'vonmises'; known fields: cauchy_stress, von_mises"),
    ('["pressure", "pressure"]', "output.fields[1]: field 'pressure' is listed twice"),
    ('["pressure", "pressure@point"]', "output.fields[1]: field 'pressure' is listed twice as point data"),
    ('["det_F_min@point"]', "output.fields[0]: 'det_F_min@point': det_F_min is written as cell data only"),
    ('["von_mises@node"]', "output.fields[0]: 'von_mises@node': the location after @ is cell or point"),
    ('[3]', "output.fields[0]: expected a field name (string), got int 3"),
    ('"von_mises"', "output.fields: expected an array of field names, got string"),
])
def test_bad_field_names_are_refused(value, message):
    with pytest.raises(SceneError, match=message.replace("[", r"\[").replace("]", r"\]").replace("(", r"\(")
                       .replace(")", r"\)")):
        Scene.from_string(TINY + f"[output]\nfields = {value}\n", load_mesh=False)


def test_scene_key_default_and_none():
    assert Scene.from_string(TINY, load_mesh=False).output.fields is None            # the default
    assert Scene.from_string(TINY + "[output]\nfields = []\n", load_mesh=False).output.fields == ()
    chosen = Scene.from_string(TINY + '[output]\nfields = ["law", "von_mises"]\n', load_mesh=False).output.fields
    assert chosen == ("law", "von_mises")
    assert set(fm.DEFAULT_FIELDS) <= set(fm.FIELDS) and "reaction" in fm.FIELDS
    both = Scene.from_string(TINY + '[output]\nfields = ["von_mises", "von_mises@cell"]\n', load_mesh=False)
    assert fm.locations(both.output.fields) == {"von_mises": ["point", "cell"]}


def test_each_default_field_is_written_once(python_kernels):
    """One location per default field: a frame carries each of them as point or as cell data."""
    for name in fm.DEFAULT_FIELDS:
        assert len(fm.FIELDS[name].where) == 1 and fm.locations([name]) == {name: list(fm.FIELDS[name].where)}
    python_kernels("tetra", "hooke")
    model = one_cell("tetra", "hooke")
    point, cell = fm.evaluate(model, np.zeros(12), fm.DEFAULT_FIELDS)
    assert sorted(list(point) + list(cell)) == sorted(fm.DEFAULT_FIELDS)


class _NoStress:
    """A hand-written kernel (here a generated one without its stress function)."""

    def __init__(self, kernel):
        self._k = kernel
        for a in custom_kernels.REQUIRED_ATTRIBUTES:
            setattr(self, a, getattr(kernel, a))
        self.backend = "python"

    def __getattr__(self, name):
        if name in custom_kernels.REQUIRED_METHODS:
            return getattr(self._k, name)
        raise AttributeError(name)

    def __repr__(self):
        return "<no-stress kernel>"


def test_kernels_without_stress_refuse_stress_fields_and_the_default_leaves_them_out():
    custom_kernels.register_kernel("tetra", "hooke", "gauss1", _NoStress(interpreted("tetra", "hooke", "gauss1")))
    try:
        model = one_cell("tetra", "hooke")
        with pytest.raises(TensormassError, match=r"von_mises need the stress records .* tetra/hooke/gauss1 "
                                                  r"\(<no-stress kernel>\) has no stress\(\)"):
            fm.check_available(model, ["law", "von_mises"])
        with pytest.raises(TensormassError, match="has no stress"):
            fm.evaluate(model, np.zeros(12), ["cauchy_stress"])
        assert fm.resolve(model) == ()                       # the default: nothing it cannot give
        point, cell = fm.evaluate(model, np.zeros(12), ["material", "law"])
        assert point == {} and list(cell["material"]) == [0] and list(cell["law"]) == [0]
    finally:
        custom_kernels.unregister_kernel("tetra", "hooke", "gauss1")


def test_reaction_is_reserved_for_runtime_reactions(python_kernels):
    python_kernels("tetra", "hooke")
    model = one_cell("tetra", "hooke")
    with pytest.raises(TensormassError, match="'reaction' is computed by runtime.physics.reactions"):
        fm.check_available(model, ["reaction"])
    point, _ = fm.evaluate(model, np.zeros(12), ["reaction"], providers={"reaction": lambda: np.ones((4, 3))})
    assert point["reaction"].shape == (4, 3)


# -- the frames -----------------------------------------------------------------------------------
def test_fields_in_the_vtu_frames_read_back_with_meshio(tmp_path):
    """Compiled kernels, the real writer: default fields, the listed ones, and none."""
    runs = {"default": "", "listed": '[output]\nfields = ["green_lagrange", "material", "energy_density"]\n',
            "none": "[output]\nfields = []\n"}
    frames = {}
    for name, extra in runs.items():
        scene = Scene.from_string(TINY + extra)
        data = run_scene(scene, out=tmp_path / name, quiet=True)
        assert data["exit_code"] == 0
        frames[name] = meshio.read(tmp_path / name / "frame_000001.vtu")
        if name == "listed":
            assert data["fields"]["names"] == ["green_lagrange", "material", "energy_density"]
            assert data["fields"]["fields"]["energy_density"]["unit"] == "J/m^3"
    m = frames["default"]
    assert set(m.point_data) == {"displacement", "von_mises"}          # each default field once
    assert set(m.cell_data) == {"cauchy_stress", "det_F_min"}
    sigma = m.cell_data["cauchy_stress"][0]
    assert sigma.shape == (12, 9) and sigma.dtype == np.float32 and m.point_data["displacement"].dtype == np.float64
    assert np.abs(sigma).max() > 1.0                         # gravity stresses the bar
    assert np.all(m.cell_data["det_F_min"][0] > 0.99)
    listed = frames["listed"]
    assert set(listed.cell_data) == {"green_lagrange", "material", "energy_density"}
    assert listed.cell_data["material"][0].dtype.kind == "i"
    assert set(frames["none"].point_data) == {"displacement"} and not frames["none"].cell_data


def test_simulation_fields_match_the_frames(tmp_path):
    """Simulation.fields() at the end of a run = the last frame's data (same scene, same bits)."""
    from tensormass.runtime.run.simulation import Simulation
    scene_text = TINY + ('[output]\nfields = ["von_mises", "von_mises@cell", "cauchy_stress@point", "cauchy_stress", '
                         '"det_F_min", "law"]\n')
    run_scene(Scene.from_string(scene_text), out=tmp_path, quiet=True)
    frame = meshio.read(tmp_path / "frame_000001.vtu")
    sim = Simulation(Scene.from_string(scene_text))
    sim.run()
    point, cell = sim.fields()
    assert set(point) == {"von_mises", "cauchy_stress"} and set(cell) == {"von_mises", "cauchy_stress", "det_F_min", "law"}
    for name, values in point.items():                     # stress fields are stored as float32
        assert np.array_equal(frame.point_data[name], values.astype(frame.point_data[name].dtype))
    for name, values in cell.items():
        assert np.array_equal(frame.cell_data[name][0], values.astype(frame.cell_data[name][0].dtype))
    s = cell["cauchy_stress"].reshape(-1, 3, 3)
    dev = s - np.trace(s, axis1=1, axis2=2)[:, None, None] / 3 * np.eye(3)
    assert np.allclose(cell["von_mises"], np.sqrt(1.5 * (dev * dev).sum(axis=(1, 2))), rtol=1e-12)
    _, only = sim.fields(["energy_density"])
    assert set(only) == {"energy_density"} and np.all(only["energy_density"] > 0)
    with pytest.raises(TensormassError, match=r"fields\[0\]: unknown field 'stress'"):
        sim.fields(["stress"])
