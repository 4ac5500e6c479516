"""The CUDA backend without a GPU: the printed CUDA file compiled as C on the host (the shim) gives the
C backend's bits in every function, NVRTC compiles it for real architectures where NVRTC is
installed, and asking for the backend without CuPy or a device is a clear error. With a GPU (CuPy
and a device present) the kernels on the device agree with the C backend."""
from __future__ import annotations

import numpy as np
import pytest

import tensormass as tm
from tensormass import backends
from tensormass.backends.cuda import loader as cuda_loader
from tensormass.runtime.assembly.assembly import SparsePattern
from tensormass.runtime.base.cache import cache_dir
from tensormass.runtime.base.dofs import node_dofs
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.kernels.fused import node_block_positions
from tensormass.runtime.kernels.kernels import kernel_source
from tensormass.runtime.mesh.bars import generate_bar

from helpers import catalogue_parameters, has_c_compiler

needs_cc = pytest.mark.skipif(not has_c_compiler(), reason="the host shim needs a C compiler")

# (bar element, law, quadrature, bar cells): one cheap case in the quick suite (its C kernel is in the
# quick pool), the large and the shell kernels in CI's heavy step.
CASES = [
    pytest.param("tetra", "neohookean", "gauss1", (2, 2, 1), id="tetra-neohookean"),
    pytest.param("tetra10", "stvk", "gauss2", (2, 1, 1), id="tetra10-stvk", marks=pytest.mark.heavy),
    pytest.param("hexahedron", "mooney_rivlin", "gauss2", (2, 2, 1), id="hexahedron-mooney", marks=pytest.mark.heavy),
    pytest.param("triangle", "hgo", "gauss1", (3, 2), id="triangle-hgo", marks=pytest.mark.heavy),
]


def _arrays(element, law, quadrature, cells):
    mesh = generate_bar((1.5, 1.0, 1.0)[:len(cells)], cells, element)
    c = tm.load_kernel(element, law, quadrature, backend="c")
    X = np.ascontiguousarray(mesh.points[mesh.blocks[0].cells])
    given = dict(catalogue_parameters(law))
    params = c._params(len(X), given.pop("E"), given.pop("nu"), given)
    return mesh, c, X, params


@needs_cc
@pytest.mark.parametrize("element,law,quadrature,cells", CASES)
def test_host_shim_gives_the_c_backends_bits(element, law, quadrature, cells):
    mesh, c, X, params = _arrays(element, law, quadrature, cells)
    shim = cuda_loader.load_host_shim(kernel_source(element, law, quadrature, "cuda"), cache_dir())
    same = lambda meta: {k: v for k, v in meta.items() if k != "templates"}
    assert same(shim.METADATA) == same(c.metadata)
    n, cm = len(X), c.module

    def both(kind, *shape_of_outputs, inputs):
        results = []
        for module in (cm, shim):
            outs = [np.zeros(s) for s in shape_of_outputs]
            flags = np.full(n, 7, dtype=np.int32)
            getattr(module, kind)(*inputs, *outs, flags)
            results.append(outs + [flags])
        for a, b in zip(*results):
            assert np.array_equal(a, b), kind
        return results[0]

    D, _ = both("constants", (n, c.n_constants), inputs=(X, params))
    u = 0.05 * np.random.default_rng(1).standard_normal((n, c.n_dofs))
    energy, _ = both("energy", n, inputs=(D, u))
    assert np.abs(energy).max() > 0
    both("forces", (n, c.n_dofs), inputs=(D, u))
    both("stiffness", (n, c.n_dofs, c.n_dofs), inputs=(D, u))
    both("forces_and_stiffness", (n, c.n_dofs), (n, c.n_dofs, c.n_dofs), inputs=(D, u))
    both("stress", (n, c.n_points, c.stress_record["size"]), inputs=(D, u))
    # the fused scatter on a mesh whose elements share nodes: one shim launch runs the elements in
    # order, as the C backend does
    dim, cells_ = mesh.points.shape[1], mesh.blocks[0].cells
    pattern = SparsePattern([node_dofs(cells_, dim)], mesh.points.size)
    pos = node_block_positions(pattern, dim)[0]
    U = 0.05 * np.random.default_rng(2).standard_normal(mesh.points.shape)
    fg = [np.zeros(U.size), np.zeros(U.size)]
    data = [np.zeros(pattern.nnz), np.zeros(pattern.nnz)]
    for k, module in enumerate((cm, shim)):
        module.forces_and_stiffness_scatter(D, U, np.ascontiguousarray(cells_, dtype=np.int64), pos, fg[k], data[k],
                                            np.zeros(n, dtype=np.int32))
    assert np.array_equal(fg[1], fg[0]) and np.array_equal(data[1], data[0])


