"""Resource estimates (runtime.scene.resources): counts without building, limits, refusals before allocating."""
from __future__ import annotations

import tracemalloc
from types import SimpleNamespace

import meshio
import numpy as np
import pytest

from tensormass.apps.cli import main
from tensormass.runtime.mesh import bars as mesh_module
from tensormass.runtime.scene import resources
from tensormass.runtime.mesh.bars import bar_counts, generate_bar
from tensormass.runtime.mesh.io import to_meshio
from tensormass.runtime.scene.resources import MeshCounts, ResourceError, estimate, limit_bytes, parse_size
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.scene.types import Solver

GiB = 2 ** 30


def bar_scene(cells=(4, 1, 1), element="hexahedron", **solver):
    return {"mesh": {"generate": "bar", "size": [1.0, 0.2, 0.2][:len(cells)], "cells": list(cells),
                     "element": element},
            "material": [{"law": "stvk", "E": 1e6, "nu": 0.3}],
            "fixed": [{"box": [[-1e-9, -1, -1][:len(cells)], [1e-9, 1, 1][:len(cells)]]}],
            "loads": {"gravity": [0.0, 0.0, -9.81][:len(cells)]},
            "solver": {"kind": "implicit_euler", "steps": 2, **solver}}


@pytest.fixture
def no_generation(monkeypatch):
    """A bar too big to build must never reach the generator."""
    monkeypatch.setattr(mesh_module, "generate_bar", lambda *a, **k: pytest.fail("the bar was generated"))


# ------------------------------------------------------------------------------ counts


@pytest.mark.parametrize("element,cells", [
    ("hexahedron", (3, 2, 2)), ("tetra", (3, 2, 1)), ("tetra10", (2, 3, 2)), ("wedge", (3, 2, 2)),
    ("pyramid", (2, 2, 3)), ("mixed", (4, 1, 1)), ("mixed", (9, 2, 3)),
    ("quad", (3, 2)), ("triangle", (3, 2)), ("triangle6", (3, 2)), ("mixed", (5, 3)),
])
def test_bar_counts_match_the_generated_bar(element, cells):
    mesh = generate_bar((1.0, 0.3, 0.2)[:len(cells)], cells, element)
    built = {}
    for b in mesh.blocks:
        built[b.type] = built.get(b.type, 0) + len(b)
    assert bar_counts(cells, element) == (built, mesh.n_points)


def test_counts_of_a_bar_and_of_its_mesh_give_the_same_estimate():
    scene = Scene.from_dict(bar_scene((12, 3, 3), "tetra"), load_mesh=False)
    from_spec = estimate(scene)
    scene.load_mesh()
    from_mesh = estimate(scene)
    assert from_spec.cells == from_mesh.cells == {"tetra": 6 * 12 * 9}
    assert from_spec.nodes == from_mesh.nodes
    assert from_mesh.bytes == pytest.approx(from_spec.bytes, rel=0.02)


@pytest.mark.parametrize("element", ["hexahedron", "tetra", "tetra10", "wedge", "pyramid"])
def test_nonzeros_are_estimated_from_above(element):
    from tensormass.runtime.assembly.assembly import SparsePattern
    mesh = generate_bar((1.0, 0.2, 0.2), (12, 3, 3), element)
    dofs = [(b.cells[:, :, None] * 3 + np.arange(3)).reshape(len(b), -1) for b in mesh.blocks]
    nnz = SparsePattern(dofs, mesh.n_points * 3).nnz
    est = estimate(MeshCounts.of_mesh(mesh))
    assert nnz <= est.nnz <= 2 * nnz


# ------------------------------------------------------------------------------ limits


def test_sizes_and_limits(monkeypatch):
    assert parse_size("8G") == 8 * GiB
    assert parse_size("500M") == 500 * 2 ** 20
    assert parse_size("1.5GiB") == int(1.5 * GiB)
    assert parse_size("2e9") == 2_000_000_000
    assert parse_size(12345) == 12345
    for bad in ("lots", "-1G", "0", "8X", True, float("nan")):
        with pytest.raises(ResourceError, match="--max-memory"):
            parse_size(bad)
    monkeypatch.delenv(resources.ENV_MAX_MEMORY, raising=False)
    monkeypatch.setattr(resources, "available_memory", lambda: 10 * GiB)
    monkeypatch.setattr(resources, "own_rss", lambda: 2 ** 28)           # already resident: not in MemAvailable
    assert limit_bytes(None)[0] == int(10 * GiB * resources.SAFETY_FRACTION) + 2 ** 28
    monkeypatch.setenv(resources.ENV_MAX_MEMORY, "3G")
    assert limit_bytes(None) == (3 * GiB, resources.ENV_MAX_MEMORY)
    assert limit_bytes("1G")[0] == GiB                          # the argument beats the environment
    monkeypatch.setenv(resources.ENV_MAX_MEMORY, "plenty")
    with pytest.raises(ResourceError, match=resources.ENV_MAX_MEMORY):
        limit_bytes(None)


