"""A thick-walled cylinder under internal pressure (`tensormass report accuracy --benchmark cylinder`):
do the locking-free formulations work on prism (wedge) and hexahedral layers?

A quarter of the ring a = 1 <= r <= b = 2 (symmetry: u_x = 0 on x = 0, u_y = 0 on y = 0), LAYERS
layers of cells along z with u_z = 0 on both ends (plane strain), Hooke E = 1000, a follower
pressure p = 0.1 on the inner surface (small: u/a ~ 1e-4, so the follower load is linear to 1e-4).
The value is the radial displacement of the inner surface, the mean of u_x at (a, 0, H/2) and u_y at
(0, a, H/2), against Lame's plane-strain solution

    u_r(r) = p a^2 (1 + nu) / (E (b^2 - a^2)) ((1 - 2 nu) r + b^2 / r).

Meshes: structured polar grids, n_r x n_theta cells in the quarter (hexahedra; wedges: each cell cut
along one diagonal into two prisms), written to a temporary VTU (the inner surface a tagged quad
group); and, when the gmsh module is installed, gmsh's unstructured triangles of the quarter
annulus extruded into wedges (the issue's case; rows "gmsh wedge"). Every element runs with each
formulation runtime.physics.formulations allows it, at nu = 0.3 and 0.499.
"""
from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import meshio
import numpy as np

from .common import benchmark_row as _row
from .common import run_dict as _run

__all__ = ["cylinder", "polar_mesh", "cylinder_scene", "lame_radial", "CYLINDER"]

CYLINDER = {"a": 1.0, "b": 2.0, "E": 1000.0, "p": 0.1, "layers": 2}
CYLINDER_FULL = {"meshes": ["wedge", "hexahedron", "gmsh wedge"], "nus": [0.3, 0.499],
                 "levels": [[4, 8], [8, 16], [16, 32]], "quadrature": "gauss2"}
CYLINDER_QUICK = {"meshes": ["wedge", "hexahedron"], "nus": [0.3, 0.499], "levels": [[2, 4], [4, 8]],
                  "quadrature": "gauss2"}
FORMULATIONS = {"wedge": ("displacement", "mean_dilatation", "nodal_pressure"),
                "hexahedron": ("displacement", "mean_dilatation")}
INNER_TAG, BODY_TAG = 2, 1


def lame_radial(r: float, nu: float, a=CYLINDER["a"], b=CYLINDER["b"], E=CYLINDER["E"], p=CYLINDER["p"]) -> float:
    """Lame's radial displacement of the plane-strain thick cylinder under internal pressure p."""
    return p * a * a * (1.0 + nu) / (E * (b * b - a * a)) * ((1.0 - 2.0 * nu) * r + b * b / r)


def polar_mesh(element: str, n_r: int, n_theta: int, layers: int = CYLINDER["layers"], height: float | None = None,
               a: float = CYLINDER["a"], b: float = CYLINDER["b"], diagonals: str = "same") -> meshio.Mesh:
    """The structured quarter ring: n_r x n_theta cells in the plane, `layers` layers of total
    height `height` (default: one radial cell size per layer); hexahedra, or wedges (each cell cut
    along a->c, or alternately a->c and b->d with diagonals="alternating"). The inner surface's
    quads are a boundary group tagged INNER_TAG (cell data "cell_tags")."""
    if element not in ("wedge", "hexahedron"):
        raise ValueError(f"polar_mesh: element {element!r} (wedge or hexahedron)")
    height = layers * (b - a) / n_r if height is None else height
    r, t = np.linspace(a, b, n_r + 1), np.linspace(0.0, 0.5 * np.pi, n_theta + 1)
    R, T = np.meshgrid(r, t, indexing="ij")
    plane = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel()])
    m = len(plane)
    z = np.linspace(0.0, height, layers + 1)
    points = np.vstack([np.column_stack([plane, np.full(m, zk)]) for zk in z])

    def node(i, j):
        return i * (n_theta + 1) + j

    cells, inner = [], []
    for k in range(layers):
        lo, hi = k * m, (k + 1) * m
        for i in range(n_r):
            for j in range(n_theta):
                q = [node(i, j), node(i + 1, j), node(i + 1, j + 1), node(i, j + 1)]   # counter-clockwise
                if element == "hexahedron":
                    cells.append([v + lo for v in q] + [v + hi for v in q])
                else:
                    a_, b_, c_, d_ = q
                    flip = diagonals == "alternating" and (i + j) % 2 == 1
                    for tri in ([[a_, b_, d_], [b_, c_, d_]] if flip else [[a_, b_, c_], [a_, c_, d_]]):
                        tri = [tri[0], tri[2], tri[1]]          # VTK's wedge: clockwise seen from the top
                        cells.append([v + lo for v in tri] + [v + hi for v in tri])
        for j in range(n_theta):
            inner.append([node(0, j) + lo, node(0, j + 1) + lo, node(0, j + 1) + hi, node(0, j) + hi])
    cells = np.array(cells, dtype=np.int64)
    inner = np.array(inner, dtype=np.int64)
    return meshio.Mesh(points, [(element, cells), ("quad", inner)],
                       cell_data={"cell_tags": [np.full(len(cells), BODY_TAG), np.full(len(inner), INNER_TAG)]})


