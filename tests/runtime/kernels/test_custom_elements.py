"""Elements the generator has no kernel for, through the public Model / Simulation API: a toy
2-node bar in 3D (topological dimension 1 < space dimension 3) with a hand-written numpy
axial-spring kernel, a scalar 1-dof spring in 2D and a 6-dof bar (axial + torsion) in 3D
(dofs per node != dimension).  Each test registers its element type and kernel and
unregisters both afterwards (fixtures)."""
import meshio
import numpy as np
import pytest

from tensormass import elements
from tensormass.elements import SIMPLEX, ElementType, Face
from tensormass.runtime.kernels import custom_kernels
from tensormass.runtime.base.dofs import dofs_per_node, split_nodal
from tensormass.runtime.base.errors import DegenerateElementError, TensormassError
from tensormass.runtime.mesh.container import CellBlock, Mesh
from tensormass.runtime.model.model import Model
from tensormass.runtime.run.output import Writer
from tensormass.runtime.scene.types import Fixed, Loads, Material, NodalLoad, Probe, Solver
from tensormass.runtime.run.simulation import Simulation

E, NU, AREA, RHO = 2.0e11, 0.3, 1.0e-4, 7800.0
BIG = 1e3


def _line(dofs: int, space: int) -> ElementType:
    return ElementType(name="line", dim=1, domain=SIMPLEX, order=1, nodes=((0,), (1,)), n_corners=2,
                       edges=((0, 1),), faces=(Face("vertex", (0,)), Face("vertex", (1,))),
                       regular_measure=1.0, flip=(1, 0), dofs_per_node=dofs, space_dims=(space,))


class _Spring:
    """Common part of the toy kernels: K constant (small strain), f_int = -K u, W = u.K.u / 2."""
    law, quadrature, backend, n_nodes, n_points, element = "hooke", "gauss1", "python", 2, 1, "line"

    def __init__(self, area: float = AREA):
        self.area = area
        self.n_dofs = self.n_nodes * self.dofs_per_node
        self.calls = 0

    def constants(self, X, lam, mu):
        X = np.asarray(X, dtype=float)
        d = X[:, 1] - X[:, 0]
        length = np.linalg.norm(d, axis=1)
        bad = np.flatnonzero(~(length > 0))
        if bad.size:
            raise DegenerateElementError("line: zero length", bad)
        young = mu * (3 * lam + 2 * mu) / (lam + mu)
        # layout: the weight x measure first (what the model reads), then axis, EA/L, GJ/L
        D = np.zeros((len(X), max(1 + self.n_dofs, 3 + self.dim)))
        D[:, 0] = self.area * length                       # weight x measure: the bar's volume
        D[:, 1:1 + self.dim] = d / length[:, None]         # axis
        D[:, 1 + self.dim] = young * self.area / length    # axial stiffness E A / L
        D[:, 2 + self.dim] = young / (2 * (1 + NU)) * 2 * self.area ** 2 / (4 * np.pi) / length  # G J / L (circle)
        return D

    def point_volumes(self, D):
        """(n, 1) weight x measure of the one point: the bar's volume (the model's lumped mass)."""
        return D[:, :1]

    def stiffness(self, D, u):
        self.calls += 1
        return self._K(np.asarray(D))

    def forces(self, D, u):
        self.calls += 1
        u = np.asarray(u, dtype=float).reshape(len(D), -1)
        return -np.einsum("eij,ej->ei", self._K(np.asarray(D)), u)

    def energy(self, D, u):
        u = np.asarray(u, dtype=float).reshape(len(D), -1)
        return 0.5 * np.einsum("ei,eij,ej->e", u, self._K(np.asarray(D)), u)

    def forces_and_stiffness(self, D, u):
        return self.forces(D, u), self.stiffness(D, u)


class AxialBar(_Spring):
    """2 nodes x 3 displacement dofs in 3D: K = EA/L [[a a^T, -a a^T], [-a a^T, a a^T]]."""
    dim, dofs_per_node = 3, 3

    def _K(self, D):
        a, k = D[:, 1:4], D[:, 4]
        B = np.einsum("e,ei,ej->eij", k, a, a)
        return np.block([[B, -B], [-B, B]])


class ScalarSpring(_Spring):
    """2 nodes x 1 dof in 2D: K = EA/L [[1, -1], [-1, 1]] (a spring chain along its own length)."""
    dim, dofs_per_node = 2, 1

    def _K(self, D):
        return D[:, 3, None, None] * np.array([[1.0, -1.0], [-1.0, 1.0]])


