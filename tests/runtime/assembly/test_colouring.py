"""Element-graph colouring (runtime.assembly.colouring): valid colourings, DSATUR against first-fit and known
chromatic numbers, and the colour-parallel matrix-free product against an assembled scipy matrix."""
import itertools

import numba
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial import Delaunay

from tensormass.runtime.assembly import colouring as col
from tensormass.runtime.base.dofs import node_dofs


def triangle_grid(n):
    """n x n squares, each cut into two triangles (node valence up to 6)."""
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def random_tets(n_points=300, seed=7):
    return Delaunay(np.random.default_rng(seed).random((n_points, 3))).simplices.astype(np.int64)


def cells_of_graph(edges, n):
    """Cells whose element graph is exactly the given k-regular graph: one mesh node per edge,
    shared by its two end elements (each element lists the nodes of its k edges)."""
    own = [[] for _ in range(n)]
    for node, (u, v) in enumerate(edges):
        own[u].append(node)
        own[v].append(node)
    return np.array(own, dtype=np.int64)


def crown(n):
    """K_{n,n} minus a perfect matching, elements interleaved a0 b0 a1 b1 ...: first-fit in index
    order needs n colours, the graph is bipartite (2 colours)."""
    edges = [(2 * i, 2 * j + 1) for i in range(n) for j in range(n) if i != j]
    return cells_of_graph(edges, 2 * n)


def brute_graph(cells):
    m = len(cells)
    return {(i, j) for i, j in itertools.permutations(range(m), 2) if set(cells[i]) & set(cells[j])}


MESHES = {
    "triangle_grid": lambda: triangle_grid(12),
    "random_tets": random_tets,
    "one_element": lambda: np.array([[0, 1, 2, 3]]),
    "crown": lambda: crown(6),
}


def test_element_graph_is_node_sharing():
    for cells in (triangle_grid(3), random_tets(30), np.array([[0, 1, 2]]), crown(4)):
        indptr, indices = col.element_graph(cells)
        pairs = {(i, int(j)) for i in range(len(cells)) for j in indices[indptr[i]:indptr[i + 1]]}
        assert pairs == brute_graph(cells)
        for i in range(len(cells)):
            row = indices[indptr[i]:indptr[i + 1]]
            assert np.all(np.diff(row) > 0)              # sorted, no duplicates
    again = col.element_graph(random_tets(30))
    assert all(np.array_equal(a, b) for a, b in zip(again, col.element_graph(random_tets(30))))


@pytest.mark.parametrize("name", sorted(MESHES))
def test_valid_colourings_and_dsatur_bounds(name):
    cells = MESHES[name]()
    indptr, indices = col.element_graph(cells)
    max_degree = int(np.diff(indptr).max())
    counts = {}
    for method in ("dsatur", "greedy"):
        colours = col.colour_cells(cells, method)
        assert colours.dtype == np.int32 and colours.shape == (len(cells),)
        col.check_colouring(cells, colours)
        counts[method] = int(colours.max()) + 1
        assert sorted(np.concatenate(col.colour_classes(colours)).tolist()) == list(range(len(cells)))
    assert counts["dsatur"] <= counts["greedy"]
    assert counts["dsatur"] <= max_degree + 1
    # a node shared by v elements forces v colours (those elements form a clique)
    assert counts["dsatur"] >= np.bincount(cells.ravel()).max()


def test_known_chromatic_numbers():
    # triangles (i, i+1, i+2) of a strip: each meets the two before and after: 3 colours
    strip = np.stack([np.arange(20), np.arange(1, 21), np.arange(2, 22)], 1)
    assert col.colour_cells(strip).max() + 1 == 3
    # bipartite: a chain of segments, an even ring of segments, a crown graph (first-fit: 6)
    chain = np.stack([np.arange(9), np.arange(1, 10)], 1)
    ring = np.stack([np.arange(10), (np.arange(10) + 1) % 10], 1)
    for cells in (chain, ring, crown(6)):
        assert col.colour_cells(cells).max() + 1 == 2
    assert col.colour_cells(crown(6), "greedy").max() + 1 == 6
    odd_ring = np.stack([np.arange(9), (np.arange(9) + 1) % 9], 1)
    assert col.colour_cells(odd_ring).max() + 1 == 3
    assert np.all(col.colour_cells(np.array([[0, 1, 2]])) == 0)


