"""Blocked, colour-ordered, threaded assembly (runtime.assembly.assembly, runtime.base.parallel): the same bytes
for one and two threads, the dense reference for every kind of part, and the one thread switch."""
import numpy as np
import pytest

from tensormass.runtime.assembly import assembly
from tensormass.runtime.base import parallel
from tensormass.runtime.assembly.assembly import Assembler, _project_psd_reference, project_psd
from tensormass.runtime.base.errors import InvertedElementError, TensormassError
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.model.model import Model
from tensormass.runtime.scene.types import Adapt, Fixed, Material, Solver
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.base.errors import SceneError

E, NU = 1e6, 0.3
CLAMP = Fixed(box=((-1, -1, -1), (0, 1, 1)))
two_cores = pytest.mark.skipif(parallel.available() < 2, reason="numba sees one core")


@pytest.fixture
def small_blocks(monkeypatch):
    """Blocks of 4 elements, so that tiny meshes have many blocks, segments and colours."""
    monkeypatch.setattr(assembly, "MIN_BLOCK", 4)
    monkeypatch.setattr(assembly, "BLOCK_BYTES", 1)


def model_of(element="tetra", cells=(6, 3, 3), law="neohookean", quadrature="gauss1", backend="c", adapt=()):
    mesh = generate_bar(size=(1.0, 0.5, 0.5), cells=cells, element=element)
    return Model(mesh, [Material(law=law, quadrature=quadrature, E=E, nu=NU)], fixed=[CLAMP],
                 solver=Solver(backend=backend), adapt=list(adapt))


def dense_reference(model, u):
    K, f, W = np.zeros((model.n_dofs,) * 2), np.zeros(model.n_dofs), 0.0
    for part in model.parts:
        if not part.n_active:
            continue
        ue = model.element_displacements(part, u)
        fe, Ke = part.kernel.forces_and_stiffness(part.D_active, ue)
        W += part.kernel.energy(part.D_active, ue).sum()
        for e, dofs in enumerate(part.dofs_active):
            f[dofs] += fe[e]
            K[np.ix_(dofs, dofs)] += Ke[e]
    return W, f, K


def check_against_reference(model, asm, u):
    W_ref, f_ref, K_ref = dense_reference(model, u)
    f, data = asm.forces_and_stiffness(u)
    scale = np.abs(K_ref).max()
    np.testing.assert_allclose(asm.matrix(data).toarray(), K_ref, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-12 * np.abs(f_ref).max())
    np.testing.assert_allclose(asm.forces(u), f, rtol=0, atol=1e-13 * np.abs(f_ref).max())
    np.testing.assert_allclose(asm.stiffness(u), data, rtol=0, atol=1e-13 * scale)
    assert asm.energy(u) == pytest.approx(W_ref, rel=1e-12)


def results(asm, u, threads):
    with parallel.threads(threads):
        f, data = asm.forces_and_stiffness(u)
        return f.tobytes(), data.tobytes(), asm.forces(u).tobytes(), asm.stiffness(u, True).tobytes(), asm.energy(u)


@two_cores
@pytest.mark.parametrize("backend", [pytest.param("numba", marks=pytest.mark.heavy), "c"])   # numba: 10 s cold
def test_one_and_two_threads_give_the_same_bytes(small_blocks, monkeypatch, backend):
    model = model_of(backend=backend)
    asm = Assembler(model, parallel=True)
    plan = asm.plans[0]
    assert plan.n_segments >= 8 and len(plan.starts) - 1 >= 2      # several segments per colour
    calls = []
    real = parallel.run_shares
    monkeypatch.setattr(parallel, "run_shares", lambda task, n: (calls.append(n), real(task, n)))
    u = 0.01 * np.random.default_rng(0).standard_normal(model.n_dofs)
    one = results(asm, u, 1)
    assert not calls
    two = results(asm, u, 2)
    assert one == two
    if plan.parallel:                                # C kernels release the GIL (numba ones with nogil)
        assert calls and max(calls) == 2
    check_against_reference(model, asm, u)


