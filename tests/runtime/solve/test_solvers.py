"""Linear solvers: every method on small SPD, indefinite, singular and bad systems; auto's choice.

Small matrices only (the whole file runs in about a second); speed is measured by
`tensormass bench steps`, never here.
"""
import numpy as np
import pytest
import scipy.sparse as sp

import tensormass as tm
from tensormass.runtime.solve import solvers
from tensormass.runtime.solve.solvers import LinearSolver, band_ordering


def grid_laplacian(nx, ny, nz, block=3, shift=0.0):
    """27-point-stencil graph Laplacian of an nx x ny x nz node grid, `block` dofs per node, + shift I.

    With shift > 0 it is SPD; its pattern is that of a hexahedral mesh's stiffness.
    """
    idx = np.arange(nx * ny * nz).reshape(nx, ny, nz)
    rows, cols = [], []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                if (dx, dy, dz) == (0, 0, 0):
                    continue
                a = idx[max(dx, 0):nx + min(dx, 0), max(dy, 0):ny + min(dy, 0), max(dz, 0):nz + min(dz, 0)]
                b = idx[max(-dx, 0):nx + min(-dx, 0), max(-dy, 0):ny + min(-dy, 0), max(-dz, 0):nz + min(-dz, 0)]
                rows.append(a.ravel())
                cols.append(b.ravel())
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    n = idx.size
    W = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    L = sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W
    B = np.eye(block) + 0.2 * (np.ones((block, block)) - np.eye(block))   # coupled components, SPD
    return (sp.kron(L, B) + shift * sp.eye(n * block)).tocsr()


def spd_system(seed=0, shape=(9, 3, 4)):
    A = grid_laplacian(*shape, shift=0.05)
    rng = np.random.default_rng(seed)
    # symmetric random scaling keeps it SPD and makes the diagonal uneven
    s = sp.diags(np.exp(rng.uniform(-1.0, 1.0, A.shape[0])))
    A = (s @ A @ s).tocsr()
    A.sort_indices()
    return A, rng.standard_normal(A.shape[0])


def relres(A, x, b):
    return np.linalg.norm(A @ x - b) / np.linalg.norm(b)


@pytest.mark.parametrize("method,preconditioner,tol", [
    ("auto", "ic", 1e-9), ("direct", "ic", 1e-9), ("band", "ic", 1e-9), ("lu", "ic", 1e-9),
    ("pardiso", "ic", 1e-9), ("amg", "ic", 1e-9), ("cg", "ic", 1e-9), ("cg", "jacobi", 1e-9),
    ("cg", "amg", 1e-9)])
def test_every_method_solves_spd(method, preconditioner, tol):
    if method == "pardiso" and not solvers.has_pardiso():
        pytest.skip("MKL (PARDISO) is not installed here")
    A, b = spd_system()
    solver = LinearSolver(method, tol=1e-11, max_iterations=5000, preconditioner=preconditioner)
    x, its = solver.solve(A, b)
    assert relres(A, x, b) < tol
    assert its >= 1 and solver.converged
    expected = {"auto": ("band32", "band64"), "direct": ("band32", "band64"),
                "band": ("band32", "band64"), "lu": ("lu",), "pardiso": ("pardiso32", "pardiso64"),
                "amg": ("cg-amg",), "cg": ("cg-ic", "cg-jacobi", "cg-amg")}[method]
    assert solver.last in expected
    if method == "cg" and preconditioner == "jacobi":
        assert solver.last == "cg-jacobi"


def test_direct_solvers_agree_and_reuse_the_ordering():
    A, b = spd_system(1)
    solver = LinearSolver("band")
    x1, _ = solver.solve(A, b)
    plan = solver._pattern
    B = sp.csr_matrix((2.0 * A.data, A.indices, A.indptr), shape=A.shape)   # same pattern, new values
    x2, _ = solver.solve(B, b)
    assert solver._pattern is plan
    np.testing.assert_allclose(x2, 0.5 * x1, rtol=1e-8, atol=1e-10 * np.abs(x1).max())
    x_lu, _ = LinearSolver("lu").solve(A, b)
    np.testing.assert_allclose(x1, x_lu, rtol=1e-7, atol=1e-9 * np.abs(x1).max())
    C = grid_laplacian(4, 3, 3, shift=1.0)                  # another pattern: a new ordering
    solver.solve(C, np.ones(C.shape[0]))
    assert solver._pattern is not plan


