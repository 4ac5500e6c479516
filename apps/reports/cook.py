"""Cook's membrane (`tensormass report accuracy --benchmark cook`): how much displacement elements lock.

The tapered panel (0, 0)-(48, 44)-(48, 60)-(0, 44) (mm-free units), plane strain, clamped at
x = 0, a total vertical shear load of 1 spread evenly along the edge x = 48 (traction 1/16 per
unit length), Hooke with E = 1 and nu = 1/3 (compressible) or 0.4999 (nearly incompressible).
The measured value is the vertical displacement of the top-right corner (48, 60).

Meshes are structured n x n: the unit square's grid mapped bilinearly onto the panel (quad),
each quad cut along one diagonal (triangle), triangles with their midside nodes (triangle6,
straight-sided: the diagonal's midside node sits on the chord).
They are written to a temporary VTU and read back like a user's file.

The reference of each nu is triangle6 on REFERENCE_CELLS x REFERENCE_CELLS (the only element
here that does not lock; a mixed u-p reference, issue 15, would replace it). error_reference =
|value - reference| / |reference|. The Pareto front and the plots take the largest nu (the
locking case); the other rows are in results.csv and the table.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

import meshio
import numpy as np

from .common import benchmark_row as _row
from .common import run_dict as _run

__all__ = ["cook", "cook_mesh", "cook_scene", "COOK_CORNERS"]

COOK_CORNERS = ((0.0, 0.0), (48.0, 44.0), (48.0, 60.0), (0.0, 44.0))
COOK_E, COOK_LOAD = 1.0, 1.0
COOK_FULL = {"elements": ["quad", "triangle", "triangle6"], "nus": [1.0 / 3.0, 0.4999],
             "levels": [2, 4, 8, 16, 32], "reference": 64, "quadrature": "gauss2"}
COOK_QUICK = {"elements": ["quad", "triangle", "triangle6"], "nus": [1.0 / 3.0, 0.4999],
              "levels": [2, 4], "reference": 8, "quadrature": "gauss2"}


def _map(s, t):
    """The bilinear map of the unit square onto the panel (s along x, t from bottom to top edge)."""
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = COOK_CORNERS
    x = (1 - s) * (1 - t) * x0 + s * (1 - t) * x1 + s * t * x2 + (1 - s) * t * x3
    y = (1 - s) * (1 - t) * y0 + s * (1 - t) * y1 + s * t * y2 + (1 - s) * t * y3
    return x, y


def cook_mesh(element: str, n: int) -> meshio.Mesh:
    """The structured n x n mesh of the panel (points with z = 0: a 2D mesh)."""
    quadratic = element == "triangle6"
    m = 2 * n if quadratic else n
    s, t = np.meshgrid(np.linspace(0.0, 1.0, m + 1), np.linspace(0.0, 1.0, m + 1), indexing="ij")
    x, y = _map(s.ravel(), t.ravel())
    points = np.column_stack([x, y, np.zeros_like(x)])

    def node(i, j):
        return i * (m + 1) + j

    k = 2 if quadratic else 1
    cells = []
    for i in range(n):
        for j in range(n):
            a, b = node(k * i, k * j), node(k * (i + 1), k * j)
            c, d = node(k * (i + 1), k * (j + 1)), node(k * i, k * (j + 1))
            if element == "quad":
                cells.append([a, b, c, d])
            elif element == "triangle":
                cells += [[a, b, c], [a, c, d]]
            elif element == "triangle6":
                I, J = k * i, k * j
                ab, bc, cd, da = node(I + 1, J), node(I + 2, J + 1), node(I + 1, J + 2), node(I, J + 1)
                ac = node(I + 1, J + 1)
                # the bilinear map bends the diagonal: put its midside node back on the chord
                # (every triangle6 stays straight-sided, like the panel)
                points[ac] = 0.5 * (points[a] + points[c])
                cells += [[a, b, c, ab, bc, ac], [a, c, d, ac, cd, da]]
            else:
                raise ValueError(f"cook: no mesh for element {element!r} (quad, triangle, triangle6)")
    return meshio.Mesh(points, [(element, np.array(cells, dtype=np.int64))])


def cook_scene(mesh_file, element: str, nu: float, quadrature: str = "gauss2") -> dict:
    """The benchmark's scene around a mesh file (2D: plane strain)."""
    x_load = COOK_CORNERS[1][0]
    height = COOK_CORNERS[2][1] - COOK_CORNERS[1][1]
    return {"name": f"cook_{element}", "mesh": {"file": str(mesh_file)},
            "material": [{"region": "all", "law": "hooke", "quadrature": quadrature, "E": COOK_E, "nu": nu,
                          "density": 1.0}],
            "fixed": [{"box": [[-1e-9, -1.0], [1e-9, 100.0]]}],
            "loads": {"traction": [{"box": [[x_load - 1e-9, -1.0], [x_load + 1e-9, 100.0]],
                                    "value": [0.0, COOK_LOAD / height]}]},
            "solver": {"kind": "static", "steps": 1},
            "probe": [{"name": "corner", "point": list(COOK_CORNERS[2])}]}


