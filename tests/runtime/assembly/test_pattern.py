"""runtime.assembly.pattern: the numba-built pattern and node-blocked maps are the sort-based build's
(_reference_by_nodes, the code they replaced) entry for entry, dtype for dtype."""
import numpy as np
import pytest

from tensormass.runtime.assembly import pattern as pattern_module
from tensormass.runtime.assembly.assembly import Assembler, SparsePattern
from tensormass.runtime.base.dofs import node_dofs
from tensormass.runtime.kernels.fused import block_positions
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.model.model import Model
from tensormass.runtime.assembly.pattern import (ReferencePattern, _reference_by_nodes,
    _reference_submatrix_map)
from tensormass.runtime.scene.types import Adapt, Fixed, Material, Solver

FIELDS = ("indices", "indptr", "diagonal", "_rows")


def _same(a, b, what):
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype, (what, a.dtype, b.dtype)
    assert np.array_equal(a, b), what


def check(cell_tables, n_nodes, dpn, tables=None):
    """The pattern of these node tables (tables: the dof-table objects, shared ones included)
    against the reference: CSR, diagonal, rows, per-entry and node-blocked maps."""
    cell_tables = [np.asarray(c, dtype=np.int64) for c in cell_tables]
    if tables is None:
        tables = [node_dofs(c, dpn) for c in cell_tables]
    unique = {id(t): c for t, c in zip(tables, cell_tables)}
    ref = _reference_by_nodes(list(unique.values()), n_nodes, dpn)
    ref_pos = dict(zip(unique, ref["positions"]))
    got = SparsePattern(tables, n_nodes * dpn, dpn)
    assert got.nnz == ref["nnz"] and isinstance(got.nnz, int)
    for name in FIELDS:
        _same(getattr(got, name), ref[name], name)
    _same(got.node_indptr, ref["node_indptr"], "node_indptr")
    _same(got.node_cols, ref["node_cols"], "node_cols")
    blocks, positions = got.blocks, got.positions
    assert len(blocks) == len(positions) == len(tables)
    for t, b, p in zip(tables, blocks, positions):
        _same(p, ref_pos[id(t)], "positions")
        _same(b, block_positions(ref_pos[id(t)], dpn), "blocks")
    for i, t in enumerate(tables):           # shared table objects share their maps
        j = [id(x) for x in tables].index(id(t))
        assert positions[i] is positions[j] and blocks[i] is blocks[j]
    # the same from the node tables alone
    again = SparsePattern.rebuild(list(unique.values()), n_nodes, dpn)
    for name in FIELDS:
        _same(getattr(again, name), ref[name], name)
    return got


@pytest.mark.parametrize("element,cells", [("tetra", (3, 2, 2)), ("hexahedron", (3, 2, 2)), ("tetra10", (2, 2, 1)),
                                           ("mixed", (4, 2, 2)), ("wedge", (2, 2, 2)), ("pyramid", (2, 1, 1))])
def test_solids_equal_the_sort_based_build(element, cells):
    mesh = generate_bar(size=(1.0, 0.5, 0.5), cells=cells, element=element)
    check([b.cells for b in mesh.blocks], mesh.n_points, 3)


@pytest.mark.parametrize("element,dpn", [("quad", 2), ("triangle", 2), ("triangle6", 2), ("mixed", 2),
                                         ("triangle", 6), ("quad", 6)])
def test_2d_and_shells_equal_the_sort_based_build(element, dpn):
    """2D solids (dpn 2) and shells (6 dofs per node on a surface mesh: the same node tables)."""
    mesh = generate_bar(size=(1.0, 0.5), cells=(3, 2), element=element)
    check([b.cells for b in mesh.blocks], mesh.n_points, dpn)


def test_shared_tables_repeated_cells_unused_nodes_and_shuffled_order():
    """A switchable group's parts share one table object; a table may repeat cells and list them
    in any order; nodes in no cell keep their diagonal."""
    mesh = generate_bar(size=(1.0, 0.5, 0.5), cells=(3, 2, 2), element="tetra")
    cells = mesh.blocks[0].cells
    rng = np.random.default_rng(0)
    shuffled = cells[rng.permutation(len(cells))]
    repeated = np.concatenate([cells[:5], cells[:5], cells[3:9, ::-1]])
    n_nodes = mesh.n_points + 4                         # four nodes in no cell
    t0, t1 = node_dofs(shuffled, 3), node_dofs(repeated, 3)
    check([shuffled, shuffled, repeated, shuffled], n_nodes, 3, tables=[t0, t0, t1, t0])


def test_random_tables_of_mixed_sizes():
    rng = np.random.default_rng(5)
    n_nodes = 40
    tables = [rng.integers(0, n_nodes, size=(30, 4)), rng.integers(0, n_nodes, size=(7, 8)),
              rng.integers(0, n_nodes, size=(3, 1)), np.zeros((0, 6), dtype=np.int64)]
    for dpn in (1, 2, 3):
        check(tables, n_nodes, dpn)


def test_a_cut_renumbers_and_duplicates_nodes_and_rebuild_follows():
    """What cutting does: a node is duplicated for the cells on one side, cells renumbered."""
    mesh = generate_bar(size=(1.0, 0.5, 0.5), cells=(4, 2, 2), element="tetra")
    cells = mesh.blocks[0].cells.copy()
    n = mesh.n_points
    side = np.flatnonzero(mesh.points[cells].mean(axis=1)[:, 0] > 0.5)
    cut = cells[side]
    on_plane = np.isclose(mesh.points[cut][..., 0], 0.5)
    cut[on_plane] += n                                  # the copies of the plane's nodes
    cells[side] = cut
    cells = cells[::-1].copy()
    got = SparsePattern.rebuild([cells], 2 * n, 3)
    ref = _reference_by_nodes([cells], 2 * n, 3)
    for name in FIELDS:
        _same(getattr(got, name), ref[name], name)
    _same(got.blocks[0], block_positions(ref["positions"][0], 3), "blocks")