def test_cg_warm_start_and_iteration_cap():
    A, b = spd_system(2)
    solver = LinearSolver("cg", tol=1e-10)
    x, its = solver.solve(A, b)
    _, its_warm = solver.solve(A, b, x0=x * (1 + 1e-6))
    assert its_warm < its
    capped = LinearSolver("cg", tol=1e-14, max_iterations=2, preconditioner="jacobi")
    x2, its2 = capped.solve(A, b)
    assert its2 == 2 and not capped.converged and np.all(np.isfinite(x2))


@pytest.mark.parametrize("method", ["auto", "direct", "band", "lu", "pardiso"])
def test_indefinite_matrix_is_solved_by_ldlt_or_lu(method):
    if method == "pardiso" and not solvers.has_pardiso():
        pytest.skip("MKL (PARDISO) is not installed here")
    A = grid_laplacian(6, 3, 3, shift=0.0) - 0.7 * sp.eye(162)    # eigenvalues on both sides of 0
    A = A.tocsr()
    w = np.linalg.eigvalsh(A.toarray())
    assert w.min() < 0 < w.max() and np.abs(w).min() > 1e-3
    b = np.random.default_rng(3).standard_normal(A.shape[0])
    solver = LinearSolver(method)
    x, _ = solver.solve(A, b)
    assert relres(A, x, b) < 1e-10
    if method == "lu" or not solvers.has_pardiso():
        assert solver.last == "lu"
    else:                                          # symmetric indefinite LDL^T, with its inertia
        assert solver.last == "pardiso64"
        assert solver.inertia == (int((w > 0).sum()), int((w < 0).sum()))


def test_float32_failure_refactors_in_double():
    # SPD, but its smallest pivot is far below float32 round-off: the float32 factor fails or is useless
    A = grid_laplacian(8, 2, 2, block=1, shift=0.0).tolil()
    A[0, 0] += 1e-9
    A = A.tocsr()
    assert np.linalg.eigvalsh(A.toarray()).min() > 0
    b = np.random.default_rng(4).standard_normal(A.shape[0])
    solver = LinearSolver("band")
    x, _ = solver.solve(A, b)
    assert solver.last in ("band32", "band64")
    x_ref = np.linalg.solve(A.toarray(), b)
    # cond(A) ~ 5e11: a double-precision solve is only good to ~cond * eps in x, and its residual
    # sits at the round-off floor eps |A| |x|; the answer must be as good as LAPACK's double solve
    assert relres(A, x, b) <= 2.0 * relres(A, x_ref, b) + 1e-12
    assert np.abs(x - x_ref).max() <= 1e-4 * np.abs(x_ref).max()


@pytest.mark.parametrize("method", ["auto", "direct", "band", "lu", "cg", "amg", "pardiso"])
def test_nan_is_an_error(method):
    if method == "pardiso" and not solvers.has_pardiso():
        pytest.skip("MKL (PARDISO) is not installed here")
    A, b = spd_system()
    b[3] = np.nan
    with pytest.raises(tm.TensormassError, match="NaN"):
        LinearSolver(method).solve(A, b)
    A2, b2 = spd_system()
    A2.data[5] = np.inf
    with pytest.raises(tm.TensormassError, match="NaN"):
        LinearSolver(method).solve(A2, b2)


@pytest.mark.parametrize("method", ["auto", "direct", "band", "lu", "pardiso"])
def test_singular_matrix_is_an_error(method):
    if method == "pardiso" and not solvers.has_pardiso():
        pytest.skip("MKL (PARDISO) is not installed here")
    A, b = spd_system()
    A = A.tolil()
    A[4, :] = 0.0                                   # a dof with no stiffness at all
    A[:, 4] = 0.0
    A = A.tocsr()
    with pytest.raises(tm.TensormassError, match="singular"):
        LinearSolver(method).solve(A, b)


