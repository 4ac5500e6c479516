"""`tensormass batch` (apps/batch.py): variations, the sequential path without dask, the same table on a
2-worker dask cluster, failures reported without stopping the study, the reports' --workers, and
two processes compiling one C kernel into an empty cache.

Tables are compared without their timing columns (batch.TIMING_COLUMNS; the reports' time_* and
peak_memory_mb, stability's wall_time): everything else must be identical, byte for byte."""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import textwrap

import pytest

from helpers import has_c_compiler
from tensormass.apps import batch
from tensormass.apps.cli import main
from tensormass.runtime.base.errors import SceneError, TensormassError

from test_cli_safety import deny_writes

SCENE = """
name = "tiny"
[mesh]
generate = "bar"
size = [1.2, 0.2, 0.2]
cells = [2, 1, 1]
element = "hexahedron"
[[material]]
law = "hooke"
quadrature = "gauss2"
E = 1.0e8
nu = 0.3
density = 800.0
[[fixed]]
box = [[-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]]
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "static"
steps = 1
[[probe]]
name = "tip"
point = [1.2, 0.1, 0.1]
[output]
dir = "must_not_be_written"
"""


@pytest.fixture
def scene(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(SCENE)
    return path


def _table(path, skip=batch.TIMING_COLUMNS):
    with open(path, newline="") as fh:
        return [{k: v for k, v in r.items() if k not in skip} for r in csv.DictReader(fh)]


# -- --vary ---------------------------------------------------------------------------------------

def test_vary_splits_outside_brackets_and_reads_toml_values():
    assert batch.split_values("[4,1,1],[8,2,2]") == ["[4,1,1]", "[8,2,2]"]
    assert batch.split_values('"a,b",c') == ['"a,b"', "c"]
    vary = batch.parse_vary(["mesh.cells=[4,1,1],[8,2,2]", "material.0.E=1e6,2e6", "material.0.law=hooke,stvk",
                             "solver.kind=\"static\""])
    assert vary == [("mesh.cells", [[4, 1, 1], [8, 2, 2]]), ("material.0.E", [1e6, 2e6]),
                    ("material.0.law", ["hooke", "stvk"]), ("solver.kind", ["static"])]
    tasks = batch.plan_tasks(["a.toml", "b.toml"], vary)
    assert len(tasks) == 2 * 2 * 2 * 2 and tasks[1]["values"]["material.0.law"] == "stvk"
    assert [t["task"] for t in tasks] == list(range(16))


@pytest.mark.parametrize("item, words", [("material.0.E", "KEY=V1"), ("=1,2", "KEY=V1"),
                                          ("mesh.cells=[4,1", "unclosed"), ("a..b=1", "empty part")])
def test_vary_syntax_errors_name_the_item(item, words):
    with pytest.raises(TensormassError, match=words):
        batch.parse_vary([item])


def test_vary_bad_keys_give_a_scene_error_naming_the_key(scene):
    with pytest.raises(SceneError, match=r"solver\.dtt: unknown key"):
        batch.load_scene(scene, {"solver.dtt": 0.1})
    with pytest.raises(SceneError, match=r"--vary material\.3\.E: material has 1 entry"):
        batch.load_scene(scene, {"material.3.E": 1.0})
    with pytest.raises(SceneError, match=r"--vary mesh\.cells\.x"):
        batch.load_scene(scene, {"mesh.cells.x": 1})
    assert batch.load_scene(scene, {"material.0.E": 2e8}, load_mesh=False).materials[0].E == 2e8


# -- the sequential path (no dask needed) -----------------------------------------------------------

def test_sequential_batch_reports_failures_and_finishes_the_others(scene, tmp_path, capsys):
    broken = tmp_path / "broken.toml"
    broken.write_text(SCENE.replace("nu = 0.3", "nu = 0.7"))
    out = tmp_path / "t.csv"
    code = main(["batch", str(scene), str(broken), "--vary", "material.0.E=1e8,-1", "--workers", "1",
                 "--out", str(out), "--quiet"])
    assert code == 2
    rows = _table(out)
    assert [r["task"] for r in rows] == ["0", "1", "2", "3"]
    assert [r["status"] for r in rows] == ["ok", "refused", "refused", "refused"]
    assert rows[0]["exit_code"] == "0" and float(rows[0]["probe.tip.2"]) < 0
    assert "material[0]" in rows[1]["error"] and "nu" in rows[2]["error"]
    err = capsys.readouterr().err
    assert "3 task(s) failed" in err and "[1]" in err and "material.0.E=-1" in err
    assert not (tmp_path / "must_not_be_written").exists()
    assert not list(tmp_path.glob("*.tmp"))


def test_workers_above_one_without_dask_name_the_extra(scene, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(batch, "dask_available", lambda: False)
    assert main(["batch", str(scene), "--vary", "material.0.E=1e8,2e8", "--workers", "2",
                 "--out", str(tmp_path / "t.csv")]) == 2
    assert 'pip install "tensormass[distributed]"' in capsys.readouterr().err
    assert not (tmp_path / "t.csv").exists()


# -- the table's path, checked before the study (issue #29: batch --out wrote over the scene) ------

def _no_task(monkeypatch):
    monkeypatch.setattr(batch, "run_task", lambda *a, **k: pytest.fail("a task ran"))


@pytest.mark.parametrize("target, reason", [
    ("tiny.toml", "is an input scene file"),
    ("tiny.parquet", "give the CSV table's name"),
    ("mine.csv", "exists and is not a table of tensormass batch"),
    ("folder", "is a folder"),
    ("missing/t.csv", "does not exist"),
    ("link.csv", "symbolic link"),
    ("locked/t.csv", "Permission denied"),
])
def test_out_is_checked_before_any_task(scene, tmp_path, capsys, monkeypatch, target, reason):
    _no_task(monkeypatch)
    (tmp_path / "mine.csv").write_text("a,b\n1,2\n")
    (tmp_path / "folder").mkdir()
    (tmp_path / "locked").mkdir()
    (tmp_path / "link.csv").symlink_to(tmp_path / "mine.csv")
    deny_writes(monkeypatch, tmp_path / "locked")
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    code = main(["batch", str(scene), "--vary", "material.0.E=1e8,2e8", "--workers", "1", "--quiet",
                 "--out", str(tmp_path / target)])
    err = capsys.readouterr().err
    assert code == 2 and reason in err and len(err.splitlines()) == 1, err
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before
    assert not list(tmp_path.rglob("*.partial"))


def test_an_earlier_table_of_ours_is_replaced(scene, tmp_path):
    out = tmp_path / "t.csv"
    assert main(["batch", str(scene), "--workers", "1", "--quiet", "--out", str(out)]) == 0
    assert batch.is_batch_table(out)
    assert main(["batch", str(scene), "--vary", "material.0.E=1e8,2e8", "--workers", "1", "--quiet",
                 "--out", str(out)]) == 0
    assert len(_table(out)) == 2 and not batch.partial_path(out).exists()


# -- rows as they finish, Ctrl-C -------------------------------------------------------------------

def test_rows_are_kept_as_they_finish_and_ctrl_c_keeps_them(scene, tmp_path, capsys, monkeypatch):
    out = tmp_path / "t.csv"
    partial = batch.partial_path(out)
    real, seen = batch.run_task, []

    def task(spec, threads=None, max_memory=None):
        # what is on disk when task k starts: the header and the k rows finished before (flushed)
        seen.append(len(partial.read_text().splitlines()))
        if spec["task"] == 2:
            raise KeyboardInterrupt                  # Ctrl-C during the third task
        return real(spec, threads, max_memory)
    monkeypatch.setattr(batch, "run_task", task)
    code = main(["batch", str(scene), "--vary", "material.0.E=1e8,2e8,3e8,4e8", "--workers", "1", "--quiet",
                 "--out", str(out)])
    err = capsys.readouterr().err.splitlines()
    assert code == 130 and seen == [1, 2, 3]
    assert err[-1] == f"tensormass: interrupted: 2 of 4 task(s) finished, their rows kept in {partial}"
    assert "Traceback" not in "\n".join(err) and not out.exists()
    lines = [json.loads(line) for line in partial.read_text().splitlines()]
    assert lines[0]["format"] == batch.PARTIAL_FORMAT and lines[0]["tasks"] == 4
    assert [r["task"] for r in lines[1:]] == [0, 1] and [r["status"] for r in lines[1:]] == ["ok", "ok"]
    # a rerun replaces the rows of ours and ends with the table, the partial file gone
    monkeypatch.setattr(batch, "run_task", real)
    assert main(["batch", str(scene), "--workers", "1", "--quiet", "--out", str(out)]) == 0
    assert out.is_file() and not partial.exists()


def test_ctrl_c_in_a_task_stops_the_study(scene, tmp_path, monkeypatch):
    # the runtime turns Ctrl-C into RunInterrupted: a study must stop there, not record the task and go on
    from tensormass.runtime.run import simulation
    monkeypatch.setattr(simulation.Simulation, "_loop", lambda self: (_ for _ in ()).throw(KeyboardInterrupt))
    rows, code = batch.run_batch([scene], ["material.0.E=1e8,2e8"], workers=1, out=tmp_path / "t.csv",
                                 progress=False)
    assert code == 130 and rows == []


# -- workers and cost --------------------------------------------------------------------------------

def test_workers_capped_at_the_tasks_and_the_memory_and_the_cost_printed(scene, tmp_path, capsys, monkeypatch):
    engine = []

    class NoStudy(Exception):
        pass

    def no_study(fn, items, **kw):                   # what the engine would start; nothing runs
        engine.append(kw["workers"])
        raise NoStudy
    monkeypatch.setattr(batch, "dask_available", lambda: True)
    monkeypatch.setattr(batch, "map_tasks", no_study)
    monkeypatch.setenv("TENSORMASS_MAX_MEMORY", "100G")
    with pytest.raises(NoStudy):
        batch.run_batch([scene], ["material.0.E=1e8,2e8"], workers=1000, out=tmp_path / "t.csv", progress=False)
    err = capsys.readouterr().err
    assert engine == [2] and "--workers 1000: capped at 2, the number of tasks" in err
    assert "cost: 2 task(s), estimated per task: up to" in err and "peak memory" in err
    # each worker needs at least MEMORY_FLOOR: a budget of 2.5 of them holds 2 workers of 3 tasks
    monkeypatch.setenv("TENSORMASS_MAX_MEMORY", str(int(2.5 * batch.MEMORY_FLOOR)))
    with pytest.raises(NoStudy):
        batch.run_batch([scene], ["material.0.E=1e8,2e8,3e8"], workers=3, out=tmp_path / "t.csv", progress=False)
    err = capsys.readouterr().err
    assert engine[-1] == 2 and "3 workers capped at 2" in err


def test_study_cost_sums_the_estimates():
    from types import SimpleNamespace as E
    line = batch.study_cost([E(bytes=2 ** 30, seconds=2.0), E(bytes=2 ** 29, seconds=4.0), None], workers=2)
    assert line.startswith("3 task(s), estimated per task: up to 1 GiB peak memory, ~3 s of stepping")
    assert "~9 s in all, ~4.5 s on 2 workers" in line and "1 task(s) not estimated" in line


# -- dask.distributed ------------------------------------------------------------------------------

def test_workers_run_one_thread_each_and_leave_ctrl_c_to_this_process(capfd):
    distributed = pytest.importorskip("distributed")
    before = {k: os.environ.get(k) for k in batch.THREAD_ENV}
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    with batch._client(distributed, 1, None, None) as client:
        info = client.submit(batch.worker_info, pure=False).result()
        assert signal.pthread_sigmask(signal.SIG_BLOCK, []) == mask          # this process takes Ctrl-C
    assert info["env"] == batch.THREAD_ENV
    assert info["numba_threads"] == 1 and info["blas_threads"] in ([1], [])
    # a terminal's Ctrl-C reaches the workers too: they block it (else: their tracebacks, 4 of 4 times)
    assert info["sigint_blocked"] in (True, None)
    assert {k: os.environ.get(k) for k in batch.THREAD_ENV} == before       # this process's own, restored
    assert signal.pthread_sigmask(signal.SIG_BLOCK, []) == mask
    assert "Traceback" not in capfd.readouterr().err                        # a quiet shutdown


@pytest.fixture(scope="module")
def two_workers():
    """The scheduler address of a 2-worker cluster started by batch's own LocalCluster code (_client), shared
    by the studies below: starting the worker processes is most of their cost, once here instead of per study."""
    distributed = pytest.importorskip("distributed")
    with batch._client(distributed, 2, None, None) as client:
        assert len(client.scheduler_info()["workers"]) == 2
        yield client.scheduler.address


def test_two_workers_give_the_sequential_table(scene, tmp_path, two_workers):
    vary = ["material.0.E=1e7,1e8", "mesh.cells=[2,1,1],[4,1,1]", "material.0.law=hooke,stvk"]   # 8 tasks
    seq, par = tmp_path / "seq.csv", tmp_path / "par.csv"
    rows, code = batch.run_batch([scene], vary, workers=1, out=seq, progress=False)
    assert code == 0 and len(rows) == 8
    _, code = batch.run_batch([scene], vary, scheduler=two_workers, out=par, progress=False)
    assert code == 0
    assert _table(seq) == _table(par)
    assert len({r["probe.tip.2"] for r in _table(par)}) == 8


def test_report_accuracy_same_csv_on_one_and_two_workers(tmp_path, two_workers):
    from tensormass.apps.reports.accuracy import run_accuracy
    tiny = {"elements": ["hexahedron", "tetra"], "laws": ["hooke"], "quadratures": {"tetra": ["gauss1"]},
            "levels": [[2, 1, 1], [4, 1, 1]], "levels_quadratic": [[2, 1, 1]], "reference": [4, 1, 1]}
    timing = ("time_setup", "time_assembly", "time_solve", "time_total", "peak_memory_mb")
    run_accuracy(tmp_path / "1", quick=True, _sweep=tiny, benchmarks=["cantilever"], progress=None, workers=1)
    run_accuracy(tmp_path / "2", quick=True, _sweep=tiny, benchmarks=["cantilever"], progress=None,
                 scheduler=two_workers)
    one, two = _table(tmp_path / "1" / "results.csv", timing), _table(tmp_path / "2" / "results.csv", timing)
    assert len(one) == 4 and one == two


# -- the kernel cache under concurrent workers -------------------------------------------------------

COMPILE = textwrap.dedent("""
    import sys
    from tensormass.apps.batch import kernel_locks
    from tensormass.backends.c import loader
    from tensormass.runtime.kernels.kernels import load_kernel
    with kernel_locks([("tetra", "hooke", "gauss1", "c")]):
        kernel = load_kernel("tetra", "hooke", "gauss1", backend="c")
    print(len(loader.COMPILATIONS))
""")


def test_two_processes_compile_one_c_kernel_once(tmp_path):
    if not has_c_compiler():
        pytest.skip("no C compiler")
    env = {**os.environ, "TENSORMASS_CACHE": str(tmp_path / "cache")}
    procs = [subprocess.Popen([sys.executable, "-c", COMPILE], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    assert sorted(int(o[0].split()[-1]) for o in outs) == [0, 1]          # compiled once, loaded once
    libs = list((tmp_path / "cache").rglob("*.so"))
    assert len(libs) == 1 and not list((tmp_path / "cache").rglob("*.tmp"))