@two_cores
def test_hooke_constant_stiffness_and_mixed_mesh_threads(small_blocks):
    u = None
    for model in (model_of(law="hooke", backend="c"), model_of("mixed", (4, 2, 2), "stvk", "gauss2", "c")):
        asm = Assembler(model, parallel=True)
        u = 0.01 * np.random.default_rng(1).standard_normal(model.n_dofs)
        assert results(asm, u, 1) == results(asm, u, 2)
        check_against_reference(model, asm, u)


def test_switchable_parts_assemble_their_active_cells(small_blocks):
    model = model_of("hexahedron", (6, 2, 2), "hooke", "gauss2",
                     adapt=[Adapt(criterion="rotation", threshold=5.0, law="stvk")])
    group = model.groups[0]
    group.switch(model, np.arange(0, model.mesh.n_cells, 3), "stvk")
    parts = [model.parts[i] for i in group.parts]
    assert all(p.index is not None and p.n_active for p in parts)
    asm = Assembler(model)
    u = 0.01 * np.random.default_rng(2).standard_normal(model.n_dofs)
    check_against_reference(model, asm, u)
    group.switch(model, np.arange(model.mesh.n_cells), "hooke")     # back: the constant K is rebuilt
    asm.refresh()
    check_against_reference(model, asm, u)


def test_blocked_equals_whole_part_buffers(monkeypatch):
    model = model_of("tetra10", (3, 2, 2), "neohookean", "gauss2")
    u = 0.01 * np.random.default_rng(3).standard_normal(model.n_dofs)
    whole = Assembler(model, parallel=False)
    assert whole.plans[0].block == whole.plans[0].n
    f0, d0 = whole.forces_and_stiffness(u)
    monkeypatch.setattr(assembly, "MIN_BLOCK", 5)
    monkeypatch.setattr(assembly, "BLOCK_BYTES", 1)
    blocked = Assembler(model, parallel=False)
    assert blocked.plans[0].block == 5
    f1, d1 = blocked.forces_and_stiffness(u)
    np.testing.assert_allclose(d1, d0, rtol=0, atol=1e-13 * np.abs(d0).max())
    np.testing.assert_allclose(f1, f0, rtol=0, atol=1e-13 * np.abs(f0).max())


def test_results_held_by_the_caller_are_never_overwritten():
    model = model_of(cells=(3, 2, 2))
    asm = Assembler(model)
    rng = np.random.default_rng(4)
    u1, u2 = (0.01 * rng.standard_normal(model.n_dofs) for _ in range(2))
    f1, d1 = asm.forces_and_stiffness(u1)
    keep_f, keep_d = f1.copy(), d1.copy()
    K1 = asm.matrix(d1)
    f2, d2 = asm.forces_and_stiffness(u2)
    assert f2 is not f1 and d2 is not d1
    np.testing.assert_array_equal(f1, keep_f)
    np.testing.assert_array_equal(K1.data, keep_d)
    del f1, d1, K1, f2, d2
    f3, d3 = asm.forces_and_stiffness(u1)                # buffers nobody holds are reused
    assert any(f3 is b for b in asm._pools["f"]) and any(d3 is b for b in asm._pools["K"])
    np.testing.assert_array_equal(d3, keep_d)


def test_bad_states_give_clear_errors_with_global_cells():
    model = model_of(cells=(3, 2, 2))
    asm = Assembler(model)
    u = np.zeros(model.n_dofs)
    u[7] = np.nan
    with pytest.raises(TensormassError, match=r"NaN or Inf at 1 dof\(s\) \(first 7\), in cell\(s\)"):
        asm.forces_and_stiffness(u)
    with pytest.raises(TensormassError, match="entries"):
        asm.forces(np.zeros(5))
    # a point-mirrored state: every element inverted, reported with the part's global cell ids
    u = (-2.0 * model.mesh.points).ravel()
    with pytest.raises(InvertedElementError) as info:
        asm.forces_and_stiffness(u)
    np.testing.assert_array_equal(np.sort(info.value.elements), np.sort(model.parts[0].cell_ids))