@pytest.mark.parametrize("method", ["cg", "amg"])
def test_cg_on_an_indefinite_matrix_falls_back_to_a_direct_solve(method):
    A, b = spd_system()
    A = A.tolil()
    A[2, 2] = -1.0                                  # a non-positive diagonal: CG cannot start
    A = A.tocsr()
    solver = LinearSolver(method)
    x, its = solver.solve(A, b)
    assert relres(A, x, b) < 1e-10 and its == 1
    assert "not positive definite" in solver.fallback and not solver.last.startswith("cg")
    # indefinite with a positive diagonal: CG meets negative curvature, then the same fallback
    B = (grid_laplacian(6, 3, 3, shift=0.0) - 0.7 * sp.eye(162)).tocsr()
    assert np.all(B.diagonal() > 0)
    c = np.random.default_rng(3).standard_normal(B.shape[0])
    solver = LinearSolver("cg")
    x, _ = solver.solve(B, c)
    assert relres(B, x, c) < 1e-10 and "not positive definite" in solver.fallback
    x, _ = solver.solve(*spd_system())              # the next (definite) system: CG again, no note
    assert solver.fallback is None and solver.last == "cg-ic"


def test_zero_rhs_and_bad_arguments():
    A, _ = spd_system()
    x, its = LinearSolver().solve(A, np.zeros(A.shape[0]))
    assert its == 0 and not np.any(x)
    with pytest.raises(tm.TensormassError, match="unknown linear solver"):
        LinearSolver("qr")
    with pytest.raises(tm.TensormassError, match="unknown preconditioner"):
        LinearSolver("cg", preconditioner="ilu")
    with pytest.raises(tm.TensormassError, match="does not match"):
        LinearSolver().solve(A, np.ones(A.shape[0] + 1))


def test_band_ordering_finds_the_slices_of_a_shuffled_bar():
    A = grid_laplacian(30, 3, 3, block=1, shift=1.0)
    p = np.random.default_rng(5).permutation(A.shape[0])
    shuffled = A[p][:, p].tocsr()
    shuffled.sort_indices()
    perm, iperm, kd = band_ordering(shuffled)
    assert np.array_equal(np.sort(perm), np.arange(A.shape[0])) and np.array_equal(iperm[perm], np.arange(A.shape[0]))
    assert kd <= 2 * 9                              # a slice is 9 nodes: natural order gives 13


def test_auto_picks_by_the_cost_model(monkeypatch):
    small, _ = spd_system()                         # below AUTO_DIRECT_BELOW: always the band
    assert small.shape[0] <= solvers.AUTO_DIRECT_BELOW
    assert LinearSolver("auto").choose(small) == "band"
    bar = grid_laplacian(120, 3, 3, shift=1.0)      # long bar: narrow band
    cube = grid_laplacian(12, 12, 12, shift=1.0)    # compact: wide band
    assert min(bar.shape[0], cube.shape[0]) > solvers.AUTO_DIRECT_BELOW
    auto = LinearSolver("auto")
    assert auto.choose(bar) == "band" and auto.kind_for(bar) == "direct"
    # fixed methods never change; kind_for on a bare size
    assert LinearSolver("cg").choose(small) == "cg" and LinearSolver("lu").choose(cube) == "lu"
    assert LinearSolver("amg").choose(small) == "amg" and LinearSolver("amg").kind_for(cube) == "cg"
    assert LinearSolver("auto").kind_for(10) == "direct" and LinearSolver("direct").kind_for(10 ** 7) == "direct"
    assert LinearSolver("cg").kind_for(10) == "cg"
    if solvers.has_pardiso():
        # band while its modelled cost is below PARDISO's (analysed only past PARDISO_ANALYSE_ABOVE)
        pattern = LinearSolver().pattern(cube)
        band = pattern.band_seconds(cube)
        factor, solve = pattern.pardiso(cube).costs()
        expected = "band" if band <= max(solvers.PARDISO_ANALYSE_ABOVE, factor + 3 * solve) else "pardiso"
        assert LinearSolver("direct").choose(cube) == expected
        monkeypatch.setattr(solvers, "PARDISO_ANALYSE_ABOVE", 0.0)
        monkeypatch.setattr(solvers, "PARDISO_FLOPS", 1e30)          # PARDISO modelled free
        assert LinearSolver("direct").choose(cube) == "pardiso"
        assert LinearSolver("auto").choose(cube) == "pardiso"
        monkeypatch.setattr(solvers, "PARDISO_FLOPS", 1.0)           # PARDISO modelled hopeless
        assert LinearSolver("direct").choose(cube) == "band"
        monkeypatch.setattr(solvers, "PARDISO_FLOPS", 1e30)
        monkeypatch.setattr(solvers, "PARDISO_MAX_BYTES", 0)         # its factor too big: multigrid
        assert LinearSolver("auto").choose(cube) == "amg" and LinearSolver("direct").choose(cube) == "pardiso"
        monkeypatch.setattr(solvers, "PARDISO_MAX_BYTES", 2 ** 40)
        monkeypatch.setattr(solvers, "DIRECT_LIMIT", cube.shape[0] - 1)
        assert LinearSolver("auto").choose(cube) == "amg"