def test_the_host_paths_scatter_adds_like_the_c_backend():
    """backend = "cuda" from numpy arrays: f and K come back from the device and are added on the host,
    in element order: the C backend's fused bits."""
    mesh, c, X, params = _arrays("tetra", "neohookean", "gauss1", (3, 2, 2))
    cells = np.ascontiguousarray(mesh.blocks[0].cells, dtype=np.int64)
    D = c.constants(X, E=2.0, nu=0.3)
    pattern = SparsePattern([node_dofs(cells, 3)], mesh.points.size)
    pos = node_block_positions(pattern, 3)[0]
    U = 0.05 * np.random.default_rng(3).standard_normal(mesh.points.shape)
    f_e, K_e = c.forces_and_stiffness(D, U[cells])
    fg, data = np.ones(U.size), np.ones(pattern.nnz)
    cuda_loader._scatter_in_order(f_e, K_e, cells, pos, fg, data)
    fg_c, data_c = np.ones(U.size), np.ones(pattern.nnz)
    c.forces_and_stiffness_scatter(D, U, cells, pos, fg_c, data_c)
    assert np.array_equal(fg, fg_c) and np.array_equal(data, data_c)


@needs_cc
def test_host_shim_flags_an_inverted_element():
    mesh, c, X, params = _arrays("tetra", "neohookean", "gauss1", (1, 1, 1))
    shim = cuda_loader.load_host_shim(kernel_source("tetra", "neohookean", "gauss1", "cuda"), cache_dir())
    n = len(X)
    D, flags = np.zeros((n, c.n_constants)), np.zeros(n, dtype=np.int32)
    shim.constants(X, params, D, flags)
    u = np.zeros((n, c.n_dofs))
    u[0, :3] = -3.0 * (X[0, 0] - X[0, 1:].mean(axis=0))       # node 0 pushed through the opposite face
    f, K = np.zeros((n, c.n_dofs)), np.zeros((n, c.n_dofs, c.n_dofs))
    shim.forces_and_stiffness(D, u, f, K, flags)
    assert flags[0] == 1 and not flags[1:].any()


def test_cuda_files_carry_the_metadata_of_the_other_backends():
    source = kernel_source("hexahedron", "neohookean", "gauss2", "cuda")
    cuda, c = backends.get("cuda"), backends.get("c")
    meta = cuda.read_metadata(source)
    other = c.read_metadata(kernel_source("hexahedron", "neohookean", "gauss2", "c"))
    assert {k: v for k, v in meta.items() if k != "templates"} == {k: v for k, v in other.items() if k != "templates"}
    assert meta["templates"] == cuda.templates_hash()[:16]
    text = source.read_text()
    for kind in backends.KERNEL_FUNCTIONS:
        assert f"TM_KERNEL {meta['name']}_{kind}(" in text


def _has_nvrtc() -> bool:
    try:
        cuda_loader._nvrtc()
    except backends.BackendError:
        return False
    return True


