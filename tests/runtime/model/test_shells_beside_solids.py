"""Shells beside solids in one mesh: a file's free triangles as shells, its volume cells as solids,
every node with 6 dofs and a solid's cells on their nodes' first 3 (runtime.mesh.shells_and_solids,
runtime.base.dofs)."""
from dataclasses import replace

import meshio
import numpy as np
import pytest

from tensormass.runtime.assembly.assembly import Assembler
from tensormass.runtime.base.errors import SceneError, TensormassError
from tensormass.runtime.mesh import bars, surfaces
from tensormass.runtime.mesh.container import MeshError
from tensormass.runtime.mesh.shells_and_solids import read_shells_and_solids
from tensormass.runtime.model.model import Model
from tensormass.runtime.run.simulation import Simulation
from tensormass.runtime.scene.scene import Scene

BLOCK, SPHERE, BOTTOM = 1, 2, 3          # physical ids: the solid, the shell, the solid's bottom face


def _write(path, with_bottom=True, spoil=False):
    """A tetra block 0.1 x 0.1 x 0.05 m and, above it, an icosphere of radius 0.03 m as free triangles."""
    block = bars.generate_bar((0.1, 0.1, 0.05), (3, 3, 2), "tetra", (-0.05, -0.05, -0.05))
    tetra = block.blocks[0].cells
    sp, st = surfaces.icosphere(0.03, 2)
    sp = sp + [0.0, 0.0, 0.04]
    n = len(block.points)
    points = np.vstack([block.points, sp])
    faces = []
    for t in tetra:                      # the bottom face z = -0.05 (outward: -z)
        low = [v for v in t if block.points[v, 2] < -0.0499]
        if len(low) == 3:
            faces.append(low)
    sphere = st + n
    if spoil:                            # one boundary face put in the shell group
        sphere = np.vstack([sphere, faces[:1]])
    cells = [("tetra", tetra), ("triangle", sphere)]
    tags = [np.full(len(tetra), BLOCK), np.full(len(sphere), SPHERE)]
    if with_bottom:
        cells.append(("triangle", np.asarray(faces)))
        tags.append(np.full(len(faces), BOTTOM))
    fields = {"block": np.array([BLOCK, 3]), "sphere": np.array([SPHERE, 2])}
    if with_bottom:
        fields["bottom"] = np.array([BOTTOM, 2])
    meshio.write(str(path), meshio.Mesh(points, cells, cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags},
                                        field_data=fields), file_format="gmsh22", binary=False)
    return path, n, len(sp)


SCENE = '''
name = "beside"
[mesh]
file = "{file}"
element = "shell"
[[material]]
region = "block"
law = "neohookean"
E = 5.0e4
nu = 0.4
density = 1000.0
[[material]]
region = "sphere"
law = "cst_dkt"
E = 1.0e7
nu = 0.3
thickness = 0.002
density = 1000.0
[[fixed]]
region = "bottom"
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "backward_euler"
dt = 0.01
steps = 3
'''


def _scene(tmp_path, text=SCENE, **kw):
    path, n_solid, n_shell = _write(tmp_path / "beside.msh", **kw)
    return Scene.from_string(text.format(file=path.as_posix()), base_dir=tmp_path), n_solid, n_shell


def test_a_file_reads_into_solids_boundary_groups_and_shells(tmp_path):
    path, n_solid, n_shell = _write(tmp_path / "m.msh")
    mesh, notes = read_shells_and_solids(path)
    assert [b.type for b in mesh.blocks] == ["tetra", "shell"]
    shells = mesh.blocks[1]
    assert len(shells) == 20 * 4 ** 2 and shells.cells.min() >= n_solid
    groups = {g.name: g for g in mesh.groups}
    assert groups["sphere"].dim == 2 and groups["sphere"].cell_ids.min() == len(mesh.blocks[0])
    assert "triangle" in groups["bottom"].cells and not groups["bottom"].cell_ids.size
    # the closed shell is wound outward
    x = mesh.points[shells.cells]
    assert np.einsum("ij,ij->i", x[:, 0], np.cross(x[:, 1], x[:, 2])).sum() > 0


def test_a_group_half_on_the_solid_is_refused(tmp_path):
    path, _, _ = _write(tmp_path / "m.msh", spoil=True)
    with pytest.raises(MeshError, match=r"surface group 'sphere' \(id 2, surface\) has 1 triangles on the solid's "
                                        r"boundary and 320 off it"):
        read_shells_and_solids(path)


