import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture
def forget_user_laws():
    """The user laws a test loads leave with it: other tests list every law of the process."""
    from tensormass import laws
    before = dict(laws._user)
    yield
    laws._user.clear()
    laws._user.update(before)


# Tests that share something long to compile, by node-id prefix: under pytest-xdist each group runs
# on one worker, so it compiles once there while the other worker goes on with other tests (where
# both need it at once, one compiles and the other waits, or both compile). Every other test is
# scheduled on its own, as with xdist's default "load".
COMPILE_GROUPS = {
    # the co-rotational shell's numba loops: about 20 s
    "corotational_shell": (
        "tests/runtime/physics/test_shells.py::",
        "tests/runtime/run/test_exit_codes_outputs.py::test_a_bare_picture_of_a_corotational_shell",
        "tests/runtime/run/test_exit_codes_outputs.py::test_a_named_field_the_kernels_cannot_give",
        "tests/runtime/run/test_exit_codes_outputs.py::test_von_mises_named_on_a_corotational_shell",
    ),
    # the cube lattices' C kernels (hybmss: 877 kB of C, about 30 s of gcc; mss: about 10 s); most of
    # their tests run in CI's heavy step
    "cube_lattice": (
        "tests/runtime/scene/test_spring_scenes.py::",
        "tests/runtime/physics/test_springs_physics.py::",
        "tests/apps/reports/test_hybmss.py::",
        "tests/apps/test_bench_springs.py::",
        "tests/apps/reports/test_report_stability.py::test_spring_lattices_buckle",
    ),
}


def compile_group(nodeid: str) -> str:
    """The scheduling unit of a test: its compile group, else the test alone."""
    for group, prefixes in COMPILE_GROUPS.items():
        if nodeid.startswith(prefixes):
            return group
    return nodeid


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    from xdist.scheduler import LoadScopeScheduling

    class CompileGroupScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid):
            return compile_group(nodeid)

    return CompileGroupScheduling(config, log)