def gmsh_wedge_mesh(path: Path, size: float, layers: int = CYLINDER["layers"], a: float = CYLINDER["a"],
                    b: float = CYLINDER["b"]) -> float:
    """gmsh's triangles of the quarter annulus (element size `size`) extruded into `layers` layers of
    wedges, height one element size per layer, written to `path` (.msh) with the physical groups
    "body" (volume) and "inner" (the inner surface); returns the height. Needs the gmsh module."""
    import gmsh
    height = layers * size
    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        gmsh.model.add("cylinder")
        occ = gmsh.model.occ
        ring = occ.cut([(2, occ.addDisk(0, 0, 0, b, b))], [(2, occ.addDisk(0, 0, 0, a, a))])[0]
        quarter = occ.intersect(ring, [(2, occ.addRectangle(0, 0, 0, b, b))])[0]
        occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        out = occ.extrude(quarter, 0, 0, height, numElements=[layers], recombine=True)
        occ.synchronize()
        volume = [t for d, t in out if d == 3]
        inner = [t for d, t in gmsh.model.getEntities(2)
                 if abs(math.hypot(*gmsh.model.occ.getCenterOfMass(2, t)[:2]) - a * 2 * math.sqrt(2) / math.pi) < 1e-3 * a]
        gmsh.model.addPhysicalGroup(3, volume, name="body")
        gmsh.model.addPhysicalGroup(2, inner, name="inner")
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return height


def cylinder_scene(mesh_file, nu: float, formulation: str, height: float, quadrature: str = "gauss2",
                   inner=INNER_TAG) -> dict:
    """The benchmark's scene around a mesh file of the quarter ring of that height."""
    a, b, eps = CYLINDER["a"], CYLINDER["b"], 1e-6
    far = 2 * b + height

    def plane(axis, value):
        lo, hi = [-far] * 3, [far] * 3
        lo[axis], hi[axis] = value - eps, value + eps
        return {"box": [lo, hi], "displacement": [0.0, 0.0, 0.0], "components": [axis]}

    return {"name": "cylinder", "mesh": {"file": str(mesh_file)},
            "material": [{"region": "all", "law": "hooke", "quadrature": quadrature, "E": CYLINDER["E"], "nu": nu,
                          "density": 1.0, "formulation": formulation}],
            "fixed": [plane(0, 0.0), plane(1, 0.0), plane(2, 0.0), plane(2, height)],
            "loads": {"pressure": [{"region": inner, "value": CYLINDER["p"]}]},
            "solver": {"kind": "static", "steps": 1},
            "output": {"fields": []},
            "probe": [{"name": "x", "point": [a, 0.0, 0.5 * height]}, {"name": "y", "point": [0.0, a, 0.5 * height]}]}


def _cfg(quick, sweep):
    cfg = dict(CYLINDER_QUICK if quick else CYLINDER_FULL)
    cfg.update(sweep or {})
    return cfg


def _mesh_file(folder: Path, family: str, n_r: int, n_theta: int):
    """(path, height, inner region, cells label) of one mesh of a family, written once."""
    if family == "gmsh wedge":
        path = folder / f"cylinder_gmsh_{n_r}.msh"
        height = gmsh_wedge_mesh(path, (CYLINDER["b"] - CYLINDER["a"]) / n_r)
        return path, height, "inner"
    path = folder / f"cylinder_{family}_{n_r}x{n_theta}.vtu"
    m = polar_mesh(family, n_r, n_theta)
    meshio.write(path, m)
    return path, float(m.points[:, 2].max()), INNER_TAG


def radial(summary) -> float:
    """The inner surface's radial displacement: mean of u_x at (a, 0) and u_y at (0, a)."""
    return 0.5 * (float(summary.probes["x"][0]) + float(summary.probes["y"][1]))


def _have_gmsh() -> bool:
    try:
        import gmsh  # noqa: F401
    except ImportError:
        return False
    return True


