"""The classic (hand-written) baseline agrees with the generated kernels; the benchmark runs and reports.

No timing assertions: speed is measured by `tensormass bench`, never asserted here.
"""
import argparse
import json

import numpy as np
import pytest

import tensormass as tm
from helpers import random_elements, relative_error
from tensormass.apps import bench
from tensormass.apps.classic import load_classic

# the classic implementation is numba code compiled per case (5 to 20 s cold): one case by default, all
# in CI's heavy step
CASES = [pytest.param(element, law, quadrature, marks=pytest.mark.heavy if (element, law) != ("tetra", "hooke") else ())
         for element, quadrature in (("tetra", "gauss1"), ("hexahedron", "gauss2"))
         for law in ("hooke", "stvk", "neohookean")]


@pytest.mark.parametrize("element,law,quadrature", CASES)
def test_classic_matches_generated(element, law, quadrature):
    X = random_elements(element, 40, seed=3)
    u = 0.05 * np.random.default_rng(4).standard_normal(X.shape)
    kernel = tm.load_kernel(element, law, quadrature)
    classic = load_classic(element, law, quadrature)
    D = kernel.constants(X, E=2.0e5, nu=0.35)
    state = classic.constants(X, E=2.0e5, nu=0.35)
    assert not kernel.inverted(D, u).any()
    np.testing.assert_allclose(state.v.sum(axis=1), kernel.point_volumes(D).sum(axis=1),
                               rtol=1e-12)
    f_gen, K_gen = kernel.forces_and_stiffness(D, u)
    f_cl, K_cl = classic.forces_and_stiffness(state, u)
    assert relative_error(f_cl, f_gen) < 1e-10
    assert relative_error(K_cl, K_gen) < 1e-10
    assert relative_error(classic.forces(state, u), kernel.forces(D, u)) < 1e-10
    assert np.abs(K_cl - K_cl.transpose(0, 2, 1)).max() <= 1e-12 * np.abs(K_cl).max()


def test_classic_preallocated_outputs_overwrite():
    # the law compiled by the quick case of test_classic_matches_generated: the outputs' handling is
    # the same code for every law
    X = random_elements("tetra", 8, seed=5)
    u = 0.05 * np.random.default_rng(6).standard_normal(X.shape)
    classic = load_classic("tetra", "hooke", "gauss1")
    state = classic.constants(X, E=1.0e5, nu=0.3)
    f, K = np.full((8, 12), np.nan), np.full((8, 12, 12), np.nan)
    flags = np.ones(8, dtype=np.int32)
    classic.forces_and_stiffness_into(state, u, f, K, flags)
    f_ref, K_ref = classic.forces_and_stiffness(state, u)
    assert not flags.any()
    np.testing.assert_array_equal(f, f_ref)
    np.testing.assert_array_equal(K, K_ref)


def test_classic_flags_inverted_neohookean():
    X = random_elements("tetra", 3, seed=7)
    classic = load_classic("tetra", "neohookean", "gauss1")
    state = classic.constants(X, E=1.0e5, nu=0.3)
    u = np.zeros_like(X)
    u[1] = -2.0 * (X[1] - X[1].mean(axis=0))         # point reflection: det F = -1
    with pytest.raises(tm.InvertedElementError) as info:
        classic.forces_and_stiffness(state, u)
    assert list(info.value.elements) == [1]


def test_classic_rejects_unknown_law():
    with pytest.raises(tm.TensormassError):
        load_classic("tetra", "mooney_rivlin", "gauss1")