def _cfg(quick, sweep):
    cfg = dict(COOK_QUICK if quick else COOK_FULL)
    cfg.update(sweep or {})
    return cfg


def _deflection(folder: Path, element: str, n: int, nu: float, quadrature: str, trace: bool = True):
    path = folder / f"cook_{element}_{n}.vtu"
    if not path.exists():
        meshio.write(path, cook_mesh(element, n))
    s, peak, _ = _run(cook_scene(path, element, nu, quadrature), trace=trace)
    return s, peak, float(s.probes["corner"][1])


def cook(quick, progress, sweep=None) -> dict:
    cfg = _cfg(quick, sweep)
    quad, ref_n = cfg["quadrature"], cfg["reference"]
    progress(f"cook: Cook's membrane, plane strain, Hooke E = {COOK_E:g}, unit shear load; "
             f"{', '.join(cfg['elements'])} x {cfg['levels']} per side, nu = {', '.join(f'{v:g}' for v in cfg['nus'])}")
    rows, compile_s, refs = [], {}, {}
    with tempfile.TemporaryDirectory(prefix="tensormass-cook-") as tmp:
        folder = Path(tmp)
        for e in cfg["elements"]:
            t0 = time.perf_counter()
            _deflection(folder, e, 1, 0.3, quad, trace=False)
            compile_s[(e, "hooke", quad)] = time.perf_counter() - t0
        for nu in cfg["nus"]:
            case = f"nu={nu:.4g}"
            refs[case] = _deflection(folder, "triangle6", ref_n, nu, quad, trace=False)[2]
            for e in cfg["elements"]:
                for n in cfg["levels"]:
                    s, peak, w = _deflection(folder, e, n, nu, quad)
                    r = _row("cook", e, "hooke", quad, (n, n), case, s, peak, w)
                    r["error_reference"] = abs(w - refs[case]) / abs(refs[case])
                    r["main"] = nu == max(cfg["nus"])   # the front and plots: the nearly incompressible case
                    rows.append(r)
                    progress(f"  {case:<10} {e:<10} {n:>3} x {n:<3} corner u_y {w:.5g} "
                             f"({(w - refs[case]) / refs[case]:+.1%} vs reference)  total {s.time['total']:.3f} s")
    notes = ["### Corner deflection against the triangle6 reference (signed error)", "",
             "| nu | element | " + " | ".join(f"{n}x{n}" for n in cfg["levels"]) + " |",
             "|---|---|" + "---:|" * len(cfg["levels"])]
    for nu in cfg["nus"]:
        case = f"nu={nu:.4g}"
        for e in cfg["elements"]:
            cells = [r for r in rows if r["case"] == case and r["element"] == e]
            notes.append(f"| {nu:.4g} | {e} | " + " | ".join(f"{(r['value'] - refs[case]) / refs[case]:+.1%}"
                                                           for r in cells) + " |")
    notes += ["", "Displacement elements lock as nu -> 1/2: linear quads and triangles stiffen far below the "
              "reference at nu = 0.4999 however fine the mesh, triangle6 converges. Locking-free formulations "
              "(issue 15) are measured against this table.", ""]
    reference = {
        "subject": "Cook's membrane: panel (0,0)-(48,44)-(48,60)-(0,44), plane strain, Hooke E = 1, clamped at "
                   "x = 0, total shear load 1 on x = 48; value = u_y at (48, 60)",
        "numerical": "triangle6 / hooke / " + quad + f" on {ref_n} x {ref_n} (x2 triangles): "
                     + ", ".join(f"{k}: {v:.6g}" for k, v in refs.items()),
        "analytic": "none (no closed form); error_analytic is n/a",
    }
    return {"rows": rows, "reference": reference, "compile_s": compile_s, "notes": notes,
            "references": refs}

