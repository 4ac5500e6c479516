"""The contact energy's gradient and Hessian as assembled into the global dof vector and matrix,
against central differences: IPC barriers against a plane, a sphere and a box, between two bodies of
one mesh, through Newton's Potential; penalty contact against plane, sphere, capsule and box."""
from __future__ import annotations

import numpy as np
import pytest

from tensormass.runtime.contact.ipc import IPCContact
from tensormass.runtime.contact.penalty import PenaltyContact
from tensormass.runtime.physics.newton import Context, Potential

from contact_scenes import SIDE, bar, fd_gradient, fd_jacobian, model_of, relative, two_blocks

DHAT = 0.01
GAP = 0.005                  # obstacles this far above the bar's top face: inside dhat, barrier pairs active
TOP = SIDE + GAP

IPC_OBSTACLES = {
    "plane": {"name": "plate", "shape": "plane", "point": [0.05, 0.05, TOP], "normal": [0.05, 0.02, -1.0]},
    "sphere": {"name": "ball", "shape": "sphere", "center": [0.05, 0.05, TOP + 0.03], "radius": 0.03},
    "box": {"name": "block", "shape": "box", "box": [[0.021, 0.018, TOP], [0.083, 0.079, 0.2]]},
}


def _state(model, scale, seed=0):
    """A random displacement of every dof, of size `scale`."""
    return scale * np.random.default_rng(seed).uniform(-1.0, 1.0, model.n_dofs)


def _check(contact, u, h=1e-6):
    """gradient = dE/du and hessian(project=False) = d gradient/du over every dof; the Hessian symmetric
    and its projection positive semi-definite."""
    g = contact.gradient(u)
    assert g.shape == (contact.n_dofs,)
    assert np.abs(g).max() > 0, "no contact term is active: the check would not test anything"
    assert relative(g, fd_gradient(contact.energy, u, h)) < 1e-6
    H = contact.hessian(u, project=False).toarray()
    assert H.shape == (contact.n_dofs, contact.n_dofs)
    assert relative(H, fd_jacobian(contact.gradient, u, h)) < 1e-5
    assert relative(H, H.T) < 1e-10
    P = contact.hessian(u, project=True).toarray()
    assert np.linalg.eigvalsh(0.5 * (P + P.T)).min() >= -1e-9 * np.abs(P).max()
    off = np.setdiff1d(np.arange(contact.n_dofs), contact.dofs)       # dofs off the surface: no contact term
    assert not g[off].any() and not H[off].any()


@pytest.mark.parametrize("shape", sorted(IPC_OBSTACLES))
def test_ipc_barrier_gradient_and_hessian_match_differences(shape):
    model = model_of(bar([IPC_OBSTACLES[shape]], contact={"dhat": DHAT, "stiffness": 10.0}))
    contact = model.contact
    assert isinstance(contact, IPCContact) and contact.dhat == DHAT and contact.kappa == 10.0
    u = _state(model, 0.1 * GAP)
    assert contact.intersecting(u) is None
    assert len(contact.collisions(contact.vertices(u))) > 0
    _check(contact, u)


def test_ipc_barrier_between_two_bodies_of_one_mesh(tmp_path):
    mesh = two_blocks(tmp_path, gap=0.004)
    data = bar(contact={"dhat": DHAT, "stiffness": 10.0, "bodies": True}, mesh={"file": mesh})
    model = model_of(data)
    contact = model.contact
    assert contact.surface.n_bodies == 2 and not contact.obstacles
    u = _state(model, 4e-4, seed=1)
    assert contact.intersecting(u) is None
    _check(contact, u)
    # the same mesh with bodies = false: nothing can touch, so no term (the filter keeps the bodies apart)
    data["contact"]["bodies"] = False
    data["obstacle"] = [{"name": "far", "shape": "plane", "point": [0, 0, -1.0], "normal": [0, 0, 1]}]
    apart = model_of(data).contact
    assert apart.energy(u) == 0.0 and not apart.gradient(u).any()


def test_newton_potential_carries_the_contact_terms():
    """Potential's energy and gradient include the barrier's, its contact matrix is the barrier's
    Hessian, and its step limit keeps a step into the plate short of it."""
    model = model_of(bar([IPC_OBSTACLES["plane"]], contact={"dhat": DHAT, "stiffness": 10.0}))
    contact = model.contact
    ctx = Context(model)
    f_ext = np.zeros(model.n_dofs)
    potential = Potential(ctx.asm, f_ext)
    u = _state(model, 0.1 * GAP, seed=2)
    g = potential.gradient(u)
    assert np.allclose(g - potential.gradient(u, contact=False), contact.gradient(u), rtol=0, atol=1e-12 * np.abs(g).max())
    assert relative(g, fd_gradient(lambda x: potential.value(x)[0], u, 1e-7)) < 1e-6
    assert relative(potential.contact_matrix(u, False).toarray(), contact.hessian(u, False).toarray()) == 0.0
    # a step that lifts the top face by twice the gap: CCD cuts it short of the plate
    d = np.zeros(model.n_dofs)
    top = np.flatnonzero(np.isclose(np.asarray(model.mesh.points)[:, 2], SIDE))
    d[top * model.dofs_per_node + 2] = 2 * GAP
    a = potential.max_step(u, d)
    assert 0.0 < a < 1.0
    assert contact.intersecting(u + a * d) is None


# ------------------------------------------------------------------ penalty contact

# clear of the bar at rest; their translation (the default ramp: all of it at run fraction 1) moves
# them 1 to 2 cm into it, so several surface vertices penetrate
PENALTY_OBSTACLES = {
    "plane": {"name": "plate", "shape": "plane", "point": [0.05, 0.05, 0.103], "normal": [0.02, 0.0, -1.0],
              "translation": [0.0, 0.0, -0.012]},
    "sphere": {"name": "ball", "shape": "sphere", "center": [0.05, 0.05, 0.2025], "radius": 0.1,
               "translation": [0.0, 0.0, -0.02]},
    "capsule": {"name": "tool", "shape": "capsule", "a": [-0.02, 0.05, 0.125], "b": [0.12, 0.05, 0.125],
                "radius": 0.02, "translation": [0.0, 0.0, -0.01]},
    "box": {"name": "block", "shape": "box", "box": [[0.02, 0.02, 0.101], [0.3, 0.3, 0.2]],
            "translation": [0.0, 0.0, -0.01],
            "rotation": {"axis": [1.0, 0.3, 0.0], "point": [0.16, 0.16, 0.15], "angle": 4.0}},
}


@pytest.mark.parametrize("shape", sorted(PENALTY_OBSTACLES))
def test_penalty_gradient_and_hessian_match_differences(shape):
    model = model_of(bar([PENALTY_OBSTACLES[shape]], contact={"method": "penalty", "stiffness": 1e3}))
    contact = model.contact
    assert isinstance(contact, PenaltyContact) and contact.k == 1e3
    u = _state(model, 1e-4, seed=3)
    assert contact.energy(u) == 0.0                     # at rest pose: clear of the body
    contact.set_pose(1.0)                               # moved in
    hit = sum(t[0].size for t in contact._terms(u))
    assert hit >= 2, f"only {hit} vertex penetrates: the check would test too little"
    assert contact.record(u)["penetration"] > 1e-3
    _check(contact, u, h=1e-7)
