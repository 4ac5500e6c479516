"""The C backend: same numbers as numba, deterministic source, a safe library cache."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import tensormass.backends.c.loader as cc
from tensormass import backends
from tensormass.generator.catalogue import Entry
from tensormass.generator.ir import build_ir
from tensormass.runtime.base.errors import DegenerateElementError, InvertedElementError, TensormassError
from tensormass.runtime.kernels.kernels import kernel_source, load_kernel

from helpers import quick, random_elements

# C = numba in the quick suite is test_backends_agree.py's (on helpers.QUICK_NUMBA_KERNELS); here the
# same metadata on those kernels (no extra compile), and the same results on a wider sample in CI's
# catalogue step (heavy: a numba compile of 5 to 30 s per kernel).
SAMPLE = [
    ("tetra", "stvk", "gauss1"),
    ("hexahedron", "neohookean", "gauss2"),
    ("wedge", "stable_neohookean", "gauss1"),
    ("tetra10", "hooke", "gauss1"),
    ("triangle", "mooney_rivlin", "gauss1"),
    ("quad", "neohookean", "gauss3"),
    ("tetra", "hooke", "gauss1"),
]
RTOL = 1e-12
N = 40


def close(a, b, what):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, what
    scale = max(float(np.abs(b).max()), 1e-300)
    err = float(np.abs(a - b).max()) / scale
    assert err <= RTOL, f"{what}: relative difference {err:.3e}"


@pytest.fixture(scope="module", params=[pytest.param(p, id="_".join(p), marks=() if quick("_".join(p), "numba")
                                                    else pytest.mark.heavy) for p in SAMPLE])
def pair(request):
    element, law, quadrature = request.param
    return load_kernel(element, law, quadrature, backend="numba"), load_kernel(element, law, quadrature, backend="c")


def test_same_metadata(pair):
    """One metadata format: the same keys and values (the templates hash aside) in C and numba."""
    numba, c = pair
    assert set(c.metadata) == set(numba.metadata) == set(backends.METADATA_KEYS)
    differ = {k for k in c.metadata if c.metadata[k] != numba.metadata[k]}
    assert differ == {"templates"}


@pytest.mark.heavy
def test_same_results(pair):
    numba, c = pair
    exact = numba.quadrature == "exact"          # needs straight edges: no node perturbation
    X = random_elements(numba.element, N, seed=7, distortion=0.0 if exact else 0.08)
    D = numba.constants(X, E=2.5e3, nu=0.35)
    close(c.constants(X, E=2.5e3, nu=0.35), D, "constants")
    u = 0.05 * np.random.default_rng(11).standard_normal((N, numba.n_nodes, numba.dim))
    assert not numba.inverted(D, u).any()
    close(c.energy(D, u), numba.energy(D, u), "energy")
    close(c.forces(D, u), numba.forces(D, u), "forces")
    close(c.stiffness(D, u), numba.stiffness(D, u), "stiffness")
    fc, Kc = c.forces_and_stiffness(D, u)
    fn, Kn = numba.forces_and_stiffness(D, u)
    close(fc, fn, "forces_and_stiffness: f")
    close(Kc, Kn, "forces_and_stiffness: K")
    close(Kc, np.swapaxes(Kc, 1, 2), "K symmetric")


def test_inverted_elements_same_error():
    numba = load_kernel("hexahedron", "neohookean", "gauss2", backend="numba")
    c = load_kernel("hexahedron", "neohookean", "gauss2", backend="c")
    X = random_elements("hexahedron", 8, seed=3)
    D = numba.constants(X, E=1e3, nu=0.3)
    u = np.zeros_like(X)
    u[[2, 5]] = -2.0 * X[[2, 5]]                 # F = -I: det F = -1 at every point
    for name in ("energy", "forces", "stiffness", "forces_and_stiffness"):
        errors = []
        for kernel in (numba, c):
            with pytest.raises(InvertedElementError) as info:
                getattr(kernel, name)(D, u)
            errors.append(info.value)
        assert str(errors[0]) == str(errors[1])
        np.testing.assert_array_equal(errors[1].elements, [2, 5])


@pytest.mark.parametrize("element, law, quadrature, rest", [
    ("tetra", "stvk", "gauss1", "mirrored"),
    pytest.param("triangle6", "hooke", "exact", "curved", marks=pytest.mark.heavy),   # a numba module of its own
])
def test_degenerate_and_curved_rest_elements(element, law, quadrature, rest):
    X = (random_elements("tetra", 4, seed=5)[:, [1, 0, 2, 3]] if rest == "mirrored"
         else random_elements("triangle6", 4, seed=5, distortion=0.1))
    messages = []
    for backend in ("numba", "c"):
        with pytest.raises(DegenerateElementError) as info:
            load_kernel(element, law, quadrature, backend=backend).constants(X, E=1e3, nu=0.3)
        messages.append(str(info.value))
    assert messages[0] == messages[1]


def test_wrong_arrays_refused():
    """The C module itself (below Kernel, which checks arrays first) refuses wrong arrays with
    the backend's error."""
    module = load_kernel("tetra", "stvk", "gauss1", backend="c").module
    D = np.zeros((3, module.METADATA["n_constants"]))
    u = np.zeros((3, 4, 3))
    with pytest.raises(backends.BackendError, match="float64"):
        module.energy(D, u.astype(np.float32), np.empty(3), np.zeros(3, np.int32))
    with pytest.raises(backends.BackendError, match="expected"):
        module.energy(D, u[:2], np.empty(3), np.zeros(3, np.int32))
    with pytest.raises(backends.BackendError, match="contiguous"):
        module.forces(D, u, np.empty((12, 3)).T, np.zeros(3, np.int32))


