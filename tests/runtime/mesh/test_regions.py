"""runtime.mesh.regions: boxes (with the tolerance), regions, material assignment (first match wins),
unused materials and conflicting [[fixed]]; the kernel outputs integrators declare; E and nu
validated once."""
import numpy as np
import pytest

from tensormass.runtime.base import integrator_kinds

from tensormass import laws
from tensormass.laws import base as laws_base
from tensormass.runtime.physics import integrators
from tensormass.runtime.base.errors import SceneError, TensormassError
from tensormass.runtime.mesh.container import CellBlock, Mesh
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.model.model import Model, assign_materials as model_assign
from tensormass.runtime.mesh.regions import (BOX_TOLERANCE, assign_materials, box_bounds, box_contains,
    box_tolerance, check_unused_materials, material_groups, prescribed_values, reachable_laws, region_mask)
from tensormass.runtime.scene.types import Adapt, Fixed, Material
from tensormass.runtime.scene.scene import Scene


def tagged_quads() -> Mesh:
    """Four unit quads along x (x = 0..4), tags 1, 1, 2, 2."""
    mesh = generate_bar((4.0, 1.0), (4, 1), "quad")
    (blk,) = mesh.blocks
    order = np.argsort(mesh.points[blk.cells].mean(axis=1)[:, 0])
    return Mesh(mesh.points, [CellBlock("quad", blk.cells[order], tags=[1, 1, 2, 2])])


# ------------------------------------------------------------------------------ boxes


def test_box_tolerance_is_relative_to_the_bounding_box_diagonal():
    points = np.array([[0.0, 0.0], [3.0, 4.0]])
    assert box_tolerance(points) == pytest.approx(5.0 * BOX_TOLERANCE)
    assert box_tolerance(np.zeros((0, 3))) == 0.0
    tol = box_tolerance(points)
    near = np.array([[1.0 + 0.5 * tol, 0.5], [1.0 + 2 * tol, 0.5]])
    box = ((0.0, 0.0), (1.0, 1.0))
    assert box_contains(box, near, tol).tolist() == [True, False]
    assert box_contains(box, near).tolist() == [False, False]            # closed, no slack without tol


def test_boxes_are_closed_take_infinite_bounds_and_corners_in_any_order():
    pts = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 5.0]])
    assert box_contains(((0, 0), (1, 1)), pts).tolist() == [True, True, False]
    assert box_contains(((1, 1), (0, 0)), pts).tolist() == [True, True, False]
    assert box_contains(((-np.inf, 0.5), (np.inf, np.inf)), pts).tolist() == [False, True, True]
    lo, hi = box_bounds(((0, 0, 9), (1, 1, 9)), 2, 0.1)                  # extra coordinates dropped
    assert lo.tolist() == [-0.1, -0.1] and hi.tolist() == [1.1, 1.1]
    with pytest.raises(TensormassError, match="box corners need 3 coordinates"):
        box_bounds(((0, 0), (1, 1)), 3)
    with pytest.raises(TensormassError, match="a box must be two corner points"):
        box_bounds(((0, 0), (1, 1), (2, 2)), 2)


# ------------------------------------------------------------------------------ regions


def test_regions_all_element_type_and_tags():
    blk = tagged_quads().blocks[0]
    assert region_mask(blk, "all").all()
    assert region_mask(blk, "quad").all() and not region_mask(blk, "triangle").any()
    assert region_mask(blk, 2).tolist() == [False, False, True, True]
    assert region_mask(blk, "1").tolist() == [True, True, False, False]     # a tag written as a string
    untagged = CellBlock("quad", blk.cells)
    assert not region_mask(untagged, 1).any()
    with pytest.raises(TensormassError, match="material region 'steel'"):
        region_mask(blk, "steel")


def test_first_match_wins_with_regions_boxes_and_tags():
    mesh = tagged_quads()
    mats = [Material(region=2, box=((3.0, -1.0), (9.0, 9.0)), E=1.0, nu=0.3),   # cell 3 only
            Material(region=2, E=1.0, nu=0.3),                                  # cell 2 (3 is taken)
            Material(box=((0.0, 0.0), (1.0, 1.0)), E=1.0, nu=0.3),              # cell 0 by its centroid
            Material(region="quad", E=1.0, nu=0.3)]                             # the rest: cell 1
    (which,) = assign_materials(mesh, mats)
    assert which.tolist() == [2, 3, 1, 0]
    groups = material_groups(mesh, [Material(law="hooke"), Material(law="stvk")], [np.array([0, 1, 1, 0])])
    assert list(groups) == [("quad", "hooke", "gauss2"), ("quad", "stvk", "gauss2")]
    assert [ids.tolist() for _, ids, _ in groups[("quad", "hooke", "gauss2")]] == [[0, 3]]


