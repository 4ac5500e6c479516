"""Predicted (runtime.scene.resources) against measured time per step, on the organ example, a
liver-like tetra10 body and the bench bodies. A script, not a test: it prints a Markdown table
(docs/results.md, "Resource estimates") and the measured Newton iterations per step.

    python tests/runtime/scene/measure_estimates.py [--quick]

Measured (Simulation(..., output=False): no frames): the mean time of the steps after the first,
as the run's report prints it. Predicted: Estimate.seconds_per_step, made from counts before the
run. The benchmark machine's 2 cores are shared: rerun when a row looks off.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import tensormass as tm
from tensormass.runtime.scene.resources import estimate

ROOT = Path(__file__).resolve().parents[3]

BAR = """
name = "{name}"
[mesh]
generate = "bar"
size = [{size}]
cells = [{cells}]
element = "{element}"
[[material]]
law = "{law}"
quadrature = "{quad}"
E = {E}
nu = {nu}
density = {rho}
[[fixed]]
box = [[-1e-9, -1e9, -1e9], [1e-9, 1e9, 1e9]]
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "{kind}"
dt = {dt}
steps = {steps}
[[probe]]
name = "tip"
point = [{tip}]
"""


def bar(name, element, cells, size, law="stvk", quad="gauss2", E=1e6, nu=0.3, rho=1000.0, kind="implicit_euler",
        dt=0.01, steps=6):
    text = BAR.format(name=name, element=element, cells=", ".join(map(str, cells)), size=", ".join(map(str, size)),
                      law=law, quad=quad, E=E, nu=nu, rho=rho, kind=kind, dt=dt, steps=steps,
                      tip=", ".join(str(s if i == 0 else s / 2) for i, s in enumerate(size)))
    return tm.Scene.from_string(text)


def cases(quick: bool):
    organ = tm.Scene.from_toml(ROOT / "examples" / "organ" / "scene.toml")
    yield "organ (examples/organ, tetra10 static)", organ
    dyn = tm.Scene.from_toml(ROOT / "examples" / "organ" / "scene.toml")
    dyn.solver.kind, dyn.solver.dt, dyn.solver.steps = "implicit_euler", 0.01, 6
    yield "organ, implicit_euler", dyn
    liver = (8, 6, 4) if quick else (12, 9, 6)
    yield (f"liver-like tetra10 {liver}, implicit_euler",
           bar("liver", "tetra10", liver, (0.15, 0.1, 0.08), law="neohookean", E=5e3, nu=0.45, rho=1050.0))
    yield (f"liver-like tetra10 {liver}, static",
           bar("liver_static", "tetra10", liver, (0.15, 0.1, 0.08), law="neohookean", E=5e3, nu=0.45, rho=1050.0,
               kind="static", steps=3))
    bodies = {"tetra_1k": ("tetra", (12, 3, 5), (2.0, 0.5, 1.0)),
              "hexahedron_2k": ("hexahedron", (24, 9, 9), (3.0, 0.9, 0.9))}
    if not quick:
        bodies.update({"tetra_10k": ("tetra", (24, 6, 12), (2.0, 0.5, 1.0)),
                       "hexahedron_20k": ("hexahedron", (60, 18, 18), (3.0, 0.9, 0.9))})
    for name, (element, cells, size) in bodies.items():
        quad = "gauss1" if element == "tetra" else "gauss2"
        yield f"bench {name} stvk, implicit_euler", bar(name, element, cells, size, quad=quad)
        yield f"bench {name} stvk, static", bar(name, element, cells, size, quad=quad, kind="static", steps=3,
                                                 E=1e7)
    yield ("bench hexahedron_2k stvk, explicit",
           bar("explicit", "hexahedron", (24, 9, 9), (3.0, 0.9, 0.9), kind="explicit", dt=2e-5, steps=60))


def measure(scene) -> tuple:
    """(predicted s/step, measured s/step: the mean of the steps after the first, as the run's
    report prints it ("after the first"), Newton iterations per step)."""
    predicted = estimate(scene).seconds_per_step
    summary = tm.Simulation(scene, output=False).run()
    t, steps = summary["time"], summary["steps"]
    after = (t["total"] - t["setup"] - t["first_step"]) / max(steps - 1, 1)
    return predicted, after, summary["iterations"]["newton"] / steps


def main(argv) -> int:
    quick = "--quick" in argv
    print("| case | dofs | predicted | measured | measured / predicted | Newton its / step |")
    print("|---|---|---|---|---|---|")
    for label, scene in cases(quick):
        start = time.perf_counter()
        predicted, measured, newton = measure(scene)
        dofs = estimate(scene).dofs
        print(f"| {label} | {dofs} | {predicted * 1e3:.3g} ms | {measured * 1e3:.3g} ms | "
              f"{measured / predicted:.2f} | {newton:.2f} |", flush=True)
        print(f"  ({time.perf_counter() - start:.1f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