def test_project_psd_matches_the_eigh_of_every_element():
    rng = np.random.default_rng(5)
    model = model_of("tetra", (3, 2, 2), "neohookean")
    part = model.parts[0]
    u = 0.3 * rng.standard_normal(model.n_dofs)                      # large: some Hessians indefinite
    ue = model.element_displacements(part, u)
    ok = part.kernel.min_det_F(part.D, ue) > 0
    K = part.kernel.stiffness(part.D[ok], ue[ok])
    A = rng.standard_normal((20, 12, 12))
    for batch in (K, A + np.swapaxes(A, 1, 2), np.zeros((3, 12, 12))):
        ref = _project_psd_reference(batch.copy())
        got = project_psd(batch)
        scale = np.abs(ref).max(axis=(1, 2), keepdims=True) + 1e-300
        assert np.all(np.abs(got - ref) <= 1e-9 * scale)
        assert np.all(np.abs(got - np.swapaxes(got, 1, 2)) <= 1e-12 * scale)
        buf = batch.copy()
        assert project_psd(buf, out=buf) is buf and np.array_equal(buf, got)
    w_ref = np.linalg.eigvalsh(_project_psd_reference(K.copy()))
    assert (np.linalg.eigvalsh(K).min(axis=1) < -1e-6 * np.abs(K).max()).any()   # the test covers real clamps
    assert np.linalg.eigvalsh(project_psd(K)).min() >= -1e-9 * np.abs(w_ref).max()


# --------------------------------------------------------------------------- the switch


def test_thread_switch_sources_and_errors(monkeypatch):
    monkeypatch.delenv(parallel.ENV, raising=False)
    with parallel.threads(None):
        assert parallel.worker_threads() == parallel.available()
        monkeypatch.setenv(parallel.ENV, "1")
        assert parallel.worker_threads() == 1
        monkeypatch.setenv(parallel.ENV, "two")
        with pytest.raises(TensormassError, match="TENSORMASS_THREADS: expected a whole number"):
            parallel.worker_threads()
        monkeypatch.delenv(parallel.ENV)
    with parallel.threads(1):
        assert parallel.worker_threads() == 1
    for bad in (0, -1, 1.5, True, "x"):
        with pytest.raises(TensormassError, match="threads: expected a whole number"):
            parallel.set_threads(bad)
    with pytest.raises(TensormassError, match=f"numba sees {parallel.available()} core"):
        parallel.set_threads(parallel.available() + 1)


def test_scene_key_and_cli_threads(tmp_path, capsys):
    text = """
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [3, 1, 1]
element = "hexahedron"
[[material]]
law = "hooke"
E = 1e6
nu = 0.3
[[fixed]]
box = [[-1, -1, -1], [0, 1, 1]]
[loads]
gravity = [0, 0, -9.81]
[solver]
threads = THREADS
"""
    assert Scene.from_string(text.replace("THREADS", "1")).solver.threads == 1
    for bad in ("0", "1.5", '"two"'):
        with pytest.raises(SceneError, match="solver.threads"):
            Scene.from_string(text.replace("THREADS", bad))
    from tensormass.apps.cli import main
    path = tmp_path / "s.toml"
    path.write_text(text.replace("THREADS", str(parallel.available() + 1)))
    with parallel.threads(None):
        assert main(["run", str(path), "--quiet"]) != 0
        assert "solver.threads" in capsys.readouterr().err
        assert main(["run", str(path), "--quiet", "--threads", "0"]) != 0
        assert "--threads: expected a whole number" in capsys.readouterr().err
        assert main(["run", str(path), "--quiet", "--threads", "1"]) == 0
        assert parallel.worker_threads() == 1


def test_full_position_scatter_when_no_node_block_map(small_blocks, monkeypatch):
    model = model_of("tetra10", (2, 2, 2), "stvk", "gauss2")
    u = 0.01 * np.random.default_rng(6).standard_normal(model.n_dofs)
    blocked = Assembler(model)
    assert blocked.plans[0].blocks is not None
    monkeypatch.setattr(assembly, "_node_blocks", lambda *args: None)
    full = Assembler(model)
    assert full.plans[0].blocks is None and full.plans[0].fused is None
    check_against_reference(model, full, u)
    assert full.forces_and_stiffness(u)[1].tobytes() == blocked.forces_and_stiffness(u)[1].tobytes()
    # the buffered scatter through the node-blocked map (projected Hessians never take the fused path)
    assert full.stiffness(u, True).tobytes() == blocked.stiffness(u, True).tobytes()