def test_a_centroid_on_the_box_face_counts_within_the_tolerance():
    mesh = tagged_quads()
    tol = box_tolerance(mesh.points)
    mats = [Material(box=((0.0, 0.0), (0.5 - 0.5 * tol, 1.0)), E=1.0, nu=0.3), Material(E=2.0, nu=0.3)]
    assert assign_materials(mesh, mats)[0].tolist() == [0, 1, 1, 1]
    mats[0].box = ((0.0, 0.0), (0.5 - 2 * tol, 1.0))
    assert assign_materials(mesh, mats)[0].tolist() == [1, 1, 1, 1]


def test_cells_without_a_material():
    mesh = tagged_quads()
    assert assign_materials(mesh, [Material(region=1)])[0].tolist() == [0, 0, -1, -1]
    with pytest.raises(TensormassError, match=r"2 cell\(s\) match no material \(e.g. cells \[2, 3\]\)"):
        assign_materials(mesh, [Material(region=1)], complete=True)
    with pytest.raises(TensormassError, match="the scene defines no material"):
        model_assign(mesh, [])


def test_unused_materials_are_named_with_the_reason():
    mesh = tagged_quads()
    mats = [Material(region="all"), Material(region=2)]
    with pytest.raises(SceneError, match=r"^material\[1\]: no cell uses it: every cell it matches is taken by "
                                         r"material\[0\] \(first match wins\); remove it"):
        check_unused_materials(mats, mesh, assign_materials(mesh, mats))
    mats = [Material(region=7), Material(region="all")]
    with pytest.raises(SceneError, match=r"^material\[0\]: no cell uses it: no cell matches its region 7 "
                                         r"\(the mesh has quad cells, tags \[1, 2\]\)"):
        check_unused_materials(mats, mesh, assign_materials(mesh, mats))
    mats = [Material(region=1), Material(region=2)]
    check_unused_materials(mats, mesh, assign_materials(mesh, mats))


def test_scene_and_model_assign_through_regions():
    text = ('[mesh]\ngenerate = "bar"\nelement = "mixed"\ncells = [8, 2, 2]\n'
            '[[material]]\nregion = "tetra"\nE = 1e6\nnu = 0.3\n'
            '[[material]]\nbox = [[0, -1, -1], [0.3, 1, 1]]\nE = 2e6\nnu = 0.3\n'
            '[[material]]\nE = 3e6\nnu = 0.3\n[[fixed]]\nbox = [[0, -1, -1], [0, 1, 1]]\n')
    scene = Scene.from_string(text)
    mesh = scene.load_mesh()
    ours = assign_materials(mesh, scene.materials)
    for a, b, c in zip(scene.assign_materials(mesh), model_assign(mesh, scene.materials), ours):
        assert a.tolist() == b.tolist() == c.tolist()
    assert {int(i) for w in ours for i in np.unique(w)} == {0, 1, 2}


# ------------------------------------------------------------------------------ [[fixed]]


def test_prescribed_values_and_conflicting_fixed_boxes():
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    left = Fixed(box=((0, -1), (1, 1)))
    right = Fixed(box=((1, -1), (2, 1)), displacement=(0.5, 0.0), components=(0,))
    with pytest.raises(SceneError, match=r"^fixed\[1\]: prescribes component 0 = 0.5 at node 1 \(\[1, 0\]\) "
                                         r"where fixed\[0\] prescribes 0 \(1 node\(s\) in both boxes\)"):
        prescribed_values([left, right], pts, 0.0)
    right.components = (1,)                # the other component: same value 0, no conflict
    right.displacement = (0.5, 0.0)
    value, owner = prescribed_values([left, right], pts, 0.0)
    assert value[:, 0].tolist()[:2] == [0.0, 0.0] and np.isnan(value[2, 0])
    assert owner[:, 1].tolist() == [0, 1, 1]
    model_pts = generate_bar((1.0, 0.2), (2, 1), "quad")
    with pytest.raises(SceneError, match="the boxes overlap with different values"):
        Model(model_pts, [Material(E=1e6, nu=0.3)],
              fixed=[Fixed(box=((0, -1), (0.6, 1))), Fixed(box=((0.4, -1), (1, 1)), displacement=(0.1, 0.0))])


