"""Uniform (red) refinement and order changes of simplicial meshes (runtime/mesh/uniform.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tensormass.runtime.mesh.container import MeshError
from tensormass.runtime.mesh.checks import check_mesh
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.mesh.io import read_mesh
from tensormass.runtime.mesh.probes import shape_functions
from tensormass.runtime.mesh.uniform import refine_uniform, to_linear, to_quadratic

DATA = Path(__file__).resolve().parents[2] / "apps" / "reports" / "data"


def _rule(dim):
    """Collapsed (Duffy) Gauss rule on the unit simplex, exact far beyond the cubic det J of quadratic cells."""
    g, w = np.polynomial.legendre.leggauss(5)
    g, w = (g + 1) / 2, w / 2
    if dim == 2:
        u, v = np.meshgrid(g, g, indexing="ij")
        W = np.outer(w, w) * (1 - u)
        return np.column_stack([u.ravel(), (v * (1 - u)).ravel()]), W.ravel()
    u, v, t = np.meshgrid(g, g, g, indexing="ij")
    W = np.einsum("i,j,k->ijk", w, w, w) * (1 - u) ** 2 * (1 - v)
    return np.column_stack([u.ravel(), (v * (1 - u)).ravel(), (t * (1 - u) * (1 - v)).ravel()]), W.ravel()


def _det(J):
    """det of a stack of 2 x 2 or 3 x 3 matrices by cofactors (np.linalg.det's batched LU is 10x slower here)."""
    if J.shape[-1] == 2:
        return J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    return (J[..., 0, 0] * (J[..., 1, 1] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 1])
            - J[..., 0, 1] * (J[..., 1, 0] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 0])
            + J[..., 0, 2] * (J[..., 1, 0] * J[..., 2, 1] - J[..., 1, 1] * J[..., 2, 0]))


def volumes(mesh):
    """Exact measure of every cell (its isoparametric map's det J integrated)."""
    out = []
    for blk in mesh.blocks:
        xi, w = _rule(mesh.dim)
        _, G = shape_functions(blk.type, xi)
        J = np.tensordot(mesh.points[blk.cells], G, axes=([1], [1])).transpose(0, 2, 1, 3)   # c q d r, by BLAS
        out.append(_det(J) @ w)
    return np.concatenate(out)


def shape_quality(mesh):
    """Measure / longest corner edge^dim of every cell (0 for a flat cell)."""
    blk = mesh.blocks[0]
    k = mesh.dim + 1
    P = mesh.points[blk.cells[:, :k]]
    longest = np.max([np.linalg.norm(P[:, a] - P[:, b], axis=1) for a in range(k) for b in range(a)], axis=0)
    return np.abs(np.linalg.det(P[:, 1:] - P[:, :1])) / longest ** mesh.dim


@pytest.mark.parametrize("element,dim", [("tetra", 3), ("triangle", 2), ("tetra10", 3), ("triangle6", 2)])
def test_red_refinement_halves_every_edge(element, dim):
    mesh = generate_bar((1.0, 0.3, 0.2)[:dim], (3, 2, 1)[:dim], element)
    for block in mesh.blocks:
        block.tags = np.arange(len(block)) % 2 + 7
    fine = refine_uniform(mesh)
    check_mesh(fine)                                          # conforming, positively oriented
    children = 2 ** dim
    assert fine.n_cells == children * mesh.n_cells
    assert np.array_equal(fine.blocks[0].tags, np.repeat(mesh.blocks[0].tags, children))
    np.testing.assert_allclose(fine.points[:mesh.n_points], mesh.points)       # old points keep their ids
    v0, v1 = volumes(mesh), volumes(fine)
    np.testing.assert_allclose(v1.reshape(-1, children).sum(axis=1), v0, rtol=1e-12)
    np.testing.assert_allclose(v1, np.repeat(v0, children) / children, rtol=1e-9)   # a bar's cells: equal halves
    # the corner mesh of the fine one is the corner mesh of the coarse one refined
    if element in ("tetra10", "triangle6"):
        lin = to_linear(fine)
        np.testing.assert_allclose(np.sort(volumes(lin)), np.sort(volumes(refine_uniform(to_linear(mesh)))),
                                   rtol=1e-12)