def test_available_memory_reads_the_machine_and_its_cgroup(tmp_path, monkeypatch):
    avail = resources.available_memory()
    assert avail is None or avail > 0
    assert resources.own_rss() > 0
    limit, usage, stat = tmp_path / "memory.max", tmp_path / "memory.current", tmp_path / "memory.stat"
    limit.write_text("1073741824\n")
    usage.write_text(str(600 * 2 ** 20))
    stat.write_text("anon 1\ninactive_file 104857600\n")
    monkeypatch.setattr(resources, "_CGROUPS", ((str(limit), str(usage), str(stat), "inactive_file"),))
    assert resources._cgroup_free() == GiB - 500 * 2 ** 20           # page cache it can drop is not used
    assert resources.available_memory() <= GiB - 500 * 2 ** 20
    limit.write_text("max\n")
    assert resources._cgroup_free() is None


def test_history_rows_cover_what_a_run_keeps():
    from tensormass.runtime.run import simulation
    assert resources.HISTORY_ROWS >= simulation.HISTORY_MAX


def test_compact_bodies_are_estimated_with_pardiso_when_mkl_is_there(monkeypatch):
    """A compact body past the band's sweet spot: the estimate counts a nested-dissection factor
    (~12 bytes x 18 n^(4/3)), far below the band's n kd; without MKL, the band as before."""
    from tensormass.runtime.solve import pardiso
    _mkl = pardiso.available()
    counts = resources.MeshCounts(dim=3, nodes=31 ** 3, cells={"tetra": 6 * 30 ** 3}, layers=30.0)
    est = resources.estimate(counts, materials=[], solver=Solver(kind="static"))
    direct = resources.estimate(counts, materials=[], solver=Solver(kind="static", linear="direct"))
    if pardiso.available():
        assert est.band == 0 and direct.band == 0 and direct.bytes == est.bytes
    monkeypatch.setattr(pardiso, "available", lambda: False)
    band = resources.estimate(counts, materials=[], solver=Solver(kind="static", linear="direct"))
    assert band.band > 0
    if _mkl:                                       # the band factor (n kd) outweighs nested dissection
        assert band.bytes > direct.bytes


# ------------------------------------------------------------------------------ refusals


def test_huge_bar_is_refused_before_it_is_generated(no_generation):
    data = bar_scene((1000, 1000, 300))
    with pytest.raises(ResourceError) as info:
        Scene.from_dict(data, max_memory="8G")
    text = str(info.value)
    assert "300,000,000 hexahedron cells" in text and "TiB" in text
    assert "above the limit of 8 GiB" in text and "--max-memory" in text


def test_huge_bar_is_refused_with_the_machine_default(no_generation, monkeypatch):
    monkeypatch.delenv(resources.ENV_MAX_MEMORY, raising=False)
    monkeypatch.setattr(resources, "available_memory", lambda: 64 * GiB)
    with pytest.raises(ResourceError, match=r"80% of the 64 GiB available"):
        Scene.from_dict(bar_scene((1000, 1000, 300)))


def test_mesh_file_is_refused_right_after_reading(tmp_path, monkeypatch):
    path = tmp_path / "part.vtu"
    meshio.write(path, to_meshio(generate_bar((1.0, 0.2, 0.2), (8, 2, 2), "tetra")))
    data = bar_scene()
    data["mesh"] = {"file": str(path)}
    # nothing that scales with the mesh may run: the scene's checks against it come first
    monkeypatch.setattr(Scene, "validate", lambda *a, **k: pytest.fail("validated a refused mesh"))
    with pytest.raises(ResourceError, match=r"192 tetra cells, 81 nodes.*above the limit of 1 MiB"):
        Scene.from_dict(data, max_memory="1M")


