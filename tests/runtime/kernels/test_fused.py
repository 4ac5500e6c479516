"""The fused evaluation and scatter (forces_and_stiffness_scatter of every generated kernel)
gives exactly the element-buffer path followed by runtime.assembly.assembly's serial scatter: the same
bits in the global forces and in the CSR values, part after part, on real meshes (shared nodes),
for both backends."""
from __future__ import annotations

import numpy as np
import pytest

import tensormass as tm
from tensormass.runtime.assembly.assembly import SparsePattern, scatter_matrix, scatter_vector
from tensormass.runtime.base.dofs import node_dofs
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.kernels.fused import block_positions, node_block_positions
from tensormass.runtime.mesh.bars import generate_bar

from helpers import quick

QUADRATURE = {"tetra": "gauss1", "triangle": "gauss1", "tetra10": "gauss2", "triangle6": "gauss2",
              "hexahedron": "gauss2", "quad": "gauss2", "wedge": "gauss2", "pyramid": "gauss2"}

CASES = [  # (mesh element, law, cells, size)
    ("tetra", "neohookean", (3, 2, 2), (1.5, 1.0, 1.0)),
    ("tetra10", "neohookean", (2, 2, 1), (1.0, 1.0, 0.5)),
    ("hexahedron", "mooney_rivlin", (3, 2, 2), (1.5, 1.0, 1.0)),
    ("wedge", "stable_neohookean", (2, 2, 2), (1.0, 1.0, 1.0)),
    ("pyramid", "stvk", (2, 2, 1), (1.0, 1.0, 0.5)),
    ("triangle", "neohookean", (4, 3), (2.0, 1.0)),
    ("triangle", "mooney_rivlin", (4, 3), (2.0, 1.0)),
    ("quad", "stvk", (4, 3), (2.0, 1.0)),
    ("hexahedron", "hooke", (3, 2, 2), (1.5, 1.0, 1.0)),
    ("hexahedron", "neohookean", (3, 2, 2), (1.5, 1.0, 1.0)),
    ("mixed", "neohookean", (8, 2, 2), (4.0, 1.0, 1.0)),      # hex | wedge | pyramid | tetra parts, shared nodes
]
MIXED = ("hexahedron", "wedge", "pyramid", "tetra")


def _quick(element, law, backend):
    """Whether every kernel of the case is in the quick suite's pools (helpers.QUICK_KERNELS,
    QUICK_NUMBA_KERNELS: compiled once for the suite); the other cases run in CI's heavy step."""
    return all(quick(f"{e}_{law}_{QUADRATURE[e]}", backend) for e in (MIXED if element == "mixed" else (element,)))


BACKEND_CASES = [pytest.param(*case, backend, id=f"{case[0]}-{case[1]}-{backend}",
                              marks=() if _quick(case[0], case[1], backend) else pytest.mark.heavy)
                 for case in CASES for backend in ("numba", "c")]


def _setup(element, law, cells, size, backend):
    mesh = generate_bar(size, cells, element)
    dim = mesh.points.shape[1]
    parts = []
    for block in mesh.blocks:
        k = tm.load_kernel(block.type, law, QUADRATURE[block.type], backend=backend)
        D = k.constants(mesh.points[block.cells], E=1.0, nu=0.3)
        parts.append((k, D, block.cells))
    pattern = SparsePattern([node_dofs(c, dim) for _, _, c in parts], mesh.points.shape[0] * dim)
    rng = np.random.default_rng(7)
    U = 0.03 * rng.standard_normal(mesh.points.shape)
    return parts, pattern, U, dim


def _element_path(parts, pattern, U, dim, f, data):
    for (k, D, cells), pos in zip(parts, pattern.positions):
        fe, Ke = k.forces_and_stiffness(D, U[cells])
        scatter_vector(f, fe, node_dofs(cells, dim))
        scatter_matrix(data, Ke, pos, 1.0)


