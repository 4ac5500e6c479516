"""Cook's membrane (`tensormass report accuracy --benchmark cook`): how much displacement elements lock.

The tapered panel (0, 0)-(48, 44)-(48, 60)-(0, 44) (mm-free units), plane strain, clamped at
x = 0, a total vertical shear load of 1 spread evenly along the edge x = 48 (traction 1/16 per
unit length), Hooke with E = 1 and nu = 1/3 (compressible) or 0.4999 (nearly incompressible).
The measured value is the vertical displacement of the top-right corner (48, 60).

Meshes are structured n x n: the unit square's grid mapped bilinearly onto the panel (quad),
each quad cut along one diagonal (triangle; `diagonals="alternating"` cuts them along a->c and
b->d in a checkerboard), triangles with their midside nodes (triangle6, straight-sided: the
diagonal's midside node sits on the chord). They are written to a temporary VTU and read back like
a user's file.

Every element runs with the displacement formulation and its locking-free ones (quad:
mean_dilatation, Q1-P0; triangle: nodal_pressure and edge_smoothed, the edge-smoothed strains of
ES-FEM with nodal pressure; triangle6: mean_dilatation, P2-P0); the
triangles also on the alternating-diagonal mesh (case "... alternating"): on the one-diagonal mesh
linear triangles bend stiffly on their own, which is not locking.

The reference of each nu is a converged mixed element: triangle6 + mean_dilatation (P2-P0, stable
and locking-free) on REFERENCE_CELLS x REFERENCE_CELLS; the report gives its change from half that
resolution and a Richardson estimate. error_reference = |value - reference| / |reference|. The
Pareto front and the plots take the largest nu (the locking case); the other rows are in
results.csv and the table.
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
             "levels": [2, 4, 8, 16, 32], "reference": 64, "quadrature": "gauss2", "alternating": True}
COOK_QUICK = {"elements": ["quad", "triangle", "triangle6"], "nus": [1.0 / 3.0, 0.4999],
              "levels": [2, 4], "reference": 8, "quadrature": "gauss2", "alternating": True}
# each element's formulations: the displacement one and its locking-free one (runtime.physics.formulations)
COOK_FORMULATIONS = {"quad": ("displacement", "mean_dilatation"),
                     "triangle": ("displacement", "nodal_pressure", "edge_smoothed"),
                     "triangle6": ("displacement", "mean_dilatation")}
REFERENCE = ("triangle6", "mean_dilatation")


def _map(s, t):
    """The bilinear map of the unit square onto the panel (s along x, t from bottom to top edge)."""
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = COOK_CORNERS
    x = (1 - s) * (1 - t) * x0 + s * (1 - t) * x1 + s * t * x2 + (1 - s) * t * x3
    y = (1 - s) * (1 - t) * y0 + s * (1 - t) * y1 + s * t * y2 + (1 - s) * t * y3
    return x, y


def cook_mesh(element: str, n: int, diagonals: str = "same") -> meshio.Mesh:
    """The structured n x n mesh of the panel (points with z = 0: a 2D mesh); linear triangles cut
    every quad along a->c (diagonals="same") or a->c and b->d in a checkerboard ("alternating")."""
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
                flip = diagonals == "alternating" and (i + j) % 2 == 1
                cells += [[a, b, d], [b, c, d]] if flip else [[a, b, c], [a, c, d]]
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


def cook_scene(mesh_file, element: str, nu: float, quadrature: str = "gauss2",
               formulation: str = "displacement") -> dict:
    """The benchmark's scene around a mesh file (2D: plane strain)."""
    x_load = COOK_CORNERS[1][0]
    height = COOK_CORNERS[2][1] - COOK_CORNERS[1][1]
    return {"name": f"cook_{element}", "mesh": {"file": str(mesh_file)},
            "material": [{"region": "all", "law": "hooke", "quadrature": quadrature, "E": COOK_E, "nu": nu,
                          "density": 1.0, "formulation": formulation}],
            "fixed": [{"box": [[-1e-9, -1.0], [1e-9, 100.0]]}],
            "loads": {"traction": [{"box": [[x_load - 1e-9, -1.0], [x_load + 1e-9, 100.0]],
                                    "value": [0.0, COOK_LOAD / height]}]},
            "solver": {"kind": "static", "steps": 1},
            "probe": [{"name": "corner", "point": list(COOK_CORNERS[2])}]}


def _cfg(quick, sweep):
    cfg = dict(COOK_QUICK if quick else COOK_FULL)
    cfg.update(sweep or {})
    return cfg


def _deflection(folder: Path, element: str, n: int, nu: float, quadrature: str, trace: bool = True,
                formulation: str = "displacement", diagonals: str = "same"):
    path = folder / f"cook_{element}_{diagonals}_{n}.vtu"
    if not path.exists():
        meshio.write(path, cook_mesh(element, n, diagonals))
    s, peak, _ = _run(cook_scene(path, element, nu, quadrature, formulation), trace=trace)
    return s, peak, float(s.probes["corner"][1])


