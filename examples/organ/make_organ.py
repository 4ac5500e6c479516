"""Make organ.msh: a small organ for examples/organ/scene.toml (needs the gmsh package: pip install gmsh).

    python examples/organ/make_organ.py            # writes examples/organ/organ.msh

The organ is the upper half of an ellipsoid with semi-axes 40 x 30 x 30 mm: 80 x 60 x 30 mm, flat
underneath (the cut plane z = 0, where it is attached).  A vertical cylinder of radius 12 mm
around the z axis splits its top into the patch a tool presses on (and the volume into two
pieces, meshed conformingly).  Quadratic tetrahedra (tetra10), mesh size 9 mm.

Physical groups (names and ids):
    "organ"     volume 1     both pieces
    "attached"  surface 2    the flat face z = 0
    "loaded"    surface 3    the curved top inside the cylinder (r < 12 mm)

Deterministic: fixed geometry and sizes, one thread, MSH 4.1 ascii.
"""
from __future__ import annotations

import sys
from pathlib import Path

A, B, C = 0.040, 0.030, 0.030        # semi-axes (m)
R_LOAD = 0.012                        # radius of the loaded patch (m)
SIZE = 0.009                          # mesh size (m)


def make(path) -> Path:
    import gmsh

    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("organ")
        occ = gmsh.model.occ
        half = occ.addSphere(0, 0, 0, 1.0, angle1=0.0)            # the upper half of a unit ball
        occ.dilate([(3, half)], 0, 0, 0, A, B, C)
        cylinder = occ.addCylinder(0, 0, 0, 0, 0, 2 * C, R_LOAD)
        inner, _ = occ.intersect([(3, half)], [(3, cylinder)], removeObject=False, removeTool=True)
        occ.fragment([(3, half)], inner)                          # two pieces sharing the cylinder wall
        occ.synchronize()
        vols = [t for _, t in gmsh.model.getEntities(3)]
        flat, loaded = [], []
        for _, tag in gmsh.model.getEntities(2):
            z = occ.getCenterOfMass(2, tag)[2]
            if abs(z) < 1e-9:
                flat.append(tag)                  # the attached face z = 0 (a disk and the ring around it)
            elif z > 0.8 * C:
                loaded.append(tag)                # the cap inside the cylinder (the wall has z ~ C / 2)
        gmsh.model.addPhysicalGroup(3, vols, 1, name="organ")
        gmsh.model.addPhysicalGroup(2, flat, 2, name="attached")
        gmsh.model.addPhysicalGroup(2, loaded, 3, name="loaded")
        gmsh.option.setNumber("Mesh.MeshSizeMin", SIZE)
        gmsh.option.setNumber("Mesh.MeshSizeMax", SIZE)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.model.mesh.generate(3)
        gmsh.model.mesh.setOrder(2)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.option.setNumber("Mesh.Binary", 0)
        path = Path(path)
        gmsh.write(str(path))
        return path
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    out = make(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).with_name("organ.msh"))
    print(out, out.stat().st_size, "bytes")