def test_model_checks_the_limit_before_building(monkeypatch):
    from tensormass.runtime.model import model as model_module
    from tensormass.runtime.model.model import Model
    from tensormass.runtime.scene.types import Material
    mesh = generate_bar((1.0, 0.2, 0.2), (6, 2, 2))
    monkeypatch.setattr(model_module, "check_mesh", lambda m: pytest.fail("checked a refused mesh"))
    with pytest.raises(ResourceError, match="model 'model' needs an estimated"):
        Model(mesh, [Material(E=1e6, nu=0.3)], max_memory="1M")


def test_python_api_and_environment(tmp_path, monkeypatch):
    from tensormass.runtime.model.model import Model
    text = ('[mesh]\ngenerate = "bar"\ncells = [4, 1, 1]\n[[material]]\nE = 1e6\nnu = 0.3\n'
            '[[fixed]]\nbox = [[0, 0, 0], [0, 1, 1]]\n')
    path = tmp_path / "s.toml"
    path.write_text(text)
    with pytest.raises(ResourceError, match="above the limit of 10 MiB"):
        Scene.from_toml(path, max_memory=10 * 2 ** 20)
    scene = Scene.from_toml(path, load_mesh=False, max_memory="10M")     # what Simulation(scene) goes through
    with pytest.raises(ResourceError):
        Model.from_scene(scene)
    monkeypatch.setenv(resources.ENV_MAX_MEMORY, "10M")
    with pytest.raises(ResourceError, match=f"10 MiB \\({resources.ENV_MAX_MEMORY}\\)"):
        Scene.from_toml(path)
    scene = Scene.from_toml(path, max_memory="64G")
    assert scene.estimate is not None and scene.estimate.bytes > resources.BASELINE
    assert Model.from_scene(scene).estimate is scene.estimate


