"""The organ mesh of examples/organ/scene.toml and of `tensormass bench organ` (needs gmsh: pip install gmsh).

    python examples/organ/make_organ.py            # writes examples/organ/organ.msh (a wrapper of this module)
    python -m tensormass.apps.organ_mesh liver.msh --scale 2.2 --size 0.006 --order 2

    from tensormass.apps.organ_mesh import make
    make("liver.msh", size=0.008, order=2, scale=2.2)

Installed with the package (the bench needs it outside a source checkout).

Options: --size (mesh size in m, default 0.009), --order (1: tetra, 2: tetra10, the
default) and --scale (every length of the geometry times this; the mesh size is not
scaled).  The defaults write the committed organ.msh byte for byte.  scale 2.2 is a
liver-sized organ (semi-axes 88 x 66 x 66 mm): tetra10 at 8 mm has 8 208 cells.

The organ is the upper half of an ellipsoid with semi-axes 40 x 30 x 30 mm: 80 x 60 x 30 mm, flat
underneath (the cut plane z = 0, where it is attached) at scale 1.  A vertical cylinder of radius 12 mm
around the z axis splits its top into the patch a tool presses on (and the volume into two
pieces, meshed conformingly).  Quadratic tetrahedra (tetra10), mesh size 9 mm.

Physical groups (names and ids):
    "organ"     volume 1     both pieces
    "attached"  surface 2    the flat face z = 0
    "loaded"    surface 3    the curved top inside the cylinder (r < 12 mm)

Deterministic: fixed geometry and sizes, one thread, MSH 4.1 ascii.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

A, B, C = 0.040, 0.030, 0.030        # semi-axes (m)
R_LOAD = 0.012                        # radius of the loaded patch (m)
SIZE = 0.009                          # mesh size (m)


def make(path, size: float = SIZE, order: int = 2, scale: float = 1.0) -> Path:
    """Write the organ mesh to path (MSH 4.1 ascii) and return it as a Path.

    size: target mesh size (m); order: 1 (tetra) or 2 (tetra10); scale: the geometry's
    lengths (semi-axes and the loaded patch's radius) times this.  Same arguments, same bytes."""
    size, scale = float(size), float(scale)
    if not (0 < size < float("inf") and 0 < scale < float("inf")):
        raise ValueError(f"make_organ: size and scale must be positive numbers (got size={size}, scale={scale})")
    if order not in (1, 2):
        raise ValueError(f"make_organ: order must be 1 (tetra) or 2 (tetra10), got {order!r}")
    if size > scale * C:
        raise ValueError(f"make_organ: mesh size {size} m is larger than the organ's height {scale * C} m")
    import gmsh
    a, b, c, r_load = scale * A, scale * B, scale * C, scale * R_LOAD

    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("organ")
        occ = gmsh.model.occ
        half = occ.addSphere(0, 0, 0, 1.0, angle1=0.0)            # the upper half of a unit ball
        occ.dilate([(3, half)], 0, 0, 0, a, b, c)
        cylinder = occ.addCylinder(0, 0, 0, 0, 0, 2 * c, r_load)
        inner, _ = occ.intersect([(3, half)], [(3, cylinder)], removeObject=False, removeTool=True)
        occ.fragment([(3, half)], inner)                          # two pieces sharing the cylinder wall
        occ.synchronize()
        vols = [t for _, t in gmsh.model.getEntities(3)]
        flat, loaded = [], []
        for _, tag in gmsh.model.getEntities(2):
            z = occ.getCenterOfMass(2, tag)[2]
            if abs(z) < 1e-9:
                flat.append(tag)                  # the attached face z = 0 (a disk and the ring around it)
            elif z > 0.8 * c:
                loaded.append(tag)                # the cap inside the cylinder (the wall has z ~ C / 2)
        gmsh.model.addPhysicalGroup(3, vols, 1, name="organ")
        gmsh.model.addPhysicalGroup(2, flat, 2, name="attached")
        gmsh.model.addPhysicalGroup(2, loaded, 3, name="loaded")
        gmsh.option.setNumber("Mesh.MeshSizeMin", size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.model.mesh.generate(3)
        if order == 2:
            gmsh.model.mesh.setOrder(2)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.option.setNumber("Mesh.Binary", 0)
        path = Path(path)
        gmsh.write(str(path))
        return path
    finally:
        gmsh.finalize()


def main(argv=None, default_path: str = "organ.msh") -> int:
    parser = argparse.ArgumentParser(description="Write the organ mesh (gmsh).")
    parser.add_argument("path", nargs="?", default=default_path,
                        help=f"output .msh file (default: {default_path})")
    parser.add_argument("--size", type=float, default=SIZE, help=f"mesh size in m (default {SIZE})")
    parser.add_argument("--order", type=int, choices=(1, 2), default=2, help="1: tetra, 2: tetra10 (default)")
    parser.add_argument("--scale", type=float, default=1.0,
                        help="geometry scale (default 1: 80 x 60 x 30 mm; 2.2: 176 x 132 x 66 mm)")
    args = parser.parse_args(argv)
    try:
        import gmsh  # noqa: F401
    except ImportError:
        parser.exit(2, "make_organ: the gmsh package is not installed (pip install gmsh, or tensormass[mesh])\n")
    try:
        out = make(args.path, size=args.size, order=args.order, scale=args.scale)
    except ValueError as error:
        parser.exit(2, f"{error}\n")
    print(out, out.stat().st_size, "bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