def test_a_file_with_no_free_triangles_is_refused(tmp_path):
    block = bars.generate_bar((1, 1, 1), (1, 1, 1), "tetra")
    meshio.write(str(tmp_path / "b.msh"), meshio.Mesh(block.points, [("tetra", block.blocks[0].cells)],
                 cell_data={"gmsh:physical": [np.ones(len(block.blocks[0].cells), int)]}), file_format="gmsh22",
                 binary=False)
    with pytest.raises(MeshError, match="found no shell triangles"):
        read_shells_and_solids(tmp_path / "b.msh")


def test_the_model_holds_each_body_as_its_own_model_would(tmp_path):
    """Forces and stiffness of the mixed model, on each body's dofs, are those of the body alone; the
    solid's rotations are held."""
    scene, n_solid, n_shell = _scene(tmp_path)
    model = Model.from_scene(scene)
    assert model.dofs_per_node == 6 and model.n_dofs == 6 * (n_solid + n_shell)
    held = np.zeros((model.n_points, 6), bool)
    held.reshape(-1)[model.fixed_dofs] = True
    assert held[:n_solid, 3:].all() and not held[n_solid:, 3:].any()
    mesh = model.mesh
    solid_mesh = type(mesh)(mesh.points[:n_solid], [mesh.blocks[0]])
    shell_mesh = type(mesh)(mesh.points[n_solid:], [type(mesh.blocks[1])("shell", mesh.blocks[1].cells - n_solid)])
    solid = Model(solid_mesh, [replace(scene.materials[0], region="all")], solver=scene.solver)
    shell = Model(shell_mesh, [replace(scene.materials[1], region="all")], solver=scene.solver)
    rng = np.random.default_rng(3)
    u = 1e-5 * rng.standard_normal((model.n_points, 6))
    f, data = Assembler(model).forces_and_stiffness(u.ravel())
    K = Assembler(model).matrix(data)
    fs, Ks = Assembler(solid).forces_and_stiffness(u[:n_solid, :3].ravel())
    fh, Kh = Assembler(shell).forces_and_stiffness(u[n_solid:].ravel())
    f = f.reshape(-1, 6)
    np.testing.assert_allclose(f[:n_solid, :3].ravel(), fs, rtol=0, atol=1e-12 * np.abs(fs).max())
    assert not f[:n_solid, 3:].any()
    np.testing.assert_allclose(f[n_solid:].ravel(), fh, rtol=0, atol=1e-12 * np.abs(fh).max())
    solid_dofs = (np.arange(n_solid)[:, None] * 6 + np.arange(3)).ravel()
    shell_dofs = np.arange(6 * n_solid, model.n_dofs)
    Ks, Kh = Assembler(solid).matrix(Ks), Assembler(shell).matrix(Kh)
    assert abs(K[solid_dofs][:, solid_dofs] - Ks).max() <= 1e-12 * abs(Ks).max()
    assert abs(K[shell_dofs][:, shell_dofs] - Kh).max() <= 1e-12 * abs(Kh).max()
    assert K[solid_dofs][:, shell_dofs].nnz == 0 or abs(K[solid_dofs][:, shell_dofs]).max() == 0


def test_a_run_moves_the_solid_as_alone_and_the_shell_falls(tmp_path):
    """Without contact the bodies do not meet: the clamped block sags as it does alone, the sphere falls
    freely (backward Euler: v1 = g h, x1 = g h^2 per step from rest)."""
    scene, n_solid, n_shell = _scene(tmp_path)
    sim = Simulation(scene, output=False)
    assert sim.run().status == "ok"
    alone = SCENE.replace('element = "shell"\n', "").split("[[material]]\nregion = \"sphere\"")[0] + \
        SCENE.split("density = 1000.0\n", 2)[2]
    block = bars.generate_bar((0.1, 0.1, 0.05), (3, 3, 2), "tetra", (-0.05, -0.05, -0.05))
    faces = [[v for v in t if block.points[v, 2] < -0.0499] for t in block.blocks[0].cells]
    faces = np.asarray([f for f in faces if len(f) == 3])
    meshio.write(str(tmp_path / "alone.msh"), meshio.Mesh(block.points, [("tetra", block.blocks[0].cells), ("triangle", faces)],
                 cell_data={"gmsh:physical": [np.full(len(block.blocks[0].cells), BLOCK), np.full(len(faces), BOTTOM)]},
                 field_data={"block": np.array([BLOCK, 3]), "bottom": np.array([BOTTOM, 2])}), file_format="gmsh22",
                 binary=False)
    solo = Simulation(Scene.from_string(alone.format(file=(tmp_path / "alone.msh").as_posix()), base_dir=tmp_path),
                      output=False)
    solo.run()
    u = sim.displacement
    assert np.abs(solo.displacement).max() > 1e-6
    np.testing.assert_allclose(u[:n_solid], solo.displacement, rtol=0, atol=1e-9 * np.abs(solo.displacement).max())
    g, h = 9.81, 0.01
    fall = -g * h * h * (1 + 2 + 3)                      # x_k = x_{k-1} + h v_k, v_k = k g h
    np.testing.assert_allclose(u[n_solid:, 2], fall, rtol=1e-6)
    assert not sim.dofs[:n_solid, 3:].any()


