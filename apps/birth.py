"""The reduced birth scene (thesis ch. 8): the fetal-head shell pushed through a soft pelvic floor.

    python -m tensormass.apps.birth examples/birth/birth.msh [--head-size 0.007] [--floor-size 0.009]
    python -m tensormass.apps.birth report [--json FILE] [--steps N]
    from tensormass.apps.birth import make, run_birth, report

One mesh holds both bodies (runtime.mesh.shells_and_solids): the head of apps.fetal_head, a CST-DKT
shell in its zones, and below it the pelvic floor, a tetrahedral ring of soft neo-Hookean tissue
(Table 8.4's abdomen and pelvic floor: C10 = 5 kPa) held at its outer rim.  The scene's periodic
push on the head's neck (the fundus' push through the fetal body) drives its vertex into the ring's
opening, narrower than the head, and the frictionless IPC contact between the shell and the ring
(runtime.contact) stretches the ring around it.  The file's groups (gmsh 2.2 ascii):

    suture band45 band40 band30 skull neck   1-6   the head's shell zones (apps.fetal_head)
    floor                                    1     the ring's tetrahedra (volume group)
    rim                                      7     the ring's outer face (boundary group: clamped)

The ring: an annulus in the plane z = FLOOR_Z, inner radius FLOOR_INNER (rounded: a half torus of the
floor's thickness), outer radius FLOOR_OUTER; the head's vertex starts GAP above it.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from . import fetal_head as head

HEAD_SIZE = 0.007             # m: 2 148 triangles
FLOOR_SIZE = 0.009            # m: 2 919 tetrahedra
FLOOR_INNER = 0.040           # m: the opening's radius, against the head's 53.7 and 55.5 mm semi-axes
FLOOR_OUTER = 0.085           # m
FLOOR_THICKNESS = 0.020       # m
GAP = 0.004                   # m between the head's vertex and the floor's top at rest
FLOOR_Z = -head.SEMI_AXES[2] - GAP - FLOOR_THICKNESS / 2
FLOOR, RIM = 1, 7             # physical ids: the ring's volume group, its outer face


def _floor(size: float):
    """(points, tetrahedra, rim triangles) of the ring, made with gmsh (one thread: deterministic)."""
    import gmsh
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("pelvic_floor")
        occ, half = gmsh.model.occ, FLOOR_THICKNESS / 2
        outer = occ.addCylinder(0, 0, FLOOR_Z - half, 0, 0, FLOOR_THICKNESS, FLOOR_OUTER)
        hole = occ.addCylinder(0, 0, FLOOR_Z - half, 0, 0, FLOOR_THICKNESS, FLOOR_INNER + half)
        annulus, _ = occ.cut([(3, outer)], [(3, hole)])
        lip = occ.addTorus(0, 0, FLOOR_Z, FLOOR_INNER + half, half)
        occ.fuse(annulus, [(3, lip)])
        occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.mesh.generate(3)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
        index[tags.astype(np.int64)] = np.arange(len(tags))
        _, nodes = gmsh.model.mesh.getElementsByType(4)
        tetra = index[np.asarray(nodes, dtype=np.int64)].reshape(-1, 4)
        rim = []
        for dim, tag in gmsh.model.getEntities(2):
            lo = gmsh.model.getBoundingBox(dim, tag)
            wide = min(-lo[0], -lo[1], lo[3], lo[4]) > FLOOR_OUTER - 0.1 * size
            if wide and lo[5] - lo[2] > 0.5 * FLOOR_THICKNESS:          # the outer cylinder (not the annuli)
                types, _, face_nodes = gmsh.model.mesh.getElements(dim, tag)
                rim += [index[np.asarray(n, dtype=np.int64)].reshape(-1, 3) for t, n in zip(types, face_nodes) if t == 2]
        points = np.asarray(coords).reshape(-1, 3)
    finally:
        gmsh.finalize()
    used = np.unique(tetra)
    remap = np.full(len(points), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return points[used], remap[tetra], remap[np.vstack(rim)]


def make(path, head_size: float = HEAD_SIZE, floor_size: float = FLOOR_SIZE) -> Path:
    """Write the scene's mesh (MSH 2.2 ascii: the head's zones, the floor, its rim) and return its path."""
    import meshio
    for name, value in (("head_size", head_size), ("floor_size", floor_size)):
        if not 0 < float(value) < 0.02:
            raise ValueError(f"birth: {name} must be in (0, 0.02) m, got {value}")
    head_points, triangles = head._ellipsoid(float(head_size))
    zones = head.zones(head_points, triangles)
    floor_points, tetra, rim = _floor(float(floor_size))
    n = len(head_points)
    points = np.vstack([head_points, floor_points])
    cells = [("triangle", triangles), ("tetra", tetra + n), ("triangle", rim + n)]
    tags = [zones, np.full(len(tetra), FLOOR), np.full(len(rim), RIM)]
    fields = {name: np.array([i, 2]) for name, i in head.ZONES.items()}
    fields.update(floor=np.array([FLOOR, 3]), rim=np.array([RIM, 2]))
    mesh = meshio.Mesh(points, cells, cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags},
                       field_data=fields)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    meshio.write(str(tmp), mesh, file_format="gmsh22", binary=False)
    tmp.replace(path)
    return path


# -- the report: the head's descent, the ring's stretch, the head's diameters -------------------
SCENE = Path(__file__).resolve().parents[1] / "examples" / "birth" / "birth.toml"
THESIS_SPEED = 0.09e-3        # m/s: the mean descent speed of the thesis' full scene (Table 8.3)


def _bodies(model):
    """(head nodes, floor nodes, the floor's lip nodes: those on its opening at rest)."""
    head_nodes = np.unique(np.vstack([b.cells for b in model.mesh.blocks if b.type == "shell"]))
    floor_nodes = np.unique(np.vstack([b.cells for b in model.mesh.blocks if b.type != "shell"]))
    X = model.mesh.points[floor_nodes]
    radius = np.hypot(X[:, 0], X[:, 1])
    lip = floor_nodes[radius < radius.min() + 0.25 * FLOOR_THICKNESS]
    return head_nodes, floor_nodes, lip


def measure(model, displacement, bodies, pairs) -> dict:
    """One row: the head's descent (its mean z displacement), the opening's stretch (mean radius of
    the lip nodes against rest), the head's three diameters (mm)."""
    head_nodes, _, lip = bodies
    X, x = model.mesh.points, model.mesh.points + displacement
    r0, r1 = np.hypot(*X[lip, :2].T).mean(), np.hypot(*x[lip, :2].T).mean()
    return {"descent_mm": -1e3 * float(displacement[head_nodes, 2].mean()),
            "stretch": float(r1 / r0), **{k: 1e3 * v for k, v in head.diameters(x, pairs).items()}}


def run_birth(scene=SCENE, steps: int | None = None, every: int = 1, progress=None) -> dict:
    """The scene (by default the checkout's examples/birth/birth.toml), stepped by hand: a row every
    `every` steps, the mean descent speed and the diameters' changes."""
    from ..runtime.run.simulation import Simulation
    from ..runtime.scene.scene import Scene
    if not Path(scene).is_file():
        from ..runtime.base.errors import TensormassError
        raise TensormassError(f"the birth scene {scene} is not there: run from a checkout, or give the scene "
                              "file (examples/birth/birth.toml)")
    sim = Simulation(Scene.from_toml(scene), output=False)
    model = sim.model
    total = model.solver.steps if steps is None else int(steps)
    bodies = _bodies(model)
    head_nodes = bodies[0]
    pairs = {k: (int(head_nodes[a]), int(head_nodes[b]))
             for k, (a, b) in head.landmarks(model.mesh.points[head_nodes]).items()}
    rows = [{"step": 0, "time": 0.0, **measure(model, np.zeros((model.n_points, 3)), bodies, pairs)}]
    sim.start()
    try:
        done = 0
        while done < total:
            n = min(every, total - done)
            sim.advance(n)
            done += n
            rows.append({"step": done, "time": done * model.solver.dt, **measure(model, sim.displacement, bodies, pairs)})
            if progress:
                progress(_line(rows[-1]))
    finally:
        summary = sim.finish()
    last, T = rows[-1], rows[-1]["time"]
    return {"rows": rows, "status": summary.status, "seconds": summary.time["total"],
            "triangles": int(sum(len(b) for b in model.mesh.blocks if b.type == "shell")),
            "tetrahedra": int(sum(len(b) for b in model.mesh.blocks if b.type != "shell")),
            "speed_mm_s": last["descent_mm"] / T if T > 0 else 0.0,
            "change_mm": {k: last[k] - rows[0][k] for k in head.DIAMETERS}}


def _line(row) -> str:
    return (f"t = {row['time']:5.2f} s: descent {row['descent_mm']:6.2f} mm, opening x {row['stretch']:.3f}, "
            + ", ".join(f"{k} {row[k]:.2f}" for k in head.DIAMETERS) + " mm")


def report(scene=SCENE, steps=None, json_path=None, progress=print) -> dict:
    """Run the scene and print its rows, the mean descent speed against the thesis', the diameters' changes."""
    out = run_birth(scene, steps, progress=progress)
    progress(f"{out['status']}: {out['triangles']} shell triangles, {out['tetrahedra']} tetrahedra, "
             f"{out['seconds']:.0f} s; mean descent {out['speed_mm_s']:.2f} mm/s (thesis {1e3 * THESIS_SPEED:.2f} mm/s "
             f"over 32 min of labour); diameter changes "
             + ", ".join(f"{k} {v:+.3f} mm" for k, v in out["change_mm"].items()))
    if json_path:
        from ..runtime.base.files import write_json_atomic
        write_json_atomic(json_path, out)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("path", help="where to write the mesh, or `report` to run the scene and report the descent")
    p.add_argument("--head-size", type=float, default=HEAD_SIZE)
    p.add_argument("--floor-size", type=float, default=FLOOR_SIZE)
    p.add_argument("--steps", type=int, help="report: run this many steps (default: the scene's)")
    p.add_argument("--json", help="report: also write the rows as JSON")
    p.add_argument("--scene", default=str(SCENE), help="report: the scene (default: the checkout's example)")
    args = p.parse_args(argv)
    if args.path == "report":
        from ..runtime.base.errors import TensormassError
        try:
            out = report(args.scene, args.steps, args.json)
        except TensormassError as exc:          # a refused scene, or a step that failed: its reason
            print(f"birth: {exc}")
            return 1
        return 0 if out["status"] == "ok" else 1
    path = make(args.path, args.head_size, args.floor_size)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
