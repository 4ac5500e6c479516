"""PARDISO (MKL) and multigrid paths of the linear solver: same bits on 1 and 2 threads, inertia,
float32 -> float64, factor reuse, rigid-body modes, whole runs against the band solver.

Small systems only; speed is measured by `tensormass bench organ` / `bench steps`."""
import numpy as np
import pytest
import scipy.sparse as sp

import tensormass as tm
from tensormass.runtime.solve import amg, pardiso, solvers
from tensormass.runtime.solve.solvers import LinearSolver

from test_solvers import grid_laplacian, relres, spd_system

needs_mkl = pytest.mark.skipif(not pardiso.available(), reason="MKL (PARDISO) is not installed here")


def cube_system(n=10, seed=0):
    """A 3 000-dof SPD system: large enough that PARDISO's bits differ between 1 and 2 threads
    outside MKL's reproducible mode (checked: the thread tests below fail with iparm[33] = 0)."""
    A = grid_laplacian(n, n, n, shift=0.02)
    A.sort_indices()
    return A, np.random.default_rng(seed).standard_normal(A.shape[0])


@needs_mkl
def test_pardiso_gives_the_same_bits_on_one_and_two_threads():
    A, b = cube_system()
    U = sp.triu(A, format="csr")
    results = []
    for threads in (1, 2, 1):
        for single in (False, True):
            h = pardiso.Pardiso(A.shape[0], U.indptr, U.indices, single=single, threads=threads)
            h.analyse()
            h.factor(U.data)
            results.append((single, h.solve(b).tobytes()))
    for single in (False, True):
        bits = {r for s, r in results if s == single}
        assert len(bits) == 1
    x = np.frombuffer(results[0][1])
    assert relres(A, x, b) < 1e-12


@needs_mkl
def test_linear_solver_bits_do_not_depend_on_the_thread_count(monkeypatch):
    A, b = cube_system(seed=1)
    out = []
    monkeypatch.setattr(solvers, "PARDISO_PARALLEL_DOFS", 0)     # this small system would factor on one thread
    for threads in (1, 2):
        monkeypatch.setattr(solvers, "_worker_threads", lambda t=threads: t)
        solver = LinearSolver("pardiso")
        x1, _ = solver.solve(A, b)
        assert solver._pattern.pardiso(A).handles[True].threads == threads
        x2, _ = solver.solve(A * 1.001, b)           # the kept factor preconditions CG
        assert solver.last == "pardiso32-reuse"
        out.append(x1.tobytes() + x2.tobytes())
    assert out[0] == out[1]


@needs_mkl
def test_inertia_and_statistics():
    A = (grid_laplacian(6, 3, 3, shift=0.0) - 0.7 * sp.eye(162)).tocsr()
    w = np.linalg.eigvalsh(A.toarray())
    U = sp.triu(A, format="csr")
    h = pardiso.Pardiso(A.shape[0], U.indptr, U.indices)
    stats = h.analyse()
    assert stats["factor_nnz"] >= U.nnz and stats["factor_flops"] >= 0 and stats["memory_bytes"] > 0
    h.factor(U.data)
    assert h.inertia == (int((w > 0).sum()), int((w < 0).sum()))
    h.release()
    h.release()                                     # twice is harmless


@needs_mkl
def test_float32_failure_refactors_in_double_precision():
    A = grid_laplacian(8, 8, 8, block=1, shift=0.0).tolil()
    A[0, 0] += 1e-5                                 # SPD, condition ~1e9: beyond float32's reach
    A = A.tocsr()
    A.sort_indices()
    w = np.linalg.eigvalsh(A.toarray())
    assert w.min() > 0 and w.max() / w.min() > 1e8
    b = np.random.default_rng(4).standard_normal(A.shape[0])
    solver = LinearSolver("pardiso")
    x, _ = solver.solve(A, b)
    assert solver.last == "pardiso64"
    x_ref = np.linalg.solve(A.toarray(), b)
    assert np.abs(x - x_ref).max() <= 1e-6 * np.abs(x_ref).max()


@needs_mkl
def test_pardiso_factor_reuse_and_refactor():
    A, b = cube_system(seed=2)
    solver = LinearSolver("pardiso")
    solver.solve(A, b)
    assert solver.last == "pardiso32" and solver.inertia == (A.shape[0], 0)
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    d = 1 + 1e-6 * np.cos(np.arange(A.shape[0]))
    near = sp.csr_matrix((A.data * d[rows] * d[A.indices], A.indices, A.indptr), shape=A.shape)
    x, _ = solver.solve(near, b)
    assert solver.last == "pardiso32-reuse" and relres(near, x, b) < 1e-9
    far = sp.csr_matrix((A.data * (1 + 3 * (rows % 2)), A.indices, A.indptr), shape=A.shape)
    far = (far + far.T).tocsr()
    far.sort_indices()
    x, _ = solver.solve(far, b)
    assert relres(far, x, b) < 1e-9


