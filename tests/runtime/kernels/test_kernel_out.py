"""The public kernel API with output buffers (out=, flags=): same results, no copies, bad buffers refused."""
import re

import numpy as np
import pytest

from tensormass.runtime.base.errors import InvertedElementError, TensormassError
from tensormass.runtime.kernels.kernels import Kernel, load_kernel
from tensormass.runtime.mesh.bars import generate_bar

BACKENDS = ("numba", "c")


def batch(kernel, n=40, seed=0):
    mesh = generate_bar(size=(1.0, 0.5, 0.5), cells=(2, 2, 2), element="tetra")
    cells = mesh.blocks[0].cells[:n]
    X = mesh.points[cells]
    D = kernel.constants(X, E=1e5, nu=0.3)
    u = 0.01 * np.random.default_rng(seed).standard_normal(X.shape)
    batch.X = X
    return D, u


@pytest.fixture(params=BACKENDS)
def kernel(request):
    return load_kernel("tetra", "stvk", "gauss1", request.param)


def test_out_buffers_give_the_same_bytes_and_are_returned(kernel):
    D, u = batch(kernel)
    n, nd = len(D), kernel.n_dofs
    W, f, K = np.empty(n), np.empty((n, nd)), np.empty((n, nd, nd))
    flags = np.full(n, 7, dtype=np.int32)
    assert kernel.energy(D, u, out=W) is W
    assert kernel.forces(D, u, out=f, flags=flags) is f
    assert not flags.any()                             # the kernel wrote the flags buffer
    assert kernel.stiffness(D, u, out=K) is K
    np.testing.assert_array_equal(W, kernel.energy(D, u))
    np.testing.assert_array_equal(f, kernel.forces(D, u))
    np.testing.assert_array_equal(K, kernel.stiffness(D, u))
    f2, K2 = np.empty_like(f), np.empty_like(K)
    rf, rK = kernel.forces_and_stiffness(D, u, out=(f2, K2))
    assert rf is f2 and rK is K2
    f3, K3 = kernel.forces_and_stiffness(D, u)
    np.testing.assert_array_equal(f2, f3)
    np.testing.assert_array_equal(K2, K3)


def bad_buffers(shape):
    good = np.empty(shape)
    readonly = np.empty(shape)
    readonly.flags.writeable = False
    yield "shape", np.empty(shape[:-1] + (shape[-1] + 1,))
    yield "dtype", np.empty(shape, dtype=np.float32)
    yield "layout", np.asfortranarray(np.empty(shape)) if len(shape) > 1 else np.empty(2 * shape[0])[::2]
    yield "readonly", readonly
    yield "type", good.tolist()


@pytest.mark.parametrize("what", ["energy", "forces", "stiffness", "f", "K"])
def test_wrong_buffers_are_refused_naming_the_expected_shape(kernel, what):
    D, u = batch(kernel, n=6)
    n, nd = len(D), kernel.n_dofs
    shapes = {"energy": (n,), "forces": (n, nd), "stiffness": (n, nd, nd), "f": (n, nd), "K": (n, nd, nd)}
    for _name, buf in bad_buffers(shapes[what]):
        with pytest.raises(TensormassError, match=re.escape(str(shapes[what]))):
            if what == "f":
                kernel.forces_and_stiffness(D, u, out=(buf, np.empty((n, nd, nd))))
            elif what == "K":
                kernel.forces_and_stiffness(D, u, out=(np.empty((n, nd)), buf))
            else:
                getattr(kernel, what)(D, u, out=buf)


def test_wrong_flags_and_pairs_are_refused(kernel):
    D, u = batch(kernel, n=5)
    with pytest.raises(TensormassError, match=r"int32 array of shape \(5,\)"):
        kernel.forces(D, u, flags=np.zeros(5, dtype=np.int64))
    with pytest.raises(TensormassError, match="pair"):
        kernel.forces_and_stiffness(D, u, out=np.empty((5, 12)))
    with pytest.raises(TensormassError, match=r"shape \(5, 4, 3\)"):
        kernel.forces(D, u[:4])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_displacements_give_a_clear_error_with_buffers(kernel, bad):
    D, u = batch(kernel, n=8)
    u[5, 2, 1] = bad
    f = np.empty((8, kernel.n_dofs))
    with pytest.raises(TensormassError, match=r"NaN or Inf in element\(s\) 5$"):
        kernel.forces(D, u, out=f)
    with pytest.raises(TensormassError, match="NaN or Inf"):
        kernel.energy(D, u)


def test_finite_check_tolerates_an_overflowing_sum():
    u = np.full((2, 4, 3), 1.5e308)                    # sum overflows; every entry is finite
    Kernel._finite(u)                                  # no error
    u[1, 0, 0] = np.nan
    with pytest.raises(TensormassError, match=r"element\(s\) 1$"):
        Kernel._finite(u)


@pytest.mark.parametrize("backend", ["c", pytest.param("numba", marks=pytest.mark.heavy)])   # numba: a module of its own
def test_flagged_elements_raise_with_buffers(backend):
    k = load_kernel("tetra", "neohookean", "gauss1", backend)
    D, u = batch(k, n=6)
    u[3] = -2.0 * batch.X[3]                           # element 3 point-mirrored: F = -I, det F < 0
    f, K = np.empty((6, 12)), np.empty((6, 12, 12))
    with pytest.raises(InvertedElementError) as info:
        k.forces_and_stiffness(D, u, out=(f, K))
    assert list(info.value.elements) == [3]