@pytest.mark.parametrize("backend", [pytest.param("numba", marks=pytest.mark.heavy), "c"])   # numba: 10 s cold
@pytest.mark.parametrize("element,quadrature", [("tetra", "gauss1"), ("hexahedron", "gauss2"), ("tetra10", "gauss2")])
def test_the_assembler_takes_the_fused_path_and_it_equals_the_buffered_one(monkeypatch, small_blocks, backend,
                                                                          element, quadrature):
    """Every generated kernel assembles f and K through its fused function (no element buffers);
    the buffered path (BUFFERED_ELEMENTS) gives the same bytes, on one thread and two."""
    model = model_of(element, cells=(4, 2, 2), quadrature=quadrature, backend=backend)
    u = 1e-3 * np.random.default_rng(3).standard_normal(model.n_dofs)
    fused = Assembler(model)
    assert all(plan.fused is not None for plan in fused.plans)
    calls = []
    for plan in fused.plans:
        original = plan.fused
        plan.fused = lambda *a, original=original: (calls.append(len(a[0])), original(*a))[1]
    out = {}
    for threads in (1, 2):
        with parallel.threads(min(threads, parallel.available())):
            f, data = fused.forces_and_stiffness(u)
            out[("fused", threads)] = (f.tobytes(), data.tobytes(), fused.stiffness(u).tobytes())
    assert sum(calls) == 2 * 2 * model.parts[0].n_active     # f+K and K-only, twice
    monkeypatch.setattr(assembly, "BUFFERED_ELEMENTS", frozenset({element}))
    buffered = Assembler(model)
    assert all(plan.fused is None for plan in buffered.plans)
    with parallel.threads(1):
        f, data = buffered.forces_and_stiffness(u)
        reference = (f.tobytes(), data.tobytes(), buffered.stiffness(u).tobytes())
    assert out[("fused", 1)] == out[("fused", 2)]
    assert out[("fused", 1)][:2] == reference[:2]
    # K alone: fused takes it from the f+K code (its K bytes equal f+K's), the buffered path from
    # the generated stiffness function (other common subexpressions: round-off apart)
    assert out[("fused", 1)][2] == out[("fused", 1)][1]
    K_fused, K_buffered = (np.frombuffer(x) for x in (out[("fused", 1)][2], reference[2]))
    np.testing.assert_allclose(K_fused, K_buffered, rtol=0, atol=1e-13 * np.abs(K_buffered).max())
    check_against_reference(model, fused, u)


@pytest.mark.parametrize("element,dpn", [("tetra", 3), ("tetra10", 3), ("mixed", 3), ("quad", 2), ("triangle6", 2)])
def test_the_pattern_by_node_pairs_equals_the_pattern_by_dofs(element, dpn):
    """Node-major dofs: the pattern built from node pairs (a sort of dpn^2 fewer keys) is the one
    built from every dof pair: the same CSR, positions and diagonal."""
    from tensormass.runtime.assembly.assembly import SparsePattern
    from tensormass.runtime.base.dofs import node_dofs
    size = (1.0, 0.5, 0.5) if dpn == 3 else (1.0, 0.5)
    cells = (4, 2, 2) if dpn == 3 else (4, 3)
    mesh = generate_bar(size=size, cells=cells, element=element)
    tables = [node_dofs(b.cells, dpn) for b in mesh.blocks]
    tables.append(tables[0])                          # a shared table (a switchable group's)
    n_dofs = mesh.n_points * dpn
    fast, slow = SparsePattern(tables, n_dofs, dpn), SparsePattern(tables, n_dofs)
    assert fast.nnz == slow.nnz
    for name in ("indices", "indptr", "diagonal", "_rows"):
        assert np.array_equal(getattr(fast, name), getattr(slow, name)), name
    assert len(fast.positions) == len(tables) and fast.positions[-1] is fast.positions[0]
    for a, b in zip(fast.positions, slow.positions):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    # a table that is not node-major falls back to the dof pairs
    shuffled = [t[:, ::-1].copy() for t in tables[:1]]
    assert np.array_equal(SparsePattern(shuffled, n_dofs, dpn).indices, SparsePattern(shuffled, n_dofs).indices)