def test_curved_quadratic_cells_keep_their_geometry_and_shapes_stay_bounded():
    """gmsh's curved tetra10 rod: the children of a cell fill exactly its (curved) volume; linear tetra
    keep their shape quality within a bounded factor over two passes (shortest diagonal)."""
    curved = read_mesh(DATA / "rod_tetra10.msh")
    fine = refine_uniform(curved)
    check_mesh(fine)
    np.testing.assert_allclose(volumes(fine).reshape(-1, 8).sum(axis=1), volumes(curved), rtol=1e-11)
    straight = read_mesh(DATA / "rod_tetra.msh")
    twice = refine_uniform(refine_uniform(straight))
    check_mesh(twice)
    assert twice.n_cells == 64 * straight.n_cells
    q0, q2 = shape_quality(straight).min(), shape_quality(twice).min()
    assert q2 > 0.3 * q0, (q0, q2)
    assert volumes(twice).sum() == pytest.approx(volumes(straight).sum(), rel=1e-12)


def test_to_quadratic_shares_midside_nodes_and_to_linear_undoes_it():
    mesh = read_mesh(DATA / "rod_tetra.msh")
    quad = to_quadratic(mesh)
    check_mesh(quad)                                          # shared midside nodes at the edge middles
    cells = mesh.blocks[0].cells
    edges = {tuple(sorted(e)) for c in cells for e in ((c[0], c[1]), (c[1], c[2]), (c[0], c[2]),
                                                       (c[0], c[3]), (c[1], c[3]), (c[2], c[3]))}
    assert quad.n_points == mesh.n_points + len(edges)
    q = quad.blocks[0].cells
    np.testing.assert_allclose(quad.points[q[:, 4]], (quad.points[q[:, 0]] + quad.points[q[:, 1]]) / 2)
    np.testing.assert_allclose(volumes(quad), volumes(mesh), rtol=1e-12)
    back = to_linear(quad)
    assert np.array_equal(back.blocks[0].cells, cells) and np.array_equal(back.points, mesh.points)


def test_other_cell_types_are_named():
    with pytest.raises(MeshError, match="uniform refinement is defined for triangle, tetra, triangle6, tetra10 "
                                        "cells; the mesh has hexahedron cells"):
        refine_uniform(generate_bar(element="hexahedron"))
    with pytest.raises(MeshError, match="raising to quadratic.*tetra10 cells"):
        to_quadratic(generate_bar(element="tetra10"))


def test_boundary_faces_kept_as_cells_are_refined_with_the_body():
    """A tetra mesh with its boundary triangles as a block (mesh tags of lower dimension): the refined
    triangles are exactly the boundary faces of the refined tetrahedra (shared new nodes)."""
    from tensormass.runtime.mesh.container import CellBlock, Mesh
    from tensormass.runtime.mesh.faces import boundary_faces
    body = generate_bar((1.0, 0.2, 0.2), (2, 1, 1), "tetra")
    faces = np.array([nodes for _, _, nodes in boundary_faces(body)])
    mesh = Mesh(body.points, body.blocks + [CellBlock("triangle", faces, np.full(len(faces), 9))])
    for fine, k in ((refine_uniform(mesh), 3), (to_quadratic(refine_uniform(mesh)), 6)):
        solid = Mesh(fine.points, fine.blocks[:1])
        expected = {tuple(sorted(n)) for _, _, n in boundary_faces(solid)}
        got = {tuple(sorted(c)) for c in fine.blocks[1].cells}
        assert fine.blocks[1].cells.shape == (4 * len(faces), k) and got == expected
