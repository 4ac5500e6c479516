"""`tensormass bench organ` and examples/organ/make_organ.py: options, determinism, the quick run's report,
tensormass and FElupe agreeing on the same problem, and the messages when gmsh is missing.

No timing assertions: speed is measured by the benchmark, never asserted here.
"""
import contextlib
import io
import json
from pathlib import Path
import sys
import time

import numpy as np
import pytest

from tensormass.apps import bench, bench_organ
from tensormass.runtime.scene import resources
from tensormass.runtime.solve import solvers
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.mesh.io import read_mesh

try:
    import gmsh  # noqa: F401
    HAVE_GMSH = True
except ImportError:
    HAVE_GMSH = False
try:
    import felupe  # noqa: F401
    HAVE_FELUPE = True
except ImportError:
    HAVE_FELUPE = False

needs_gmsh = pytest.mark.skipif(not HAVE_GMSH, reason="gmsh is not installed (pip install tensormass[mesh])")
COMMITTED = Path(__file__).resolve().parents[2] / "examples" / "organ" / "organ.msh"


def _counts(path):
    mesh = read_mesh(path)
    return {b.type: len(b.cells) for b in mesh.blocks}, mesh.n_points, mesh.points.min(axis=0), mesh.points.max(axis=0)


# -- make_organ ---------------------------------------------------------------------------------
@needs_gmsh
def test_make_organ_default_is_the_committed_mesh(tmp_path):
    maker = bench_organ.load_make_organ()
    out = maker.make(tmp_path / "organ.msh")
    assert out.read_bytes() == COMMITTED.read_bytes()


@needs_gmsh
def test_make_organ_options_are_deterministic(tmp_path):
    maker = bench_organ.load_make_organ()
    a = maker.make(tmp_path / "a.msh", size=0.02, order=1, scale=1.5)
    b = maker.make(tmp_path / "b.msh", size=0.02, order=1, scale=1.5)
    assert a.read_bytes() == b.read_bytes()
    c = maker.make(tmp_path / "c.msh", size=0.02, order=2, scale=1.5)
    (cells1, points1, lo, hi), (cells2, points2, _, _) = _counts(a), _counts(c)
    assert set(cells1) == {"tetra"} and set(cells2) == {"tetra10"}
    assert cells1["tetra"] == cells2["tetra10"] > 0          # the order changes the nodes, not the cells
    assert points2 > points1
    # the geometry is scaled (semi-axes 40 x 30 x 30 mm x 1.5), flat underneath at z = 0
    # (+x and the top pole are geometry vertices; other extremes lie on curved edges, between nodes)
    np.testing.assert_allclose([hi[0], hi[2], lo[2]], [0.060, 0.045, 0.0], atol=1e-9)
    ideal = np.array([0.060, 0.045, 0.045])
    assert np.all(hi <= ideal + 1e-9) and np.all(hi > 0.95 * ideal)
    assert np.all(lo[:2] >= -ideal[:2] - 1e-9) and np.all(lo[:2] < -0.95 * ideal[:2])
    # a finer mesh has more cells
    d = maker.make(tmp_path / "d.msh", size=0.012, order=1, scale=1.5)
    assert _counts(d)[0]["tetra"] > cells1["tetra"]


@needs_gmsh
@pytest.mark.parametrize("kwargs,match", [({"size": 0.0}, "positive"), ({"scale": -1.0}, "positive"),
                                          ({"size": float("nan")}, "positive"), ({"order": 3}, "order"),
                                          ({"size": 1.0}, "larger than")])
