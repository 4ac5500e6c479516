"""Make the mesh files of the contact examples next to this file (needs only numpy and meshio):

    python examples/contact/make_meshes.py      # writes torus.vtu and two_blocks.vtu

torus.vtu: a closed shell torus (major radius 0.3 m, tube radius 0.1 m) of 30 x 20 quadrilaterals
split into 600 nodes and 1 200 triangles, its axis along y (it stands like a wheel) and its centre at
(0, 0, 0).  The thesis' torus (chapter 6, B13) has 2 400 nodes / 4 800 triangles: torus(nu=60, nv=40);
explicitly that is 4 x the work per step at a smaller stable step, minutes instead of a minute.
two_blocks.vtu: two disjoint hexahedral blocks 0.1 x 0.1 x 0.05 m (4 x 4 x 2 cells each), one above
the other with a 2 cm gap: two bodies of one mesh file.
"""
import math
from pathlib import Path

import meshio
import numpy as np

HERE = Path(__file__).resolve().parent


def torus(R=0.3, r=0.1, nu=30, nv=20):
    u = 2 * math.pi * np.arange(nu) / nu           # around the axis
    v = 2 * math.pi * np.arange(nv) / nv           # around the tube
    U, V = np.meshgrid(u, v, indexing="ij")
    rho = R + r * np.cos(V)
    # axis along y: the ring lies in the x-z plane
    points = np.stack([rho * np.cos(U), r * np.sin(V), rho * np.sin(U)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = i * nv + j
    b = ((i + 1) % nu) * nv + j
    c = ((i + 1) % nu) * nv + (j + 1) % nv
    d = i * nv + (j + 1) % nv
    tri = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    # outward normals: flip if the first triangle's normal points to the tube's centre line
    p = points[tri[0]]
    n = np.cross(p[1] - p[0], p[2] - p[0])
    centre = np.array([R * math.cos(0.0), 0.0, R * math.sin(0.0)])
    if n @ (p.mean(axis=0) - centre) < 0:
        tri = tri[:, [0, 2, 1]]
    return points, tri


def block(origin, size=(0.1, 0.1, 0.05), cells=(4, 4, 2)):
    axes = [np.linspace(o, o + s, n + 1) for o, s, n in zip(origin, size, cells)]
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    points = np.stack([X, Y, Z], -1).reshape(-1, 3)
    nx, ny, nz = (n + 1 for n in cells)
    idx = lambda i, j, k: (i * ny + j) * nz + k        # noqa: E731
    hexes = []
    for i in range(cells[0]):
        for j in range(cells[1]):
            for k in range(cells[2]):
                hexes.append([idx(i, j, k), idx(i + 1, j, k), idx(i + 1, j + 1, k), idx(i, j + 1, k),
                              idx(i, j, k + 1), idx(i + 1, j, k + 1), idx(i + 1, j + 1, k + 1), idx(i, j + 1, k + 1)])
    return points, np.array(hexes)


if __name__ == "__main__":
    points, tri = torus()
    meshio.write(HERE / "torus.vtu", meshio.Mesh(points, [("triangle", tri)]))
    p0, h0 = block((0.0, 0.0, 0.0))
    p1, h1 = block((0.02, 0.02, 0.07))
    meshio.write(HERE / "two_blocks.vtu", meshio.Mesh(np.vstack([p0, p1]), [("hexahedron", np.vstack([h0, h1 + len(p0)]))]))
    print(f"torus.vtu: {len(points)} nodes, {len(tri)} triangles; two_blocks.vtu: {len(p0) + len(p1)} nodes")
