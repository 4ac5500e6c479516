"""The fetal head of the thesis' birth scene (ch. 8, B24) as a two-zone shell, made with gmsh.

    python -m tensormass.apps.fetal_head examples/birth/fetal_head.msh [--size 0.0033]
    python -m tensormass.apps.fetal_head report [--json FILE]     # diameters over three mesh sizes
    from tensormass.apps.fetal_head import make, diameters, run_head, report

There is no BirthSIM head mesh, so the head is an ellipsoid with Table 8.2's diameters (Bailet): 124.6 mm
along z (the descent axis: MaVD, vertex at z < 0 leading, neck at z > 0), 110.9 mm along x (OrVD,
occiput at x < 0, face at x > 0) and 107.4 mm along y (SOBD, across). At h = 3.3 mm it has about the
BirthSIM mesh's 8 928 triangles. Its triangles carry one physical group each (gmsh 2.2 ascii):

    suture   1   the sutures (bands 4 mm wide: the sagittal one on the leading half, the coronal and
                 lambdoid ones down the sides through the cervix's bands) and the anterior and
                 posterior fontanelles (discs of 12 and 6 mm radius)
    band45   2   bone in the cervix's top band, 10 mm below the SOB plane z = 0 (45 kPa)
    band40   3   the band below it (40 kPa)
    band30   4   the lowest band (30 kPa)
    skull    5   the rest of the bone (7 kPa, amniotic)
    neck     6   the neck base: bone within 12 mm of the top (clamped)

Zones are chosen per triangle by its centroid, so their edges follow the mesh. Deterministic: fixed
geometry and sizes, one thread.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .mesh_tools import surface_of_model

SEMI_AXES = (0.05545, 0.0537, 0.0623)      # x: OrVD / 2, y: SOBD / 2, z: MaVD / 2 (m)
SIZE = 0.0033                              # mesh size (m): about 9 000 triangles
ZONES = {"suture": 1, "band45": 2, "band40": 3, "band30": 4, "skull": 5, "neck": 6}
BANDS = ((-0.010, 0.0, "band45"), (-0.020, -0.010, "band40"), (-0.030, -0.020, "band30"))
SUTURE_HALF_WIDTH = 0.002
NECK = 0.012


def _ellipsoid(size: float) -> tuple[np.ndarray, np.ndarray]:
    import gmsh
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("fetal_head")
        ball = gmsh.model.occ.addSphere(0, 0, 0, 1.0)
        gmsh.model.occ.dilate([(3, ball)], 0, 0, 0, *SEMI_AXES)
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.mesh.generate(2)
        return surface_of_model(gmsh)
    finally:
        gmsh.finalize()


def zones(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The ZONES id of each triangle, from its centroid."""
    a, b, c = SEMI_AXES
    x, y, z = points[triangles].mean(axis=1).T
    out = np.full(len(triangles), ZONES["skull"])
    for lo, hi, name in BANDS:
        out[(z >= lo) & (z < hi)] = ZONES[name]
    out[z > c - NECK] = ZONES["neck"]
    # the sagittal suture and the fontanelles on the leading vertex; the coronal and lambdoid sutures
    # run down the sides through the cervix's bands (the bone plates move against each other there)
    lead, sides = z < -0.35 * c, z < 0.25 * c
    bregma, lambda_ = (0.35 * a, 0.0), (-0.55 * a, 0.0)     # the fontanelles' centres (x, y)
    suture = lead & (np.abs(y) < SUTURE_HALF_WIDTH) & (x > lambda_[0]) & (x < bregma[0])          # sagittal
    suture |= sides & (np.abs(x - bregma[0]) < SUTURE_HALF_WIDTH)                                     # coronal
    suture |= sides & (np.abs(x - lambda_[0] + 0.6 * np.abs(y)) < SUTURE_HALF_WIDTH)                  # lambdoid
    suture |= lead & (np.hypot(x - bregma[0], y) < 0.012)                                            # anterior fontanelle
    suture |= lead & (np.hypot(x - lambda_[0], y) < 0.006)                                           # posterior fontanelle
    out[suture] = ZONES["suture"]
    return out


def make(path, size: float = SIZE) -> Path:
    """Write the head (MSH 2.2 ascii, one physical group per triangle) and return its path."""
    import meshio
    size = float(size)
    if not 0 < size < 0.02:
        raise ValueError(f"fetal_head: the mesh size must be in (0, 0.02) m, got {size}")
    points, triangles = _ellipsoid(size)
    tags = zones(points, triangles)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh = meshio.Mesh(points, [("triangle", triangles)],
                       cell_data={"gmsh:physical": [tags], "gmsh:geometrical": [tags]},
                       field_data={name: np.array([i, 2]) for name, i in ZONES.items()})
    tmp = path.with_name(f".{path.name}.tmp")
    meshio.write(str(tmp), mesh, file_format="gmsh22", binary=False)
    tmp.replace(path)
    return path


