"""C and numba kernels agree for every catalogue entry (the C forces_and_stiffness runs
4 elements per vector instruction, with a scalar remainder and a scalar fallback).

The fast suite checks a sample; CI's catalogue step sets TENSORMASS_FULL_CATALOGUE=1
to check every entry.
"""
from __future__ import annotations


import numpy as np
import pytest

import tensormass as tm
from tensormass import laws
from tensormass.generator.catalogue import catalogue
from tensormass.generator.ir import law_degree

from helpers import QUICK_NUMBA_KERNELS, catalogue_elements, catalogue_parameters, catalogue_selection, random_elements, relative_error

pytestmark = pytest.mark.catalogue

# The quick suite's numba modules (helpers.QUICK_NUMBA_KERNELS: 3D and 2D, simplices and a hexahedron,
# four laws; numba compiles each for 5 to 30 s cold): the one place where the quick
# suite checks C = numba. CI's catalogue step checks every entry (measures, gauss3, exact ...).
SELECTED = catalogue_selection(catalogue(), QUICK_NUMBA_KERNELS)


@pytest.mark.parametrize("entry", SELECTED, ids=[e.name for e in SELECTED])
def test_c_equals_numba(entry):
    numba = tm.load_kernel(entry.element, entry.law, entry.quadrature, backend="numba")
    c = tm.load_kernel(entry.element, entry.law, entry.quadrature, backend="c")
    X = catalogue_elements(entry.element, entry.law, entry.quadrature, 11, seed=3)                                  # 2 blocks of 4 + 3
    params = catalogue_parameters(entry.law)
    D = numba.constants(X, **params)
    assert relative_error(c.constants(X, **params), D) < 1e-12
    u = 0.04 * np.random.default_rng(1).standard_normal((len(X), numba.n_dofs))
    fn, Kn = numba.forces_and_stiffness(D, u)
    fc, Kc = c.forces_and_stiffness(D, u)
    assert relative_error(fc, fn) < 1e-12 and relative_error(Kc, Kn) < 1e-12
    assert relative_error(c.energy(D, u), numba.energy(D, u)) < 1e-12
    assert relative_error(c.forces(D, u), fn) < 1e-12
    assert relative_error(c.stiffness(D, u), Kn) < 1e-12


@pytest.mark.parametrize("law", ["neohookean", pytest.param("mooney_rivlin", marks=pytest.mark.heavy)])
def test_inverted_element_inside_a_vector_block(law):
    """An inverted element in a block of 4 sends the block to the scalar path: same flags, same values."""
    numba = tm.load_kernel("hexahedron", law, "gauss2", backend="numba")
    c = tm.load_kernel("hexahedron", law, "gauss2", backend="c")
    X = random_elements("hexahedron", 10, seed=5)
    D = numba.constants(X, E=2.0, nu=0.3)
    u = 0.02 * np.random.default_rng(2).standard_normal(X.shape)
    u[5] = -2.0 * (X[5] - X[5].mean(axis=0))
    results = []
    for k in (numba, c):
        f = np.empty((10, 24))
        K = np.empty((10, 24, 24))
        flags = np.zeros(10, dtype=np.int32)
        k.module.forces_and_stiffness(D, u.copy(), f, K, flags)
        results.append((f, K, flags))
        with pytest.raises(tm.InvertedElementError) as info:
            k.forces_and_stiffness(D, u)
        assert list(info.value.elements) == [5]
    (fn, Kn, gn), (fc, Kc, gc) = results
    assert list(gn) == list(gc) == [0, 0, 0, 0, 0, 1, 0, 0, 0, 0]
    ok = gn == 0
    assert relative_error(fc[ok], fn[ok]) < 1e-12 and relative_error(Kc[ok], Kn[ok]) < 1e-12


@pytest.mark.parametrize("entry", SELECTED, ids=[e.name for e in SELECTED])
def test_fused_scatter_c_equals_numba(entry):
    """forces_and_stiffness_scatter: C (vector blocks, scalar remainder) = numba, on elements that
    share nodes (so several elements add into the same global entries)."""
    from tensormass.runtime.assembly.assembly import SparsePattern
    from tensormass.runtime.base.dofs import node_dofs
    from tensormass.runtime.kernels.fused import block_positions
    numba = tm.load_kernel(entry.element, entry.law, entry.quadrature, backend="numba")
    c = tm.load_kernel(entry.element, entry.law, entry.quadrature, backend="c")
    n, k, d = 11, numba.n_nodes, numba.dofs_per_node                      # 2 blocks of 4 + 3
    X = catalogue_elements(entry.element, entry.law, entry.quadrature, n, seed=4)
    D = numba.constants(X, **catalogue_parameters(entry.law))
    rng = np.random.default_rng(5)
    n_points = 2 * k
    cells = np.array([rng.permutation(n_points)[:k] for _ in range(n)], dtype=np.int64)   # shared nodes
    pattern = SparsePattern([node_dofs(cells, d)], n_points * d)
    pos = block_positions(pattern.positions[0], d)
    U = 0.04 * rng.standard_normal((n_points, d))
    results = []
    for kernel in (numba, c):
        f, data = np.zeros(n_points * d), np.zeros(pattern.nnz)
        kernel.forces_and_stiffness_scatter(D, U, cells, pos, f, data)
        results.append((f, data))
    (fn, dn), (fc, dc) = results
    assert np.abs(dn).max() > 0 or law_degree(laws.kernel_law(entry.law)) == 1   # a linear measure: K = 0
    assert relative_error(fc, fn) < 1e-12 and relative_error(dc, dn) < 1e-12
