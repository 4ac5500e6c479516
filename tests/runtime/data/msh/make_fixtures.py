"""Make the small gmsh .msh fixtures of tests/runtime/mesh/test_msh_node_order.py (needs the gmsh package).

    python tests/runtime/data/msh/make_fixtures.py [OUT_DIR]      # default: this folder

One mesh per cell type tensormass supports, made by gmsh itself (so the files carry gmsh's own
node order, not meshio's or ours), each with physical groups: the volume ("body", id 1; the
surface "body" in 2D) and one boundary group ("side", id 2: a face in 3D, an edge in 2D).
Every fixture is written as MSH 4.1 (ascii) and 2.2 (binary); the hexahedron + wedge mesh (an
extrusion with recombine, the case of issue #12) also as 4.1 binary and 2.2 ascii.

Deterministic: fixed geometry, fixed sizes, one thread, no random perturbation; gmsh writes no
date into .msh files.  The test that regenerates them compares the cell types and counts.
"""
from __future__ import annotations

import sys
from pathlib import Path

# name -> (expected meshio cell type of the body, builder)
FORMATS = {"v41": ("msh41", False), "v22b": ("msh22", True)}
EXTRA_FORMATS = {"v41b": ("msh41", True), "v22": ("msh22", False)}


def _box(gmsh, lc):
    occ = gmsh.model.occ
    occ.addBox(0, 0, 0, 1.0, 0.6, 0.4)
    occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMin", lc)
    gmsh.option.setNumber("Mesh.MeshSizeMax", lc)


def _groups_3d(gmsh):
    """Volume "body" (1) and the x = 0 face "side" (2)."""
    m = gmsh.model
    vols = [t for _, t in m.getEntities(3)]
    m.addPhysicalGroup(3, vols, 1, name="body")
    side = [t for _, t in m.getEntities(2)
            if abs(m.occ.getCenterOfMass(2, t)[0]) < 1e-9] if m.getEntities(2) else []
    m.addPhysicalGroup(2, side, 2, name="side")


def tetra(gmsh):
    _box(gmsh, 0.5)
    _groups_3d(gmsh)
    gmsh.model.mesh.generate(3)


def tetra10(gmsh):
    tetra(gmsh)
    gmsh.model.mesh.setOrder(2)


def hexahedron(gmsh):
    _box(gmsh, 0.5)
    gmsh.option.setNumber("Mesh.RecombineAll", 1)
    for d in (1, 2, 3):
        for _, t in gmsh.model.getEntities(d):
            if d == 1:
                gmsh.model.mesh.setTransfiniteCurve(t, 3)
            elif d == 2:
                gmsh.model.mesh.setTransfiniteSurface(t)
            else:
                gmsh.model.mesh.setTransfiniteVolume(t)
    _groups_3d(gmsh)
    gmsh.model.mesh.generate(3)


def _extruded(gmsh, recombine_surface: bool):
    """A 1 x 0.6 rectangle (triangles, or triangles + quads), extruded 0.4 along z in 2 layers."""
    occ = gmsh.model.occ
    if recombine_surface:               # two rectangles: one of quads (-> hexahedra), one of triangles (-> wedges)
        a = occ.addRectangle(0, 0, 0, 0.5, 0.6)
        b = occ.addRectangle(0.5, 0, 0, 0.5, 0.6)
        occ.fragment([(2, a)], [(2, b)])
    else:
        a = occ.addRectangle(0, 0, 0, 1.0, 0.6)
    occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.3)
    gmsh.option.setNumber("Mesh.MeshSizeMax", 0.3)
    surfaces = gmsh.model.getEntities(2)
    if recombine_surface:
        left = min(surfaces, key=lambda e: gmsh.model.occ.getCenterOfMass(*e)[0])
        for _, t in gmsh.model.getBoundary([left], oriented=False):
            gmsh.model.mesh.setTransfiniteCurve(t, 3)
        gmsh.model.mesh.setTransfiniteSurface(left[1])
        gmsh.model.mesh.setRecombine(2, left[1])
    occ.extrude(surfaces, 0, 0, 0.4, numElements=[2], recombine=True)
    occ.synchronize()
    _groups_3d(gmsh)
    gmsh.model.mesh.generate(3)