@pytest.mark.heavy            # CI's heavy step installs NVRTC
@pytest.mark.skipif(not _has_nvrtc(), reason="NVRTC is not installed (pip install 'tensormass[cuda]')")
def test_nvrtc_compiles_and_caches_a_generated_kernel(tmp_path):
    """NVRTC needs no GPU: the real CUDA compiler checks the printed file, and ptxas reports what a
    thread of each function uses."""
    source = kernel_source("tetra", "neohookean", "gauss1", "cuda")
    path, record = cuda_loader.compile_cubin(source, "sm_80", tmp_path)
    assert path.exists() and path.read_bytes()[:4] == b"\x7fELF" and record["arch"] == "sm_80"
    assert set(record["resources"]) == set(backends.KERNEL_FUNCTIONS)
    assert all(0 < r["registers"] <= 255 for r in record["resources"].values())
    again, second = cuda_loader.compile_cubin(source, "sm_80", tmp_path)
    assert again == path and second is None                            # from the cache
    path.write_bytes(b"truncated")                                     # a corrupted cubin is rebuilt
    _, third = cuda_loader.compile_cubin(source, "sm_80", tmp_path)
    assert third is not None and path.read_bytes()[:4] == b"\x7fELF"


@pytest.mark.heavy
@pytest.mark.skipif(not _has_nvrtc(), reason="NVRTC is not installed (pip install 'tensormass[cuda]')")
@pytest.mark.parametrize("element", ["tetra", "tetra10", "hexahedron", "wedge", "pyramid", "triangle", "quad",
                                     "triangle6"])
def test_nvrtc_compiles_every_element_type(element, tmp_path):
    quadrature = "gauss1" if element in ("tetra", "triangle") else "gauss2"
    _, record = cuda_loader.compile_cubin(kernel_source(element, "neohookean", quadrature, "cuda"), "sm_90", tmp_path)
    assert set(record["resources"]) == set(backends.KERNEL_FUNCTIONS)


@pytest.mark.heavy
@pytest.mark.skipif(not _has_nvrtc(), reason="NVRTC is not installed (pip install 'tensormass[cuda]')")
def test_nvrtc_compiles_the_device_cg(tmp_path):
    _, record = cuda_loader.compile_cubin(cuda_loader.PCG_SOURCE, "sm_90", tmp_path, name="tm_pcg")
    assert set(record["resources"]) == set(cuda_loader.PCG_FUNCTIONS)
    assert all(r["spill_bytes"] == 0 for r in record["resources"].values())


def _has_device() -> bool:
    try:
        cuda_loader.cupy()
    except backends.BackendError:
        return False
    return True


@pytest.mark.skipif(_has_device(), reason="CuPy and a CUDA device are present")
def test_backend_without_a_device_is_a_clear_error(tmp_path):
    with pytest.raises(TensormassError, match=r"(CUDA needs CuPy .*tensormass\[cuda\].*use backend = \"c\"|no usable CUDA device|no CUDA device)"):
        tm.load_kernel("tetra", "neohookean", "gauss1", backend="cuda")


@pytest.mark.skipif(not _has_device(), reason="needs CuPy and a CUDA device")
@pytest.mark.parametrize("element,law,quadrature,cells", CASES)
def test_device_kernels_agree_with_c(element, law, quadrature, cells):
    import cupy as cp
    mesh, c, X, params = _arrays(element, law, quadrature, cells)
    g = tm.load_kernel(element, law, quadrature, backend="cuda")
    n = len(X)
    D, Dg = np.zeros((n, c.n_constants)), np.zeros((n, c.n_constants))
    c.module.constants(X, params, D, np.zeros(n, dtype=np.int32))
    g.module.constants(X, params, Dg, np.zeros(n, dtype=np.int32))
    np.testing.assert_allclose(Dg, D, rtol=1e-12, atol=1e-14 * np.abs(D).max())
    u = 0.05 * np.random.default_rng(1).standard_normal((n, c.n_dofs))
    for a, b in zip(g.forces_and_stiffness(D, u), c.forces_and_stiffness(D, u)):
        np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-12 * np.abs(b).max())
    # device arrays stay on the device
    Dd, ud = cp.asarray(D), cp.asarray(u)
    f = cp.zeros((len(X), c.n_dofs))
    g.module.forces(Dd, ud, f, cp.zeros(len(X), dtype=cp.int32))
    np.testing.assert_allclose(f.get(), c.forces(D, u), rtol=1e-11, atol=1e-12 * np.abs(f.get()).max())
