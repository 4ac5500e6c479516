"""Backends as units: one registry, one metadata format (constants layout included), loaders
that need nothing from the runtime, and loading committed kernels without the renderer."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tensormass import backends
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.kernels.kernels import load_kernel

from helpers import random_elements

BACKENDS_DIR = Path(backends.__file__).resolve().parent


def test_registry():
    assert backends.BACKENDS == ("numba", "c", "cuda")
    for name in backends.BACKENDS:
        b = backends.get(name)
        assert b.name == name and b.file_name("tetra_stvk_gauss1") == "tetra_stvk_gauss1" + b.suffix
        assert sorted(p.name for p in b.templates_dir().glob("*.j2"))
    with pytest.raises(backends.BackendError, match="unknown backend 'opencl'; known backends: numba, c, cuda"):
        backends.get("opencl")
    with pytest.raises(TensormassError, match="unknown backend 'opencl'"):
        load_kernel("tetra", "stvk", "gauss1", backend="opencl")


def test_backends_import_nothing_from_the_runtime():
    """Dependency direction: runtime -> backends and generator -> backends, never backends -> runtime."""
    for path in BACKENDS_DIR.rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                module = ("." * node.level) + (node.module or "")
                assert "runtime" not in module and "apps" not in module, f"{path.name} imports {module}"
            elif isinstance(node, ast.Import):
                assert not any("tensormass.runtime" in a.name for a in node.names), path.name


@pytest.mark.parametrize("backend", ["numba", "c"])
def test_metadata_file_equals_kernel(backend):
    """The metadata read from the file (no import, no compile) is what the loaded kernel carries."""
    b = backends.get(backend)
    k = load_kernel("hexahedron", "neohookean", "gauss2", backend=backend)
    root = Path(__import__("tensormass.generated", fromlist=["x"]).__file__).parent
    meta = b.read_metadata(root / backend / b.file_name(k.name))
    assert meta == k.metadata and tuple(sorted(meta)) == tuple(sorted(backends.METADATA_KEYS))
    assert meta["templates"] == b.templates_hash()[:16]


# one, two and three points per direction, simplex and tensor-product elements; the kernels are the
# quick pool's (helpers.QUICK_KERNELS): the layout does not depend on the law
@pytest.mark.parametrize("element,law,quadrature", [("tetra", "stvk", "gauss1"), ("hexahedron", "hooke", "gauss2"),
                                                    ("quad", "hooke", "gauss3"), ("tetra10", "stvk", "gauss2")])
def test_constants_layout_from_metadata(element, law, quadrature):
    """Kernel.point_volumes / point_gradients (the metadata's layout) against an independent
    numpy evaluation: v = w det J and G = dN J^-1 at each point, from the reference table."""
    from tensormass.generator.ir import build_ir
    k = load_kernel(element, law, quadrature)
    ir = build_ir(element, law, quadrature)
    X = random_elements(element, 5, seed=2)
    D = k.constants(X, E=1e3, nu=0.3)
    dN = np.array(ir.dN_table)                                   # (q, n, dim)
    J = np.einsum("ena,qnk->eqak", X, dN)                        # dx_a / dxi_k
    v = np.array(ir.weights) * np.linalg.det(J)
    G = np.einsum("qnk,eqka->eqna", dN, np.linalg.inv(J))
    np.testing.assert_allclose(k.point_volumes(D), v, rtol=1e-12)
    np.testing.assert_allclose(k.point_gradients(D), G, rtol=1e-10, atol=1e-12 * np.abs(G).max())
    assert k.material_offset == k.n_points * k.point_stride
    assert k.n_constants == k.material_offset + len(ir.material_names)


def test_run_path_does_not_import_the_renderer():
    """Loading committed kernels (both backends) imports neither jinja2 nor the printers."""
    code = ("import sys\nfrom tensormass.runtime.kernels.kernels import load_kernel\n"
            "load_kernel('tetra', 'stvk', 'gauss1', backend='numba')\n"
            "load_kernel('tetra', 'stvk', 'gauss1', backend='c')\n"
            "bad = [m for m in sys.modules if m == 'jinja2' or (m.startswith('tensormass.')"
            " and m.endswith(('.printer', '.render', '.pipeline')))]\n"
            "print(bad)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]"
