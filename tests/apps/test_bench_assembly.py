"""`tensormass bench assembly --quick`: runs through the CLI for both backends, checks on the way
that the fused path equals buffers + scatter bit for bit, writes JSON with every rate."""
import json

import pytest

from tensormass.apps.cli import main


@pytest.mark.heavy          # the benchmark's quick run, 10 to 35 s cold: CI's heavy step
def test_quick_assembly_bench_writes_json(tmp_path, capsys):
    out = tmp_path / "assembly.json"
    assert main(["bench", "assembly", "--quick", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "faster path per element type" in printed and "buffers+scatter" in printed
    report = json.loads(out.read_text())
    assert report["quick"] is True and report["threads"] == 1
    assert {c["element"] for c in report["cases"].values()} == {"tetra", "tetra10", "hexahedron"}
    for case in report["cases"].values():
        assert set(case["backends"]) == {"numba", "c"} and case["nnz"] > case["dofs"] > 0
        for row in case["backends"].values():
            assert set(row["ms"]) == {"kernel", "buffers", "fused"} and min(row["ms"].values()) > 0
            assert row["faster"] in ("buffers", "fused")
            assert abs(row["elements_per_s"]["kernel"] * row["ms"]["kernel"] / 1e3 / case["cells"] - 1) < 1e-9
    assert set(report["faster"]) == {"tetra", "tetra10", "hexahedron"}


def test_assembly_bench_backend_choice(capsys):
    assert main(["bench", "assembly", "--quick", "--backend", "c"]) == 0
    assert "numba" not in capsys.readouterr().out.split("full Newton assembly")[1]