# The three diameters of Table 8.2, on the stand-in: node pairs at the ends of its axes.
DIAMETERS = {"MaVD": 2, "OrVD": 0, "SOBD": 1}


def landmarks(points: np.ndarray) -> dict:
    """{diameter: (node a, node b)}: the nodes nearest the two ends of its axis."""
    out = {}
    for name, axis in DIAMETERS.items():
        end = np.zeros(3)
        end[axis] = SEMI_AXES[axis]
        out[name] = (int(np.argmin(np.linalg.norm(points - end, axis=1))),
                     int(np.argmin(np.linalg.norm(points + end, axis=1))))
    return out


def diameters(points: np.ndarray, pairs: dict) -> dict:
    """{diameter: length (m)} between each pair of landmark nodes."""
    return {name: float(np.linalg.norm(points[a] - points[b])) for name, (a, b) in pairs.items()}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("path", help="where to write the mesh, or `report` for the diameters over three mesh sizes")
    p.add_argument("--size", type=float, default=SIZE)
    p.add_argument("--json", help="report: also write the rows as JSON")
    p.add_argument("--scene", default=str(SCENE), help="report: the head's scene (default: the checkout's example)")
    args = p.parse_args(argv)
    if args.path == "report":
        report(json_path=args.json, scene=args.scene)
        return 0
    path = make(args.path, args.size)
    print(f"wrote {path}")
    return 0



# -- the report: diameters before and after, the volume kept, over mesh sizes --------------------
SCENE = Path(__file__).resolve().parents[1] / "examples" / "birth" / "fetal_head.toml"
TABLE_8_2 = {"MaVD": (124.6, 1.29), "OrVD": (110.9, 1.13), "SOBD": (107.4, -3.57)}     # Bailet 2013 (mm)


def enclosed_volume(points: np.ndarray, triangles: np.ndarray) -> float:
    """The volume a closed, consistently wound surface encloses (divergence theorem)."""
    a, b, c = (points[triangles[:, k]] for k in range(3))
    return abs(float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0)


def run_head(mesh_file, steps: int | None = None, scene=SCENE) -> dict:
    """The example scene (a checkout's examples/birth/fetal_head.toml, or scene) on a head mesh: the
    diameters and the enclosed volume before and after."""
    from ..runtime.base.errors import TensormassError
    from ..runtime.run.simulation import Simulation
    from ..runtime.scene.scene import Scene
    if not Path(scene).is_file():
        raise TensormassError(f"the fetal head's scene {scene} is not there: run from a checkout, or give the "
                              "scene file (examples/birth/fetal_head.toml)")
    text = Path(scene).read_text(encoding="utf-8").replace('file = "fetal_head.msh"', f'file = "{Path(mesh_file).as_posix()}"')
    if steps is not None:
        text = text.replace("steps = 40", f"steps = {steps}")
    text = text.replace('[output]\ndir = "out/fetal_head"\n', "")
    sim = Simulation(Scene.from_string(text), output=False)
    summary = sim.run()
    P = sim.model.mesh.points
    T = np.vstack([b.cells for b in sim.model.mesh.blocks])
    moved = P + sim.displacement
    pairs = landmarks(P)
    before, after = diameters(P, pairs), diameters(moved, pairs)
    v0, v1 = enclosed_volume(P, T), enclosed_volume(moved, T)
    return {"status": summary.status, "triangles": int(len(T)), "steps": summary.steps_done,
            "diameters_mm": {k: [1e3 * before[k], 1e3 * after[k]] for k in before},
            "change_mm": {k: 1e3 * (after[k] - before[k]) for k in before},
            "volume_change": (v1 - v0) / v0, "seconds": summary.time["total"]}


def report(sizes=(0.0047, SIZE, 0.0023), json_path=None, progress=print, scene=SCENE) -> list:
    """The head at each mesh size (made with gmsh): Table 8.2's diameters and their changes."""
    import tempfile
    rows = []
    with tempfile.TemporaryDirectory(prefix="tensormass-head-") as folder:
        for size in sizes:
            path = make(Path(folder) / f"head_{1e3 * size:g}mm.msh", size)
            row = {"size_mm": 1e3 * size, **run_head(path, scene=scene)}
            rows.append(row)
            changes = ", ".join(f"{k} {row['diameters_mm'][k][0]:.2f} -> {row['diameters_mm'][k][1]:.2f} mm "
                                f"({row['change_mm'][k]:+.3f}; thesis {TABLE_8_2[k][1]:+.2f})" for k in DIAMETERS)
            progress(f"h = {row['size_mm']:.1f} mm, {row['triangles']} triangles, {row['status']}: {changes}; "
                     f"volume change {row['volume_change']:+.1e}; {row['seconds']:.0f} s")
    if json_path:
        from ..runtime.base.files import write_json_atomic
        write_json_atomic(json_path, rows)
    return rows


if __name__ == "__main__":
    raise SystemExit(main())
