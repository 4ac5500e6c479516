"""Make docs/cantilever_displacement.png: the README's picture, from a real run.

    tensormass run examples/cantilever_hexahedron.toml --out /tmp/cantilever --json /tmp/cantilever.json
    python docs/make_picture.py /tmp/cantilever/frame_000001.vtu docs/cantilever_displacement.png

Reads the last frame (meshio), and draws the deformed bar (displacement x 20) coloured by
|displacement| with runtime.picture.write_picture (matplotlib back end, as on any machine).
"""
import sys

import meshio

from tensormass.runtime.mesh import CellBlock, Mesh
from tensormass.runtime.picture import write_picture

frame, out = sys.argv[1], sys.argv[2]
m = meshio.read(frame)
mesh = Mesh(m.points, [CellBlock(c.type, c.data) for c in m.cells])
u = m.point_data["displacement"]
write_picture(out, mesh, None, u, None, "displacement", unit="m", scale=20.0,
              title="cantilever_hexahedron (gravity, static)", step=1, size=(900, 420),
              view=(22, -58), backend="matplotlib")
