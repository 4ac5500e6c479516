"""The device step (runtime.solve.device) on every device under test: the host shim (numpy arrays and the
cuda backend's files compiled as C run the code a GPU runs with CuPy) and, where present, the GPU. Its
colour-by-colour assembly equals the C backend's, its CG solves like a direct solver, and its trajectory
equals an independent implicit Euler (scipy's direct solve, the C kernel)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as spla

import tensormass as tm
from tensormass.runtime.assembly.colouring import check_colouring
from tensormass.runtime.base.dofs import node_dofs
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.solve.device import DevicePCG, DeviceStep, colour_ranges

from helpers import device_params, to_host

DT, GRAVITY = 0.01, (0.0, 0.0, -9.81)


def _scene():
    mesh = generate_bar((4.0, 1.0, 1.0), (8, 2, 2), "tetra")
    cells = mesh.blocks[0].cells
    c = tm.load_kernel("tetra", "neohookean", "gauss1", backend="c")
    params = c._params(len(cells), 2e4, 0.3, {})
    fixed = np.flatnonzero(mesh.points[:, 0] < 1e-9)
    mass = np.full(len(mesh.points), 1000.0 * 4.0 / len(mesh.points))
    return mesh, cells, c, params, fixed, mass


@pytest.fixture(params=device_params())
def device(request):
    return request.param()


def _device_step(device):
    mesh, cells, c, params, fixed, mass = _scene()
    step = DeviceStep(device, mesh.points, cells, c, params, fixed, mass, DT, GRAVITY, tolerance=1e-12)
    return step, mesh, c


def test_colour_ranges_hold_elements_that_share_no_node():
    mesh = generate_bar((2.0, 1.0, 1.0), (4, 2, 2), "tetra")
    cells = mesh.blocks[0].cells
    order, offsets = colour_ranges(cells)
    assert sorted(order) == list(range(len(cells))) and offsets[-1] == len(cells)
    colours = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    check_colouring(cells[order], colours)
    for a, b in zip(offsets[:-1], offsets[1:]):
        assert np.all(np.diff(order[a:b]) > 0)               # element order kept within a colour


def test_device_assembly_equals_the_c_backends(device):
    step, mesh, c = _device_step(device)
    u = 0.02 * np.random.default_rng(4).standard_normal(step.n_dofs)
    f_dev, _ = step.system.assemble(device.xp.asarray(u))
    f_dev, K_dev = to_host(f_dev), step.system.K.get() if hasattr(step.system.K, "get") else step.system.K
    D = c.constants(mesh.points[mesh.blocks[0].cells], E=2e4, nu=0.3)
    f_e, K_e = c.forces_and_stiffness(D, u.reshape(-1, 3)[mesh.blocks[0].cells])
    dofs = node_dofs(mesh.blocks[0].cells, 3)
    f = np.zeros(step.n_dofs)
    np.add.at(f, dofs, f_e)
    import scipy.sparse as sp
    rows = np.repeat(dofs, dofs.shape[1], axis=1).ravel()
    cols = np.tile(dofs, dofs.shape[1]).ravel()
    K = sp.csr_matrix((K_e.ravel(), (rows, cols)), shape=(step.n_dofs,) * 2)
    np.testing.assert_allclose(f_dev, f, rtol=0, atol=1e-12 * np.abs(f).max())
    assert abs(K_dev - K).max() <= 1e-12 * abs(K).max()


def test_device_step_follows_an_independent_implicit_euler(device):
    step, mesh, c = _device_step(device)
    cells = mesh.blocks[0].cells
    D = c.constants(mesh.points[cells], E=2e4, nu=0.3)
    dofs = node_dofs(cells, 3)
    n = step.n_dofs
    free = to_host(step.system.free).astype(bool)
    mass = to_host(step.system.mass_data)[step.pattern.diagonal]
    f_ext = mass * np.tile(GRAVITY, len(mesh.points))
    u, v = np.zeros(n), np.zeros(n)
    import scipy.sparse as sp
    rows = np.repeat(dofs, dofs.shape[1], axis=1).ravel()
    cols = np.tile(dofs, dofs.shape[1]).ravel()
    tip = np.argmax(mesh.points[:, 0] + mesh.points[:, 2])
    for k in range(6):
        f_e, K_e = c.forces_and_stiffness(D, u.reshape(-1, 3)[cells])
        f = np.zeros(n)
        np.add.at(f, dofs, f_e)
        K = sp.csr_matrix((K_e.ravel(), (rows, cols)), shape=(n, n))
        A = (sp.diags(mass) + DT * DT * K).tocsr()[free][:, free]
        b = DT * (f + f_ext - DT * (K @ v))
        dv = np.zeros(n)
        dv[free] = spla.spsolve(A.tocsc(), b[free])
        v += dv
        u += DT * v
        step.advance()
        assert step.iterations[-1] > 0
        np.testing.assert_allclose(to_host(step.u), u, rtol=0, atol=1e-8 * np.abs(u).max())
    assert u.reshape(-1, 3)[tip, 2] < -1e-4                  # it fell
    assert np.all(to_host(step.u)[~free] == 0)


def _spd_system(n_cells=(6, 2, 2)):
    import scipy.sparse as sp
    mesh = generate_bar((3.0, 1.0, 1.0), n_cells, "tetra")
    cells = mesh.blocks[0].cells
    c = tm.load_kernel("tetra", "neohookean", "gauss1", backend="c")
    D = c.constants(mesh.points[cells], E=2e4, nu=0.3)
    _, K_e = c.forces_and_stiffness(D, np.zeros((len(cells), 12)))
    dofs = node_dofs(cells, 3)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, 12).ravel()
    n = mesh.points.size
    A = (sp.csr_matrix((K_e.ravel(), (rows, cols)), shape=(n, n)) + sp.eye(n) * 50.0).tocsr()
    A.sort_indices()
    return A


def test_device_pcg_solves_like_a_direct_solver_and_repeats_its_bits(device):
    A = _spd_system()
    rng = np.random.default_rng(5)
    xp = device.xp
    b_host = rng.standard_normal(A.shape[0])
    b, diagonal = xp.asarray(b_host), xp.asarray(A.diagonal())
    pcg = DevicePCG(device, A.indptr, A.indices, A.shape[0], check_every=4)
    data = xp.asarray(np.ascontiguousarray(A.data))
    x, its = pcg.solve(data, b, diagonal, 1e-12, 10000)
    x = to_host(x)
    b = b_host
    exact = spla.spsolve(A.tocsc(), b)
    assert its > 0 and its % 4 == 0
    assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b)
    np.testing.assert_allclose(x, exact, rtol=0, atol=1e-9 * np.abs(exact).max())
    bd = xp.asarray(b)
    again, its_again = pcg.solve(data, bd, diagonal, 1e-12, 10000)
    assert its_again == its and np.array_equal(to_host(again), x)          # the same bits, solve after solve
    warm, its_warm = pcg.solve(data, bd, diagonal, 1e-12, 10000, x0=xp.asarray(x + 1e-9))      # a warm start
    assert its_warm < its and np.linalg.norm(A @ to_host(warm) - b) <= 1e-12 * np.linalg.norm(b)
    zero, none = pcg.solve(data, xp.zeros_like(bd), diagonal, 1e-12, 10000)
    assert none == 0 and not to_host(zero).any()
    with pytest.raises(TensormassError, match="did not reach a relative residual of 1e-14 in 8 iterations"):
        pcg.solve(data, bd, diagonal, 1e-14, 8)