def test_cli_max_memory(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv(resources.ENV_MAX_MEMORY, raising=False)
    path = tmp_path / "big.toml"
    path.write_text('[mesh]\ngenerate = "bar"\ncells = [1000, 1000, 300]\n[[material]]\nE = 1e6\nnu = 0.3\n'
                    '[[fixed]]\nbox = [[0, 0, 0], [0, 1, 1]]\n')
    monkeypatch.setattr(mesh_module, "generate_bar", lambda *a, **k: pytest.fail("the bar was generated"))
    assert main(["run", str(path), "--max-memory", "16G", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tensormass: error: scene 'big' needs an estimated") and "16 GiB" in err
    assert not (tmp_path / "out").exists()
    assert main(["run", str(path), "--max-memory", "sixteen"]) == 2
    assert "--max-memory: expected a size" in capsys.readouterr().err
    assert main(["demo", "--max-memory", "1M", "--out", str(tmp_path / "demo")]) == 2
    assert "above the limit of 1 MiB" in capsys.readouterr().err


def test_refinement_rounds_grow_the_estimate():
    data = bar_scene((8, 2, 2), "tetra")
    plain = estimate(Scene.from_dict(data, load_mesh=False))
    data["adapt"] = [{"criterion": "R_L", "threshold": 0.1, "action": "refine", "rounds": 2}]
    refined = estimate(Scene.from_dict(data, load_mesh=False))
    assert refined.cells["tetra"] == 4 * plain.cells["tetra"] and refined.bytes > plain.bytes


# ------------------------------------------------------------------------------ calibration


def _warm(data):
    """Load and compile the kernels once, so that the measured run allocates only its arrays."""
    from tensormass.runtime.physics.newton import Context
    from tensormass.runtime.physics.integrators import make_integrator
    from tensormass.runtime.model.model import Model
    small = dict(data, mesh=dict(data["mesh"], cells=[1, 1, 1]))
    model = Model.from_scene(Scene.from_dict(small))
    model.warm_up()
    ctx = Context(model)
    ctx.asm.warm_up()
    make_integrator(ctx).step(1)


def _measured_peak(data) -> tuple:
    """(traced peak bytes of mesh, model, pattern and two steps; the scene's estimate)."""
    from tensormass.runtime.physics.newton import Context
    from tensormass.runtime.physics.integrators import make_integrator
    from tensormass.runtime.model.model import Model
    scene = Scene.from_dict(data, load_mesh=False, max_memory="64G")
    tracemalloc.start()
    try:
        scene.load_mesh()
        model = Model.from_scene(scene)
        model.warm_up()
        ctx = Context(model)
        ctx.asm.warm_up()
        integrator = make_integrator(ctx)
        integrator.step(1)
        integrator.step(2)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return peak, scene.estimate


@pytest.mark.parametrize("element,project", [("hexahedron", True), ("hexahedron", False), ("tetra", True)])
def test_estimate_is_above_a_measured_run_and_within_twice_it(element, project):
    """What the arrays of a real run take (tracemalloc: numpy reports its allocations), against
    the estimate without its fixed runtime part (interpreter and libraries, not traced)."""
    data = bar_scene((16, 6, 6) if element == "hexahedron" else (12, 4, 4), element, project_psd=project)
    _warm(data)
    peak, est = _measured_peak(data)
    arrays = est.bytes - est.parts["runtime"]
    assert peak <= arrays <= 2 * peak


def test_history_rows_count_the_probes_and_the_reactions():
    """Every kept history row holds each probe's vector and each [[fixed]] entry's force and moment."""
    text = """
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [4, 1, 1]
element = "tetra"
[[material]]
law = "hooke"
E = 1e6
nu = 0.3
density = 1000.0
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[solver]
kind = "implicit_euler"
steps = 10000
"""
    extra = """
[[fixed]]
box = [[0.999, -1, -1], [1.001, 1, 1]]
[[probe]]
name = "tip"
point = [1.0, 0.1, 0.1]
"""
    plain = resources.estimate(Scene.from_string(text, load_mesh=False)).parts["history"]
    more = resources.estimate(Scene.from_string(text + extra, load_mesh=False)).parts["history"]
    rows = resources.HISTORY_ROWS                                  # 10 000 steps: the bound
    assert plain == rows * (resources.HISTORY_ROW_BYTES + resources.HISTORY_BYTES_PER_FIXED)
    assert more - plain == rows * (resources.HISTORY_BYTES_PER_FIXED + resources.HISTORY_BYTES_PER_PROBE)


# ------------------------------------------------------------------------------ every generated mesh


@pytest.mark.parametrize("spec", [{"generate": "plate", "element": "shell", "cells": [7, 5], "size": [1.0, 0.5]},
                                  {"generate": "sphere", "element": "shell", "subdivisions": 2},
                                  {"generate": "ball", "element": "tetra", "divisions": 2},
                                  {"generate": "ball", "element": "tetra", "divisions": 5}])
def test_generated_counts_match_the_generated_meshes(spec):
    from tensormass.runtime.scene.mesh_source import ball_mesh, shell_mesh
    spec = SimpleNamespace(file=None, origin=(0.0, 0.0, 0.0), radius=1.0, **spec)
    mesh = shell_mesh(spec) if spec.element == "shell" else ball_mesh(spec)
    counts = MeshCounts.of_generated(spec)
    assert (counts.nodes, counts.cells) == (mesh.n_points, {b.type: len(b) for b in mesh.blocks})


_SHELL = {"law": "cst_dkt", "E": 1e7, "nu": 0.3, "thickness": 0.01, "density": 1000.0}


@pytest.mark.parametrize("mesh, material, limit", [
    ({"generate": "plate", "size": [1.0, 1.0], "cells": [20000, 20000]}, _SHELL, "8 GiB"),
    ({"generate": "sphere", "radius": 1.0, "subdivisions": 7}, _SHELL, "64 MiB"),
    ({"generate": "ball", "radius": 1.0, "divisions": 40}, {"law": "stvk", "E": 1e6, "nu": 0.3}, "64 MiB"),
    ({"generate": "bar", "size": [1.0, 1.0, 1.0], "cells": [400, 400, 400], "element": "hexahedron"},
     {"law": "mss", "E": 1e6, "nu": 0.25, "density": 1000.0}, "8 GiB"),
])
def test_every_generated_mesh_is_refused_before_it_is_built(mesh, material, limit, monkeypatch):
    from tensormass.runtime.scene import mesh_source as scene_mesh
    from tensormass.runtime.mesh import solids, surfaces
    for module, name in ((surfaces, "plate"), (surfaces, "icosphere"), (solids, "ball_tetrahedra"),
                         (mesh_module, "generate_bar")):
        monkeypatch.setattr(module, name, lambda *a, _n=name, **k: pytest.fail(f"{_n}: the mesh was built"))
    monkeypatch.setattr(scene_mesh, "ball_tetrahedra", lambda *a, **k: pytest.fail("the ball was built"),
                        raising=False)
    data = {"mesh": mesh, "material": [material], "fixed": [{"box": [[-9, -9, -9], [9, 9, 1e-9]]}],
            "solver": {"kind": "static"}}
    with pytest.raises(ResourceError, match=f"above the limit of {limit}"):
        Scene.from_dict(data, max_memory=limit.replace(" ", "").replace("iB", ""))