class TorsionBar(_Spring):
    """2 nodes x 6 dofs (3 displacements, 3 rotations) in 3D: axial EA/L and torsion GJ/L about the axis."""
    dim, dofs_per_node = 3, 6

    def _K(self, D):
        a, ka, kt = D[:, 1:4], D[:, 4], D[:, 5]
        n = len(D)
        aa = np.einsum("ei,ej->eij", a, a)
        K = np.zeros((n, 12, 12))
        for blk, k in ((slice(0, 3), ka), (slice(3, 6), kt)):
            for r, s, sign in ((0, 0, 1), (0, 6, -1), (6, 0, -1), (6, 6, 1)):
                rows = slice(blk.start + r, blk.stop + r)
                cols = slice(blk.start + s, blk.stop + s)
                K[:, rows, cols] = sign * k[:, None, None] * aa
        return K


def _register(dofs, space, kernel):
    elements.register(_line(dofs, space))
    custom_kernels.register_kernel("line", "hooke", "gauss1", kernel)
    try:
        yield kernel
    finally:
        custom_kernels.unregister_kernel("line", "hooke", "gauss1")
        elements.unregister("line")


@pytest.fixture
def bar3d():
    yield from _register(3, 3, AxialBar())


@pytest.fixture
def spring2d():
    yield from _register(1, 2, ScalarSpring())


@pytest.fixture
def torsion3d():
    yield from _register(6, 3, TorsionBar())


def _material(**kw):
    return Material(law="hooke", quadrature="gauss1", E=E, nu=NU, density=RHO, **kw)


def _box(p, tol=1e-6):
    p = np.asarray(p, dtype=float)
    return (tuple(p - tol), tuple(p + tol))


# --------------------------------------------------------------------------- a bar in 3D


def _tripod(h=1.5, r=1.0):
    angles = np.deg2rad([90.0, 210.0, 330.0])
    supports = np.column_stack([r * np.cos(angles), r * np.sin(angles), np.zeros(3)])
    points = np.vstack([supports, [[0.0, 0.0, h]]])
    return Mesh(points, [CellBlock("line", [[0, 3], [1, 3], [2, 3]])])


def _tripod_model(force, mesh=None, **kw):
    mesh = _tripod() if mesh is None else mesh
    apex = mesh.points[3]
    fixed = [Fixed(box=((-BIG, -BIG, -1e-6), (BIG, BIG, 1e-6)))]
    loads = Loads(nodal=[NodalLoad(box=_box(apex), force=tuple(force))])
    return Model(mesh, [_material()], fixed=fixed, loads=loads, probes=[Probe("apex", tuple(apex))],
                 solver=Solver(kind="static", linear="direct"), **kw)


def _tripod_analytic(mesh, force):
    """Statics by hand: bar forces N from the apex equilibrium, elongations N L / (E A), then the
    apex displacement from e_i . u = elongation_i (e_i: unit vector support -> apex)."""
    d = mesh.points[3] - mesh.points[:3]
    L = np.linalg.norm(d, axis=1)
    e = d / L[:, None]
    # bar i in tension N_i pulls the apex towards its support (-e_i): sum_i N_i e_i = F
    N = np.linalg.solve(e.T, np.asarray(force, float))
    return np.linalg.solve(e, N * L / (E * AREA))


def test_tripod_under_a_vertical_load_matches_the_closed_form(bar3d):
    h, r, P = 1.5, 1.0, 1.0e4
    model = _tripod_model((0.0, 0.0, -P))
    assert (model.dim, model.dofs_per_node, model.n_dofs) == (3, 3, 12)
    summary = Simulation(model).run()
    assert summary.status == "ok" and summary.n_dofs == 12 and summary.n_free_dofs == 3
    L = np.hypot(h, r)
    sin = h / L
    expected = -P * L / (3 * E * AREA * sin ** 2)            # each bar carries P / (3 sin)
    u = np.array(summary.probes["apex"])
    assert u[2] == pytest.approx(expected, rel=1e-10)
    assert abs(u[0]) < 1e-12 * abs(expected) and abs(u[1]) < 1e-12 * abs(expected)
    assert bar3d.calls > 0                                    # the registered kernel did the work


def test_tripod_under_a_skew_load_matches_hand_statics(bar3d):
    mesh = _tripod()
    mesh.points[3] += (0.2, -0.1, 0.0)                       # not symmetric any more
    force = (3.0e3, -2.0e3, -5.0e3)
    sim = Simulation(_tripod_model(force, mesh=mesh))
    sim.run()
    np.testing.assert_allclose(sim.displacement[3], _tripod_analytic(mesh, force), rtol=1e-10)
    np.testing.assert_array_equal(sim.displacement[:3], 0.0)
    assert sim.displacement.shape == sim.dofs.shape == (4, 3)