# -- generated source -------------------------------------------------------------------------
def test_source_deterministic_with_metadata():
    ir = build_ir("tetra", "stvk", "gauss1")
    c = backends.get("c")
    first, second = c.render(ir), c.render(build_ir("tetra", "stvk", "gauss1"))
    assert first == second
    assert first.startswith("/* generated by tensormass ")
    assert "#include <math.h>" in first
    meta = cc.parse_metadata(first)
    assert meta["name"] == "tetra_stvk_gauss1" and meta["n_constants"] == ir.n_constants
    for kind in ("constants", "energy", "forces", "stiffness", "forces_and_stiffness"):
        assert f"void tetra_stvk_gauss1_{kind}(long n," in first


# -- library cache ----------------------------------------------------------------------------
# The cheapest C build of the quick pool (helpers.QUICK_KERNELS): the tests below that are about
# compiling build it again in a fresh cache; the others start from a copy of the session's library.
ENTRY = Entry("triangle", "hooke", "gauss1")

LOAD = """
import json
from tensormass.runtime.kernels.kernels import load_kernel
m = load_kernel("triangle", "hooke", "gauss1", backend="c").module
print(json.dumps({"compiled": m.COMPILED, "library": str(m.LIBRARY), "seconds": m.COMPILE_SECONDS}))
"""


def c_module(entry):
    """The C module of an entry, loaded now (load_kernel without its per-process memo)."""
    return load_kernel.__wrapped__(entry.element, entry.law, entry.quadrature, "c").module


def source_path(entry):
    return kernel_source(entry.element, entry.law, entry.quadrature, "c")


