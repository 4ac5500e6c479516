"""One build per C library, whatever the number of processes that need it at once.

The library's build lock is held here while a second process asks for the kernel; the library
then appears (copied from a cache that has it, as a process finishing its build would leave
it), the lock is released, and the second process must load that library instead of compiling
its own.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
import time

import pytest

from helpers import has_c_compiler

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="the build lock is POSIX (fcntl)")

LOAD = textwrap.dedent("""
    from tensormass.backends.c import loader
    from tensormass.runtime.kernels.kernels import load_kernel
    load_kernel("tetra", "hooke", "gauss1", backend="c")
    print(len(loader.COMPILATIONS))
""")


def test_a_process_waits_for_the_build_under_way_and_loads_its_library(tmp_path):
    import fcntl
    if not has_c_compiler():
        pytest.skip("no C compiler")
    built = tmp_path / "built"
    subprocess.run([sys.executable, "-c", LOAD], env={**os.environ, "TENSORMASS_CACHE": str(built)},
                   check=True, capture_output=True, timeout=300)
    (source_lib,) = built.rglob("tetra_hooke_gauss1-*.so")
    lib = tmp_path / "cache" / source_lib.relative_to(built)           # where the other process looks
    lib.parent.mkdir(parents=True)
    with open(lib.parent / f".{lib.name}.lock", "a+b") as handle:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX)            # "this process is building it"
        waiting = subprocess.Popen([sys.executable, "-c", LOAD],
                                   env={**os.environ, "TENSORMASS_CACHE": str(tmp_path / "cache")},
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        # the other process gets as far as the lock (it cannot get past it while this one holds it)
        deadline = time.monotonic() + 120
        while not list(lib.parent.glob(".*.tmp")) and waiting.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
            if _waits_on_lock(waiting.pid):
                break
        for path in (source_lib, source_lib.with_name(source_lib.name + ".sha256")):
            shutil.copy2(path, lib.parent / path.name)
        fcntl.flock(handle.fileno(), fcntl.LOCK_UN)
    out, err = waiting.communicate(timeout=300)
    assert waiting.returncode == 0, err[-2000:]
    assert out.split()[-1] == "0"                            # loaded the library, compiled nothing
    assert sorted(p.name for p in lib.parent.glob("*.so")) == [lib.name]


def _waits_on_lock(pid: int) -> bool:
    """The process is blocked in flock (Linux: its wchan names the lock wait)."""
    try:
        with open(f"/proc/{pid}/wchan", encoding="ascii") as handle:
            return "lock" in handle.read()
    except OSError:
        return False
