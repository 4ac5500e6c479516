"""The tetrahedral ball of runtime.mesh.solids: valid, good-quality, conforming, on the sphere, converging."""
import math

import numpy as np
import pytest

from tensormass.runtime.mesh.container import CellBlock, Mesh
from tensormass.runtime.mesh.checks import check_mesh
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.base.errors import SceneError
from tensormass.runtime.mesh.solids import ball_tetrahedra, boundary_faces, tetra_quality, tetra_volumes
from tensormass.runtime.physics.volume_constraint import VolumeConstraint

BALL = 4.0 / 3.0 * math.pi


@pytest.mark.parametrize("n, smallest", [(1, 12.0), (2, 15.0), (3, 15.0), (6, 15.0)])   # measured 13.8, 19.0, 18.1, 18.1
def test_ball_is_a_valid_conforming_mesh_of_positive_tetrahedra_with_bounded_angles(n, smallest):
    points, tetra = ball_tetrahedra(1.0, n)
    q = tetra_quality(points, tetra)
    print(f"n = {n}: {q['n_tetra']} tetrahedra, {q['n_nodes']} nodes, dihedral angles "
          f"{q['min_dihedral_deg']:.1f} .. {q['max_dihedral_deg']:.1f} deg")
    assert q["min_volume"] > 0.0
    assert q["min_dihedral_deg"] > smallest and q["max_dihedral_deg"] < 150.0
    assert q["n_nodes"] == len(points)                      # no unused node
    check_mesh(Mesh(points, [CellBlock("tetra", tetra)]))    # conforming: no hanging face, no duplicate node


def test_default_ball_is_near_the_thesis_count():
    points, tetra = ball_tetrahedra(1.0)
    assert len(tetra) == 6480 and abs(len(tetra) - 6665) / 6665 < 0.05


def test_boundary_is_a_closed_outward_surface_on_the_sphere():
    radius = 2.5
    points, tetra = ball_tetrahedra(radius, 4)
    faces = boundary_faces(tetra)
    r = np.linalg.norm(points[np.unique(faces)], axis=1)
    assert np.abs(r - radius).max() < 1e-12 * radius
    vc = VolumeConstraint(faces, points)                    # refuses an open or inconsistently wound surface
    assert vc.rest_volume == pytest.approx(tetra_volumes(points, tetra).sum(), rel=1e-12)
    inner = np.setdiff1d(np.arange(len(points)), np.unique(faces))
    assert np.linalg.norm(points[inner], axis=1).max() < radius * (1 - 1e-3)


def test_volume_converges_to_the_ball_from_below():
    errors = []
    for n in (2, 4, 8):
        points, tetra = ball_tetrahedra(1.0, n)
        errors.append(BALL - tetra_volumes(points, tetra).sum())
    assert all(e > 0 for e in errors)                       # an inscribed polyhedron
    assert errors[2] < 0.02 * BALL
    assert errors[1] / errors[2] > 3.0 and errors[0] / errors[1] > 3.0     # about 1 / n^2


def test_ball_is_mirror_symmetric():
    points, _ = ball_tetrahedra(1.0, 3)
    key = {tuple(np.round(p, 9)) for p in points}
    for axis in range(3):
        flipped = points.copy()
        flipped[:, axis] *= -1
        assert {tuple(np.round(p, 9)) for p in flipped} == key


def test_bad_arguments_are_refused():
    for bad in (0, -1.0, float("nan"), True):
        with pytest.raises(ValueError, match="radius"):
            ball_tetrahedra(bad, 2)
    for bad in (0, 2.5, True):
        with pytest.raises(ValueError, match="n must"):
            ball_tetrahedra(1.0, bad)


SCENE = """
[mesh]
generate = "ball"
radius = 0.5
divisions = 2
{extra}
[[material]]
law = "hooke"
quadrature = "gauss1"
E = 1000.0
nu = 0.3
[[fixed]]
box = [[-1, -1, -1], [1, 1, -0.45]]
[solver]
kind = "static"
"""


def test_scene_generates_the_ball():
    scene = Scene.from_string(SCENE.format(extra='origin = [1.0, 0.0, 0.0]'))
    mesh = scene.load_mesh()
    assert mesh.blocks[0].type == "tetra" and len(mesh.blocks[0].cells) == len(ball_tetrahedra(0.5, 2)[1])
    assert np.allclose(mesh.points.mean(axis=0), [1.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("extra, key", [("subdivisions = 2", "mesh.subdivisions"), ("cells = [2, 2, 2]", "mesh.cells"),
                                        ('element = "hexahedron"', "mesh.element")])
def test_scene_refuses_keys_the_ball_does_not_use(extra, key):
    with pytest.raises(SceneError, match=key):
        Scene.from_string(SCENE.format(extra=extra))


def test_divisions_only_with_the_ball():
    text = SCENE.replace('generate = "ball"\nradius = 0.5\ndivisions = 2', 'generate = "bar"\ndivisions = 2')
    with pytest.raises(SceneError, match="mesh.divisions"):
        Scene.from_string(text.format(extra=""))