def test_bar_chain_with_fixed_components_and_mass(bar3d):
    """Bars along x with the lateral dofs fixed: tip displacement F L / (E A); masses rho A L."""
    lengths = np.array([0.5, 1.0, 1.5])
    x = np.concatenate([[0.0], np.cumsum(lengths)])
    mesh = Mesh(np.column_stack([x, np.zeros(4), np.zeros(4)]), [CellBlock("line", [[0, 1], [1, 2], [2, 3]])])
    F = 2.5e4
    fixed = [Fixed(box=_box(mesh.points[0])),
             Fixed(box=((-BIG, -BIG, -BIG), (BIG, BIG, BIG)), components=(1, 2))]
    model = Model(mesh, [_material()], fixed=fixed, loads=Loads(nodal=[NodalLoad(box=_box(mesh.points[3]),
                                                                                  force=(F, 0, 0))]))
    assert model.fixed_dofs.tolist() == [0, 1, 2, 4, 5, 7, 8, 10, 11]
    np.testing.assert_allclose(model.mass.reshape(4, 3).sum(axis=0), RHO * AREA * lengths.sum())
    sim = Simulation(model)
    sim.run()
    np.testing.assert_allclose(sim.displacement[:, 0], F * x / (E * AREA), rtol=1e-10)


def test_bar_output_writes_lines(bar3d, tmp_path):
    writer = Writer(tmp_path, _tripod())
    Simulation(_tripod_model((0, 0, -1e4)), writer=writer).run()
    last = meshio.read(tmp_path / writer.frames[-1][1])
    assert last.cells[0].type == "line" and last.point_data["displacement"].shape == (4, 3)
    assert last.point_data["displacement"][3, 2] < 0 and "dofs" not in last.point_data


def test_bar_dynamics_runs_with_the_lumped_mass(bar3d):
    """Implicit Euler with gravity: the registered kernel and the bar masses in a dynamic run."""
    mesh = _tripod()
    model = Model(mesh, [_material()], fixed=[Fixed(box=((-BIG, -BIG, -1e-6), (BIG, BIG, 1e-6)))],
                  loads=Loads(gravity=(0, 0, -9.81)), solver=Solver(kind="implicit_euler", dt=1e-4, steps=5))
    summary = Simulation(model).run()
    assert summary.status == "ok" and summary.kinetic_energy > 0
    assert summary.health["min_det_F"] is None           # no inversion check for this kernel


def test_bad_registrations_are_refused(bar3d):
    with pytest.raises(TensormassError, match="already registered"):
        custom_kernels.register_kernel("line", "hooke", "gauss1", AxialBar())
    with pytest.raises(TensormassError, match="lacks .*forces_and_stiffness"):
        custom_kernels.register_kernel("line", "stvk", "gauss1", object())
    with pytest.raises(TensormassError, match="registered as"):
        custom_kernels.register_kernel("line", "stvk", "gauss1", AxialBar())
    assert isinstance(bar3d, custom_kernels.Kernel)
    # a kernel whose dof count does not fit the element type's dofs per node: refused by the model
    wrong = ScalarSpring()
    wrong.dim = 3
    custom_kernels.register_kernel("line", "hooke", "gauss1", wrong, replace=True)
    with pytest.raises(TensormassError, match=r"the model needs 2 nodes, 6 dofs \(3 per node\)"):
        _tripod_model((0, 0, -1.0))


def test_degenerate_bar_is_reported_with_its_cell_id(bar3d):
    mesh = _tripod()
    with pytest.raises(Exception, match=r"degenerate cells|zero length"):
        _tripod_model((0, 0, -1.0), mesh=Mesh(np.vstack([mesh.points, mesh.points[3]]),
                                              [CellBlock("line", [[0, 3], [1, 3], [3, 4]])]))


def _tet_stiffness(X, lam, mu):
    """Linear-elastic stiffness of a 4-node tetrahedron by hand: V B^T C B (Voigt, engineering shear)."""
    J = (X[1:] - X[0]).T
    G = np.linalg.solve(J.T, np.array([[-1.0, -1, -1], [1, 0, 0], [0, 1, 0], [0, 0, 1]]).T).T   # grad N_i
    B = np.zeros((6, 12))
    for i, (gx, gy, gz) in enumerate(G):
        B[:, 3 * i:3 * i + 3] = [[gx, 0, 0], [0, gy, 0], [0, 0, gz], [gy, gx, 0], [0, gz, gy], [gz, 0, gx]]
    C = np.diag([2 * mu] * 3 + [mu] * 3)
    C[:3, :3] += lam
    return abs(np.linalg.det(J)) / 6 * B.T @ C @ B


