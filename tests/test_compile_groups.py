"""The compile groups of conftest.py name tests that exist (a stale prefix would group nothing)."""
import re
from pathlib import Path

from conftest import COMPILE_GROUPS, compile_group

ROOT = Path(__file__).parent.parent


def test_every_prefix_names_a_test_file_and_its_tests():
    for group, prefixes in COMPILE_GROUPS.items():
        for prefix in prefixes:
            path, _, name = prefix.partition("::")
            source = (ROOT / path).read_text(encoding="utf-8")
            tests = re.findall(r"^def (test_\w+)", source, flags=re.M)
            assert any(t.startswith(name) for t in tests), (group, prefix)


def test_a_grouped_test_gets_its_group_and_others_stay_alone():
    assert compile_group("tests/runtime/physics/test_shells.py::test_x[1]") == "corotational_shell"
    other = "tests/runtime/physics/test_hanging.py::test_y"
    assert compile_group(other) == other