def test_dof_tables_that_are_not_node_major_go_by_dofs():
    mesh = generate_bar(size=(1.0, 0.5, 0.5), cells=(2, 1, 1), element="tetra")
    table = node_dofs(mesh.blocks[0].cells, 3)[:, ::-1].copy()
    p = SparsePattern([table], mesh.n_points * 3, 3)
    assert p.blocks == [None] and p.positions[0].shape == (len(table), 12, 12)
    ref = SparsePattern([table], mesh.n_points * 3)
    for name in FIELDS:
        _same(getattr(p, name), getattr(ref, name), name)


def test_submatrix_map_equals_the_numpy_map():
    mesh = generate_bar(size=(1.0, 0.5, 0.5), cells=(3, 2, 2), element="hexahedron")
    p = SparsePattern([node_dofs(mesh.blocks[0].cells, 3)], mesh.n_points * 3, 3)
    rng = np.random.default_rng(1)
    fixed = np.sort(rng.choice(p.n_dofs, 20, replace=False))
    free = np.setdiff1d(np.arange(p.n_dofs), fixed)
    for rows, cols in ((free, free), (free, fixed), (fixed, free), (free, free[:0])):
        got, ref = p.submatrix_map(rows, cols), _reference_submatrix_map(p, rows, cols)
        assert got[3] == ref[3]
        for a, b, what in zip(got[:3], ref[:3], ("entries", "indices", "indptr")):
            _same(a, b, what)


def _full_positions(model):
    """The pattern by dofs of the Assembler's tables: every per-entry map built at once."""
    tables = [p.dofs for p in model.parts] + [t for c in model.couplings for t in c.patch_tables]
    return SparsePattern(tables, model.n_dofs)


def test_assembler_plans_get_the_blocks_of_the_full_positions_and_couplings_theirs(monkeypatch):
    """Switchable parts (shared tables, active subsets) and a nodal-pressure coupling (patch tables):
    the plans' blocks, block sizes and the couplings' maps are those of the full positions."""
    monkeypatch.setattr("tensormass.runtime.assembly.assembly.MIN_BLOCK", 4)
    monkeypatch.setattr("tensormass.runtime.assembly.assembly.BLOCK_BYTES", 1)
    model = Model(generate_bar(size=(1.0, 0.5, 0.5), cells=(4, 2, 2), element="tetra"),
                  [Material(law="hooke", quadrature="gauss1", E=1e6, nu=0.3)],
                  fixed=[Fixed(box=((-1, -1, -1), (0, 1, 1)))], solver=Solver(),
                  adapt=[Adapt(criterion="rotation", threshold=5.0, law="stvk")])
    group = model.groups[0]
    group.switch(model, np.arange(0, model.mesh.n_cells, 3), "stvk")
    asm = Assembler(model)
    old = _full_positions(model)
    for i, (part, plan) in enumerate(zip(model.parts, asm.plans)):
        full = old.positions[i] if part.index is None else old.positions[i][part.index]
        _same(plan.blocks, block_positions(full, 3), "blocks")
        _same(asm.positions[i], full, "assembler positions")
    press = Model(generate_bar(size=(1.0, 0.5, 0.5), cells=(3, 2, 2), element="tetra"),
                  [Material(law="neohookean", quadrature="gauss1", E=1e6, nu=0.45, formulation="nodal_pressure")])
    asm = Assembler(press)
    old = _full_positions(press)
    (c,) = press.couplings
    _same(c.positions, old.positions[c.part_index][c.rows], "coupling positions")
    for j, pos in enumerate(c.patch_positions):
        _same(pos, old.positions[len(press.parts) + j], "patch positions")
    assert len(asm.pattern.positions) == len(press.parts)
    _same(asm.plans[0].blocks, block_positions(old.positions[0], 3), "blocks")


def test_no_full_positions_on_the_setup_path(monkeypatch):
    """Assembler setup (node-major dofs) never expands the per-entry maps."""
    def refuse(self, blocks):
        raise AssertionError("full positions built")
    monkeypatch.setattr(pattern_module.SparsePattern, "_expand", refuse)
    model = Model(generate_bar(size=(1.0, 0.5, 0.5), cells=(3, 2, 2), element="hexahedron"),
                  [Material(law="stvk", quadrature="gauss2", E=1e6, nu=0.3)])
    asm = Assembler(model)
    asm.warm_up()
    assert asm.plans[0].blocks is not None and asm.plans[0].pos is None


def test_assembly_is_bit_identical_to_the_old_pattern(monkeypatch):
    """f and K through the new pattern's maps are the bytes the old build's maps gave."""
    from tensormass.runtime.assembly import assembly
    model = Model(generate_bar(size=(1.0, 0.5, 0.5), cells=(3, 2, 2), element="tetra10"),
                  [Material(law="stvk", quadrature="gauss2", E=1e6, nu=0.3)])
    u = 1e-3 * np.random.default_rng(2).standard_normal(model.n_dofs)
    new = Assembler(model).forces_and_stiffness(u)
    monkeypatch.setattr(assembly, "SparsePattern", ReferencePattern)
    old = Assembler(model).forces_and_stiffness(u)
    assert new[0].tobytes() == old[0].tobytes() and new[1].tobytes() == old[1].tobytes()
