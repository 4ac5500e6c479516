"""The small scenes the run wing's tests share: a 1 m hexahedron bar clamped at x = 0 that sags
under gravity, and a clamped CST-DKT plate under pressure (each runs in well under a second).

    from run_scenes import bar, write_scene
    text = bar(cells=4, solver=IMPLICIT, output='dir = "frames"')
    path = write_scene(tmp_path, text, "bar")
"""
from __future__ import annotations

STATIC = 'kind = "static"\nsteps = 2'
IMPLICIT = 'kind = "implicit_euler"\ndt = 0.01\nsteps = 3'
TIP = ("tip", "point = [1.0, 0.1, 0.1]")
END = ("end", "box = [[0.99, -1, -1], [2, 1, 1]]")


def bar(cells: int = 2, solver: str = STATIC, backend: str | None = None, probes=(TIP,),
        output: str | None = None) -> str:
    """A bar of `cells` x 1 x 1 stvk hexahedra (1 x 0.2 x 0.2 m, E = 1 MPa) under gravity; solver: the
    [solver] lines besides backend; probes: (name, the line placing it); output: the [output] lines."""
    lines = ['name = "bar"', "[mesh]", 'generate = "bar"', "size = [1.0, 0.2, 0.2]", f"cells = [{cells}, 1, 1]",
             'element = "hexahedron"', "[[material]]", 'law = "stvk"', 'quadrature = "gauss2"', "E = 1.0e6",
             "nu = 0.3", "density = 800.0", "[[fixed]]", "box = [[-1e-9, -1, -1], [1e-9, 1, 1]]", "[loads]",
             "gravity = [0.0, 0.0, -9.81]", "[solver]", solver]
    if backend is not None:
        lines.append(f'backend = "{backend}"')
    for name, where in probes:
        lines += ["[[probe]]", f'name = "{name}"', where]
    if output is not None:
        lines += ["[output]", output]
    return "\n".join(lines) + "\n"


def plate(corotational: bool = False) -> str:
    """A 1 m square of 2 x 2 x 2 cst_dkt triangles clamped along x = 0 under a 1 Pa pressure, one
    static step; corotational=False: the linear shell (its kernel gives stress records)."""
    return "\n".join([
        'name = "plate"', "[mesh]", 'generate = "plate"', "size = [1.0, 1.0]", "cells = [2, 2]", "[[material]]",
        'law = "cst_dkt"', "E = 1.0e7", "nu = 0.3", "thickness = 0.01", *([] if corotational else ["corotational = 0"]),
        "density = 1000.0", "[[fixed]]", "box = [[-1, -1, -1], [1e-9, 2, 1]]", "[[loads.pressure]]",
        "box = [[-1, -1, -1], [2, 2, 1]]", "value = 1.0", "[solver]", 'kind = "static"', "steps = 1", 'backend = "c"',
        "[[probe]]", 'name = "corner"', "point = [1.0, 1.0, 0.0]"]) + "\n"


def write_scene(folder, text: str, name: str = "bar"):
    """The scene file <folder>/<name>.toml holding text; its path."""
    path = folder / f"{name}.toml"
    path.write_text(text)
    return path
