"""Scenes (parsing and validation), the VTU/PVD writer and the `run` / `demo` commands."""
from __future__ import annotations

import argparse
import copy
import io
import json
import math
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np
import pytest

from tensormass.apps import commands
from tensormass.apps.commands import ProgressBar, add_commands, demo_text
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.mesh.io import to_meshio
from tensormass.runtime.run.output import Writer
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.base.errors import SceneError

ROOT = Path(__file__).resolve().parents[3]
EXAMPLES = sorted((ROOT / "examples").glob("*.toml"))

BASE = {
    "mesh": {"generate": "bar", "size": [1.2, 0.2, 0.2], "cells": [4, 1, 1], "element": "hexahedron"},
    "material": [{"region": "all", "law": "stvk", "quadrature": "gauss2", "E": 1e8, "nu": 0.3, "density": 800.0}],
    "fixed": [{"box": [[-1e-9, -1, -1], [1e-9, 1, 1]]}],
    "loads": {"gravity": [0.0, 0.0, -9.81]},
    "solver": {"kind": "static", "steps": 1},
    "probe": [{"name": "tip", "point": [1.2, 0.1, 0.1]}],
}

BASE_2D = {
    "mesh": {"generate": "bar", "size": [1.2, 0.2], "cells": [4, 1], "element": "triangle6"},
    "material": [{"law": "hooke", "E": 1e8, "nu": 0.3}],
    "fixed": [{"box": [[-1e-9, -1], [1e-9, 1]]}],
    "loads": {"gravity": [0.0, -9.81]},
}


def scene_with(change, base=BASE):
    data = copy.deepcopy(base)
    change(data)
    return data


def _set(path, value):
    """A change setting data[a][b]... = value (integers index arrays)."""
    def change(data):
        node = data
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value
    return change


def _delete(path):
    def change(data):
        node = data
        for k in path[:-1]:
            node = node[k]
        del node[path[-1]]
    return change


# ============================================================================== parsing


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_examples_parse(path):
    scene = Scene.from_toml(path)
    mesh = scene.load_mesh()
    assert mesh.n_cells > 0 and scene.materials and scene.fixed
    assert scene.name == path.stem
    assert all(len(w) and (w >= 0).all() for w in scene.assign_materials(mesh))
    assert len(scene.loads.gravity) == mesh.dim


def test_expected_examples_exist():
    names = {p.stem for p in EXAMPLES}
    for e in ("hexahedron", "tetra", "tetra10", "wedge", "pyramid"):
        assert f"cantilever_{e}" in names
    assert {"mixed_bar", "soft_block_squeezed", "cantilever_2d_triangle6"} <= names


def test_demo_scene_parses():
    scene = Scene.from_string(demo_text(), name="demo")
    mesh = scene.load_mesh()
    assert mesh.cell_types() == ["hexahedron", "wedge", "pyramid", "tetra"]
    assert scene.mesh.size == (8.0, 1.0, 1.0)
    assert [p.name for p in scene.probes] == ["tip"]
    laws = {blk.type: scene.materials[int(w[0])].law for blk, w in zip(mesh.blocks, scene.assign_materials(mesh))}
    assert laws == {"hexahedron": "hooke", "wedge": "hooke", "pyramid": "stvk", "tetra": "stvk"}


def test_base_scene_values():
    s = Scene.from_dict(copy.deepcopy(BASE))
    assert s.mesh.cells == (4, 1, 1) and s.mesh.element == "hexahedron"
    m = s.materials[0]
    assert (m.E, m.nu, m.density, m.law, m.quadrature) == (1e8, 0.3, 800.0, "stvk", "gauss2")
    assert s.fixed[0].displacement is None and s.fixed[0].components is None
    assert s.loads.gravity == (0.0, 0.0, -9.81)
    assert s.probes[0].point == (1.2, 0.1, 0.1)
    assert s.output.dir is None and s.output.every == 1
    assert s.dim == 3