def test_dsatur_tie_rules():
    # path a - b - c: b has the largest degree and goes first; greedy takes index order
    chain = np.array([[0, 1], [1, 2], [2, 3]])
    assert col.colour_cells(chain).tolist() == [1, 0, 1]
    assert col.colour_cells(chain, "greedy").tolist() == [0, 1, 0]
    cells = random_tets(200, seed=3)
    assert np.array_equal(col.colour_cells(cells), col.colour_cells(cells))


def test_check_colouring_rejects_clashes():
    cells = triangle_grid(3)
    with pytest.raises(ValueError, match="share node"):
        col.check_colouring(cells, np.zeros(len(cells), dtype=np.int32))
    with pytest.raises(ValueError):
        col.check_colouring(cells, np.zeros(len(cells) - 1, dtype=np.int32))
    with pytest.raises(ValueError):
        col.colour_cells(cells, "nope")


def element_blocks(m, n_e, seed):
    """Random symmetric element blocks of order n_e."""
    B = np.random.default_rng(seed).standard_normal((m, n_e, n_e))
    return B + B.transpose(0, 2, 1) + n_e * np.eye(n_e)


def assembled(cells, d, Ke, n_nodes):
    dofs = node_dofs(cells, d)
    n_e = dofs.shape[1]
    rows, cols = np.repeat(dofs, n_e, axis=1).ravel(), np.tile(dofs, (1, n_e)).ravel()
    return sp.coo_matrix((Ke.ravel(), (rows, cols)), shape=(n_nodes * d,) * 2).tocsr()


@pytest.mark.parametrize("cells_of, d", [(random_tets, 3), (lambda: triangle_grid(10), 6)])
def test_coloured_operator_matches_assembled_matrix(cells_of, d):
    cells = cells_of()
    k = cells.shape[1]
    Ke = element_blocks(len(cells), k * d, seed=d)
    Ke[0] += np.triu(np.ones((k * d, k * d)))                      # one non-symmetric block for rmatvec
    op = col.ColouredOperator(cells, d, Ke, col.colour_cells(cells))
    A = assembled(cells, d, Ke, cells.max() + 1)
    x = np.random.default_rng(1).standard_normal(op.n)
    for got, want in ((op.matvec(x), A @ x), (op.as_linear_operator() @ x, A @ x), (op.rmatvec(x), A.T @ x)):
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())
    np.testing.assert_allclose(op.to_csr().toarray(), A.toarray(), rtol=1e-14, atol=1e-14 * abs(A).max())


def test_coloured_operator_rejects_bad_input():
    cells = triangle_grid(2)
    Ke = element_blocks(len(cells), 6, seed=0)
    with pytest.raises(ValueError, match="share node"):
        col.ColouredOperator(cells, 2, Ke, np.zeros(len(cells), dtype=np.int32))
    with pytest.raises(ValueError, match="shape"):
        col.ColouredOperator(cells, 3, Ke, col.colour_cells(cells))


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="numba sees one core")
def test_matvec_bit_identical_across_thread_counts():
    cells = random_tets(600, seed=11)
    Ke = element_blocks(len(cells), 12, seed=5)
    op = col.ColouredOperator(cells, 3, Ke, col.colour_cells(cells))
    x = np.random.default_rng(2).standard_normal(op.n)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = op.matvec(x)
        numba.set_num_threads(2)
        two = [op.matvec(x) for _ in range(3)]
    finally:
        numba.set_num_threads(before)
    for y in two:
        assert np.array_equal(one.view(np.int64), y.view(np.int64))


def test_bench_meshes():
    """The benchmark's meshes (apps.bench_colouring; its timings are not run here)."""
    from tensormass.apps.bench_colouring import icosphere, plate, tet_mesh
    sphere = icosphere(1280)
    assert sphere.shape == (1280, 3)
    edges = np.sort(np.concatenate([sphere[:, [0, 1]], sphere[:, [1, 2]], sphere[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)                                       # closed surface
    assert sphere.max() + 1 - len(unique) + len(sphere) == 2          # Euler characteristic of a sphere
    assert set(np.bincount(sphere.ravel()).tolist()) == {5, 6}
    assert plate(50).shape == (50, 3) and tet_mesh(300).shape[1] == 4
    for cells in (sphere, plate(50)):
        col.check_colouring(cells, col.colour_cells(cells))