def test_materials_select_cells_and_refuse_a_boundary_group(tmp_path):
    text = SCENE.replace('region = "block"', 'region = "bottom"')
    path, _, _ = _write(tmp_path / "beside.msh")
    with pytest.raises((SceneError, TensormassError), match=r"region 'bottom' \(id 3, surface\) holds no cells"):
        Model.from_scene(Scene.from_string(text.format(file=path.as_posix()), base_dir=tmp_path))


def test_a_pressure_on_the_shells_and_one_on_the_solid(tmp_path):
    """A shell group's pressure acts on its triangles; a boundary group's on the solid's faces."""
    text = SCENE.replace("[loads]\ngravity = [0.0, 0.0, -9.81]\n",
                         '[[loads.pressure]]\nregion = "sphere"\nvalue = 100.0\n'
                         '[[loads.pressure]]\nregion = "block"\nvalue = 10.0\n')
    path, n_solid, _ = _write(tmp_path / "beside.msh")
    model = Model.from_scene(Scene.from_string(text.format(file=path.as_posix()), base_dir=tmp_path))
    faces = model.pressure.groups["triangle"][0]
    on_shell = faces.min(axis=1) >= n_solid
    assert on_shell.sum() == 320 and (~on_shell).sum() == 2 * (2 * 3 * 3 + 2 * 3 * 2 + 2 * 3 * 2)   # 2 per quad
    # a closed sphere under uniform pressure: no net force on it
    f = model.pressure.forces(np.zeros(model.n_dofs)).reshape(-1, 6)
    assert np.abs(f[n_solid:, :3].sum(axis=0)).max() < 1e-12


def test_a_formulation_beside_shells_is_refused(tmp_path):
    text = SCENE.replace("nu = 0.4\n", 'nu = 0.45\nformulation = "nodal_pressure"\n', 1)
    scene, _, _ = _scene(tmp_path, text)
    with pytest.raises(TensormassError, match=r"material\[0\].formulation = 'nodal_pressure': the locking-free "
                                              "formulations are not available for solids beside shells"):
        Model.from_scene(scene)


def test_the_inversion_checks_read_each_solid_node_at_its_own_dofs(tmp_path):
    """One solid node pushed through its cells' opposite faces is seen inverted by Newton's check and by
    the health monitor; the same push on its rotation dofs (which the solid does not read) is not."""
    from tensormass.runtime.base.errors import InvertedElementError
    from tensormass.runtime.physics import health
    from tensormass.runtime.physics.newton import Context
    scene, n_solid, _ = _scene(tmp_path)
    model = Model.from_scene(scene)
    node = int(np.argmin(np.linalg.norm(model.mesh.points[:n_solid] - [0.0, 0.0, -0.025], axis=1)))
    assert node > 0
    ctx = Context(model)
    u = np.zeros((model.n_points, 6))
    u[node, 3:] = 0.2                                  # rotations: no cell of the solid reads them
    ctx.check_not_inverted(u.ravel())
    assert health.min_det_F(model, u.ravel())[0] > 0.999
    u[node] = 0.0
    u[node, 2] = 0.2                                   # 8 cell sizes up through its neighbours
    with pytest.raises(InvertedElementError):
        ctx.check_not_inverted(u.ravel())
    low, inverted = health.min_det_F(model, u.ravel())
    assert low < 0