def test_full_schema():
    data = scene_with(lambda d: d.update({
        "name": "x", "description": "y",
        "fixed": [{"box": [[-1e-9, -1, -1], [1e-9, 1, 1]]},
                  {"box": [[1.2, -1, -1], [1.3, 1, 1]], "displacement": [0, 0, -0.01], "components": [2]}],
        "loads": {"gravity": [0, 0, -9.81],
                  "force": [{"box": [[1.2, -1, -1], [1.3, 1, 1]], "value": [0, 0, -10]}],
                  "traction": [{"box": [[1.2, -1, -1], [1.3, 1, 1]], "value": [0, 0, -100]}]},
        "solver": {"kind": "implicit_euler", "dt": 0.005, "steps": 3, "linear": "cg", "rayleigh": [0.1, 0.01],
                   "backend": "c", "cg_tolerance": 1e-6, "cg_max_iterations": 20, "newton_tolerance": 1e-7,
                   "newton_max_iterations": 5, "project_psd": True},
        "output": {"dir": "out", "every": 2},
    }))
    s = Scene.from_dict(data)
    assert s.fixed[1].displacement == (0.0, 0.0, -0.01) and s.fixed[1].components == (2,)
    assert [(n.kind, n.force) for n in s.loads.nodal] == [("force", (0.0, 0.0, -10.0)), ("traction", (0.0, 0.0, -100.0))]
    sv = s.solver
    assert (sv.kind, sv.dt, sv.steps, sv.linear, sv.rayleigh, sv.backend) == ("implicit_euler", 0.005, 3, "cg", (0.1, 0.01), "c")
    assert (sv.cg_max_iterations, sv.newton_max_iterations, sv.project_psd) == (20, 5, True)
    assert (s.output.dir, s.output.every, s.name, s.description) == ("out", 2, "x", "y")


def test_native_parameters_and_regions():
    mats = [{"region": "hexahedron", "box": [[-1, -1, -1], [0.6, 1, 1]], "law": "neohookean", "mu": 3e7, "lam": 5e7},
            {"region": "all", "law": "mooney_rivlin", "C10": 1e6, "C01": 2e5, "kappa": 1e8, "density": 900}]
    s = Scene.from_dict(scene_with(_set(["material"], mats)))
    assert s.materials[0].params == {"mu": 3e7, "lam": 5e7} and s.materials[0].E is None
    assert s.materials[1].native_parameters() == {"C10": 1e6, "C01": 2e5, "kappa": 1e8}
    (which,) = s.assign_materials()
    assert which.tolist() == [0, 0, 1, 1]     # centroids at x = 0.15, 0.45 | 0.75, 1.05


def test_exact_quadrature_on_tetra():
    s = Scene.from_dict(scene_with(lambda d: (d["mesh"].update(element="tetra"),
                                              d["material"][0].update(quadrature="exact"))))
    assert s.materials[0].quadrature == "exact"


def test_two_dimensional_scene():
    s = Scene.from_dict(copy.deepcopy(BASE_2D))
    assert s.dim == 2 and s.loads.gravity == (0.0, -9.81)
    s = Scene.from_dict(scene_with(_delete(["loads", "gravity"]), BASE_2D))
    assert s.loads.gravity == (0.0, 0.0)


def test_2d_default_element_is_quad():
    data = scene_with(_delete(["mesh", "element"]), BASE_2D)
    s = Scene.from_dict(data)
    assert s.mesh.element == "quad" and s.load_mesh().cell_types() == ["quad"]


@pytest.mark.parametrize("name", ["mixed_bar", "cantilever_2d_triangle6"])
def test_material_assignment_matches_the_model(name):
    from tensormass.runtime.model.model import assign_materials
    s = Scene.from_toml(ROOT / "examples" / f"{name}.toml")
    mesh = s.load_mesh()
    for mine, theirs in zip(s.assign_materials(mesh), assign_materials(mesh, s.materials)):
        np.testing.assert_array_equal(mine, theirs)


def test_mesh_file_relative_to_scene(tmp_path):
    mesh = generate_bar((1.0, 0.2, 0.2), (3, 1, 1), "wedge")
    sub = tmp_path / "meshes"
    sub.mkdir()
    meshio.write(sub / "organ.vtu", to_meshio(mesh))
    text = """
[mesh]
file = "meshes/organ.vtu"
[[material]]
law = "hooke"
E = 1e6
nu = 0.3
[[fixed]]
box = [[0, 0, 0], [0, 1, 1]]
"""
    (tmp_path / "scene.toml").write_text(text)
    s = Scene.from_toml(tmp_path / "scene.toml")
    assert Path(s.mesh.file) == sub / "organ.vtu"
    assert s.load_mesh().cell_types() == ["wedge"] and s.loads.gravity == (0.0, 0.0, 0.0)
    (tmp_path / "bad.toml").write_text(text.replace("meshes/organ.vtu", "organ.msh"))
    with pytest.raises(SceneError, match=r"mesh\.file: mesh file not found: .*organ\.msh"):
        Scene.from_toml(tmp_path / "bad.toml")
    # a 2-component gravity on a 3D file mesh is only detectable once the mesh is read
    (tmp_path / "g2.toml").write_text(text + "[loads]\ngravity = [0, -9.81]\n")
    with pytest.raises(SceneError, match=r"loads\.gravity: expected 3 components"):
        Scene.from_toml(tmp_path / "g2.toml")