def cylinder(quick, progress, sweep=None) -> dict:
    cfg = _cfg(quick, sweep)
    quad = cfg["quadrature"]
    families = list(cfg["meshes"])
    notes_extra = []
    if "gmsh wedge" in families and not _have_gmsh():
        families.remove("gmsh wedge")
        notes_extra.append("The gmsh module is not installed: the gmsh wedge rows (unstructured triangles extruded "
                           "into prisms) were skipped; the structured rows do not need it.")
        progress("cylinder: gmsh is not installed: skipping the gmsh wedge meshes")
    progress(f"cylinder: thick cylinder a = {CYLINDER['a']:g}, b = {CYLINDER['b']:g}, internal pressure "
             f"{CYLINDER['p']:g}, Hooke E = {CYLINDER['E']:g}, plane strain, {CYLINDER['layers']} layers; "
             f"{', '.join(families)} x formulations x {cfg['levels']} (n_r x n_theta), "
             f"nu = {', '.join(f'{v:g}' for v in cfg['nus'])}; against Lame")
    rows, compile_s, table = [], {}, {}
    with tempfile.TemporaryDirectory(prefix="tensormass-cylinder-") as tmp:
        folder = Path(tmp)
        files = {(fam, tuple(lv)): _mesh_file(folder, fam, *lv) for fam in families for lv in cfg["levels"]}
        for fam in families:                       # warm-up: the kernels each formulation loads
            element = fam.split()[-1]
            path, height, inner = files[fam, tuple(cfg["levels"][0])]
            for form in FORMULATIONS[element]:
                t0 = time.perf_counter()
                _run(cylinder_scene(path, 0.3, form, height, quad, inner), trace=False)
                key = (element, "hooke", quad)
                compile_s[key] = compile_s.get(key, 0.0) + time.perf_counter() - t0
        for nu in cfg["nus"]:
            exact = lame_radial(CYLINDER["a"], nu)
            for fam in families:
                element = fam.split()[-1]
                case = f"nu={nu:g}" + (" gmsh" if fam.startswith("gmsh") else "")
                for form in FORMULATIONS[element]:
                    for lv in cfg["levels"]:
                        path, height, inner = files[fam, tuple(lv)]
                        s, peak, _ = _run(cylinder_scene(path, nu, form, height, quad, inner))
                        if s.status != "ok":
                            raise RuntimeError(f"cylinder: {fam} {form} nu = {nu:g} {lv}: run {s.status}: {s.message}")
                        w = radial(s)
                        cells = (*lv, CYLINDER["layers"])
                        r = _row("cylinder", element, "hooke", quad, cells, case, s, peak, w)
                        r["formulation"] = form
                        r["error_analytic"] = r["error_reference"] = abs(w - exact) / abs(exact)
                        r["main"] = nu == max(cfg["nus"]) and not fam.startswith("gmsh")
                        rows.append(r)
                        table.setdefault((nu, fam, form), []).append((w - exact) / exact)
                        progress(f"  {case:<14} {fam:<11} {form:<16} {lv[0]:>3} x {lv[1]:<3} u_r(a) {w:.6g} "
                                 f"({(w - exact) / exact:+.2%} vs Lame)  total {s.time['total']:.3f} s")
    heads = " | ".join(f"{a}x{b}" for a, b in cfg["levels"])
    notes = ["### Inner radial displacement against Lame (signed error)", "",
             "Levels are n_r x n_theta cells of the quarter ring (wedges: two prisms per cell); gmsh rows: "
             "element size (b - a) / n_r.", "",
             f"| nu | mesh | formulation | {heads} |", "|---|---|---|" + "---:|" * len(cfg["levels"])]
    for (nu, fam, form), errs in table.items():
        notes.append(f"| {nu:g} | {fam} | {form} | " + " | ".join(f"{e:+.2%}" for e in errs) + " |")
    notes += ["", "Linear prisms loaded in the plane of their layers have one dilatation per cell (their "
              "triangle's), so mean dilatation gives the displacement answer on wedges and locks like P1/P0 "
              "triangles at nu -> 1/2; nodal pressure (the volumetric energy at node-averaged volumes) cures "
              "it. Hexahedra with mean dilatation (Q1-P0) do not lock. At nu = 0.3 every formulation converges "
              "to Lame (the remaining error is the faceted boundary and the coarse grid).", ""] + notes_extra
    reference = {
        "subject": f"thick-walled cylinder a = {CYLINDER['a']:g}, b = {CYLINDER['b']:g} (a quarter, symmetry planes), "
                   f"internal follower pressure {CYLINDER['p']:g}, Hooke E = {CYLINDER['E']:g}, plane strain (u_z = 0 "
                   "on both ends); value = radial displacement of the inner surface",
        "numerical": "none: error_reference is the error against Lame's solution (as error_analytic)",
        "analytic": "Lame, plane strain: u_r(a) = p a^2 (1 + nu) / (E (b^2 - a^2)) ((1 - 2 nu) a + b^2 / a)",
    }
    return {"rows": rows, "reference": reference, "compile_s": compile_s, "notes": notes}
