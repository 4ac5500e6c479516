"""Element-graph colouring benchmark: DSATUR against first-fit, and the colour-parallel matrix-free
product (runtime.assembly.colouring.ColouredOperator) against scipy's CSR product of the assembled matrix.

    python -m tensormass.apps.bench_colouring [--n 50000] [--threads 1 2] [--json out.json]

Meshes (about N elements each, fixed seeds so every run colours the same graphs):
    tets        Delaunay tetrahedra of random points in the unit cube (seed 0), 3 dofs per node
    icosphere   a subdivided icosahedron (triangles, node valence 5 and 6), 6 dofs per node (shell)
    plate       a structured square grid cut into triangles, 6 dofs per node
    icosphere_shuffled   the icosphere's triangles in a random order (seed 0): first-fit depends on
                the element order (a mesh generator's order is rarely this regular), DSATUR hardly

Per mesh: colours (DSATUR, first-fit in index order, and the lower bound "most elements on one
node": they form a clique), the time to build the element graph and to colour it, and the time of
one matvec with 1, 2, ... numba threads against one scipy CSR matvec of the assembled matrix
measured in the same run (ratio > 1: slower than CSR).  Times are the best of `repeats` runs of
`inner` products, after a warm-up that compiles the numba kernels.  The element-by-element product
does k^2 d^2 multiply-adds per element against about one per stored entry for CSR (6-8 times more
for tetrahedra), so it pays off where assembling K is the cost, not at equal flops.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from ..runtime.assembly import colouring as col
from ..runtime.base import parallel
from ..runtime.base.files import write_json_atomic
from .machine import machine_info

__all__ = ["main", "run_colouring_bench", "tet_mesh", "icosphere", "plate"]


def tet_mesh(n_elements: int, seed: int = 0) -> np.ndarray:
    """Delaunay tetrahedra of random points in the unit cube: about 6.6 tetrahedra per point."""
    from scipy.spatial import Delaunay
    points = np.random.default_rng(seed).random((max(8, round(n_elements / 6.6)), 3))
    return Delaunay(points).simplices.astype(np.int64)


def icosphere(n_elements: int) -> np.ndarray:
    """Triangles of an icosahedron subdivided r times (20 * 4^r), r closest to n_elements (log scale)."""
    level = max(0, round(np.log(max(n_elements, 20) / 20) / np.log(4)))
    t = (1 + 5 ** 0.5) / 2
    points = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
              (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = np.array([(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
                      (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
                      (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)])
    n_points = len(points)
    for _ in range(level):
        # one midpoint node per edge (numbered by the sorted edge list), each triangle into four
        edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = (n_points + inverse.ravel()).reshape(3, -1).T        # midpoints of edges 01, 12, 20
        a, b, c = faces.T
        ab, bc, ca = mid.T
        faces = np.concatenate([np.stack(f, 1) for f in ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))])
        n_points += len(unique)
    return faces.astype(np.int64)


def plate(n_elements: int) -> np.ndarray:
    """A structured n x n grid of squares, each cut into two triangles (about n_elements triangles)."""
    n = max(1, round((n_elements / 2) ** 0.5))
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _best(fn, repeats: int, inner: int = 1) -> float:
    """Best over `repeats` of the mean time of `inner` calls (seconds)."""
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(inner):
            fn()
        best = min(best, (time.perf_counter() - start) / inner)
    return best


def _warm_up() -> None:
    """Compile the numba kernels on a tiny mesh so that no timing includes compilation."""
    cells = plate(8)
    colours = col.colour_cells(cells)
    col.colour_cells(cells, "greedy")
    op = col.ColouredOperator(cells, 1, np.ones((len(cells), 3, 3)), colours)
    op.matvec(np.ones(op.n))


def _element_blocks(m: int, n_e: int, seed: int = 1) -> np.ndarray:
    B = np.random.default_rng(seed).standard_normal((m, n_e, n_e))
    return B + B.transpose(0, 2, 1)


def measure(name: str, cells: np.ndarray, dofs_per_node: int, threads: list, repeats: int) -> dict:
    row = {"mesh": name, "elements": int(len(cells)), "nodes": int(cells.max()) + 1,
           "dofs_per_node": dofs_per_node, "lower_bound": int(np.bincount(cells.ravel()).max())}
    graph = col.element_graph(cells)
    row["graph_edges"] = int(graph[1].size // 2)
    row["max_degree"] = int(np.diff(graph[0]).max())
    row["graph_s"] = _best(lambda: col.element_graph(cells), max(1, repeats // 2))
    colours = {}
    for method in ("dsatur", "greedy"):
        colours[method] = col.METHODS[method](*graph)
        col.check_colouring(cells, colours[method])
        row[f"{method}_colours"] = int(colours[method].max()) + 1
        row[f"{method}_s"] = _best(lambda: col.METHODS[method](*graph), repeats)
    k = cells.shape[1]
    op = col.ColouredOperator(cells, dofs_per_node, _element_blocks(len(cells), k * dofs_per_node), colours["dsatur"])
    A = op.to_csr()
    x = np.random.default_rng(2).standard_normal(op.n)
    row["csr_nnz"] = int(A.nnz)
    want = A @ x
    row["max_rel_diff"] = float(np.abs(op.matvec(x) - want).max() / np.abs(want).max())
    inner = max(1, int(2e7 // (len(cells) * (k * dofs_per_node) ** 2)))       # ~ 2e7 multiply-adds a repeat
    row["csr_matvec_s"] = _best(lambda: A @ x, repeats, inner)
    for t in threads:
        with parallel.threads(t):
            row[f"matvec_{t}t_s"] = _best(lambda: op.matvec(x), repeats, inner)
        row[f"ratio_{t}t"] = row[f"matvec_{t}t_s"] / row["csr_matvec_s"]
    return row


def run_colouring_bench(n: int = 50000, threads=(1, 2), repeats: int = 5) -> dict:
    threads = [t for t in threads if t <= parallel.available()]
    _warm_up()
    sphere = icosphere(n)
    shuffled = sphere[np.random.default_rng(0).permutation(len(sphere))]
    meshes = [("tets", tet_mesh(n), 3), ("icosphere", sphere, 6), ("icosphere_shuffled", shuffled, 6),
              ("plate", plate(n), 6)]
    rows = [measure(name, cells, d, threads, repeats) for name, cells, d in meshes]
    try:
        load = os.getloadavg()
    except OSError:
        load = None
    return {"n": n, "threads": threads, "repeats": repeats, "load_average": load,
            "machine": machine_info(), "rows": rows}


def format_table(report: dict) -> str:
    threads = report["threads"]
    head = (f"{'mesh':<18} {'elems':>7} {'nodes':>7} {'d':>2} {'lb':>3} {'dsatur':>6} {'greedy':>6} "
            f"{'graph ms':>8} {'dsatur ms':>9} {'greedy ms':>9} {'csr ms':>7} "
            + " ".join(f"{f'{t}t ms (x csr)':>16}" for t in threads))
    lines = [head, "-" * len(head)]
    for r in report["rows"]:
        lines.append(f"{r['mesh']:<18} {r['elements']:>7} {r['nodes']:>7} {r['dofs_per_node']:>2} "
                     f"{r['lower_bound']:>3} {r['dsatur_colours']:>6} {r['greedy_colours']:>6} "
                     f"{r['graph_s'] * 1e3:>8.1f} {r['dsatur_s'] * 1e3:>9.1f} {r['greedy_s'] * 1e3:>9.1f} "
                     f"{r['csr_matvec_s'] * 1e3:>7.2f} "
                     + " ".join(f"{r[f'matvec_{t}t_s'] * 1e3:>8.2f} ({r[f'ratio_{t}t']:>5.2f})" for t in threads))
    lines.append("lb: most elements on one node (a lower bound on the colours); d: dofs per node; "
                 "matvec: ColouredOperator with DSATUR colours, ratio against scipy CSR of the assembled matrix")
    if report.get("load_average"):
        lines.append(f"load average at the end: {', '.join(f'{v:.2f}' for v in report['load_average'])} "
                     f"on {report['machine'].get('usable_cores')} usable core(s)")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="bench_colouring", description=__doc__.split("\n")[0])
    p.add_argument("--n", type=int, default=50000, help="about this many elements per mesh (default 50000)")
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="numba thread counts (default 1 2)")
    p.add_argument("--repeats", type=int, default=5, help="best of this many runs (default 5)")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    args = p.parse_args(argv)
    report = run_colouring_bench(args.n, args.threads, args.repeats)
    print(format_table(report))
    if args.json:
        write_json_atomic(args.json, report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
