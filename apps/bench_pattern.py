"""Setup-time benchmark of the sparsity pattern: runtime.assembly.pattern's numba build against the sort-based
build it replaced (runtime.assembly.pattern.ReferencePattern), in the same run.

    python -m tensormass.apps.bench_pattern [--repeats 5] [--json bench_pattern.json] [--quick]

Why: cutting changes the mesh topology during a run and the pattern must be rebuilt then, so its
build has to take milliseconds.  Meshes (generated bars, StVK, one clamped end, implicit Euler):
    tetra       40 x 15 x 14 hexahedral cells split into 50 400 tetrahedra (29 520 dofs)
    tetra10     20 x 8 x 7 -> 6 720 quadratic tetrahedra
    hexahedron  40 x 15 x 14 -> 8 400 hexahedra
Per mesh and implementation (old, new): the best of `repeats` times of
    pattern     SparsePattern(dof tables, n_dofs, dofs_per_node) (old: with its full positions)
    rebuild     SparsePattern.rebuild(node tables, n_nodes, dofs_per_node) (new only)
    assembler   Assembler(model): pattern, per-part plans (node-blocked maps, colours)
    context     Context(model): the Assembler and the Dirichlet elimination maps (submatrix_map)
and old / new ratios.  Old and new are checked to give the same CSR and the same bytes of f and K.
"""
from __future__ import annotations

import argparse
import time
from contextlib import contextmanager

import numpy as np

from ..runtime.assembly import assembly
from ..runtime.base.files import write_json_atomic
from ..runtime.assembly.pattern import SparsePattern, ReferencePattern
from ..runtime.scene.scene import Scene
from ..runtime.physics.newton import Context
from ..runtime.model.model import Model

__all__ = ["main", "run_pattern_bench", "scene_dict"]

MESHES = {"tetra": (40, 15, 14), "tetra10": (20, 8, 7), "hexahedron": (40, 15, 14)}
QUICK = {"tetra": (8, 3, 3), "tetra10": (4, 2, 2), "hexahedron": (8, 3, 3)}


def scene_dict(element: str, cells) -> dict:
    """The benchmark's bar scene (p50k for tetra at 40 x 15 x 14)."""
    return {
        "name": f"pattern-{element}",
        "mesh": {"generate": "bar", "size": [1.2, 0.4, 0.4], "cells": list(cells), "element": element},
        "material": [{"region": "all", "law": "stvk", "quadrature": "gauss1" if element == "tetra" else "gauss2",
                      "E": 1.0e6, "nu": 0.3, "density": 800.0}],
        "fixed": [{"box": [[-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]]}],
        "loads": {"gravity": [0.0, 0.0, -9.81]},
        "solver": {"kind": "implicit_euler", "dt": 0.01, "steps": 3},
    }


@contextmanager
def _implementation(name: str):
    """Assembler (and so Context) building the new pattern or the old one."""
    saved = assembly.SparsePattern
    assembly.SparsePattern = SparsePattern if name == "new" else ReferencePattern
    try:
        yield
    finally:
        assembly.SparsePattern = saved


def _best(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def _check_same(model) -> None:
    """Old and new: the same CSR and the same bytes of f and K at a random displacement."""
    u = 1e-3 * np.random.default_rng(0).standard_normal(model.n_dofs)
    out = {}
    for name in ("old", "new"):
        with _implementation(name):
            asm = assembly.Assembler(model)
        f, data = asm.forces_and_stiffness(u)
        p = asm.pattern
        out[name] = (p.indptr.tobytes(), p.indices.tobytes(), p.diagonal.tobytes(), f.tobytes(), data.tobytes())
    if out["old"] != out["new"]:
        raise AssertionError("old and new patterns assemble different bytes")


def run_pattern_bench(repeats: int = 5, quick: bool = False, progress=print) -> dict:

    report = {"repeats": repeats, "cases": {}}
    for element, cells in (QUICK if quick else MESHES).items():
        model = Model.from_scene(Scene.from_dict(scene_dict(element, cells)))
        model.warm_up()
        tables = [p.dofs for p in model.parts]
        node_tables = [np.ascontiguousarray(p.cells) for p in model.parts]
        dpn, n = model.dofs_per_node, model.n_dofs
        _check_same(model)                           # also compiles every numba loop
        case = {"cells": int(model.mesh.n_cells), "dofs": int(n)}
        for name, cls in (("old", ReferencePattern), ("new", SparsePattern)):
            with _implementation(name):
                case[f"pattern_{name}_s"] = _best(lambda: cls(tables, n, dpn), repeats)
                case[f"assembler_{name}_s"] = _best(lambda: assembly.Assembler(model), repeats)
                case[f"context_{name}_s"] = _best(lambda: Context(model), repeats)
        case["rebuild_new_s"] = _best(lambda: SparsePattern.rebuild(node_tables, model.n_points, dpn), repeats)
        case["nnz"] = int(SparsePattern(tables, n, dpn).nnz)
        for what in ("pattern", "assembler", "context"):
            case[f"{what}_ratio"] = case[f"{what}_old_s"] / case[f"{what}_new_s"]
        report["cases"][element] = case
        progress(f"{element:10s} {case['cells']:6d} cells {n:6d} dofs {case['nnz']:8d} nnz | "
                 + " | ".join(f"{w} {1e3 * case[f'{w}_old_s']:7.1f} -> {1e3 * case[f'{w}_new_s']:6.1f} ms "
                              f"(x{case[f'{w}_ratio']:.1f})" for w in ("pattern", "assembler", "context"))
                 + f" | rebuild {1e3 * case['rebuild_new_s']:.1f} ms")
    return report


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", default="bench_pattern.json", help="where to write the report ('' for nowhere)")
    ap.add_argument("--quick", action="store_true", help="tiny meshes (a smoke test)")
    args = ap.parse_args(argv)
    report = run_pattern_bench(args.repeats, args.quick)
    if args.json:
        write_json_atomic(args.json, report)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