def _reference(folder, nu, ref_n, quad) -> dict:
    """The converged P2-P0 value, its value at half the resolution and a Richardson estimate
    (order from the last three levels)."""
    values = [_deflection(folder, *REFERENCE[:1], m, nu, quad, False, REFERENCE[1])[2]
              for m in (ref_n // 4, ref_n // 2, ref_n)]
    d1, d2 = values[1] - values[0], values[2] - values[1]
    richardson = values[2] + d2 * d2 / (d1 - d2) if d1 != d2 and d1 * d2 > 0 and abs(d2) < abs(d1) else None
    return {"value": values[2], "half": values[1], "quarter": values[0], "richardson": richardson}


def _runs(cfg):
    """(element, formulation, diagonals) of every series of the sweep."""
    out = [(e, f, "same") for e in cfg["elements"] for f in COOK_FORMULATIONS[e]]
    if cfg.get("alternating") and "triangle" in cfg["elements"]:
        out += [("triangle", f, "alternating") for f in COOK_FORMULATIONS["triangle"]]
    return out


def cook(quick, progress, sweep=None) -> dict:
    cfg = _cfg(quick, sweep)
    quad, ref_n = cfg["quadrature"], cfg["reference"]
    runs = _runs(cfg)
    progress(f"cook: Cook's membrane, plane strain, Hooke E = {COOK_E:g}, unit shear load; "
             f"{', '.join(cfg['elements'])} x formulations x {cfg['levels']} per side, "
             f"nu = {', '.join(f'{v:g}' for v in cfg['nus'])}")
    rows, compile_s, refs, checks = [], {}, {}, {}
    with tempfile.TemporaryDirectory(prefix="tensormass-cook-") as tmp:
        folder = Path(tmp)
        for e, form, _ in runs:
            if (e, "hooke", quad) not in compile_s or form != "displacement":
                t0 = time.perf_counter()
                _deflection(folder, e, 1, 0.3, quad, False, form)
                compile_s.setdefault((e, "hooke", quad), 0.0)
                compile_s[(e, "hooke", quad)] += time.perf_counter() - t0
        for nu in cfg["nus"]:
            case = f"nu={nu:.4g}"
            checks[case] = _reference(folder, nu, ref_n, quad)
            refs[case] = checks[case]["value"]
            for e, form, diagonals in runs:
                label = case + (" alternating" if diagonals == "alternating" else "")
                for n in cfg["levels"]:
                    s, peak, w = _deflection(folder, e, n, nu, quad, True, form, diagonals)
                    r = _row("cook", e, "hooke", quad, (n, n), label, s, peak, w)
                    r["formulation"] = form
                    r["error_reference"] = abs(w - refs[case]) / abs(refs[case])
                    r["main"] = nu == max(cfg["nus"]) and diagonals == "same"   # the front: the locking case
                    rows.append(r)
                    progress(f"  {label:<22} {e:<10} {form:<16} {n:>3} x {n:<3} corner u_y {w:.5g} "
                             f"({(w - refs[case]) / refs[case]:+.1%} vs reference)  total {s.time['total']:.3f} s")
    notes = ["### Corner deflection against the converged P2-P0 reference (signed error)", "",
             "| nu | mesh | element | formulation | " + " | ".join(f"{n}x{n}" for n in cfg["levels"]) + " |",
             "|---|---|---|---|" + "---:|" * len(cfg["levels"])]
    for nu in cfg["nus"]:
        case = f"nu={nu:.4g}"
        for e, form, diagonals in runs:
            label = case + (" alternating" if diagonals == "alternating" else "")
            cells = [r for r in rows if r["case"] == label and r["element"] == e and r["formulation"] == form]
            mesh = "alternating diagonals" if diagonals == "alternating" else "structured"
            notes.append(f"| {nu:.4g} | {mesh} | {e} | {form} | " + " | ".join(
                f"{(r['value'] - refs[case]) / refs[case]:+.1%}" for r in cells) + " |")
    notes += ["", "### The reference", "", "| nu | P2-P0 at " + f"{ref_n // 4}x{ref_n // 4} | {ref_n // 2}x{ref_n // 2} | "
              f"{ref_n}x{ref_n} (reference) | Richardson |", "|---|---:|---:|---:|---:|"]
    for case, c in checks.items():
        rich = "n/a" if c["richardson"] is None else f"{c['richardson']:.5g}"
        notes.append(f"| {case.split('=')[1]} | {c['quarter']:.5g} | {c['half']:.5g} | {c['value']:.5g} | {rich} |")
    notes += ["", "Displacement elements lock as nu -> 1/2: linear quads and triangles stiffen far below the "
              "reference at nu = 0.4999 however fine the mesh. Mean dilatation (quad, triangle6), nodal "
              "pressure and edge smoothing (triangle) do not. On the one-diagonal mesh linear triangles are stiff "
              "in bending even at nu = 1/3 (the displacement row at nu = 1/3): that error stays with nodal "
              "pressure; edge-smoothed strains remove most of it; on the alternating-diagonal mesh it is "
              "smaller.", ""]
    reference = {
        "subject": "Cook's membrane: panel (0,0)-(48,44)-(48,60)-(0,44), plane strain, Hooke E = 1, clamped at "
                   "x = 0, total shear load 1 on x = 48; value = u_y at (48, 60)",
        "numerical": f"triangle6 + mean_dilatation (P2-P0) / hooke / {quad} on {ref_n} x {ref_n} (x2 triangles): "
                     + ", ".join(f"{k}: {v:.6g} (half resolution {checks[k]['half']:.6g})" for k, v in refs.items()),
        "analytic": "none (no closed form); error_analytic is n/a",
    }
    return {"rows": rows, "reference": reference, "compile_s": compile_s, "notes": notes,
            "references": refs, "reference_checks": checks}