def test_bar_rides_on_a_solid(bar3d):
    """A tetrahedron (generated kernel) and a bar (registered kernel) share the apex node: the apex
    displacement solves (K_tet + K_bar) u = F with both stiffnesses computed by hand."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.3, 1.0], [1.2, 1.1, 2.0]])
    mesh = Mesh(pts, [CellBlock("tetra", [[0, 1, 2, 3]]), CellBlock("line", [[3, 4]])])
    F = np.array([2.0e5, -1.0e5, 3.0e5])
    fixed = [Fixed(box=((-BIG, -BIG, -1e-6), (BIG, BIG, 1e-6))), Fixed(box=_box(pts[4]))]
    model = Model(mesh, [_material()], fixed=fixed, loads=Loads(nodal=[NodalLoad(box=_box(pts[3]), force=tuple(F))]))
    assert {p.element for p in model.parts} == {"tetra", "line"} and model.dofs_per_node == 3
    sim = Simulation(model)
    sim.run()
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    d = pts[4] - pts[3]
    L = np.linalg.norm(d)
    K = _tet_stiffness(pts[:4], lam, mu)[9:, 9:] + E * AREA / L * np.outer(d, d) / L ** 2
    np.testing.assert_allclose(sim.displacement[3], np.linalg.solve(K, F), rtol=1e-9)
    # the bar's volume joins the lumped mass of its two nodes
    np.testing.assert_allclose(model.mass.reshape(5, 3)[4], RHO * AREA * L / 2)


# --------------------------------------------------------------------------- dofs per node != dimension


def test_scalar_spring_chain_in_2d(spring2d, tmp_path):
    """1 dof per node in 2D: springs in series along a bent line, u_end = F (L1 + L2) / (E A)."""
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]])
    mesh = Mesh(pts, [CellBlock("line", [[0, 1], [1, 2]])])
    F = 1.0e4
    model = Model(mesh, [_material()], fixed=[Fixed(box=_box(pts[0]))],
                  loads=Loads(gravity=(0.0, 0.0), nodal=[NodalLoad(box=_box(pts[2]), force=(F,))]),
                  probes=[Probe("end", (1.0, 2.0))])
    assert (model.dim, model.dofs_per_node, model.n_dofs) == (2, 1, 3) and model.estimate.dofs == 3
    assert model.fixed_dofs.tolist() == [0]
    np.testing.assert_allclose(model.mass, RHO * AREA * np.array([0.5, 1.5, 1.0]))
    writer = Writer(tmp_path, mesh)
    sim = Simulation(model, writer=writer)
    summary = sim.run()
    expected = F * np.array([0.0, 1.0, 3.0]) / (E * AREA)
    np.testing.assert_allclose(sim.dofs[:, 0], expected, rtol=1e-10)
    assert summary.probes["end"] == pytest.approx([expected[2]], rel=1e-10)
    np.testing.assert_array_equal(sim.displacement, np.zeros((3, 2)))   # the nodes do not move
    frame = meshio.read(tmp_path / writer.frames[-1][1])
    np.testing.assert_allclose(frame.point_data["dofs"].ravel(), expected, rtol=1e-10)
    np.testing.assert_array_equal(frame.point_data["displacement"], 0.0)


def test_scalar_model_refuses_what_it_cannot_mean(spring2d):
    pts = np.array([[0.0, 0.0], [1.0, 0.0]])
    mesh = Mesh(pts, [CellBlock("line", [[0, 1]])])
    fixed = [Fixed(box=_box(pts[0]))]
    with pytest.raises(TensormassError, match="loads.gravity: the nodes carry 1 dof"):
        Model(mesh, [_material()], fixed=fixed, loads=Loads(gravity=(0.0, -9.81)))
    with pytest.raises(TensormassError, match=r"loads.nodal\[0\] \(traction\): the nodes carry 1 dof"):
        Model(mesh, [_material()], fixed=fixed,
              loads=Loads(gravity=(0, 0), nodal=[NodalLoad(box=_box(pts[1]), force=(1.0,), kind="traction")]))
    with pytest.raises(TensormassError, match=r"fixed\[0\].components must be in 0..0"):
        Model(mesh, [_material()], fixed=[Fixed(box=_box(pts[0]), components=(1,))], loads=Loads(gravity=(0, 0)))
    with pytest.raises(TensormassError, match=r"\[\[adapt\]\] rules need solid elements"):
        from tensormass.runtime.scene.types import Adapt
        Model(mesh, [_material()], fixed=fixed, loads=Loads(gravity=(0, 0)),
              adapt=[Adapt(criterion="R_S", threshold=1.0, action="switch_law", law="stvk")])


def test_six_dofs_per_node_bar_with_torsion(torsion3d, tmp_path):
    """6 dofs per node: displacements first, rotations after; a prescribed end rotation twists the
    chain linearly, an axial force stretches it; the rotations are written as dofs_extra."""
    x = np.array([0.0, 1.0, 3.0])
    mesh = Mesh(np.column_stack([x, np.zeros(3), np.zeros(3)]), [CellBlock("line", [[0, 1], [1, 2]])])
    F, twist = 1.0e4, 0.02
    everything = ((-BIG, -BIG, -BIG), (BIG, BIG, BIG))
    fixed = [Fixed(box=_box(mesh.points[0])),                                  # all 6 dofs
             Fixed(box=everything, components=(1, 2, 4, 5)),                   # no bending here
             Fixed(box=_box(mesh.points[2]), components=(3,), displacement=(0, 0, 0, twist))]
    model = Model(mesh, [_material()], fixed=fixed,
                  loads=Loads(nodal=[NodalLoad(box=_box(mesh.points[2]), force=(F, 0, 0))]))
    assert (model.dofs_per_node, model.n_dofs, model.n_load) == (6, 18, 3)
    assert model.estimate.dofs == 18                        # the resource estimate counts them too
    assert model.free_dofs.tolist() == [6, 9, 12]
    # gravity and forces act on the displacement dofs only
    np.testing.assert_allclose(model.f_ext.reshape(3, 6)[2], [F, 0, 0, 0, 0, 0])
    writer = Writer(tmp_path, mesh)
    sim = Simulation(model, writer=writer)
    sim.run()
    U = sim.dofs
    np.testing.assert_allclose(U[:, 0], F * x / (E * AREA), rtol=1e-10)
    np.testing.assert_allclose(U[:, 3], twist * x / x[-1], rtol=1e-10)        # equal GJ per length
    np.testing.assert_array_equal(sim.displacement, U[:, :3])
    frame = meshio.read(tmp_path / writer.frames[-1][1])
    np.testing.assert_allclose(frame.point_data["dofs_extra"][:, 0], U[:, 3], rtol=1e-12)
    with pytest.raises(TensormassError, match=r"fixed\[0\].displacement must be a finite vector of 4 components"):
        Model(mesh, [_material()], fixed=[Fixed(box=_box(mesh.points[2]), components=(3,), displacement=(0, 0, 0))])


def test_scalar_dofs_do_not_mix_with_displacements(bar3d):
    """A count below the dimension (no displacement) mixes with no other; 6 beside 3 is the largest."""
    elements.unregister("line")
    elements.register(_line(1, 3))
    mesh = Mesh(np.vstack([np.eye(3), [[0, 0, 0]], [[2.0, 0, 0]]]),
                [CellBlock("tetra", [[3, 0, 1, 2]]), CellBlock("line", [[0, 4]])])
    with pytest.raises(TensormassError, match=r"mixes element types with different dofs per node \(line: 1; tetra: 3\)"):
        dofs_per_node(mesh)
    with pytest.raises(TensormassError, match="different dofs per node"):
        Model(mesh, [_material()])
    elements.unregister("line")
    elements.register(_line(6, 3))
    assert dofs_per_node(mesh) == 6


def test_split_nodal_layouts():
    U = np.arange(12.0).reshape(2, 6)
    d, extra = split_nodal(U, 3)
    np.testing.assert_array_equal(d, U[:, :3]) and np.testing.assert_array_equal(extra["dofs_extra"], U[:, 3:])
    d, extra = split_nodal(U[:, :3], 3)
    assert extra == {} and d.shape == (2, 3)
    d, extra = split_nodal(U[:, :1], 2)
    np.testing.assert_array_equal(d, 0.0) and np.testing.assert_array_equal(extra["dofs"], U[:, :1])


def test_solids_keep_their_layout():
    """A solid mesh: dofs per node = dimension, no registered kernel involved."""
    from tensormass.runtime.mesh.bars import generate_bar
    mesh = generate_bar((1.0, 0.2, 0.2), (2, 1, 1), "tetra")
    assert dofs_per_node(mesh) == 3 and custom_kernels.registered() == ()