def load_in_new_process(cache) -> dict:
    env = {**os.environ, "TENSORMASS_CACHE": str(cache)}
    done = subprocess.run([sys.executable, "-c", LOAD], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def reference():
    """ENTRY's kernel from the session's cache (module scope: loaded before a test points
    TENSORMASS_CACHE at its own folder)."""
    return load_kernel(ENTRY.element, ENTRY.law, ENTRY.quadrature, backend="c")


def check_module(module, reference):
    """The library computes what the session's library of the same kernel computes."""
    X = random_elements(ENTRY.element, 5, seed=1)
    D = reference.constants(X, E=1e3, nu=0.3)
    u = 0.05 * np.random.default_rng(2).standard_normal(X.shape)
    n = reference.n_dofs
    f, K, flags = np.empty((5, n)), np.empty((5, n, n)), np.zeros(5, np.int32)
    module.forces_and_stiffness(D, u, f, K, flags)
    fr, Kr = reference.forces_and_stiffness(D, u)
    assert np.abs(fr).max() > 0 and np.abs(Kr).max() > 0
    close(f, fr, "f")
    close(K, Kr, "K")


@pytest.fixture
def built(tmp_path, monkeypatch, reference):
    """A cache holding a library another process built: the session's library of ENTRY and its
    checksum sidecar, copied into an empty cache (cache folder, library path)."""
    session_library = Path(reference.module.LIBRARY)
    folder = tmp_path / session_library.parent.parent.name / session_library.parent.name
    folder.mkdir(parents=True)
    for path in (session_library, session_library.with_name(session_library.name + ".sha256")):
        shutil.copy2(path, folder / path.name)
    monkeypatch.setenv("TENSORMASS_CACHE", str(tmp_path))      # the session's flags: the same library name
    return tmp_path, str(folder / session_library.name)


def test_second_process_does_not_recompile(built, reference):
    cache, library = built
    mtime = os.stat(library).st_mtime_ns
    second = load_in_new_process(cache)
    assert second == {"compiled": False, "library": library, "seconds": 0.0}
    assert os.stat(library).st_mtime_ns == mtime
    # This process: the same library, loaded without compiling.
    before = len(cc.COMPILATIONS)
    module = c_module(ENTRY)
    assert str(module.LIBRARY) == library and not module.COMPILED
    assert module.COMPILE_SECONDS == 0 and module.COMPILE_MAXRSS_MB == 0
    assert len(cc.COMPILATIONS) == before
    check_module(module, reference)


@pytest.mark.parametrize("damage", ["garbage", "truncated", "no-sidecar"])
def test_damaged_library_is_rebuilt(built, reference, damage):
    _, library = built
    data = open(library, "rb").read()
    if damage == "garbage":
        with open(library, "wb") as handle:
            handle.write(os.urandom(len(data)))
    elif damage == "truncated":
        with open(library, "wb") as handle:
            handle.write(data[: len(data) // 2])
    else:
        os.remove(library + ".sha256")
    module = c_module(ENTRY)
    assert module.COMPILED and module.COMPILE_SECONDS > 0 and module.COMPILE_MAXRSS_MB > 0
    assert str(module.LIBRARY) == library
    assert cc.COMPILATIONS[-1]["library"] == library
    check_module(module, reference)
    leftovers = [p for p in os.listdir(os.path.dirname(library)) if p.endswith(".tmp")]
    assert leftovers == []


def test_concurrent_builds(tmp_path, monkeypatch, reference):
    """Processes that need the same kernel at once in an empty cache: one compiles, all get a
    working library; no temporary files stay."""
    monkeypatch.setenv("TENSORMASS_CACHE", str(tmp_path))
    monkeypatch.delenv("TENSORMASS_CFLAGS", raising=False)
    source_path(ENTRY)                         # generate the source once, then race the compilers
    env = {**os.environ, "TENSORMASS_CACHE": str(tmp_path)}
    procs = [subprocess.Popen([sys.executable, "-c", LOAD], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(3)]
    results = []
    for proc in procs:
        out, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err
        results.append(json.loads(out.strip().splitlines()[-1]))
    # the cache was empty: one compiled, the others waited on its build lock and loaded its library
    assert sum(r["compiled"] for r in results) == 1
    assert len({r["library"] for r in results}) == 1
    module = c_module(ENTRY)
    assert not module.COMPILED
    check_module(module, reference)
    folder = os.path.dirname(results[0]["library"])
    assert [p for p in os.listdir(folder) if p.endswith(".tmp")] == []


def test_missing_compiler(tmp_path, monkeypatch):
    monkeypatch.setenv("TENSORMASS_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    monkeypatch.setenv("PATH", "")
    with pytest.raises(TensormassError, match="no C compiler was found") as info:
        c_module(ENTRY)
    assert "apt-get install gcc" in str(info.value) and "numba" in str(info.value)
    monkeypatch.delenv("CC")
    monkeypatch.setattr(cc.shutil, "which", lambda name: None)
    with pytest.raises(TensormassError, match="no C compiler was found"):
        c_module(ENTRY)


def test_compile_error_shows_compiler_output(tmp_path, monkeypatch):
    monkeypatch.setenv("TENSORMASS_CACHE", str(tmp_path))
    source = source_path(ENTRY)
    if not source.is_relative_to(tmp_path):
        pytest.skip("the committed C source is used; not editing it")
    with open(source, "a", encoding="utf-8") as handle:
        handle.write("\n#error tensormass-test-broken-source\n")
    with pytest.raises(TensormassError, match="tensormass-test-broken-source"):
        c_module(ENTRY)
    assert not any(p.name.endswith(".so") for p in source.parent.iterdir())


def test_cflags_override(monkeypatch):
    monkeypatch.delenv("TENSORMASS_CFLAGS", raising=False)
    assert cc.cflags() == list(cc.CFLAGS)
    assert "-ffast-math" not in cc.CFLAGS
    monkeypatch.setenv("TENSORMASS_CFLAGS", "-O1 -std=c99")
    assert cc.cflags() == ["-O1", "-std=c99", "-fPIC", "-shared"]


def test_a_scenes_kernels_are_built_together_and_then_loaded_without_compiling(tmp_path, monkeypatch):
    """prepare_kernels compiles every missing library (one compiler per core); loading finds them built."""
    from tensormass.runtime.base.cache import cache_dir
    from tensormass.runtime.kernels.kernels import prepare_kernels
    monkeypatch.setenv("TENSORMASS_CACHE", str(tmp_path))
    monkeypatch.delenv("TENSORMASS_CFLAGS", raising=False)
    triples = [("triangle", "hooke", "gauss1"), ("triangle", "measure_volume", "gauss1")]   # cheap builds
    before = len(cc.COMPILATIONS)
    prepare_kernels(triples + triples[:1], "c")
    assert sorted(r["name"] for r in cc.COMPILATIONS[before:]) == ["triangle_hooke_gauss1", "triangle_measure_volume_gauss1"]
    prepare_kernels(triples, "c")                  # nothing left to build
    assert len(cc.COMPILATIONS) == before + 2
    for triple in triples:
        module = cc.load_source(kernel_source(*triple, "c"), cache_dir())
        assert not module.COMPILED