@pytest.mark.parametrize("element,law,cells,size,backend", BACKEND_CASES)
def test_fused_is_bit_identical_to_element_buffers_and_scatter(element, law, cells, size, backend):
    parts, pattern, U, dim = _setup(element, law, cells, size, backend)
    rng = np.random.default_rng(3)
    # Start from non-zero globals (another part, a constant K): the sums must still be identical.
    f0, data0 = rng.standard_normal(U.size), rng.standard_normal(pattern.nnz)
    f_ref, data_ref = f0.copy(), data0.copy()
    _element_path(parts, pattern, U, dim, f_ref, data_ref)
    f, data = f0.copy(), data0.copy()
    for (k, D, c), pos in zip(parts, node_block_positions(pattern, dim)):
        k.forces_and_stiffness_scatter(D, U, c, pos, f, data)
    assert np.array_equal(f, f_ref) and np.array_equal(data, data_ref)
    assert np.abs(data - data0).max() > 0          # something was assembled
    K = pattern.matrix(data - data0)
    assert abs(K - K.T).max() <= 1e-12 * abs(K).max()


def test_block_positions_are_the_first_dof_of_each_node():
    parts, pattern, U, dim = _setup("tetra", "stvk", (2, 1, 1), (1.0, 1.0, 1.0), "numba")
    full = pattern.positions[0]
    pos = block_positions(full, dim)
    assert pos.dtype == np.int32 and pos.shape == (len(parts[0][2]), 12, 4)
    for c in range(dim):
        assert np.array_equal(full[:, :, c::dim], pos + c)
    # dofs numbered component-major are refused (a node's dofs are not consecutive in a row)
    cells = parts[0][2]
    n_points = U.shape[0]
    component_major = (cells[:, :, None] + n_points * np.arange(dim)).reshape(len(cells), -1)
    bad = SparsePattern([component_major], n_points * dim)
    with pytest.raises(TensormassError, match="node-major"):
        block_positions(bad.positions[0], dim)
    with pytest.raises(TensormassError, match="whole number"):
        block_positions(full, 5)


@pytest.mark.parametrize("backend", ["numba", "c"])
def test_fused_refuses_bad_inputs_and_flags_inverted_elements(backend):
    parts, pattern, U, dim = _setup("hexahedron", "neohookean", (2, 2, 1), (1.0, 1.0, 0.5), backend)
    k, D, cells = parts[0]
    pos = node_block_positions(pattern, dim)[0]
    f, data = np.zeros(U.size), np.zeros(pattern.nnz)
    with pytest.raises(TensormassError, match="cells must be an integer array of shape"):
        k.forces_and_stiffness_scatter(D, U, cells[:, :4], pos, f, data)
    with pytest.raises(TensormassError, match="pos must be an integer array of shape"):
        k.forces_and_stiffness_scatter(D, U, cells, pos[:1], f, data)
    with pytest.raises(TensormassError, match="f must have"):
        k.forces_and_stiffness_scatter(D, U, cells, pos, np.zeros(U.size + 1), data)
    with pytest.raises(TensormassError, match="data must be a writable"):
        k.forces_and_stiffness_scatter(D, U, cells, pos, f, data.astype(np.float32))
    with pytest.raises(TensormassError, match="outside the"):
        k.forces_and_stiffness_scatter(D, U, cells, pos, f, data[:10])
    bad_cells = cells.copy()
    bad_cells[1, 2] = len(U)
    with pytest.raises(TensormassError, match="node ids outside"):
        k.forces_and_stiffness_scatter(D, U, bad_cells, pos, f, data)
    with pytest.raises(TensormassError, match="constants must have shape"):
        k.forces_and_stiffness_scatter(D[:, 1:], U, cells, pos, f, data)
    V = U.copy()
    V[3, 1] = np.nan
    with pytest.raises(TensormassError, match="NaN or Inf at node"):
        k.forces_and_stiffness_scatter(D, V, cells, pos, f, data)
    X = generate_bar((1.0, 1.0, 0.5), (2, 2, 1), "hexahedron").points
    V = U.copy()
    V[cells[2]] = -2.0 * (X[cells[2]] - X[cells[2]].mean(axis=0))       # turns element 2 inside out
    with pytest.raises(tm.InvertedElementError) as info:
        k.forces_and_stiffness_scatter(D, V, cells, pos, f, data)
    assert 2 in list(info.value.elements)


def test_numba_kernels_release_the_gil():
    """Every generated numba function is compiled nogil (the runtime may run them in threads)."""
    module = tm.load_kernel("tetra", "stvk", "gauss1", backend="numba").module
    for name in ("constants", "energy", "forces", "stiffness", "forces_and_stiffness", "forces_and_stiffness_scatter"):
        assert getattr(module, name).targetoptions.get("nogil") is True, name
