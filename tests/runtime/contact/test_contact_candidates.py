"""The broad-phase candidates IPC keeps between Newton's calls (runtime.contact.candidates): the
collisions and CCD steps they give equal those of a fresh broad phase, they are rebuilt as soon as a
state leaves the region they cover, and a contact run repeats bit for bit."""
from __future__ import annotations

import copy

import numpy as np

from tensormass.runtime.run.simulation import Simulation
from tensormass.runtime.scene.scene import Scene

from contact_scenes import SIDE, bar, model_of

DHAT = 0.01
GAP = 1.3 * DHAT             # the obstacles start beyond dhat: only candidates the cache kept find them
SCENE = bar([{"name": "ball", "shape": "sphere", "center": [0.03, 0.04, SIDE + GAP + 0.02], "radius": 0.02},
             {"name": "plate", "shape": "plane", "point": [0.05, 0.05, SIDE + GAP], "normal": [0.0, 0.0, -1.0]}],
            contact={"dhat": DHAT, "stiffness": 10.0})


def _fresh(contact, V):
    """Collisions at V from a broad phase of their own (what the cache must reproduce)."""
    ipc = contact.ipc
    candidates = ipc.Candidates()
    candidates.build(contact.mesh, V, contact.dhat + contact.dmin, broad_phase=contact.broad)
    cs = ipc.NormalCollisions()
    cs.build(candidates, contact.mesh, V, contact.dhat, contact.dmin)
    return cs


def _same(contact, V, cs):
    ref = _fresh(contact, V)
    assert len(cs) == len(ref) > 0
    barrier = contact.barrier()
    assert np.isclose(barrier(cs, contact.mesh, V), barrier(ref, contact.mesh, V), rtol=1e-12, atol=0)


def _random_move(contact, size, seed, lift=0.0):
    """Every surface dof moved by at most `size` at random, and `lift` up."""
    d = np.zeros(contact.n_dofs)
    d[contact.dofs] = size * np.random.default_rng(seed).uniform(-1.0, 1.0, contact.dofs.size)
    d[contact.dofs[2::3]] += lift
    return d


def test_near_candidates_are_reused_within_half_the_margin_and_rebuilt_beyond():
    contact = model_of(SCENE).contact
    cache = contact.candidates
    u = np.zeros(contact.n_dofs)
    assert len(contact.collisions(contact.vertices(u))) == 0
    assert cache.builds == {"near": 1, "swept": 0}
    for seed in range(3):      # lifted into the barrier's reach, no vertex moved by dhat / 2: no new broad phase
        V = contact.vertices(u + _random_move(contact, 0.04 * DHAT, seed, lift=0.4 * DHAT))
        _same(contact, V, contact.collisions(V))
    assert cache.builds == {"near": 1, "swept": 0}
    V = contact.vertices(u + _random_move(contact, 0.04 * DHAT, 9, lift=0.6 * DHAT))
    _same(contact, V, contact.collisions(V))
    assert cache.builds == {"near": 2, "swept": 0}


def test_a_long_step_sweeps_once_and_its_trial_states_reuse_the_sweep():
    """Within the barrier's reach, a step sideways of twice dhat: the pairs stay as close all along, so
    only boxes swept and inflated by the barrier's reach hold them."""
    contact = model_of(SCENE).contact
    cache = contact.candidates
    u = _random_move(contact, 0.0, 0, lift=0.5 * DHAT)
    assert len(contact.collisions(contact.vertices(u))) > 0
    d = _random_move(contact, 0.02 * DHAT, 1)
    d[contact.dofs[0::3]] += 2.0 * DHAT
    a = contact.max_step(u, d)
    ipc = contact.ipc
    V0, V1 = contact.vertices(u), contact.vertices(u + d)
    assert a == ipc.compute_collision_free_stepsize(contact.mesh, V0, V1, min_distance=contact.dmin,
                                                    broad_phase=contact.broad, narrow_phase_ccd=contact.ccd)
    assert cache.builds == {"near": 1, "swept": 1}
    for share in (0.5, 0.75, 1.0):               # line-search trial states
        V = contact.vertices(u + share * a * d)
        _same(contact, V, contact.collisions(V))
    assert cache.builds == {"near": 1, "swept": 1}
    V = contact.vertices(u + a * d + _random_move(contact, 0.05 * DHAT, 3))        # off the path
    _same(contact, V, contact.collisions(V))
    assert cache.builds == {"near": 2, "swept": 1}


def test_a_contact_run_repeats_bit_for_bit():
    """ipctk runs on one thread: summed over threads, its Hessians differed by 1e-17 between calls."""
    data = bar([{"name": "plate", "shape": "plane", "point": [0.05, 0.05, 0.102], "normal": [0, 0, -1],
                 "translation": [0, 0, -0.02]}], solver={"kind": "static", "steps": 2})
    runs = []
    for _ in range(2):
        sim = Simulation(Scene.from_dict(copy.deepcopy(data)), output=False)
        assert sim.run().status == "ok"
        runs.append(sim.ctx.u.copy())
    assert np.array_equal(runs[0], runs[1])
    contact = model_of(SCENE).contact
    u = _random_move(contact, 0.0, 0, lift=0.5 * DHAT)
    first = contact.hessian(u, False).toarray()
    assert np.abs(first).max() > 0 and np.array_equal(first, contact.hessian(u, False).toarray())


def test_a_contact_matrix_is_added_on_the_pattern_and_grows_it_only_off_it():
    """ConstrainedSystem.solve(extra=): the solution is that of K + E (dense reference); entries the
    mesh couples already leave the solver's pattern as it was, an entry between two uncoupled nodes
    grows it (and stays in it when its value is zero later)."""
    import scipy.sparse as sp
    from tensormass.runtime.physics.newton import Context
    model = model_of(bar([], cells=(3, 1, 1)))
    ctx = Context(model)
    data = ctx.asm.stiffness(np.zeros(model.n_dofs))
    K, free = ctx.asm.matrix(data).toarray(), model.free_dofs
    b = np.random.default_rng(4).uniform(-1.0, 1.0, model.n_dofs)
    points = np.asarray(model.mesh.points)
    up = np.flatnonzero(points[:, 2] > 0)                                  # free nodes (the base is held)
    far = [int(up[np.argmin(points[up, 0])]), int(up[np.argmax(points[up, 0])])]   # in no cell together
    top = far[0]
    for nodes, grows in (([top, top], False), (far, True)):
        rows, cols = 3 * np.array(nodes) + 2, 3 * np.array(nodes[::-1]) + 2
        E = sp.coo_matrix((np.full(2, 50.0), (rows, cols)), shape=K.shape) + sp.coo_matrix(
            (np.full(2, 80.0), (rows, rows)), shape=K.shape)
        before = None if ctx.system._seen is None else ctx.system._seen["indices"]
        x = ctx.solve(data, b, np.zeros(model.fixed_dofs.size), extra=E.tocoo())
        A = (K + E.toarray())[np.ix_(free, free)]
        assert np.allclose(x[free], np.linalg.solve(A, b[free]), rtol=1e-8, atol=1e-12)
        seen = ctx.system._seen
        assert (seen["indices"].size > ctx.system.ff[1].size) == grows
        if before is not None and not grows:
            assert seen["indices"] is before
