"""`tensormass mesh simplify`: a surface simplified to a target reduction, its precision against the
original (the thesis' alpha, ch. 8), and optionally a volume mesh regenerated from it with gmsh.

    tensormass mesh simplify organ.stl --reduction 0.9 --size 0.01 --out organ_simple.stl [--volume organ.msh]
    tensormass mesh simplify --stand-in uterus --reduction 0.9 --volume uterus.msh
    tensormass mesh simplify --stand-in all --sweep            # alpha against the reduction (Fig. 8.7)

The stand-ins replace the birth scene's organs (there is no BirthSIM mesh), each with the thesis'
characteristic size d_organ: the fetal head (an ellipsoid with the Table 8.2 diameters; d_organ the
head's smallest diameter), the uterus (a thick-walled ellipsoid 230 mm from fundus to base; d_organ
its 10 mm wall) and the pelvis (a bony ring 8 mm thick; d_organ that thickness). gmsh makes them.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from ..runtime.base.errors import TensormassError
from ..runtime.base.files import write_json_atomic
from ..runtime.mesh import simplify as _simplify

# name: (what, d_organ in m, mesh size in m)
STAND_INS = {
    "head": ("fetal head: ellipsoid of diameters 124.6 x 110.9 x 107.4 mm (Table 8.2)", 0.1074, 0.003),
    "uterus": ("uterus: ellipsoidal wall 10 mm thick, 230 x 180 x 160 mm outside", 0.010, 0.005),
    "pelvis": ("pelvis: a bony ring 8 mm thick, 40 mm high, 120 mm across", 0.008, 0.003),
}
SWEEP = (0.5, 0.7, 0.8, 0.9, 0.95, 0.98)


def _gmsh():
    try:
        import gmsh
    except ImportError:
        raise TensormassError("this needs gmsh: pip install 'tensormass[mesh]' (or pip install gmsh)") from None
    return gmsh


def surface_of_model(gmsh) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of every surface of the current gmsh model, nodes renumbered from 0."""
    tags, coords, _ = gmsh.model.mesh.getNodes()
    index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    _, nodes = gmsh.model.mesh.getElementsByType(2)                # 3-node triangles
    triangles = index[np.asarray(nodes, dtype=np.int64)].reshape(-1, 3)
    points = np.asarray(coords).reshape(-1, 3)
    used = np.unique(triangles)
    remap = np.full(len(points), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return points[used], remap[triangles]


def stand_in(name: str) -> tuple[np.ndarray, np.ndarray, float]:
    """(points, triangles, d_organ) of a stand-in organ's closed surface, made with gmsh
    (deterministic: one thread, fixed sizes)."""
    if name not in STAND_INS:
        raise TensormassError(f"unknown stand-in {name!r}; known: {', '.join(STAND_INS)}")
    gmsh = _gmsh()
    _, size_organ, h = STAND_INS[name]
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add(name)
        occ = gmsh.model.occ
        if name == "head":
            ball = occ.addSphere(0, 0, 0, 1.0)
            occ.dilate([(3, ball)], 0, 0, 0, 0.0623, 0.05545, 0.0537)
        elif name == "uterus":
            outer = occ.addSphere(0, 0, 0, 1.0)
            occ.dilate([(3, outer)], 0, 0, 0, 0.090, 0.080, 0.115)
            inner = occ.addSphere(0, 0, 0, 1.0)
            occ.dilate([(3, inner)], 0, 0, 0, 0.080, 0.070, 0.105)
            occ.cut([(3, outer)], [(3, inner)])
        else:
            outer = occ.addCylinder(0, 0, 0, 0, 0, 0.040, 0.060)
            inner = occ.addCylinder(0, 0, -0.001, 0, 0, 0.042, 0.052)
            occ.cut([(3, outer)], [(3, inner)])
        occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", h)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.model.mesh.generate(2)
        points, triangles = surface_of_model(gmsh)
    finally:
        gmsh.finalize()
    return points, triangles, size_organ


def tetrahedralise(points, triangles, path: Path, size: float | None = None) -> dict:
    """A tetrahedral volume mesh (MSH 4.1) of the closed surface, its triangles kept as the boundary;
    physical groups "organ" (the volume) and "surface". Written atomically. Returns counts."""
    try:
        _simplify.check_closed(triangles)
    except TensormassError as error:
        raise TensormassError(f"no volume mesh: {error} (quadric decimation can pinch a surface; "
                              "--method pymeshlab keeps its topology)") from None
    gmsh = _gmsh()
    path = Path(path)
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("volume")
        points = np.asarray(points, dtype=float)
        # one discrete surface per closed component: the largest bounds the volume, the others are
        # its cavities (a uterus's inner wall)
        surfaces, tagged = [], 0
        for component in _components(triangles, points):
            surface = gmsh.model.addDiscreteEntity(2)
            nodes = np.unique(component)
            tags = np.arange(tagged + 1, tagged + 1 + len(nodes))
            tagged += len(nodes)
            local = np.searchsorted(nodes, component)
            gmsh.model.mesh.addNodes(2, surface, tags.tolist(), points[nodes].ravel().tolist())
            gmsh.model.mesh.addElementsByType(surface, 2, [], tags[local].ravel().tolist())
            surfaces.append(surface)
        loops = [gmsh.model.geo.addSurfaceLoop([s]) for s in surfaces]
        volume = gmsh.model.geo.addVolume(loops)
        gmsh.model.geo.synchronize()
        gmsh.model.addPhysicalGroup(3, [volume], 1, name="organ")
        gmsh.model.addPhysicalGroup(2, surfaces, 2, name="surface")
        if size is not None:
            gmsh.option.setNumber("Mesh.MeshSizeMax", float(size))
        gmsh.model.mesh.generate(3)
        _, tets = gmsh.model.mesh.getElementsByType(4)
        if not len(tets):
            raise TensormassError("gmsh made no tetrahedra from the surface (self-intersecting after simplification?)")
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=path.parent, prefix=".tm-mesh-") as folder:
            tmp = Path(folder) / path.name
            gmsh.write(str(tmp))
            tmp.replace(path)
        return {"tetrahedra": len(tets) // 4, "path": str(path)}
    finally:
        gmsh.finalize()


def _components(triangles, points) -> list:
    """The triangles of each connected component, the one with the largest bounding box first."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components
    t = np.asarray(triangles, dtype=np.int64)
    n = len(points)
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]]])
    graph = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    groups = [t[label[t[:, 0]] == k] for k in np.unique(label[t[:, 0]])]
    extent = [float(np.prod(np.ptp(points[np.unique(g)], axis=0))) for g in groups]
    order = np.argsort(extent, kind="stable")[::-1]
    outer = points[np.unique(groups[order[0]])]
    lo, hi = outer.min(axis=0), outer.max(axis=0)
    for k in order[1:]:
        inner = points[np.unique(groups[k])]
        if np.any(inner.min(axis=0) < lo) or np.any(inner.max(axis=0) > hi):
            raise TensormassError("the surface has disjoint closed parts: one volume mesh takes one body "
                                  "(with cavities inside it)")
    return [groups[k] for k in order]


def read_surface(path: Path) -> tuple[np.ndarray, np.ndarray]:
    import meshio
    try:
        mesh = meshio.read(str(path))
    except Exception as error:
        raise TensormassError(f"{path}: cannot read the mesh ({error})") from None
    triangles = [block.data for block in mesh.cells if block.type == "triangle"]
    if not triangles:
        raise TensormassError(f"{path}: no triangles (mesh simplify takes a triangulated surface: .stl, .obj, .msh ...)")
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.shape[1] == 2:
        raise TensormassError(f"{path}: a 2D mesh; mesh simplify takes a surface in 3D")
    return points[:, :3], np.concatenate(triangles).astype(np.int64)


def write_surface(path: Path, points, triangles) -> None:
    import meshio
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=path.parent, prefix=".tm-mesh-") as folder:
        tmp = Path(folder) / path.name
        meshio.write(str(tmp), meshio.Mesh(points, [("triangle", triangles)]))
        tmp.replace(path)


def simplify_report(points, triangles, reduction: float, size: float, method: str = "fast-simplification"
                    ) -> tuple[dict, tuple]:
    t0 = time.perf_counter()
    P, T = _simplify.simplify(points, triangles, reduction, method)
    seconds = time.perf_counter() - t0
    d = _simplify.mean_distance((points, triangles), (P, T))
    row = {"reduction": reduction, "triangles": [int(len(triangles)), int(len(T))],
           "points": [int(len(points)), int(len(P))], "mean_distance_m": d, "d_organ_m": size,
           "alpha_percent": _simplify.precision(d, size), "seconds": seconds, "method": method}
    return row, (P, T)


def _line(name, row) -> str:
    return (f"{name}: {row['reduction']:.0%} reduction: {row['triangles'][0]} -> {row['triangles'][1]} triangles, "
            f"{row['points'][0]} -> {row['points'][1]} points; mean distance {1e3 * row['mean_distance_m']:.3f} mm, "
            f"d_organ {1e3 * row['d_organ_m']:.1f} mm: alpha = {row['alpha_percent']:.2f} %")


def cmd_simplify(args) -> int:
    if (args.input is None) == (args.stand_in is None):
        raise TensormassError("mesh simplify: give a surface file or --stand-in NAME (not both)")
    names = list(STAND_INS) if args.stand_in == "all" else [args.stand_in] if args.stand_in else [None]
    if len(names) > 1 and (args.out or args.volume):
        raise TensormassError("mesh simplify: --out and --volume take one surface, not --stand-in all")
    report = []
    for name in names:
        if name is None:
            points, triangles = read_surface(Path(args.input))
            size, label = args.size, Path(args.input).name
            if size is None:
                raise TensormassError("mesh simplify: give --size D (m), the organ's characteristic size d_organ")
        else:
            points, triangles, size = stand_in(name)
            size, label = args.size or size, name
            print(f"{name}: {STAND_INS[name][0]} (gmsh): {len(triangles)} triangles")
        for reduction in (SWEEP if args.sweep else (args.reduction,)):
            row, simple = simplify_report(points, triangles, reduction, size, args.method)
            row["surface"] = label
            report.append(row)
            print(_line(label, row))
        if args.out:
            write_surface(Path(args.out), *simple)
            print(f"simplified surface: {args.out}")
        if args.volume:
            done = tetrahedralise(*simple, Path(args.volume), size=args.volume_size)
            report[-1]["volume"] = done
            print(f"volume mesh: {done['tetrahedra']} tetrahedra in {done['path']} (groups \"organ\", \"surface\")")
    if args.json:
        write_json_atomic(args.json, report)
    return 0


def add_mesh_command(subparsers) -> None:
    p = subparsers.add_parser("mesh", help="mesh tools: simplify a surface (precision alpha), regenerate a volume")
    sub = p.add_subparsers(dest="mesh_command", required=True)
    s = sub.add_parser("simplify", help="simplify a triangulated surface and report the thesis' precision alpha")
    s.add_argument("input", nargs="?", help="a triangulated surface (.stl, .obj, .ply, .msh, ...)")
    s.add_argument("--stand-in", choices=list(STAND_INS) + ["all"],
                   help="a gmsh-made stand-in of a birth-scene organ instead of a file")
    s.add_argument("--reduction", type=float, default=0.9, help="the fraction of triangles removed (default 0.9)")
    s.add_argument("--size", type=float, help="d_organ (m): the organ's characteristic size (a stand-in has its own)")
    s.add_argument("--method", choices=_simplify.METHODS, default="fast-simplification",
                   help="the decimation: fast-simplification (default) or pymeshlab (more precise, slower)")
    s.add_argument("--sweep", action="store_true", help=f"alpha at reductions {', '.join(f'{r:g}' for r in SWEEP)}")
    s.add_argument("--out", help="write the simplified surface here (format by extension)")
    s.add_argument("--volume", help="write a tetrahedral mesh of the simplified surface here (.msh, gmsh)")
    s.add_argument("--volume-size", type=float, help="the volume mesh's largest size (m; default: gmsh's from the surface)")
    s.add_argument("--json", help="also write the report as JSON")
    s.set_defaults(run=cmd_simplify)