def test_without_mkl_the_band_and_cg_rules_apply(monkeypatch):
    monkeypatch.setattr(solvers.pardiso, "available", lambda: False)
    cube = grid_laplacian(12, 12, 12, shift=1.0)
    plan_cube = LinearSolver().plan(cube)
    # the rule: band while n kd^2 <= AUTO_BAND_WORK_PER_NNZ x nnz
    monkeypatch.setattr(solvers, "AUTO_BAND_WORK_PER_NNZ", 0.99 * plan_cube.work / cube.nnz)
    assert LinearSolver("auto").choose(cube) == "cg"
    monkeypatch.setattr(solvers, "AUTO_BAND_WORK_PER_NNZ", 1.01 * plan_cube.work / cube.nnz)
    assert LinearSolver("auto").choose(cube) == "band"
    monkeypatch.setattr(solvers, "BAND_MAX_ENTRIES", plan_cube.entries - 1)
    assert LinearSolver("auto").choose(cube) == "cg"
    assert LinearSolver("direct").choose(cube) == "lu"  # too big a band for "direct": SuperLU
    with pytest.raises(tm.TensormassError, match="pardiso.*unavailable"):
        LinearSolver("pardiso")


def test_band_factor_reuse():
    A, b = spd_system(6)
    solver = LinearSolver("band")
    solver.solve(A, b)
    assert solver.last in ("band32", "band64")
    d = 1 + 1e-6 * np.cos(np.arange(A.shape[0]))   # D A D: same pattern, slightly other values
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    near = sp.csr_matrix((A.data * d[rows] * d[A.indices], A.indices, A.indptr), shape=A.shape)
    x, _ = solver.solve(near, b)
    assert solver.last.endswith("-reuse")
    assert relres(near, x, b) < 1e-9
    far, _ = spd_system(7)                          # same pattern, unrelated values: refactored
    far = sp.csr_matrix((far.data, A.indices, A.indptr), shape=A.shape)
    x, _ = solver.solve(far, b)
    assert not solver.last.endswith("-reuse") and relres(far, x, b) < 1e-9
    fresh = LinearSolver("band", reuse=False)
    fresh.solve(A, b)
    fresh.solve(near, b)
    assert not fresh.last.endswith("-reuse")


def test_the_warm_up_loads_only_the_chosen_methods_loops(monkeypatch):
    """Setup compiles the numba loops of the method the pattern gets, not every path's."""
    calls = []
    monkeypatch.setattr(solvers, "warm_up", lambda index=None, pointer=None, paths=solvers.NUMBA_PATHS: calls.append(tuple(paths)))
    A = grid_laplacian(3, 3, 3, shift=0.1)
    LinearSolver("band").warm_up(A)
    LinearSolver("cg").warm_up(A)
    LinearSolver("cg", preconditioner="jacobi").warm_up(A)
    LinearSolver("lu").warm_up(A)                   # SciPy's SuperLU: no numba loop
    LinearSolver("band").warm_up(None)              # P^T A P formed per solve: every path
    assert calls == [(("band", "ic"),), (("cg", "ic"),), (("cg", "jacobi"),), solvers.NUMBA_PATHS]


def test_an_explicit_run_warms_up_no_linear_solver(monkeypatch):
    from tensormass.runtime.physics.newton import Context
    warmed = []
    monkeypatch.setattr(Context, "warm_up_solver", lambda self: warmed.append(self.model.solver.kind))
    for kind in ("explicit", "static"):
        scene = tm.Scene.from_string(f"""
[mesh]
generate = "bar"
size = [0.4, 0.1, 0.1]
cells = [4, 1, 1]
element = "tetra"
[[material]]
law = "hooke"
E = 1.0e6
nu = 0.3
density = 1000.0
[[fixed]]
box = [[-1, -1, -1], [1e-9, 1, 1]]
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "{kind}"
steps = 2
dt = 1e-5
""")
        tm.Simulation(scene).run()
    assert warmed == ["static"]