def test_pardiso_unavailable_is_a_clear_error(monkeypatch):
    monkeypatch.setattr(pardiso, "_lib", None)
    monkeypatch.setattr(pardiso, "_why", "MKL's mkl_rt library was not found (pip install mkl)")
    assert not pardiso.available()
    with pytest.raises(tm.TensormassError, match="'pardiso' is unavailable: MKL's mkl_rt library was not found"):
        LinearSolver("pardiso")
    A, b = spd_system()
    x, _ = LinearSolver("direct").solve(A, b)      # everything else still works
    assert relres(A, x, b) < 1e-9


def _bar_model(linear="auto", element="tetra", cells=(8, 2, 2)):
    text = f"""
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = {list(cells)}
element = "{element}"
[[material]]
region = "all"
law = "neohookean"
quadrature = "{'gauss1' if element == 'tetra' else 'gauss2'}"
E = 1e5
nu = 0.3
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[loads]
gravity = [0, 0, -9.81]
[solver]
kind = "static"
linear = "{linear}"
cg_tolerance = 1e-12
"""
    return tm.Scene.from_string(text)


def test_rigid_body_modes_span_the_stiffness_nullspace():
    from tensormass.runtime.assembly.assembly import assemble
    from tensormass.runtime.model.model import Model
    model = Model.from_scene(_bar_model())
    _, _, K = assemble(model, np.zeros(model.n_dofs))
    modes = amg.rigid_body_modes(model.mesh.points, np.arange(model.n_dofs), model.dofs_per_node)
    assert modes.shape == (model.n_dofs, 6) and np.linalg.matrix_rank(modes) == 6
    assert np.abs(K @ modes).max() <= 1e-9 * np.abs(K).max() * np.abs(modes).max()
    pts2 = np.random.default_rng(0).standard_normal((5, 2))
    assert amg.rigid_body_modes(pts2, np.arange(10), 2).shape == (10, 3)
    assert amg.rigid_body_modes(pts2, np.arange(15), 3) is None      # other dofs than a displacement


def test_multigrid_with_rigid_modes_beats_plain_aggregation():
    from tensormass.runtime.assembly.assembly import assemble
    from tensormass.runtime.model.model import Model
    model = Model.from_scene(_bar_model(cells=(24, 4, 4)))
    _, _, K = assemble(model, np.zeros(model.n_dofs))
    free = model.free_dofs
    A = K[free][:, free].tocsr()
    b = np.random.default_rng(0).standard_normal(free.size)
    modes = amg.rigid_body_modes(model.mesh.points, free, 3)
    counts = []
    for B in (modes, None):
        x, its, ok = amg.solve(A, b, amg.build(A, B), None, 1e-10, 2000)
        assert ok and relres(A, x, b) < 1e-9
        counts.append(its)
    assert counts[0] < counts[1]


@pytest.mark.parametrize("linear", ["pardiso", "amg", "cg", "lu"])
def test_whole_runs_agree_with_the_band_solver(linear):
    if linear == "pardiso" and not pardiso.available():
        pytest.skip("MKL (PARDISO) is not installed here")
    ref, run = tm.Simulation(_bar_model("band")), tm.Simulation(_bar_model(linear))
    assert ref.run().exit_code == 0 and run.run().exit_code == 0
    u_ref, u = ref.displacement, run.displacement
    assert np.abs(u_ref).max() > 1e-4
    assert np.abs(u - u_ref).max() <= 1e-7 * np.abs(u_ref).max()


def test_scene_solver_names_are_the_runtime_methods():
    from tensormass.runtime.scene.parser import LINEAR_SOLVERS
    assert LINEAR_SOLVERS == solvers.METHODS


def test_a_run_asking_for_pardiso_without_mkl_fails_with_the_reason(tmp_path):
    """TENSORMASS_MKL_RT names the library to use, and only it: a wrong path makes `linear =
    "pardiso"` a clear error and a non-zero exit through the CLI, before anything is written."""
    import os
    import subprocess
    import sys
    scene = tmp_path / "bar.toml"
    scene.write_text('''
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [4, 1, 1]
element = "hexahedron"
[[material]]
region = "all"
law = "stvk"
quadrature = "gauss2"
E = 1e6
nu = 0.3
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[loads]
gravity = [0, 0, -9.81]
[solver]
linear = "pardiso"
[output]
dir = "out"
''')
    env = dict(os.environ, TENSORMASS_MKL_RT=str(tmp_path / "missing" / "libmkl_rt.so"))
    done = subprocess.run([sys.executable, "-m", "tensormass.launcher", "run", str(scene)], env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode != 0
    assert "'pardiso' is unavailable" in done.stderr and "missing" in done.stderr
    assert not (tmp_path / "out").exists()