# ============================================================================== validation errors

CASES = [
    # (change, message pattern)
    (_set(["meshh"], {}), r"^meshh: unknown table or key; allowed: name, description, mesh, material"),
    (_set(["material", 0, "Young"], 1.0), r"^material\[0\]\.Young: unknown key; allowed keys in \[material\]: .*E, nu"),
    (_set(["solver", "dtt"], 1.0), r"^solver\.dtt: unknown key; allowed keys in \[solver\]: kind, dt, steps"),
    (_set(["mesh", "colour"], 1), r"^mesh\.colour: unknown key"),
    (_set(["probe", 0, "where"], 1), r"^probe\[0\]\.where: unknown key"),
    (_set(["loads", "force"], [{"box": [[0, 0, 0], [1, 1, 1]], "value": [0, 0, 1], "extra": 1}]),
     r"^loads\.force\[0\]\.extra: unknown key"),
    (_set(["solver", "steps"], "10"), r"^solver\.steps: expected an integer, got string"),
    (_set(["solver", "steps"], 2.0), r"^solver\.steps: expected an integer, got float"),
    (_set(["material", 0, "E"], "1e8"), r"^material\[0\]\.E: expected a number, got string"),
    (_set(["material", 0, "E"], True), r"^material\[0\]\.E: expected a number, got boolean"),
    (_set(["material", 0, "E"], "__import__('os').system('true')"), r"^material\[0\]\.E: expected a number"),
    (_set(["mesh", "size"], 1.2), r"^mesh\.size: expected an array"),
    (_set(["material"], {"law": "stvk", "E": 1.0, "nu": 0.2, "region": "all", "box": "x"}), r"^material\[0\]\.box"),
    (_set(["material", 0, "law"], "rubber"), r"^material\[0\]\.law: unknown law 'rubber'; known laws: cst_dkt, hgo, hgo2, hooke, hybmss, mooney_rivlin"),
    (_set(["mesh", "element"], "octahedron"), r"^mesh\.element: unknown value 'octahedron'; allowed: hexahedron"),
    (_set(["mesh", "element"], "quad"), r"^mesh\.element: 'quad' is not a 3D element"),
    (_set(["mesh", "generate"], "torus"), r"^mesh\.generate: unknown value 'torus'"),
    (_set(["material", 0, "quadrature"], "gauss9"), r"^material\[0\]\.quadrature: unknown quadrature gauss9"),
    (_set(["material", 0, "quadrature"], "exact"),
     r"^material\[0\]\.quadrature: quadrature 'exact' is not available for hexahedron with law 'stvk'; available: gauss1, gauss2, gauss3"),
    (_set(["material", 0, "region"], "octahedron"), r"^material\[0\]\.region: unknown region 'octahedron'"),
    (_set(["material", 0, "region"], 1.5), r"^material\[0\]\.region: expected"),
    (_set(["material", 0, "E"], 0.0), r"^material\[0\]\.E: Young's modulus must be > 0 \(got 0\)"),
    (_set(["material", 0, "E"], -5.0), r"^material\[0\]\.E: Young's modulus must be > 0"),
    (_set(["material", 0, "nu"], 0.5), r"^material\[0\]\.nu: Poisson's ratio must be < 0.5 \(got 0.5\)"),
    (_set(["material", 0, "nu"], -1.0), r"^material\[0\]\.nu: Poisson's ratio must be > -1"),
    (_set(["material", 0, "E"], math.nan), r"^material\[0\]\.E: must be a finite number \(got nan\)"),
    (_set(["material", 0, "nu"], math.inf), r"^material\[0\]\.nu: must be a finite number \(got inf\)"),
    (_set(["loads", "gravity"], [0.0, 0.0, math.nan]), r"^loads\.gravity\[2\]: must be a finite number"),
    (_set(["probe", 0, "point"], [math.inf, 0, 0]), r"^probe\[0\]\.point\[0\]: must be a finite number"),
    (_set(["fixed", 0, "box"], [[math.nan, 0, 0], [1, 1, 1]]), r"^fixed\[0\]\.box\[0\]\[0\]: must be a finite"),
    (_set(["material", 0, "density"], 0.0), r"^material\[0\]\.density: must be > 0"),
    (_set(["material", 0, "density"], -800.0), r"^material\[0\]\.density: must be > 0"),
    (_delete(["material", 0, "nu"]), r"^material\[0\]\.nu: missing"),
    (lambda d: [d["material"][0].pop(k) for k in ("E", "nu")], r"^material\[0\]: needs E and nu, or the native parameters"),
    (_set(["material", 0, "mu"], 1e6), r"^material\[0\]: give either E and nu or the native parameters"),
    (lambda d: d["material"].__setitem__(0, {"law": "stvk", "mu": 1e6}), r"^material\[0\]\.lam: missing"),
    (lambda d: d["material"].__setitem__(0, {"law": "stvk", "mu": 1e6, "lam": 1e6, "C10": 1.0}),
     r"^material\[0\]\.C10: unknown key; allowed keys in \[material\]: .*lam, mu$"),
    (lambda d: d["material"].__setitem__(0, {"law": "stvk", "mu": -1.0, "lam": 1e6}), r"^material\[0\]\.mu: shear modulus must be > 0"),
    (lambda d: d["material"].__setitem__(0, {"law": "hooke", "mu": 1.0, "lam": -1.0}), r"^material\[0\]\.lam: .*non-positive bulk"),
    (lambda d: d["material"].append({"law": "hooke", "E": 1.0, "nu": 0.5}), r"^material\[1\]\.nu: Poisson's ratio must be < 0.5 \(got 0.5\)"),
    (_set(["solver", "dt"], 0.0), r"^solver\.dt: must be > 0"),
    (_set(["solver", "dt"], -0.01), r"^solver\.dt: must be > 0"),
    (_set(["solver", "steps"], 0), r"^solver\.steps: must be >= 1 \(got 0\)"),
    (_set(["solver", "kind"], "rk4"), r"^solver\.kind: unknown value 'rk4'; allowed: static, implicit_euler, backward_euler, explicit"),
    (_set(["solver", "linear"], "qr"), r"^solver\.linear: unknown value 'qr'; allowed: auto, direct, cg, amg, band, pardiso, lu"),
    (_set(["solver", "backend"], "opencl"), r"^solver\.backend: unknown value 'opencl'; allowed: numba, c, cuda"),
    (_set(["solver", "rayleigh"], [0.1]), r"^solver\.rayleigh: expected \[alpha, beta\]"),
    (_set(["solver", "rayleigh"], [-0.1, 0.0]), r"^solver\.rayleigh\[0\]: must be >= 0"),
    (_set(["solver", "project_psd"], 1), r"^solver\.project_psd: expected true or false"),
    (_set(["solver", "cg_max_iterations"], 0), r"^solver\.cg_max_iterations: must be >= 1"),
    (_set(["solver", "newton_tolerance"], 0.0), r"^solver\.newton_tolerance: must be > 0"),
    (_set(["fixed", 0, "box"], [[1e-9, -1, -1], [-1e-9, 1, 1]]), r"^fixed\[0\]\.box: min > max in component 0"),
    (_set(["fixed", 0, "box"], [[0, 0, 0]]), r"^fixed\[0\]\.box: expected \[\[min\.\.\.\], \[max\.\.\.\]\]"),
    (_set(["fixed", 0, "box"], [[0, 0], [1, 1]]), r"^fixed\[0\]\.box\[0\]: expected 3 components, got 2 \(the mesh is 3D"),
    (_set(["fixed", 0, "box"], [[5, 5, 5], [6, 6, 6]]), r"^fixed\[0\]\.box: no mesh node inside \(mesh bounds"),
    (_set(["fixed", 0, "components"], [3]), r"^fixed\[0\]\.components: component 3 does not exist in 3D"),
    (_set(["fixed", 0, "components"], [0, 0]), r"^fixed\[0\]\.components: repeated component"),
    (_set(["fixed", 0, "displacement"], [0.0, 0.1]), r"^fixed\[0\]\.displacement: expected 3 components, got 2"),
    (_delete(["fixed", 0, "box"]), r"^fixed\[0\]\.box: missing"),
    (_set(["loads", "gravity"], [0.0, -9.81]), r"^loads\.gravity: expected 3 components, got 2"),
    (_set(["loads", "force"], [{"box": [[1.2, -1, -1], [1.3, 1, 1]], "value": [0, -10]}]), r"^loads\.force\[0\]\.value: expected 3 components"),
    (_set(["loads", "traction"], [{"box": [[1.2, -1, -1], [1.3, 1, 1]]}]), r"^loads\.traction\[0\]\.value: missing"),
    (_set(["loads", "force"], [{"box": [[9, 9, 9], [10, 10, 10]], "value": [0, 0, 1]}]), r"^loads\.force\[0\]\.box: no mesh node inside"),
    (_set(["probe", 0, "point"], [1.2, 0.1]), r"^probe\[0\]\.point: expected 3 components, got 2"),
    (lambda d: d["probe"].append({"name": "tip", "point": [0, 0, 0]}), r"^probe\[1\]\.name: duplicate probe name 'tip'"),
    (_delete(["mesh"]), r"^mesh: missing \[mesh\] table"),
    (_set(["material"], []), r"^material: no \[\[material\]\] given"),
    (_delete(["material"]), r"^material: no \[\[material\]\] given"),
    (_set(["material"], "stvk"), r"^material: expected an array of tables"),
    (lambda d: d["mesh"].update(file="x.msh"), r"^mesh: give exactly one of generate"),
    (_set(["mesh", "cells"], [4, 1]), r"^mesh\.cells: expected 3 integers"),
    (_set(["mesh", "cells"], [0, 1, 1]), r"^mesh\.cells\[0\]: must be >= 1"),
    (_set(["mesh", "size"], [1.2, 0.0, 0.2]), r"^mesh\.size\[1\]: must be > 0"),
    (lambda d: d["mesh"].update(element="mixed", cells=[3, 1, 1]), r"^mesh\.cells\[0\]: element = \"mixed\" needs at least 4 cells"),
    (_set(["material", 0, "region"], "tetra"), r"^material: 4 hexahedron cell\(s\) match no \[\[material\]\]: cells \[0, 1, 2, 3\]"),
    (_delete(["fixed"]), r"^fixed: a static scene needs at least one \[\[fixed\]\] box"),
    (_set(["name"], 3), r"^name: expected a string"),
    (lambda d: d.update(output={"every": 0}), r"^output\.every: must be >= 1 \(got 0\)"),
    (lambda d: d.update(output={"dir": ""}), r"^output\.dir: must not be empty"),
]


