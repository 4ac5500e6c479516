"""`tensormass bench gpu --host`: the GPU benchmark's every line on the host shim (small bodies), the check
that the script a GPU machine runs works; its numbers are sane (the device system's K is the CPU's,
the runs' displacements agree)."""
from __future__ import annotations

import json

import pytest

from tensormass.apps.bench_gpu import run_gpu_bench

from helpers import has_c_compiler


@pytest.mark.heavy
@pytest.mark.skipif(not has_c_compiler(), reason="the host shim needs a C compiler")
def test_gpu_bench_runs_on_the_host_shim(tmp_path):
    lines = []
    report = run_gpu_bench(quick=True, host=True, json_path=tmp_path / "gpu.json", progress=lines.append)
    assert report["device"] == "cuda (host shim)" and "not a GPU's" in lines[0]
    assert {r["name"] for r in report["kernels"]} == {"tetra_neohookean_gauss1", "tetra10_neohookean_gauss2",
                                                      "hexahedron_neohookean_gauss2"}
    assert all(r["device_rate"] > 0 and r["cpu_rate"] > 0 for r in report["kernels"])
    assert report["assembly"]["K_difference"] < 1e-12
    assert report["step"]["trajectory_difference"] < 1e-8 and report["step"]["cg_iterations"] > 0
    assert [r["cells"] for r in report["scaling"]] == sorted(r["cells"] for r in report["scaling"])
    assert json.loads((tmp_path / "gpu.json").read_text())["assembly"]["dofs"] == report["assembly"]["dofs"]
    assert (tmp_path / "gpu.png").stat().st_size > 1000
