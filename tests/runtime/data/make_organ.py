"""Regenerate organ_tetra10.msh (needs the gmsh extra: pip install tensormass[mesh]).

A half ellipsoid hanging from its flat face (z = 0): semi-axes 40 x 30 mm, 50 mm deep, tetra10
with midside nodes on the curved surface, physical groups "organ" (volume) and "attached"
(the flat face).  Used by tests/runtime/assembly/test_loads.py (consistent loads against FElupe).

    python tests/runtime/data/make_organ.py [h_in_m]
"""
import sys
from pathlib import Path

import gmsh


def make(path, h=0.012):
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("organ")
        occ = gmsh.model.occ
        ball = occ.addSphere(0, 0, 0, 1.0)
        occ.dilate([(3, ball)], 0, 0, 0, 0.04, 0.03, 0.05)
        box = occ.addBox(-0.1, -0.1, 0.0, 0.2, 0.2, 0.1)
        out, _ = occ.cut([(3, ball)], [(3, box)])
        occ.synchronize()
        volume = out[0][1]
        flat = [s for _, s in gmsh.model.getBoundary(out, oriented=False)
                if abs(gmsh.model.occ.getCenterOfMass(2, s)[2]) < 1e-9]
        gmsh.model.addPhysicalGroup(3, [volume], 1, "organ")
        gmsh.model.addPhysicalGroup(2, flat, 2, "attached")
        gmsh.option.setNumber("Mesh.MeshSizeMin", h)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.model.mesh.generate(3)
        gmsh.model.mesh.setOrder(2)           # midside nodes on the curved surface
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    make(Path(__file__).with_name("organ_tetra10.msh"), float(sys.argv[1]) if len(sys.argv) > 1 else 0.012)