@pytest.mark.parametrize("change, pattern", CASES, ids=[f"case{i}" for i in range(len(CASES))])
def test_validation_errors_name_the_key(change, pattern):
    with pytest.raises(SceneError, match=pattern):
        Scene.from_dict(scene_with(change))


@pytest.mark.parametrize("change, pattern", [
    (_set(["loads", "gravity"], [0.0, 0.0, -9.81]), r"^loads\.gravity: expected 2 components, got 3 \(the mesh is 2D"),
    (_set(["mesh", "element"], "tetra"), r"^mesh\.element: 'tetra' is not a 2D element"),
    (_set(["fixed", 0, "components"], [2]), r"^fixed\[0\]\.components: component 2 does not exist in 2D"),
    (_set(["probe"], [{"point": [1.2, 0.1, 0.0]}]), r"^probe\[0\]\.point: expected 2 components"),
])
def test_validation_errors_2d(change, pattern):
    with pytest.raises(SceneError, match=pattern):
        Scene.from_dict(scene_with(change, BASE_2D))


def test_toml_syntax_error_names_the_line(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text('[mesh]\ngenerate = "bar"\nsize = [1.2, 0.2, 0.2\n[[material]]\n')
    with pytest.raises(SceneError, match=r"broken\.toml: invalid TOML: .*line \d+"):
        Scene.from_toml(path)
    with pytest.raises(SceneError, match=r"invalid TOML: .*line 2"):
        Scene.from_string("[mesh]\ngenerate = \n")


def test_missing_scene_file(tmp_path):
    with pytest.raises(SceneError, match="scene file not found"):
        Scene.from_toml(tmp_path / "nope.toml")


def test_scene_error_is_a_tensormass_error():
    assert issubclass(SceneError, TensormassError) and issubclass(SceneError, ValueError)


# ============================================================================== writer


def _mixed_mesh():
    return generate_bar((8.0, 1.0, 1.0), (4, 1, 1), "mixed")


def _pvd_entries(path):
    root = ET.parse(path).getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    return [(float(d.get("timestep")), d.get("file")) for d in root.find("Collection").findall("DataSet")]


def test_writer_series_and_pvd(tmp_path):
    mesh = _mixed_mesh()
    out = tmp_path / "out" / "run"
    w = Writer(out, mesh)
    assert not out.exists()                                   # created with the first frame
    rng = np.random.default_rng(0)
    us = []
    for k in range(3):
        u = rng.normal(size=mesh.points.shape)
        us.append(u)
        energy = np.arange(mesh.n_cells, dtype=float)
        w.write_frame(k * 5, 0.1 * k, mesh.points, u, {"speed": np.linalg.norm(u, axis=1), "energy": energy})
        assert _pvd_entries(out / "frame.pvd")[-1] == (pytest.approx(0.1 * k), f"frame_{k * 5:06d}.vtu")
    w.close()
    w.close()                                                 # idempotent
    entries = _pvd_entries(out / "frame.pvd")
    assert [f for _, f in entries] == ["frame_000000.vtu", "frame_000005.vtu", "frame_000010.vtu"]
    assert sorted(p.name for p in out.iterdir()) == sorted([f for _, f in entries] + ["frame.pvd"])  # no temp files
    back = meshio.read(out / "frame_000010.vtu")
    np.testing.assert_allclose(back.point_data["displacement"], us[-1])
    np.testing.assert_allclose(back.points, mesh.points)
    assert [c.type for c in back.cells] == ["hexahedron", "wedge", "pyramid", "tetra"]
    np.testing.assert_allclose(np.concatenate(back.cell_data["energy"]), np.arange(mesh.n_cells))
    assert back.point_data["speed"].shape == (mesh.n_points,)


def test_writer_deformed_and_2d(tmp_path):
    mesh = generate_bar((1.0, 0.2), (3, 1), "triangle6")
    u = np.full((mesh.n_points, 2), 0.01)
    w = Writer(tmp_path / "o", mesh, name="beam", deformed=True)
    w.write_frame(1, 1.0, None, u, cell_fields={"id": np.arange(mesh.n_cells)})
    back = meshio.read(tmp_path / "o" / "beam_000001.vtu")
    assert back.point_data["displacement"].shape == (mesh.n_points, 3)
    np.testing.assert_allclose(back.point_data["displacement"][:, :2], u)
    np.testing.assert_allclose(back.points[:, :2], mesh.points + u)
    np.testing.assert_allclose(back.points[:, 2], 0.0)
    assert _pvd_entries(tmp_path / "o" / "beam.pvd") == [(1.0, "beam_000001.vtu")]


@pytest.mark.parametrize("where", ["displacement", "field", "cell_field"])
def test_writer_refuses_nan_and_writes_nothing(tmp_path, where):
    mesh = _mixed_mesh()
    out = tmp_path / "out"
    w = Writer(out, mesh)
    u = np.zeros(mesh.points.shape)
    bad_u = u.copy()
    fields = {}
    if where == "displacement":
        bad_u[3, 1] = np.nan
    elif where == "field":
        fields = {"s": np.r_[np.inf, np.zeros(mesh.n_points - 1)]}
    else:
        fields = {"e": np.r_[np.zeros(mesh.n_cells - 1), np.nan]}
    with pytest.raises(TensormassError, match="NaN or Inf"):
        w.write_frame(0, 0.0, mesh.points, bad_u, fields)
    assert not out.exists()                                   # nothing created for a refused first frame
    w.write_frame(1, 0.1, mesh.points, u)
    before = sorted(p.name for p in out.iterdir())
    pvd = (out / "frame.pvd").read_text()
    with pytest.raises(TensormassError, match="NaN or Inf"):
        w.write_frame(2, 0.2, mesh.points, bad_u, fields)
    assert sorted(p.name for p in out.iterdir()) == before and (out / "frame.pvd").read_text() == pvd


def test_writer_shape_errors_and_discard(tmp_path):
    mesh = _mixed_mesh()
    w = Writer(tmp_path / "o", mesh)
    with pytest.raises(TensormassError, match="one row per point"):
        w.write_frame(0, 0.0, None, np.zeros((3, 3)))
    with pytest.raises(TensormassError, match="field 'x' has 2 rows"):
        w.write_frame(0, 0.0, None, np.zeros(mesh.points.shape), {"x": np.zeros(2)})
    assert not (tmp_path / "o").exists()
    w._make_dir()
    assert (tmp_path / "o").is_dir()
    w.discard()                                               # created by us and empty: removed
    assert not (tmp_path / "o").exists()
    keep = tmp_path / "mine"
    keep.mkdir()
    w = Writer(keep, mesh)
    w.discard()                                               # not ours: kept
    assert keep.is_dir()
    (tmp_path / "file").write_text("x")
    with pytest.raises(TensormassError, match="not a folder"):
        Writer(tmp_path / "file", mesh)


def test_progress_bar_text():
    s = io.StringIO()
    bar = ProgressBar(stream=s, label="step")
    for k in range(1, 11):
        bar(k, 10)
    bar.finish()
    lines = s.getvalue().splitlines()
    assert lines[-1].startswith("step 10/10 [") and "100.0%" in lines[-1]
    assert len(lines) <= 5


# ============================================================================== command line


def _main(argv):
    """What apps.cli.main does with these subcommands (exit code 2 on bad input)."""
    parser = argparse.ArgumentParser(prog="tensormass")
    sub = parser.add_subparsers(dest="command", required=True)
    add_commands(sub)
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except (TensormassError, ValueError, FileNotFoundError) as error:
        print(f"tensormass: error: {error}", file=sys.stderr)
        return 2


TINY = """
name = "tiny"
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [4, 1, 1]
element = "hexahedron"
[[material]]
law = "hooke"
quadrature = "gauss2"
E = 1.0e6
nu = 0.3
density = 100.0
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "static"
steps = 2
[[probe]]
name = "tip"
point = [1.0, 0.1, 0.1]
[output]
every = 1
"""


class FakeSummary:
    def __init__(self, steps):
        self.steps = steps

    def to_dict(self):
        return {"kernels": ["hexahedron/hooke/gauss2 (numba)"],
                "time": {"setup": 0.5, "first_step": 0.2, "assembly": 0.01, "linear_solve": 0.02, "total": 0.9},
                "iterations": {"newton": 2, "linear": 2}, "probes": {"tip": [0.0, 0.0, -1e-3]},
                "energy": -1.5, "steps": self.steps}


def fake_simulation(fail_at=None, error=TensormassError("Newton did not converge in step 1")):
    class FakeSimulation:
        def __init__(self, scene, progress=None, writer=None):
            self.scene, self.progress, self.writer = scene, progress, writer
            self.mesh = scene.load_mesh()

        def run(self):
            n = self.scene.solver.steps
            for step in range(1, n + 1):
                if fail_at == step:
                    raise error
                u = np.zeros(self.mesh.points.shape)
                u[:, 2] = -1e-3 * step * self.mesh.points[:, 0]
                if self.writer is not None and step % self.scene.output.every == 0:
                    self.writer.write_frame(step, float(step), self.mesh.points, u, {})
                if self.progress:
                    self.progress(step, n)
            if self.writer is not None:
                self.writer.close()
            return FakeSummary(n)
    return FakeSimulation


@pytest.fixture
def tiny(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


def test_run_bad_scene_exits_2_and_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(commands, "_simulation_class", lambda: pytest.fail("must not get that far"))
    bad = tmp_path / "bad.toml"
    bad.write_text(TINY.replace("nu = 0.3", "nu = 0.5"))
    out, js = tmp_path / "out", tmp_path / "s.json"
    assert _main(["run", str(bad), "--out", str(out), "--json", str(js)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tensormass: error: material[0].nu: Poisson's ratio must be < 0.5 (got 0.5)")
    assert not out.exists() and not js.exists()
    bad.write_text(TINY.replace("[solver]", "[solver\n"))
    assert _main(["run", str(bad), "--out", str(out)]) == 2
    assert "invalid TOML" in capsys.readouterr().err and not out.exists()
    assert _main(["run", str(tmp_path / "missing.toml"), "--out", str(out)]) == 2
    assert "scene file not found" in capsys.readouterr().err and not out.exists()


def test_run_bad_json_path_checked_first(tiny, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(commands, "_simulation_class", lambda: fake_simulation())
    out = tmp_path / "out"
    assert _main(["run", str(tiny), "--out", str(out), "--json", str(tmp_path / "no" / "s.json")]) == 2
    assert "does not exist" in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize("error", [TensormassError("Newton did not converge"),
                                   np.linalg.LinAlgError("singular matrix"), FloatingPointError("overflow")])
def test_run_failing_before_first_frame_leaves_no_folder(tiny, tmp_path, capsys, monkeypatch, error):
    monkeypatch.setattr(commands, "_simulation_class", lambda: fake_simulation(fail_at=1, error=error))
    out, js = tmp_path / "out", tmp_path / "s.json"
    assert _main(["run", str(tiny), "--out", str(out), "--json", str(js)]) == 2
    assert str(error) in capsys.readouterr().err
    assert not out.exists() and not js.exists()


def test_run_failing_later_keeps_finished_frames(tiny, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(commands, "_simulation_class", lambda: fake_simulation(fail_at=2))
    out = tmp_path / "out"
    assert _main(["run", str(tiny), "--out", str(out), "--quiet"]) == 2
    assert _pvd_entries(out / "frame.pvd") == [(1.0, "frame_000001.vtu")]
    assert meshio.read(out / "frame_000001.vtu").point_data["displacement"].shape[1] == 3


def test_run_with_mock_simulation(tiny, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(commands, "_simulation_class", lambda: fake_simulation())
    out, js = tmp_path / "out", tmp_path / "summary.json"
    assert _main(["run", str(tiny), "--out", str(out), "--json", str(js)]) == 0
    captured = capsys.readouterr()
    data = json.loads(js.read_text())
    assert {"kernels", "time", "iterations", "probes", "energy", "steps", "scene", "output"} <= set(data)
    assert data["output"]["frames"] == 2 and data["scene"]["cells"] == {"hexahedron": 4}
    assert [f for _, f in _pvd_entries(out / "frame.pvd")] == ["frame_000001.vtu", "frame_000002.vtu"]
    for word in ("probe tip", "Newton 2", "before 1st step", "time per step", "final energy", "frame.pvd", str(js)):
        assert word in captured.out
    assert "load step 2/2" in captured.err                   # progress bar on stderr


def test_demo_with_mock_simulation(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(commands, "_simulation_class", lambda: fake_simulation())
    monkeypatch.chdir(tmp_path)
    assert _main(["demo"]) == 0
    text = capsys.readouterr().out
    assert "Euler-Bernoulli 0.6027 m" in text and "tensormass-demo" in text
    assert (tmp_path / "tensormass-demo" / "frame.pvd").is_file()


# ============================================================================== with the real runtime


REQUIRED = {"kernels": None, "time": {"setup", "first_step", "assembly", "linear_solve", "total"},
            "iterations": {"newton", "linear"}, "probes": None, "energy": None, "steps": None}


def test_run_real_simulation(tiny, tmp_path, capsys):
    out, js = tmp_path / "out", tmp_path / "summary.json"
    assert _main(["run", str(tiny), "--out", str(out), "--json", str(js)]) == 0, capsys.readouterr().err
    data = json.loads(js.read_text())
    for key, sub in REQUIRED.items():
        assert key in data
        if sub:
            assert sub <= set(data[key])
    assert data["steps"] == 2 and set(data["probes"]) == {"tip"}
    assert data["probes"]["tip"][2] < 0                       # it sags
    frames = _pvd_entries(out / "frame.pvd")
    assert frames and all((out / f).is_file() for _, f in frames)
    back = meshio.read(out / frames[-1][1])
    assert np.isfinite(back.point_data["displacement"]).all()


def test_demo_real(tmp_path, capsys):
    js = tmp_path / "demo.json"
    assert _main(["demo", "--out", str(tmp_path / "demo"), "--json", str(js)]) == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "tip deflection" in text and "Euler-Bernoulli" in text
    data = json.loads(js.read_text())
    ratio = -data["probes"]["tip"][2] / 0.6027264
    assert 0.3 < ratio < 1.2
    assert (tmp_path / "demo" / "frame.pvd").is_file()
