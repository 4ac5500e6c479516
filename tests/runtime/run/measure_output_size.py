"""Measurement (not a test): bytes per VTU frame with the default [output] fields, for a dynamic run
of a liver-sized tetra10 block (generated, default 16 x 12 x 6 cells) and the organ example.

    python tests/runtime/run/measure_output_size.py [NX NY NZ]

Each case runs 2 steps writing a frame per step; it prints the mean frame size, the point and cell
arrays the frames carry, and the size of a 0.5 s run at 1 ms steps with a frame every 10 steps.
"""
import copy
import sys
import tempfile
from pathlib import Path

import meshio

from tensormass.runtime.run.simulation import Simulation
from tensormass.runtime.scene.scene import Scene

ROOT = Path(__file__).resolve().parents[3]
cells = [int(c) for c in sys.argv[1:4]] if len(sys.argv) >= 4 else [16, 12, 6]

BLOCK = {
    "name": "liver_block",
    "mesh": {"generate": "bar", "size": [0.16, 0.12, 0.06], "cells": cells, "element": "tetra10"},
    "material": [{"law": "neohookean", "quadrature": "gauss2", "E": 5e3, "nu": 0.45, "density": 1050.0}],
    "fixed": [{"box": [[-1e-9, -1, -1], [1e-9, 1, 1]]}],
    "loads": {"gravity": [0.0, 0.0, -9.81]},
    "solver": {"kind": "implicit_euler", "dt": 1e-3, "steps": 2},
}


def measure(label, scene):
    with tempfile.TemporaryDirectory() as tmp:
        scene.output.dir = tmp
        scene.output.every = 1
        Simulation(scene).run()
        frames = sorted(Path(tmp).glob("frame_*.vtu"))
        sizes = [f.stat().st_size for f in frames[1:]]     # frame 0 is the rest state: zero fields
        m = meshio.read(frames[-1])
        point = {k: v.shape[1:] for k, v in m.point_data.items()}
        cell = {k: v[0].shape[1:] for k, v in m.cell_data.items()}
    per = sum(sizes) / len(sizes)
    print(f"{label}: {m.points.shape[0]} points, {sum(len(c.data) for c in m.cells)} cells, "
          f"{len(frames) - 1} frames after the rest state, {per / 1e6:.3f} MB/frame; 0.5 s at 1 ms, a frame every 10 steps: "
          f"{51 * per / 1e6:.1f} MB")
    print(f"    point data {point}\n    cell data  {cell}")


measure(f"tetra10 block {cells}", Scene.from_dict(copy.deepcopy(BLOCK), ROOT))
organ = Scene.from_toml(ROOT / "examples/organ/scene.toml")
organ.solver.steps = 2
measure("organ (static)", organ)