def test_make_organ_refuses_bad_options(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        bench_organ.load_make_organ().make(tmp_path / "x.msh", **kwargs)
    assert not (tmp_path / "x.msh").exists()


def test_make_organ_without_gmsh(monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, "gmsh", None)           # `import gmsh` raises ImportError
    maker = bench_organ.load_make_organ()
    with pytest.raises(SystemExit) as stop:
        maker.main([str(tmp_path / "x.msh")])
    assert stop.value.code == 2
    assert "gmsh package is not installed" in capsys.readouterr().err
    assert not (tmp_path / "x.msh").exists()


# -- bench organ: input and environment -----------------------------------------------------------
def test_bench_organ_without_gmsh(monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, "gmsh", None)
    with pytest.raises(bench_organ.GmshMissing, match=r"pip install tensormass\[mesh\]"):
        bench_organ.run_organ_bench(quick=True, mesh_folder=tmp_path, progress=None, felupe=False)
    assert list(tmp_path.iterdir()) == []                   # stopped before anything ran or was written
    # the command line: a message and exit code 2, no traceback
    monkeypatch.setattr(bench_organ, "mesh_path", lambda case, folder=None: tmp_path / "missing.msh")
    assert bench.main(["organ", "--quick", "--no-felupe"]) == 2
    err = capsys.readouterr().err
    assert "gmsh package is not installed" in err and "Traceback" not in err


def test_bench_organ_refuses_unknown_names(capsys):
    assert bench.main(["organ", "--cases", "kidney"]) == 2
    assert "unknown case kidney" in capsys.readouterr().err
    with pytest.raises(TensormassError, match="unknown case kidney"):
        bench_organ.select_cases(["kidney"], quick=False)
    with pytest.raises(TensormassError, match="unknown linear solver 'magic'"):
        bench_organ.available_solvers(["magic"])
    with pytest.raises(TensormassError, match="thread count"):
        bench_organ.run_organ_bench(quick=True, threads=[0], progress=None)


def test_solvers_are_read_from_the_runtime(monkeypatch):
    """Every name of solvers.METHODS is run unless the module reports it unavailable."""
    methods, skipped = bench_organ.available_solvers()
    assert set(methods) | set(skipped) == set(solvers.METHODS)
    monkeypatch.setattr(solvers, "METHODS", solvers.METHODS + ("newsolver",), raising=True)
    real = solvers.unavailable
    monkeypatch.setattr(solvers, "unavailable", lambda m: "its package is missing" if m == "newsolver" else real(m))
    methods, skipped = bench_organ.available_solvers()
    assert "newsolver" in skipped and "its package is missing" in skipped["newsolver"]
    assert "lu" in methods
    monkeypatch.setattr(solvers, "unavailable", real)
    assert "newsolver" in bench_organ.available_solvers()[0]


def test_bench_organ_skips_a_case_past_the_memory(monkeypatch, tmp_path):
    def refuse(est, limit=None, what="this run"):
        raise resources.ResourceError(f"{what} needs an estimated 9 TiB of memory")
    monkeypatch.setattr(resources, "check", refuse)
    report = bench_organ.run_organ_bench(quick=True, cases=["quick_hex_cantilever_12x2x4"], progress=None,
                                         json_path=tmp_path / "r.json")
    (case,) = report["cases"]
    assert case["runs"] == [] and "9 TiB" in case["skipped"]
    assert "skipped" in bench_organ.format_organ_report(report)


def test_scene_is_the_example_scene():
    """The bench's organ scene is examples/organ/scene.toml's (law, E, nu, density, loads, groups)."""
    import tomllib
    example = tomllib.loads((Path(__file__).resolve().parents[2] / "examples" / "organ" / "scene.toml").read_text())
    case = bench_organ.select_cases(["tetra10_h8_static"], quick=False)[0]
    ours = tomllib.loads(bench_organ.organ_scene_text(case, "/tmp/organ.msh"))
    assert ours["material"] == example["material"]
    assert ours["fixed"] == example["fixed"]
    assert ours["loads"] == example["loads"]
    assert ours["solver"]["kind"] == "static" and ours["solver"]["steps"] == 1


# -- the quick run --------------------------------------------------------------------------------
def _in_process(role, spec, threads, timeout):
    """bench_organ._subprocess's result, from the same worker entry point (_worker_main: its JSON line on
    stdout) run in this process: a fresh interpreter per run (2-4 s of imports, tensormass's and FElupe's)
    is what the benchmark's isolation costs, and test_a_failing_run_is_reported_not_raised runs that path."""
    out, t0 = io.StringIO(), time.perf_counter()
    with contextlib.redirect_stdout(out):
        assert bench_organ._worker_main([role, json.dumps(spec)]) == 0
    (line,) = [line for line in out.getvalue().splitlines() if line.startswith(bench_organ.RESULT_TAG)]
    result = json.loads(line[len(bench_organ.RESULT_TAG):])
    if result is not None:
        result["process_s"] = time.perf_counter() - t0
    return result


@needs_gmsh
def test_bench_organ_quick(tmp_path, monkeypatch):
    monkeypatch.setattr(bench_organ, "_subprocess", _in_process)
    path = tmp_path / "organ.json"
    report = bench_organ.run_organ_bench(quick=True, json_path=path, mesh_folder=tmp_path, progress=None)
    data = json.loads(path.read_text())
    assert data["benchmark"] == "organ" and data["settings"]["quick"] is True
    assert data["settings"]["solvers"] == ["auto"] and data["settings"]["threads"] == [1]
    assert [c["case"] for c in data["cases"]] == [c.name for c in bench_organ.QUICK_CASES]
    for case in data["cases"]:
        assert case["skipped"] is None
        (run,) = case["runs"]
        assert run["status"] in ("ok", "warnings"), run
        assert run["method"] == "auto" and run["threads"] == 1 and run["used"]
        assert run["free_dofs"] > 0 and run["elements"] > 0 and run["newton"] >= 1
        assert 0 < run["setup_s"] <= run["total_s"] and run["assembly_s"] > 0 and run["solve_s"] > 0
        assert run["peak_mb"] > 0 and np.isfinite(run["probe"]).all() and run["max_u"] > 0
        if case["spec"]["kind"] == "static":
            assert run["per_iteration_ms"] > 0
        else:
            assert run["later_steps_ms"] > 0 and run["first_step_ms"] > 0
        if case["spec"]["body"] == "organ":
            assert case["mesh"]["path"].startswith(str(tmp_path))
    # the meshes are in the given folder, named by the script's hash and the options
    assert sorted(p.name for p in tmp_path.glob("organ-*.msh")) == sorted(
        {bench_organ.mesh_path(c, tmp_path).name for c in bench_organ.QUICK_CASES if c.body == "organ"})
    # the budgeted case: its speed and its trajectory against its exact twin's, in the same run
    (budgeted,) = [c for c in data["cases"] if c["spec"]["exact"]]
    (run,) = budgeted["runs"]
    assert run["budget"]["refreshes"] >= 1 and run["exact_ratio"] > 0
    assert 0 < run["error_vs_exact"] < 0.01
    assert len(run["trajectory"]) == budgeted["spec"]["steps"]
    text = bench_organ.format_organ_report(report)
    assert "quick_tetra10_h12_static" in text and "auto" in text
    if not HAVE_FELUPE:
        assert all(c["felupe"] is None for c in data["cases"])
        return
    for case in data["cases"]:
        if case["spec"]["kind"] != "static":
            assert case["felupe"] is None
            continue
        fe, (run,) = case["felupe"], case["runs"]
        assert fe["converged"] and fe["newton"] >= 1 and fe["free_dofs"] == run["free_dofs"]
        assert fe["elements"] == run["elements"] and fe["probe_node"] == run["probe_node"]
        # the same problem: the displacement at the probe agrees to the Newton tolerance
        assert run["probe_difference"] < 1e-6, (run["probe"], fe["probe"])
        assert abs(fe["max_u"] - run["max_u"]) <= 1e-6 * fe["max_u"]
        assert run["felupe_ratio"] > 0 and run["felupe_ratio_per_iteration"] > 0
    assert "FElupe" in text and "probe" in text


def test_a_failing_run_is_reported_not_raised(tmp_path):
    """A run whose process fails (here: its mesh file is missing) becomes a row with the reason."""
    case = bench_organ.QUICK_CASES[0]
    missing = tmp_path / "nothing.msh"
    result = bench_organ._subprocess("--worker", {"case": bench_organ.asdict(case), "mesh": str(missing),
                                                  "method": "auto"}, 1, 120)
    assert result["status"] == "failed" and "nothing.msh" in result["message"]
    result.update(method="auto", threads=1)
    entry = {"case": case.name, "title": case.title, "spec": bench_organ.asdict(case), "runs": [result],
             "felupe": None, "skipped": None}
    bench_organ._compare(entry)
    report = {"machine": {"cpu": "x", "python": "3", "numpy": "n", "numba": "n"}, "date": "today",
              "settings": {"solvers": ["auto"], "skipped_solvers": {}, "threads": [1], "felupe": False},
              "cases": [entry]}
    text = bench_organ.format_organ_report(report)
    assert "failed" in text and "nothing.msh" in text


def test_thread_counts_past_the_cores_are_skipped(monkeypatch):
    import numba
    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", 1)
    monkeypatch.setattr(resources, "check", lambda *a, **k: (_ for _ in ()).throw(resources.ResourceError("big")))
    report = bench_organ.run_organ_bench(quick=True, cases=["quick_hex_cantilever_12x2x4"], threads=[1, 2],
                                         progress=None)
    assert report["settings"]["threads"] == [1] and "1 core" in report["settings"]["skipped_threads"][2]
    assert "2 threads skipped" in bench_organ.format_organ_report(report)