@pytest.mark.heavy          # the benchmark's quick run, 10 to 35 s cold: CI's heavy step
def test_quick_kernel_bench_writes_json(tmp_path):
    path = tmp_path / "out" / "bench.json"
    report = bench.run_kernel_bench(quick=True, entries=["tetra_stvk_gauss1"], json_path=path, progress=False)
    assert report["settings"]["n_elements"] == bench.QUICK_ELEMENTS
    assert report["settings"]["repeats"] == bench.QUICK_REPEATS
    (result,) = report["results"]
    assert result["entry"] == "tetra_stvk_gauss1"
    assert "numba" in result["rates"] and "classic" in result["rates"]
    for backend, rates in result["rates"].items():
        for kind in bench.KINDS:
            assert rates[kind] > 0 and np.isfinite(rates[kind]), (backend, kind)
    for kind in bench.KINDS:
        assert result["ratios"][kind]["best"] > 0
        assert result["ratios"][kind]["numba"] > 0
    assert result["ops"]["forces_and_stiffness"] > result["ops"]["forces"] > 0
    assert result["constants_bytes"] == 8 * result["n_constants"]
    assert "flags" not in result["errors"]
    on_disk = json.loads(path.read_text())
    assert on_disk["results"][0]["entry"] == "tetra_stvk_gauss1"
    assert on_disk["machine"]["python"]
    assert not list(path.parent.glob(".*.tmp"))
    text = bench.format_kernel_report(report)
    assert "tetra_stvk_gauss1" in text and "classic" in text


def test_bench_command_line():
    parser = argparse.ArgumentParser()
    bench.add_bench_command(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["bench", "kernels", "--quick", "--json", "x.json", "--entries", "tetra_hooke_gauss1"])
    assert args.run is bench.cmd_kernels and args.quick and args.json == "x.json"
    assert args.entries == ["tetra_hooke_gauss1"] and args.elements == 100_000
    args = parser.parse_args(["bench", "compile"])
    assert args.run is bench.cmd_compile and args.json is None


def test_unknown_entry_is_an_error():
    with pytest.raises(ValueError, match="unknown catalogue entry"):
        bench.resolve_entries(["tetra_nothing_gauss1"])
    assert [e.name for e in bench.resolve_entries(["tetra_mooney_rivlin_gauss1"])] == ["tetra_mooney_rivlin_gauss1"]


@pytest.mark.heavy          # the benchmark's quick run, 10 to 35 s cold: CI's heavy step
def test_quick_steps_bench_writes_json(tmp_path, monkeypatch):
    from tensormass.apps import bench_steps
    monkeypatch.setitem(__import__("sys").modules, "felupe", None)     # comparison skipped
    lines = []
    path = tmp_path / "steps.json"
    report = bench_steps.run_steps_bench(quick=True, json_path=path, progress=lines.append, bodies=["tetra_1k"])
    assert {r["body"] for r in report["results"]} == {"tetra_1k"}
    assert len(report["results"]) == len(bench_steps.LAWS) * 2 * len(bench_steps.LINEAR)
    for r in report["results"]:
        assert r["per_unit_s"] > 0 and r["newton"] >= 1 and r["solver_used"]
    newton = report["newton_iteration"]
    assert newton["free_dofs"] > 0 and newton["assembly_s"] > 0
    for label, r in newton["solvers"].items():
        assert r["relative_residual"] < 1e-7, label
        assert r["difference_to_first"] < 1e-5, label
    assert newton["solvers"]["auto"]["used"].startswith("band")
    assert newton["felupe"] is None and newton["felupe_ratio"] is None
    assert any("FElupe comparison skipped" in line for line in lines)
    assert json.loads(path.read_text())["newton_iteration"]["body"] == bench_steps.QUICK_NEWTON_CASE[0]


def test_felupe_comparison_when_installed():
    pytest.importorskip("felupe")
    from tensormass.apps import bench_steps
    report = bench_steps.compare_newton(bench_steps.QUICK_NEWTON_CASE, 1, 1, progress=None)
    assert report["felupe"]["free_dofs"] == report["free_dofs"]
    assert report["felupe_ratio"] > 0
    assert report["displacement_ratio"] == pytest.approx(1.0, rel=1e-6)     # the same problem


def test_steps_command_line():
    parser = argparse.ArgumentParser()
    bench.add_bench_command(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["bench", "steps", "--quick", "--json", "s.json"])
    assert args.quick and args.json == "s.json" and args.run.__name__ == "cmd_steps"