def wedge(gmsh):
    _extruded(gmsh, recombine_surface=False)


def hex_wedge(gmsh):
    _extruded(gmsh, recombine_surface=True)


def pyramid(gmsh):
    """Tetrahedra against a recombined (quad) face: gmsh puts pyramids on the quads."""
    _box(gmsh, 0.5)
    m = gmsh.model
    bottom = [t for _, t in m.getEntities(2) if abs(m.occ.getCenterOfMass(2, t)[2]) < 1e-9]
    for t in bottom:
        for _, c in m.getBoundary([(2, t)], oriented=False):
            m.mesh.setTransfiniteCurve(c, 3)
        m.mesh.setTransfiniteSurface(t)
        m.mesh.setRecombine(2, t)
    _groups_3d(gmsh)
    m.mesh.generate(3)


def _rect(gmsh, quads: bool, order: int):
    m = gmsh.model
    m.occ.addRectangle(0, 0, 0, 1.0, 0.6)
    m.occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.3)
    gmsh.option.setNumber("Mesh.MeshSizeMax", 0.3)
    if quads:
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
    m.addPhysicalGroup(2, [t for _, t in m.getEntities(2)], 1, name="body")
    side = [t for _, t in m.getEntities(1) if abs(m.occ.getCenterOfMass(1, t)[0]) < 1e-9]
    m.addPhysicalGroup(1, side, 2, name="side")
    m.mesh.generate(2)
    if order > 1:
        m.mesh.setOrder(order)


def triangle(gmsh):
    _rect(gmsh, False, 1)


def triangle6(gmsh):
    _rect(gmsh, False, 2)


def quad(gmsh):
    _rect(gmsh, True, 1)


# fixture name -> (builder, the body's cell types as meshio reads them)
FIXTURES = {
    "tetra": (tetra, {"tetra"}),
    "tetra10": (tetra10, {"tetra10"}),
    "hexahedron": (hexahedron, {"hexahedron"}),
    "wedge": (wedge, {"wedge"}),
    "pyramid": (pyramid, {"pyramid", "tetra"}),
    "hex_wedge": (hex_wedge, {"hexahedron", "wedge"}),
    "triangle": (triangle, {"triangle"}),
    "triangle6": (triangle6, {"triangle6"}),
    "quad": (quad, {"quad"}),
}


def file_names(name: str) -> list:
    formats = dict(FORMATS, **(EXTRA_FORMATS if name == "hex_wedge" else {}))
    return [f"{name}_{suffix}.msh" for suffix in formats]


def make(out_dir) -> list:
    """Write every fixture into out_dir; returns the paths."""
    import gmsh

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, (build, _) in FIXTURES.items():
        formats = dict(FORMATS, **(EXTRA_FORMATS if name == "hex_wedge" else {}))
        for suffix, (version, binary) in formats.items():
            gmsh.initialize(readConfigFiles=False)
            try:
                gmsh.option.setNumber("General.Terminal", 0)
                gmsh.option.setNumber("General.NumThreads", 1)
                gmsh.option.setNumber("Mesh.RandomFactor", 1e-9)
                gmsh.model.add(name)
                build(gmsh)
                gmsh.option.setNumber("Mesh.MshFileVersion", 4.1 if version == "msh41" else 2.2)
                gmsh.option.setNumber("Mesh.Binary", int(binary))
                path = out_dir / f"{name}_{suffix}.msh"
                gmsh.write(str(path))
                written.append(path)
            finally:
                gmsh.finalize()
    return written


if __name__ == "__main__":
    for p in make(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent):
        print(p, p.stat().st_size)