def test_reachable_laws_are_transitive():
    rules = [Adapt("R_L", 0.1, law="stvk", from_law="hooke"), Adapt("R_L", 0.2, law="neohookean", from_law="stvk"),
             Adapt("R_A", 0.1, action="refine")]
    assert reachable_laws("hooke", rules) == ["hooke", "stvk", "neohookean"]
    assert reachable_laws("neohookean", rules) == ["neohookean"]


# ------------------------------------------------------------------------------ declared outputs


KINDS = {"static": integrators.Static, "implicit_euler": integrators.ImplicitEuler,
         "backward_euler": integrators.BackwardEuler, "explicit": integrators.Explicit}


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_each_integrator_declares_exactly_the_outputs_the_model_loads(kind, monkeypatch):
    declared = KINDS[kind].outputs
    assert integrators.integrator_class(kind) is KINDS[kind] and integrators.outputs_for(kind) == declared
    assert declared and set(declared) <= {"energy", "forces", "stiffness"}
    text = (f'[mesh]\ngenerate = "bar"\ncells = [2, 1, 1]\n[[material]]\nE = 1e6\nnu = 0.3\n'
            f'[[fixed]]\nbox = [[0, -1, -1], [0, 1, 1]]\n[solver]\nkind = "{kind}"\n')
    scene = Scene.from_string(text)
    model = Model.from_scene(scene)
    assert model.outputs == declared
    assert {k[3] for k in Model.required_kernels(scene)} == {declared}
    assert all(info["outputs"] == list(declared) for info in model.kernel_info())
    called = []
    for part in model.parts:
        for name in ("energy", "forces", "stiffness", "forces_and_stiffness"):
            if hasattr(part.kernel, name):
                monkeypatch.setattr(part.kernel, name, lambda D, u, _n=name: called.append(_n))
    model.warm_up()
    assert tuple(called) == declared
    # the light declaration (what the scene parser and the resource estimate read) is the integrator's
    assert integrator_kinds.get(kind).outputs == declared
    assert integrator_kinds.get(kind).step_output == ("forces_and_stiffness" if "stiffness" in declared else "forces")
    with pytest.raises(TensormassError, match="unknown solver kind 'leapfrog'"):
        integrators.outputs_for("leapfrog")


def test_every_declared_kind_has_its_integrator():
    assert set(integrator_kinds.NAMES) == set(integrators._KINDS)
    for name, kind in integrator_kinds.KINDS.items():
        assert integrators.integrator_class(name).kind == name and kind.dynamic == (name != "static")


# ------------------------------------------------------------------------------ E and nu once


def test_scene_validates_E_and_nu_once_through_laws(monkeypatch):
    calls = []
    original = laws_base.validate_E_nu

    def spy(E, nu, *args):
        calls.append((float(E), float(nu)))
        return original(E, nu, *args)

    monkeypatch.setattr(laws_base, "validate_E_nu", spy)
    text = ('[mesh]\ngenerate = "bar"\ncells = [2, 1, 1]\n[[material]]\nE = 1e6\nnu = 0.3\n'
            '[[fixed]]\nbox = [[0, -1, -1], [0, 1, 1]]\n')
    Scene.from_string(text, load_mesh=False)
    assert calls == [(1e6, 0.3)]
    with pytest.raises(SceneError, match=r"^material\[0\]\.nu: Poisson's ratio must be < 0.5 \(got 0.5\)"):
        Scene.from_string(text.replace("nu = 0.3", "nu = 0.5"), load_mesh=False)
    assert len(calls) == 2
    with pytest.raises(laws.LawError, match="Young's modulus E must be > 0"):
        laws.get("stvk").native_parameters(E=-1.0, nu=0.3)


def test_may_cover_without_a_mesh():
    from tensormass.runtime.mesh.regions import may_cover
    assert may_cover(Material(region="all"), "tetra") and may_cover(Material(region=3), "tetra")
    assert may_cover(Material(region="tetra", box=((0, 0, 0), (1, 1, 1))), "tetra")
    assert not may_cover(Material(region="hexahedron"), "tetra")
