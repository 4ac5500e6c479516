"""`tensormass bench history` (apps/bench_history.py): runs, keeps the rows it says, writes JSON."""
import json

from tensormass.apps.cli import main
from tensormass.runtime.run import simulation


def test_quick_history_bench_writes_json(tmp_path, capsys):
    path = tmp_path / "history.json"
    assert main(["bench", "history", "--quick", "--json", str(path)]) == 0
    report = json.loads(path.read_text())
    for kind in ("explicit", "implicit_euler"):
        case = report["cases"][kind]
        assert case["rows"] == case["steps"] == 20 and case["few_rows"] < 8      # the two settings differ
        assert case["ratio"] > 0 and case["every_row_s_per_step"] > 0
    assert simulation.HISTORY_MAX == 4096                                           # restored
    assert "the history costs" in capsys.readouterr().out
